"""CPU and memory of processes and of the whole machine, read from /proc (Linux).

The benchmarks use these to say how busy the machine was while they measured: on a shared 2-core
machine a step rate means little without it.
"""

from __future__ import annotations

import os
from pathlib import Path

TICKS_PER_S = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def proc_sample(pid: int) -> tuple[float, int] | None:
    """(RSS in MB, utime+stime in clock ticks) of process `pid`, None once it is gone."""
    try:
        status = Path(f"/proc/{pid}/status").read_text()
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rss_kb = next((int(ln.split()[1]) for ln in status.splitlines() if ln.startswith("VmRSS:")), 0)
    fields = stat[stat.rindex(")") + 2 :].split()  # after "pid (comm) "
    return rss_kb / 1024, int(fields[11]) + int(fields[12])  # utime, stime (fields 14, 15)


def machine_cpu() -> tuple[float, float] | None:
    """(busy, total) jiffies of the whole machine, or None where /proc/stat is missing."""
    try:
        with open("/proc/stat") as fh:
            f = [float(x) for x in fh.readline().split()[1:]]
    except (OSError, ValueError):
        return None
    idle = f[3] + (f[4] if len(f) > 4 else 0.0)
    return sum(f) - idle, sum(f)


def children(pid: int) -> list[int]:
    """The direct child processes of `pid` (empty where /proc does not list them)."""
    out: list[int] = []
    try:
        for task in os.listdir(f"/proc/{pid}/task"):
            out += [int(c) for c in Path(f"/proc/{pid}/task/{task}/children").read_text().split()]
    except OSError:
        pass
    return out


def cpu_ticks(pids: dict[str, list[int]]) -> dict[str, int]:
    """utime+stime ticks summed per named group of processes (a process gone counts 0)."""
    return {name: sum((s[1] if (s := proc_sample(p)) else 0) for p in group) for name, group in pids.items()}


def cores_used(before: dict[str, int], after: dict[str, int], seconds: float) -> dict[str, float]:
    """Mean cores each group used between two `cpu_ticks` readings `seconds` apart."""
    if seconds <= 0:
        return {}
    return {k: round((after.get(k, 0) - v) / TICKS_PER_S / seconds, 3) for k, v in before.items()}


def busy_fraction(before: tuple[float, float] | None, after: tuple[float, float] | None) -> float | None:
    """The machine's busy fraction between two `machine_cpu` readings."""
    if before is None or after is None or after[1] <= before[1]:
        return None
    return round((after[0] - before[0]) / (after[1] - before[1]), 3)
