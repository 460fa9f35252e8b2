"""`sme bench gap`: the largest observation->action gap of a gridworld while a retina on the same
agent learns and re-embeds, with learning on the act path ("inline": each learning job runs inside
the act that starts it, as before issue 11) and off it ("background": jobs on the shared pool,
swapped in `lag` acts later), in one run.

The agent daemon runs in this process (its default: every world answered from the bus callback),
the two worlds in their own processes (`sme world gridworld|retina --stats-json`); each world
measures every step's gap (observation published -> its action received, resends included).
The agent side also times each `WorldLink.answer` (decode excluded), in wall time and in the act
thread's own CPU time: a long wall time with a short CPU time is the act thread not running (the
OS scheduling a busy machine, or another thread holding the GIL), not work on the act path.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import subprocess
import sys
import tempfile
import threading
import time

import numpy as np

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.base import Program
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.tools.common import free_port

MODES = ("inline", "background")
WORLDS = ("gridworld", "retina")
TARGET_MAX_MS = 20.0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gap",
        help="max observation->action gap: gridworld beside a re-embedding retina, learning inline vs background",
        description="Run a gridworld and a retina (each its own process) against one agent daemon "
        "over zenoh on loopback, once with learning jobs inline on the act path and once in the "
        "background; report each world's steps, p50/p99/max observation->action gap and embeddings.",
    )
    p.add_argument("--seconds", type=float, default=30.0, help="seconds per mode (default 30)")
    p.add_argument("--modes", default=",".join(MODES), help="comma-separated modes (default inline,background)")
    p.add_argument("--retina-embed-every", type=int, default=50, help="retina saccades between embeddings (default 50)")
    p.add_argument("--warmup", type=int, default=50, help="steps per world left out of the statistics (default 50)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def run_mode(mode: str, seconds: float, retina_embed_every: int, warmup: int) -> list[dict]:
    """One mode: the daemon here, both worlds as processes for `seconds`; a row per world."""
    if mode not in MODES:
        raise ValueError(f"mode must be one of {MODES}, not {mode!r}")
    ep = f"tcp/127.0.0.1:{free_port()}"
    before = Program.inline_background
    Program.inline_background = mode == "inline"
    embeddings: dict[str, int] = {}

    def on_output(channel: str, msg: object) -> None:
        if channel == "embedding":
            wid = getattr(msg, "world_id", "")
            embeddings[wid] = embeddings.get(wid, 0) + 1

    answer_ms: dict[str, list[tuple[float, float]]] = {}  # (wall, this thread's CPU) per answer
    original = WorldLink.answer

    def timed(link: WorldLink, obs: object) -> object:
        t, c = time.perf_counter(), time.thread_time()
        try:
            return original(link, obs)  # type: ignore[arg-type]
        finally:
            wall, cpu = (time.perf_counter() - t) * 1e3, (time.thread_time() - c) * 1e3
            answer_ms.setdefault(link.world_id, []).append((wall, cpu))

    procs: dict[str, subprocess.Popen] = {}
    quiet = logging.getLogger("sme.agent")
    level = quiet.level
    quiet.setLevel(logging.WARNING)
    WorldLink.answer = timed  # type: ignore[method-assign,assignment]
    try:
        with tempfile.TemporaryDirectory() as tmp, Bus(BusConfig.for_role("agent", ep)) as bus:
            daemon = AgentDaemon(
                bus,
                "gap",
                program_params={"retina": {"embed_every": retina_embed_every}},
                on_output=on_output,
            )
            links = daemon.links
            daemon.start()
            th = threading.Thread(target=daemon.run, daemon=True)
            th.start()
            load = os.getloadavg()[0]  # the machine's state: a shared machine stretches every gap
            for kind in WORLDS:
                cmd = [sys.executable, "-m", "sensorimotor.tools.cli", "world", kind, "--id", f"gap-{kind}"]
                cmd += ["--seconds", str(seconds), "--warmup", str(warmup), "--stats-json", os.path.join(tmp, kind)]
                # stdout stays clean for --json: PyBullet's C code prints its build time there
                procs[kind] = subprocess.Popen([*cmd, "--connect", ep, "-q"], stdout=subprocess.DEVNULL)
            try:
                for p in procs.values():
                    p.wait(timeout=seconds + 120)
            finally:
                for p in procs.values():
                    if p.poll() is None:
                        p.kill()
                        p.wait()
                daemon.stop()
                th.join(timeout=5)
                daemon.close()
            rows = []
            for kind in WORLDS:
                path = os.path.join(tmp, kind)
                if procs[kind].returncode != 0 or not os.path.exists(path):
                    raise RuntimeError(f"{kind} world process failed (exit {procs[kind].returncode})")
                with open(path) as f:
                    st = json.load(f)
                link = links.get(f"gap-{kind}")
                bg = link.program.background if link is not None else None
                ms = np.asarray(answer_ms.get(f"gap-{kind}", [])[warmup:] or [(0.0, 0.0)])
                rows.append(
                    {
                        "bench": "gap",
                        "mode": mode,
                        "world": kind,
                        "seconds": st["seconds"],
                        "steps": st["steps"],
                        "steps_per_s": st["steps_per_s"],
                        "resends": st["resends"],
                        "embeddings": embeddings.get(f"gap-{kind}", 0),
                        "p50_ms": st.get("p50_ms"),
                        "p99_ms": st.get("p99_ms"),
                        "max_ms": st.get("max_ms"),
                        "agent_answer_p99_ms": round(float(np.percentile(ms[:, 0], 99)), 4),
                        "agent_answer_max_ms": round(float(ms[:, 0].max()), 4),
                        "agent_answer_cpu_max_ms": round(float(ms[:, 1].max()), 4),
                        "load_average": round(load, 2),
                        "learning_waits": None if bg is None else bg.waits,
                        "target_max_ms": TARGET_MAX_MS,
                    }
                )
            return rows
    finally:
        Program.inline_background = before
        WorldLink.answer = original  # type: ignore[method-assign]
        quiet.setLevel(level)


def main(seconds: float, modes: tuple[str, ...], retina_embed_every: int, warmup: int, as_json: bool) -> int:
    """Run each mode in turn and print a row per world and mode."""
    for mode in modes:
        t0 = time.monotonic()
        rows = run_mode(mode, seconds, retina_embed_every, warmup)
        for r in rows:
            if as_json:
                print(json.dumps(r), flush=True)
            else:
                print(
                    f"{mode:<10} {r['world']:<9} {r['steps']:>7} steps {r['steps_per_s']:>8,.0f}/s  "
                    f"{r['embeddings']:>3} embeddings  gap p50 {r['p50_ms']} ms  p99 {r['p99_ms']} ms  "
                    f"max {r['max_ms']} ms; agent answer p99 {r['agent_answer_p99_ms']} ms "
                    f"max {r['agent_answer_max_ms']} ms (CPU {r['agent_answer_cpu_max_ms']} ms); "
                    f"load {r['load_average']}",
                    flush=True,
                )
        if not as_json:
            print(f"({mode}: {time.monotonic() - t0:.0f} s)")
    return 0


def main_args(args: argparse.Namespace) -> int:
    modes = tuple(m.strip() for m in args.modes.split(",") if m.strip())
    bad = [m for m in modes if m not in MODES]
    if bad or not modes or args.seconds <= 0 or args.retina_embed_every < 1 or args.warmup < 0:
        what = f"unknown mode(s) {bad}; choose from {list(MODES)}" if bad or not modes else "bad bound"
        print(f"sme bench gap: {what}", file=sys.stderr)
        return 2
    return main(args.seconds, modes, args.retina_embed_every, args.warmup, args.json)
