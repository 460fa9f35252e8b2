"""`sme bench scale`'s summary against its targets, and the echo program's stand-in learner work."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import numpy as np

from sensorimotor.agent.programs.base import EchoProgram
from sensorimotor.protocol.messages import Observation
from sensorimotor.tools.bench.scale import summarize
from sensorimotor.worlds.bench import BenchWorld


def _row(workers: int, worlds: int, rate: float, busy: float, pp: float | None = None) -> dict:
    r = {"workers": workers, "worlds": worlds, "steps_per_s": rate, "machine_cpu_busy": busy, "agent_work_us": 0.0}
    if pp is not None:
        r.update(over_pingpong=rate / pp, over_pingpong_callback=rate / (1.5 * pp))
    return r


def test_summary_takes_medians_over_rounds_and_the_cpu_estimate():
    by = {
        (1, 1): [_row(1, 1, 2400, 0.5, 4000), _row(1, 1, 1800, 0.5, 4500), _row(1, 1, 2500, 0.5, 4000)],
        (1, 8): [_row(1, 8, 4000, 0.8)],
        (2, 8): [_row(2, 8, 6000, 1.0)],
    }
    s = summarize(by, [1, 8], 2, {"seconds": 1.5})
    assert s["single_world_steps_per_s"] == 2400
    assert s["single_world_over_pingpong"] == np.median([0.6, 0.4, 0.625]) == 0.6
    assert s["rounds"] == 3 and s["speedup_at_8_worlds"] == 1.5
    assert s["speedup_cpu_estimate_at_8_worlds"] == 1.25 and s["failover_seconds"] == 1.5
    assert s["targets"]["speedup_at_8_worlds"] == 1.6


def test_echo_work_us_spends_that_much_cpu_per_answer():
    w = BenchWorld(obs_bytes=16)
    obs = Observation("bench", 0, 0, 0, w.reset().tensors)
    idle, busy = EchoProgram(w.spec()), EchoProgram(w.spec(), work_us=3000)
    t0 = time.thread_time()
    for _ in range(5):
        assert idle.act(obs).values == (0.0,)
    t1 = time.thread_time()
    for _ in range(5):
        assert busy.act(obs).values == (0.0,)
    t2 = time.thread_time()
    assert t2 - t1 >= 5 * 3000e-6 and t1 - t0 < 5 * 3000e-6 / 10


def test_summary_reports_the_worlds_cpu_and_the_gap():
    row = _row(1, 1, 2400, 0.5, 4000)
    by = {(1, 1): [row], (1, 8): [{**_row(1, 8, 6000, 0.9), "world_cpu_cores": 1.15}], (2, 8): [_row(2, 8, 5000, 1.0)]}
    gaps = [{"bench": "gap", "world": "gridworld", "max_ms": 12.5}, {"bench": "gap", "world": "retina", "max_ms": 30.1}]
    s = summarize(by, [1, 8], 2, None, gaps)
    assert s["gridworld_max_gap_ms"] == 12.5 and s["targets"]["gridworld_max_gap_ms"] == 20.0
    assert s["single_world_over_pingpong"] == 0.6 and s["single_world_over_pingpong_callback"] == 0.4
    assert s["world_cpu_cores_at_8_worlds_workers_1"] == 1.15 and s["speedup_at_8_worlds"] == 0.83


def test_bench_scale_runs_end_to_end(tmp_path):
    """A shortened `sme bench scale`: one world, one round, the ping-pong baseline (failover has its
    own tests in test_owners.py)."""
    out = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "bench", "scale", "--worlds", "1", "--rounds", "1"]
        + [
            "--seconds",
            "4",
            "--workers",
            "1",
            "--obs-bytes",
            "256",
            "--no-failover",
            "--gap-seconds",
            "0",
            "--json",
            "-q",
        ],
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert out.returncode == 0, out.stderr[-2000:]
    rows = [json.loads(line) for line in out.stdout.splitlines()]
    (scale,) = [r for r in rows if r["bench"] == "scale"]
    assert scale["steps_per_s"] > 100 and scale["world_cpu_cores"] > 0
    assert scale["pingpong"]["round_trips_per_s"] > 100 and scale["over_pingpong"] > 0
    assert rows[-1]["bench"] == "scale-summary" and rows[-1]["single_world_steps_per_s"] == scale["steps_per_s"]
