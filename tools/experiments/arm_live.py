"""The arm live over the bus, several seeds at once: one `sme agent` and `--seeds` arm worlds
(`sme world arm --seed S --id arm-S`, defaults: the Kuka iiwa, joints 2 and 4, 7 x 7 starts) on
loopback Zenoh; every `--every` seconds the agent's status is read, and at the end each world's
last embedding error, the step it first fell below 0.1, and the drops the agent detected.

With `--changes`, world arm-S gets the S-th body change once it has embedded below 0.1 and run
`--settle` more steps (`sme perturb`, as a user would); `sme watch --json` tells when the agent
detected the drop and the error of its `relearned` embedding against the changed body.

    python -m sensorimotor.tools.experiments.arm_live --seeds 5 --seconds 600
    python -m sensorimotor.tools.experiments.arm_live --seeds 3 --seconds 300 --changes
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import threading
import time
from typing import Any

from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.tools.commands.status import fetch_status
from sensorimotor.tools.common import free_port

#: the body changes of `--changes`, one per world in turn (the Kuka's link 4 and joints 2 and 4)
CHANGES = (
    ("morph", ["link=lbr_iiwa_link_4", "scale=1.3"]),
    ("lesion", ["joint=lbr_iiwa_joint_2", "at=-0.2"]),
    ("reverse", ["joint=lbr_iiwa_joint_4"]),
)


def main(
    seeds: int,
    seconds: float,
    every: float = 2.0,
    params: list[str] | None = None,
    changes: bool = False,
    settle: int = 2000,
) -> dict[str, Any]:
    """Run the agent and the worlds for `seconds`; per seed its links' last status rows (and, with
    `changes`, what became of its body change)."""
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    cli = [sys.executable, "-m", "sensorimotor.tools.cli"]
    quiet = ["-q", "--no-multicast-scouting"]
    procs: list[subprocess.Popen[Any]] = [
        subprocess.Popen([*cli, "agent", "--listen", endpoint, *quiet], stderr=subprocess.DEVNULL)
    ]
    extra = [a for p in params or [] for a in ("--param", p)]
    for s in range(seeds):
        cmd = [*cli, "world", "arm", "--seed", str(s), "--id", f"arm-{s}", *extra, "--connect", endpoint, *quiet]
        procs.append(subprocess.Popen(cmd, stderr=subprocess.DEVNULL))
    seen: dict[int, dict[str, Any]] = {}
    rows: list[dict[str, Any]] = []
    if changes:
        watch = subprocess.Popen(
            [*cli, "watch", "--json", "--connect", endpoint, "--no-multicast-scouting"],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
        )
        procs.append(watch)
        assert watch.stdout is not None
        out = watch.stdout
        threading.Thread(target=lambda: rows.extend(json.loads(line) for line in out), daemon=True).start()
    t0 = time.monotonic()
    try:
        bus = None
        while bus is None:  # the agent takes a moment to listen
            try:
                bus = Bus(BusConfig.for_role("tool", endpoint))
            except BusError:
                if time.monotonic() - t0 > 60:
                    raise
                time.sleep(0.5)
        with bus:
            while time.monotonic() - t0 < seconds:
                try:
                    st = fetch_status(bus, "a0", 2.0)
                except BusError:
                    st = None
                for ln in st.links if st is not None else []:
                    if not ln.world_id.startswith("arm-") or not ln.embedding_version:
                        continue
                    row = seen.setdefault(int(ln.world_id[4:]), {"first_below_0.1": None})
                    row.update(steps=int(ln.steps), version=int(ln.embedding_version), drops=int(ln.drops))
                    row["error"] = round(float(ln.last_procrustes_error), 4)
                    if row["first_below_0.1"] is None and row["error"] < 0.1:
                        row["first_below_0.1"] = row["steps"]
                    s = int(ln.world_id[4:])
                    if changes and "change" not in row and row["first_below_0.1"] is not None:
                        if row["steps"] >= row["first_below_0.1"] + settle:
                            kind, kv = CHANGES[s % len(CHANGES)]
                            cmd = [*cli, "perturb", kind, "--world", ln.world_id, "--connect", endpoint]
                            cmd += [a for x in kv for a in ("--param", x)]
                            done = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
                            row.update(change=f"{kind} {' '.join(kv)}", change_exit=done.returncode)
                            row["changed_at"] = row["steps"]
                time.sleep(every)
    finally:
        for p in procs:
            p.terminate()
        for p in procs:
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
    for s, row in seen.items():
        if "change" not in row:
            continue
        mine = [r for r in rows if r.get("world") == f"arm-{s}"]
        drops = [r["step"] for r in mine if r.get("kind") == "drop_detected"]
        rel = next((r for r in mine if r.get("trigger") == "relearned"), None)
        row["detected_at"] = drops[0] if drops else None
        row["relearned"] = None if rel is None else {"step": rel["step"], "error": round(rel["procrustes_error"], 4)}
    return {"seeds": seen, "seconds": round(time.monotonic() - t0)}


def _cli(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensorimotor.tools.experiments.arm_live", description=__doc__)
    p.add_argument("--seeds", type=int, default=5, help="arm worlds, seeds 0..N-1 (default 5)")
    p.add_argument("--seconds", type=float, default=600.0, help="how long to run (default 600)")
    p.add_argument("--param", action="append", metavar="K=V", help="world parameter for every arm")
    p.add_argument(
        "--changes", action="store_true", help="give world arm-S the S-th body change (morph, lesion, reverse)"
    )
    p.add_argument("--settle", type=int, default=2000, help="steps after the first error below 0.1 before the change")
    a = p.parse_args(argv)
    if a.seeds < 1 or a.seconds <= 0:
        p.error("--seeds must be >= 1 and --seconds > 0")
    res = main(a.seeds, a.seconds, params=a.param, changes=a.changes, settle=a.settle)
    for s, row in sorted(res["seeds"].items()):
        print(f"seed {s}: {row}")
    errors = [row["error"] for row in res["seeds"].values()]
    if not errors:
        print(f"no embedding in {res['seconds']} s")
        return 1
    drops = sum(row["drops"] for row in res["seeds"].values())
    what = "one body change per world" if a.changes else "no change was made"
    print(
        f"{len(errors)} of {a.seeds} worlds embedded; final error mean {sum(errors) / len(errors):.4f}, "
        f"worst {max(errors):.4f}; drops detected {drops} ({what}); {res['seconds']} s"
    )
    return 0


if __name__ == "__main__":
    sys.exit(_cli())
