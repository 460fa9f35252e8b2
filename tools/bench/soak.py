"""`sme bench soak`: a long run of the whole system, watched for leaks.

Starts an agent, three worlds (gridworld, retina, mountaincar) and a recorder as `sme` subprocesses
on a free loopback port, and every `--every` seconds samples each process's RSS and CPU (from
/proc), the embeddings published per minute (counted by a subscriber) and the error and warning
lines in the processes' stderr. Writes OUT/soak.jsonl (one sample a line), OUT/soak.png and
OUT/summary.json, and prints the summary: RSS growth of each process after the first 5 minutes
(the warm-up: imports, caches, first policy iterations).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusMessage
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import Embedding
from sensorimotor.tools.bench.procstat import TICKS_PER_S as TICK
from sensorimotor.tools.bench.procstat import proc_sample
from sensorimotor.tools.common import free_port, require

WARMUP_S = 300.0  # RSS growth is measured from the first sample at or after this time
PROBLEM = re.compile(r"\b(ERROR|WARNING|CRITICAL)\b|Traceback")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "soak", help="long run of agent + worlds + recorder: RSS, CPU, embeddings/min", description=__doc__
    )
    p.add_argument("--minutes", type=float, default=30.0, help="how long to run (default 30)")
    p.add_argument("--out", default="soak-out", help="output directory (default ./soak-out)")
    p.add_argument("--every", type=float, default=20.0, help="seconds between samples (default 20)")
    p.add_argument("--keep-recording", action="store_true", help="keep OUT/soak.mcap (deleted by default)")
    p.set_defaults(
        func=lambda a: main(a.minutes, a.out, every=a.every, keep_recording=a.keep_recording),
    )


@dataclass
class Proc:
    """One `sme` subprocess and what the soak has read of it."""

    name: str
    popen: subprocess.Popen
    stderr_path: Path
    stderr: IO[str]
    cpu_ticks: int = 0
    problems: int = 0
    last_problems: list[str] = field(default_factory=list)


def start(name: str, args: list[str], out: Path) -> Proc:
    """Start `sme ARGS` with its stderr in OUT/NAME.stderr."""
    path = out / f"{name}.stderr"
    err = open(path, "w")
    popen = subprocess.Popen(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args],
        stdout=subprocess.DEVNULL,
        stderr=err,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    return Proc(name, popen, path, open(path))


def new_problems(p: Proc) -> int:
    """Count the error/warning lines written to the process's stderr since the last call."""
    n = 0
    for line in p.stderr.readlines():
        if PROBLEM.search(line):
            n += 1
            p.last_problems = (p.last_problems + [line.rstrip()])[-5:]
    p.problems += n
    return n


def run(minutes: float, out: Path, every: float = 20.0, keep_recording: bool = False) -> dict[str, Any]:
    """Run the soak; returns the summary (also written to OUT/summary.json)."""
    out.mkdir(parents=True, exist_ok=True)
    ep = f"tcp/127.0.0.1:{free_port()}"
    bus_args = ["--connect", ep]
    recording = out / "soak.mcap"
    procs = [start("agent", ["agent", "--listen", ep, "--state-dir", str(out / "state")], out)]
    time.sleep(2.0)  # the router first; the others wait for it anyway
    procs += [
        start("gridworld", ["world", "gridworld", "--id", "g1", *bus_args], out),
        start("retina", ["world", "retina", "--id", "r1", *bus_args], out),
        start("mountaincar", ["world", "mountaincar", "--id", "m1", *bus_args], out),
        start("recorder", ["record", str(recording), *bus_args], out),
    ]
    samples: list[dict[str, Any]] = []
    counts: dict[str, int] = {}
    versions: dict[str, int] = {}  # the highest embedding version heard per world
    repeats: dict[str, int] = {}  # versions heard that were not above the highest before them

    def on_embedding(msg: BusMessage) -> None:
        wid = keys.world_of(msg.key)
        counts[wid] = counts.get(wid, 0) + 1
        try:
            v = int(codec.decode(Embedding, msg.payload).version)
        except ProtocolError:
            return
        if wid in versions and v <= versions[wid]:
            repeats[wid] = repeats.get(wid, 0) + 1
        versions[wid] = max(v, versions.get(wid, v))

    try:
        with Bus(BusConfig.for_role("world", ep), wait_limit=120) as bus, open(out / "soak.jsonl", "w") as jl:
            bus.subscribe(keys.ALL_EMBEDDINGS, on_embedding)
            t0 = last = time.monotonic()
            last_total = 0
            for p in procs:
                s = proc_sample(p.popen.pid)
                p.cpu_ticks = s[1] if s else 0
            while True:
                now = time.monotonic()
                wait = min(every, t0 + minutes * 60 - now)
                if wait > 0:
                    time.sleep(wait)
                now = time.monotonic()
                dt = now - last
                total = sum(counts.values())
                row: dict[str, Any] = {
                    "t": round(now - t0, 1),
                    "embeddings_per_min": round((total - last_total) * 60 / dt, 2) if dt > 0 else 0.0,
                    "embeddings": dict(counts),
                    "versions": dict(versions),
                    "version_repeats": dict(repeats),
                    "procs": {},
                }
                for p in procs:
                    s = proc_sample(p.popen.pid) if p.popen.poll() is None else None
                    rec: dict[str, Any] = {"alive": s is not None, "problems": new_problems(p)}
                    if s is not None:
                        rec["rss_mb"] = round(s[0], 1)
                        rec["cpu_pct"] = round(100 * (s[1] - p.cpu_ticks) / TICK / dt, 1) if dt > 0 else 0.0
                        p.cpu_ticks = s[1]
                    row["procs"][p.name] = rec
                samples.append(row)
                jl.write(json.dumps(row) + "\n")
                jl.flush()
                last, last_total = now, total
                if now - t0 >= minutes * 60 - 1e-6:
                    break
    finally:
        for p in procs:
            if p.popen.poll() is None:
                p.popen.send_signal(signal.SIGINT)
        for p in procs:
            try:
                p.popen.wait(15)
            except subprocess.TimeoutExpired:
                p.popen.kill()
                p.popen.wait()
            new_problems(p)
            p.stderr.close()
    summary = summarize(samples, procs, minutes)
    summary["recording_mb"] = round(recording.stat().st_size / 2**20, 1) if recording.exists() else None
    if recording.exists() and not keep_recording:
        recording.unlink()
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    plot(samples, out / "soak.png")
    return summary


def summarize(samples: list[dict[str, Any]], procs: list[Proc], minutes: float) -> dict[str, Any]:
    """Per process: RSS at the end of the warm-up and at the end, growth between them (%), peak,
    mean CPU, error/warning lines; embeddings in all and per minute."""
    base = next((s for s in samples if s["t"] >= WARMUP_S), samples[0] if samples else None)
    per: dict[str, Any] = {}
    for p in procs:
        rows = [s["procs"][p.name] for s in samples if s["procs"][p.name].get("rss_mb") is not None]
        first = base["procs"][p.name].get("rss_mb") if base else None
        final = rows[-1]["rss_mb"] if rows else None
        per[p.name] = {
            "rss_mb_after_warmup": first,
            "rss_mb_end": final,
            "rss_growth_pct": round(100 * (final - first) / first, 2) if first and final else None,
            "rss_mb_peak": max((r["rss_mb"] for r in rows), default=None),
            "cpu_pct_mean": round(sum(r["cpu_pct"] for r in rows) / len(rows), 1) if rows else None,
            "alive_at_end": bool(samples and samples[-1]["procs"][p.name]["alive"]),
            "exit_code": p.popen.returncode,
            "error_warning_lines": p.problems,
            "last_error_warning_lines": p.last_problems,
        }
    total = sum(samples[-1]["embeddings"].values()) if samples else 0
    return {
        "minutes": minutes,
        "samples": len(samples),
        "warmup_s": WARMUP_S if base is not None and base["t"] >= WARMUP_S else (base["t"] if base else None),
        "embeddings": dict(samples[-1]["embeddings"]) if samples else {},
        # embedding versions never repeat nor go back (per world: the highest heard, and how many were not above it)
        "versions": dict(samples[-1].get("versions", {})) if samples else {},
        "version_repeats": sum(samples[-1].get("version_repeats", {}).values()) if samples else 0,
        "embeddings_per_min": round(total / (samples[-1]["t"] / 60), 2) if samples and samples[-1]["t"] else 0.0,
        "procs": per,
    }


def plot(samples: list[dict[str, Any]], path: Path) -> None:
    """RSS and CPU of each process and embeddings per minute against time, as a PNG."""
    mpl = require("matplotlib")
    mpl.use("Agg")
    plt = require("matplotlib.pyplot")
    fig, (a1, a2, a3) = plt.subplots(3, 1, figsize=(9, 9), sharex=True)
    t = [s["t"] / 60 for s in samples]
    names = list(samples[0]["procs"]) if samples else []
    for name in names:
        a1.plot(t, [s["procs"][name].get("rss_mb") for s in samples], label=name)
        a2.plot(t, [s["procs"][name].get("cpu_pct") for s in samples], label=name)
    a3.plot(t, [s["embeddings_per_min"] for s in samples], color="k")
    if t and t[-1] >= WARMUP_S / 60:
        a1.axvline(WARMUP_S / 60, color="grey", linestyle=":")  # growth is measured from here
    a1.set_ylabel("RSS (MB)")
    a2.set_ylabel("CPU (%)")
    a3.set_ylabel("embeddings / min")
    a3.set_xlabel("minutes")
    a1.legend(fontsize=8)
    a1.set_title("sme bench soak")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(minutes: float, out: str, every: float = 20.0, keep_recording: bool = False) -> int:
    """Run the soak and print its summary; exit status 1 if a process died or exited with an error."""
    if minutes <= 0 or every <= 0:
        print("sme bench soak: --minutes and --every must be > 0", file=sys.stderr)
        return 2
    summary = run(minutes, Path(out), every, keep_recording)
    print(json.dumps(summary, indent=1))
    for name, p in summary["procs"].items():
        growth = p["rss_growth_pct"]
        print(
            f"{name:<12} RSS {p['rss_mb_after_warmup']} -> {p['rss_mb_end']} MB "
            f"({'n/a' if growth is None else f'{growth:+.2f} %'} after the warm-up), peak {p['rss_mb_peak']} MB, "
            f"CPU {p['cpu_pct_mean']} %, error/warning lines {p['error_warning_lines']}"
        )
    print(f"embeddings: {summary['embeddings']} ({summary['embeddings_per_min']}/min); files in {out}")
    print(f"embedding versions: highest {summary['versions']}, not above the one before: {summary['version_repeats']}")
    # 130 / -SIGINT: a process still starting up when the soak stopped it with SIGINT
    stopped = (0, 130, -signal.SIGINT, None)
    ok = all(p["alive_at_end"] and p["exit_code"] in stopped for p in summary["procs"].values())
    ok = ok and summary["version_repeats"] == 0
    return 0 if ok else 1
