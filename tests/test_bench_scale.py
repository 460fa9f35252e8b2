"""`sme bench scale`'s summary against its targets, and the echo program's stand-in learner work."""

from __future__ import annotations

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
