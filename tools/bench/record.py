"""`sme bench record`: can the recorder keep up? Two worlds in lockstep at full speed with the
daemon, and the recorder on the same bus; every observation the worlds published and every
action the daemon published is counted against what the recorder wrote."""

from __future__ import annotations

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
import threading
import time

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.tools.commands.record import Recorder
from sensorimotor.tools.common import free_port
from sensorimotor.tools.mcap_io import read


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("record", help="recorder throughput with two lockstep worlds", description=__doc__)
    p.add_argument("--steps", type=int, default=10000, help="steps per world (default 10000)")
    p.add_argument("--obs-bytes", type=int, default=16384, help="observation size (default 16 KB)")
    p.add_argument("--json", action="store_true", help="one JSON object")
    p.set_defaults(func=main_args)


def run(steps: int, obs_bytes: int, timeout: float = 600.0) -> dict:
    ep = f"tcp/127.0.0.1:{free_port()}"
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    with (
        tempfile.TemporaryDirectory() as tmp,
        Bus(BusConfig.for_role("agent", ep)) as abus,
        Bus(BusConfig.for_role("world", ep)) as rbus,
    ):
        daemon = AgentDaemon(abus, "bench")
        daemon.start()
        th = threading.Thread(target=daemon.run, daemon=True)
        th.start()
        path = os.path.join(tmp, "bench.mcap")
        rec = Recorder(rbus, path).start()
        time.sleep(0.5)
        procs, stats = [], []
        t0 = time.monotonic()
        for i in (1, 2):
            f = os.path.join(tmp, f"w{i}.json")
            stats.append(f)
            procs.append(
                subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "sensorimotor.tools.cli",
                        "world",
                        "bench",
                        "--id",
                        f"w{i}",
                        "--steps",
                        str(steps),
                        "--param",
                        f"obs_bytes={obs_bytes}",
                        "--stats-json",
                        f,
                        "--connect",
                        ep,
                        "-q",
                    ],
                    cwd=root,
                )
            )
        try:
            for p in procs:
                p.wait(timeout)
        finally:
            for p in procs:
                if p.poll() is None:
                    p.kill()
        seconds = time.monotonic() - t0
        time.sleep(1.0)  # the last messages reach the recorder
        rec.stop()
        daemon.stop()
        th.join(5)
        daemon.close()
        answered = {wid: ln.counters.steps + ln.counters.duplicates for wid, ln in daemon.links.items()}
        counts = collections.Counter(r.topic for r in read(path))
        size = os.path.getsize(path)
        worlds = {}
        for i, f in enumerate(stats, 1):
            with open(f) as fh:
                st = json.load(fh)
            wid = f"w{i}"
            worlds[wid] = {
                "obs_published": st["published"],
                "obs_written": counts[keys.world_obs(wid)],
                "actions_published": answered.get(wid, 0),
                "actions_written": counts[keys.world_act(wid)],
                "steps": st["steps"],
            }
    total_pub = sum(w["obs_published"] + w["actions_published"] for w in worlds.values())
    total_written = sum(w["obs_written"] + w["actions_written"] for w in worlds.values())
    return {
        "bench": "record",
        "worlds": worlds,
        "seconds": round(seconds, 2),
        "messages_per_s": round(total_written / seconds, 1),
        "mb_per_s": round(size / seconds / 1e6, 2),
        "file_mb": round(size / 1e6, 2),
        "published": total_pub,
        "written": total_written,
        "all_written": all(
            w["obs_published"] == w["obs_written"] and w["actions_published"] == w["actions_written"]
            for w in worlds.values()
        ),
    }


def main_args(args: argparse.Namespace) -> int:
    r = run(args.steps, args.obs_bytes)
    if args.json:
        print(json.dumps(r))
    else:
        for wid, w in r["worlds"].items():
            print(
                f"{wid}: observations published {w['obs_published']}, written {w['obs_written']}; "
                f"actions published {w['actions_published']}, written {w['actions_written']}"
            )
        print(
            f"{r['written']} of {r['published']} messages written in {r['seconds']} s "
            f"({r['messages_per_s']:,.0f} msg/s, {r['mb_per_s']} MB/s compressed); all written: {r['all_written']}"
        )
    return 0 if r["all_written"] else 1
