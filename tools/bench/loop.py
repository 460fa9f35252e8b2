"""`sme bench loop`: lockstep steps/s and round-trip latency between a world process and the daemon
over zenoh on loopback, against the same world/program loop run in-process.

The world runs in a separate process (spawned, as a user would run `sme world bench`), the daemon
in this one; the world measures each round trip (observation published -> its action received).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.programs.base import EchoProgram
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import Observation
from sensorimotor.tools.common import free_port
from sensorimotor.worlds.bench import BenchWorld


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "loop",
        help="lockstep loop over zenoh vs in-process",
        description="Measure lockstep steps/s and round-trip latency (p50/p99) between a world "
        "process and the agent daemon over zenoh on loopback (free port, no multicast), and "
        "the same loop in-process; print both and their ratio.",
    )
    p.add_argument("--steps", type=int, default=20000, help="lockstep steps per measurement (default 20000)")
    p.add_argument("--obs-bytes", type=int, default=16384, help="observation size in bytes (default 16 KB)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def inprocess(steps: int, obs_bytes: int) -> dict:
    world = BenchWorld(obs_bytes=obs_bytes)
    program = EchoProgram(world.spec())
    lat = np.empty(steps)
    res = world.reset()
    t0 = time.perf_counter()
    ep = t = 0
    for k in range(steps):
        s = time.perf_counter()
        dec = program.act(Observation(world.world_id, ep, k, t, res.tensors, res.reward, res.done))
        if res.done:
            res, t, ep = world.reset(), 0, ep + 1
        else:
            res, t = world.step(np.asarray(dec.values)), t + 1
        lat[k] = time.perf_counter() - s
    sec = time.perf_counter() - t0
    return {
        "bench": "loop",
        "mode": "inprocess",
        "steps": steps,
        "obs_bytes": obs_bytes,
        "seconds": round(sec, 4),
        "steps_per_s": round(steps / sec, 1),
        "p50_ms": round(float(np.percentile(lat, 50)) * 1e3, 4),
        "p99_ms": round(float(np.percentile(lat, 99)) * 1e3, 4),
    }


def over_zenoh(steps: int, obs_bytes: int, timeout: float = 300.0, world_args: tuple[str, ...] = ()) -> dict:
    ep = f"tcp/127.0.0.1:{free_port()}"
    with tempfile.TemporaryDirectory() as tmp, Bus(BusConfig.for_role("agent", ep)) as bus:
        daemon = AgentDaemon(bus, "bench")
        daemon.start()
        th = threading.Thread(target=daemon.run, daemon=True)
        th.start()
        stats_file = os.path.join(tmp, "stats.json")
        cmd = [
            sys.executable,
            "-m",
            "sensorimotor.tools.cli",
            "world",
            "bench",
            "--id",
            "bench",
            "--steps",
            str(steps),
            "--param",
            f"obs_bytes={obs_bytes}",
            "--stats-json",
            stats_file,
            "--connect",
            ep,
            "-q",
            *world_args,
        ]
        proc = subprocess.Popen(cmd, cwd=os.path.dirname(os.path.dirname(os.path.dirname(__file__))))
        try:
            proc.wait(timeout=timeout)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
            daemon.stop()
            th.join(timeout=5)
            daemon.close()
        if proc.returncode != 0 or not os.path.exists(stats_file):
            raise RuntimeError(f"world process failed (exit {proc.returncode})")
        with open(stats_file) as f:
            st = json.load(f)
    return {
        "bench": "loop",
        "mode": "zenoh",
        "steps": st["steps"],
        "obs_bytes": obs_bytes,
        "seconds": st["seconds"],
        "steps_per_s": st.get("steady_steps_per_s", st["steps_per_s"]),
        "steps_per_s_including_attach": st["steps_per_s"],
        "p50_ms": st.get("p50_ms"),
        "p99_ms": st.get("p99_ms"),
        "resends": st["resends"],
    }


def main_args(args: argparse.Namespace) -> int:
    a = inprocess(args.steps, args.obs_bytes)
    b = over_zenoh(args.steps, args.obs_bytes)
    ratio = {
        "bench": "loop",
        "mode": "ratio",
        "inprocess_over_zenoh_steps_per_s": round(a["steps_per_s"] / b["steps_per_s"], 2),
        "zenoh_steps_per_s": b["steps_per_s"],
        "zenoh_p99_ms": b["p99_ms"],
        "target_steps_per_s": 2000,
        "target_p99_ms": 2.0,
        "meets_target": bool(b["steps_per_s"] >= 2000 and (b["p99_ms"] or 1e9) <= 2.0),
    }
    rows = [a, b, ratio]
    if args.json:
        for r in rows:
            print(json.dumps(r))
    else:
        for r in (a, b):
            print(
                f"{r['mode']:<10} {r['steps']:>7} steps  {r['steps_per_s']:>10,.0f} steps/s  "
                f"p50 {r['p50_ms']:.3f} ms  p99 {r['p99_ms']:.3f} ms"
            )
        print(
            f"in-process is {ratio['inprocess_over_zenoh_steps_per_s']}x the zenoh loop; target >= 2000 steps/s "
            f"and p99 <= 2 ms over zenoh: {'met' if ratio['meets_target'] else 'NOT met'}"
        )
    return 0
