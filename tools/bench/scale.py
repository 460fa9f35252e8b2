"""`sme bench scale`: aggregate lockstep steps/s and per-world p99 for 1, 2, 4, 8 bench worlds served
by one agent with `--workers 1` and `--workers N`, in one run; a raw Zenoh ping-pong of the same
message sizes through the same router as the baseline; the failover time (kill -9 of one of two
agents until its worlds are answered again by the other); and the max observation->action gap of a
gridworld beside a re-embedding retina (`bench.gap`, learning in the background).

Every process is a subprocess on loopback (free ports, no multicast): `sme agent`, `sme world bench`.
Aggregate steps/s is the sum of each world's steady rate (after its warm-up) over runs of the same
length started together. The single-world rate and the ping-pong alternate `--rounds` times (the
load of a shared machine drifts; the ratio is the median of the rounds'). Each row also says how busy
the whole machine was (from /proc/stat): when the worlds and the router already keep every core
busy with one worker, no number of workers can add throughput, and the row shows it.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from typing import Any

import numpy as np

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.messages import Action, AgentStatus, Observation
from sensorimotor.tools.bench import gap
from sensorimotor.tools.bench.procstat import busy_fraction, machine_cpu
from sensorimotor.tools.common import free_port

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "scale",
        help="steps/s and p99 for 1-8 worlds with 1 and N workers; ping-pong baseline; failover time; max gap",
        description="Serve 1, 2, 4 and 8 bench worlds (separate processes) by one `sme agent --workers 1` "
        "and by one `sme agent --workers N`; report the aggregate steps/s and each world's round-trip p99; "
        "a raw zenoh ping-pong of the same message sizes through a router (the baseline); the failover "
        "time: two agents, kill -9 of one, seconds until its worlds are answered by the other; and the max "
        "observation->action gap of a gridworld beside a re-embedding retina.",
    )
    p.add_argument("--workers", type=int, default=max(2, os.cpu_count() or 1), help="N (default: cores, at least 2)")
    p.add_argument("--worlds", default="1,2,4,8", help="world counts (default 1,2,4,8)")
    p.add_argument("--seconds", type=float, default=6.0, help="seconds each world count runs (default 6)")
    p.add_argument("--obs-bytes", type=int, default=1024, help="observation size in bytes (default 1024)")
    p.add_argument(
        "--agent-work-us",
        type=float,
        default=0.0,
        help="CPU time (us) the agent's echo program spends in Python per answer, a stand-in for a learner "
        "(default 0: the bare loop)",
    )
    p.add_argument("--rounds", type=int, default=3, help="ping-pong / single-world alternations (default 3)")
    p.add_argument("--no-failover", action="store_true", help="skip the failover measurement")
    p.add_argument(
        "--gap-seconds",
        type=float,
        default=20.0,
        help="seconds of a gridworld beside a re-embedding retina on one agent, learning in the background, "
        "for the max observation->action gap (as `sme bench gap --modes background`; 0 skips it; default 20)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def _sme(*args: str, **kw: Any) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "sensorimotor.tools.cli", *args], cwd=ROOT, **kw)


def _stop(p: subprocess.Popen, sig: int = signal.SIGINT) -> None:
    if p.poll() is None:
        p.send_signal(sig)
        try:
            p.wait(15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def _owners(ep: str) -> list[str]:
    try:
        with Bus(BusConfig.for_role("tool", ep)) as bus:
            return bus.alive(keys.ALL_ALIVE_OWNERS, timeout=1.0)
    except BusError:
        return []


def _wait(pred: Any, timeout: float) -> Any:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(0.2)
    return pred()


def _sample_cpu(out: list, stop: threading.Event, every: float = 0.25) -> None:
    while True:
        out.append((time.monotonic(), machine_cpu()))
        if stop.wait(every):
            out.append((time.monotonic(), machine_cpu()))
            return


def _busy_mid(samples: list[tuple[float, tuple[float, float] | None]]) -> float | None:
    """The machine's busy fraction from 50 % to 90 % of the samples' span: the worlds are past
    their start-up (imports) and not yet stopping."""
    if len(samples) < 3:
        return None
    t0, t1 = samples[0][0], samples[-1][0]
    a = min(samples, key=lambda x: abs(x[0] - (t0 + 0.5 * (t1 - t0))))[1]
    b = min(samples, key=lambda x: abs(x[0] - (t0 + 0.9 * (t1 - t0))))[1]
    return busy_fraction(a, b)


def serve_worlds(
    ep: str, n: int, seconds: float, obs_bytes: int, tmp: str, connect: tuple[str, ...] = ()
) -> list[dict]:
    """Run `n` bench worlds for `seconds` at once; their --stats-json summaries."""
    files = [os.path.join(tmp, f"w{n}_{k}.json") for k in range(n)]
    eps = [a for e in (connect or (ep,)) for a in ("--connect", e)]
    procs = [
        _sme(
            "world",
            "bench",
            "--id",
            f"b{k}",
            "--seconds",
            str(seconds),
            "--warmup",
            "300",
            "--param",
            f"obs_bytes={obs_bytes}",
            "--stats-json",
            f,
            *eps,
            "-q",
        )  # fmt: skip
        for k, f in enumerate(files)
    ]
    for p in procs:
        try:
            p.wait(seconds + 120)
        except subprocess.TimeoutExpired:
            _stop(p)
    out = []
    for f in files:
        with open(f) as fh:
            out.append(json.load(fh))
    return out


def _row(workers: int, n: int, obs_bytes: int, stats: list[dict], busy: float | None) -> dict:
    rates = [s.get("steady_steps_per_s", s["steps_per_s"]) for s in stats]
    p99 = [s.get("p99_ms") for s in stats]
    return {
        "bench": "scale",
        "workers": workers,
        "worlds": n,
        "obs_bytes": obs_bytes,
        "steps_per_s": round(float(sum(rates)), 1),
        "per_world_steps_per_s": rates,
        "p99_ms_max": max((x for x in p99 if x is not None), default=None),
        "p99_ms": p99,
        "resends": sum(s["resends"] for s in stats),
        "actions_ignored": sum(s.get("actions_ignored", 0) for s in stats),
        "machine_cpu_busy": busy,
        "world_cpu_cores": round(sum(s.get("cpu_cores", 0.0) for s in stats), 3),
        "world_cpu_us_per_step": [s.get("cpu_us_per_step") for s in stats],
    }


def scale_rows(
    workers: int,
    counts: list[int],
    seconds: float,
    obs_bytes: int,
    rounds: int = 0,
    emit: Any = None,
    work_us: float = 0.0,
) -> list[dict]:
    """One agent with `workers` workers; a row per world count. With `rounds` > 0 the one-world row
    is measured `rounds` times, each after a ping-pong (`pingpong`); each row is emitted as it comes."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    work = ("--program-param", f"echo.work_us={work_us}") if work_us > 0 else ()
    agent = _sme("agent", "--listen", ep, "--workers", str(workers), "--id", "s", *work, "-q")
    rows = []
    try:
        if not _wait(lambda: len(_owners(ep)) >= workers, 120):
            raise RuntimeError(f"the agent's {workers} workers did not come up")
        time.sleep(3.0)  # the workers finish starting up (imports) before anything is measured
        with tempfile.TemporaryDirectory() as tmp:
            for n in counts:
                pairs = rounds if n == 1 and rounds > 0 else 1
                for _ in range(pairs):
                    pp = pingpong(obs_bytes, min(seconds, 5.0)) if n == 1 and rounds > 0 else None
                    samples: list[tuple[float, tuple[float, float] | None]] = []
                    stop = threading.Event()
                    sampler = threading.Thread(target=_sample_cpu, args=(samples, stop), daemon=True)
                    sampler.start()
                    stats = serve_worlds(ep, n, seconds, obs_bytes, tmp)
                    stop.set()
                    sampler.join()
                    row = _row(workers, n, obs_bytes, stats, _busy_mid(samples))
                    row["agent_work_us"] = work_us
                    if pp is not None:
                        row["pingpong"] = pp
                        for way, field in (("", "round_trips_per_s"), ("_callback", "callback_round_trips_per_s")):
                            row[f"over_pingpong{way}"] = round(row["steps_per_s"] / max(pp[field], 1e-9), 3)
                    rows.append(row)
                    if emit is not None:
                        emit(row)
    finally:
        _stop(agent)
    return rows


def _pong_side(ep: str, ready: Any, pong_bytes: int) -> None:
    with Bus(BusConfig.for_role("agent", ep)) as bus:  # a router answering in its callback, as `sme agent`
        pub = bus.publisher("bench/pong")
        data = b"\0" * pong_bytes
        bus.subscribe("bench/ping", lambda m: pub.put(data))
        ready.set()
        time.sleep(3600)


def _ping_side(ep: str, seconds: float, obs: bytes, out: Any) -> None:
    with Bus(BusConfig.for_role("world", ep)) as bus:
        got = threading.Event()
        in_callback = threading.Event()
        stamps: list[float] = []

        def on_pong(m: Any) -> None:
            if not in_callback.is_set():
                got.set()
                return
            stamps.append(time.perf_counter())
            pub.put(obs)

        bus.subscribe("bench/pong", on_pong)
        pub = bus.publisher("bench/ping")
        time.sleep(0.5)
        lat = []
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            got.clear()
            t = time.perf_counter()
            pub.put(obs)
            if not got.wait(1.0):
                continue
            lat.append(time.perf_counter() - t)
        in_callback.set()
        pub.put(obs)
        time.sleep(seconds)
        in_callback.clear()
        time.sleep(0.05)
    out.put((lat, stamps))


def pingpong(obs_bytes: int, seconds: float) -> dict:
    """Raw zenoh round trips with the bench world's message sizes through a router, two ways for
    `seconds` each: a client process (like a world) puts an observation-sized ping and a router
    process answers an action-sized pong in its subscriber callback (as `sme agent --workers 1`
    does). The ping side either waits on its main thread for the pong (`round_trips_per_s`) or
    puts the next ping from its pong callback (`callback_round_trips_per_s`), as `sme world` does.
    """
    obs = codec.encode(Observation("b0", 0, 1, 0, {"frame": np.zeros(obs_bytes // 4, np.float32)}, 0.0, False))
    act = codec.encode(Action("b0", 1, (0.0,)))
    ep = f"tcp/127.0.0.1:{free_port()}"
    ctx = mp.get_context("spawn")
    ready = ctx.Event()
    out = ctx.Queue()
    peer = ctx.Process(target=_pong_side, args=(ep, ready, len(act)), daemon=True)
    peer.start()
    try:
        ready.wait(60)
        pinger = ctx.Process(target=_ping_side, args=(ep, seconds, obs, out), daemon=True)
        pinger.start()
        lat, stamps = out.get(timeout=2 * seconds + 60)
        pinger.join(10)
    finally:
        peer.kill()
        peer.join()
    lat_ms = np.asarray(lat[300:] or lat) * 1e3
    cb = np.diff(np.asarray(stamps[300:] or stamps)) * 1e3
    return {
        "bench": "pingpong",
        "ping_bytes": len(obs),
        "pong_bytes": len(act),
        "round_trips_per_s": round(1e3 / float(lat_ms.mean()), 1) if lat_ms.size else 0.0,
        "p50_ms": round(float(np.percentile(lat_ms, 50)), 4) if lat_ms.size else None,
        "p99_ms": round(float(np.percentile(lat_ms, 99)), 4) if lat_ms.size else None,
        "callback_round_trips_per_s": round(1e3 / float(cb.mean()), 1) if cb.size else 0.0,
        "callback_p99_ms": round(float(np.percentile(cb, 99)), 4) if cb.size else None,
    }


def _status(ep: str, agent: str) -> AgentStatus | None:
    try:
        with Bus(BusConfig.for_role("tool", ep)) as bus:
            r = bus.get(keys.agent_status(agent), timeout=1.0)
            return codec.decode(AgentStatus, r[0].payload) if r else None
    except BusError:
        return None


def failover(obs_bytes: int) -> dict:
    """Two agents (a, b), two bench worlds connected to both; kill -9 of a; seconds until b answers a's worlds."""
    e1, e2 = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    common = ("--workers", "1", "--checkpoint-every", "1", "-q")
    a = _sme("agent", "--id", "a", "--listen", e1, *common)
    b = _sme("agent", "--id", "b", "--listen", e2, "--connect", e1, *common)
    worlds: list[subprocess.Popen] = []
    try:
        if not _wait(lambda: len(_owners(e2)) >= 2, 120):
            raise RuntimeError("the two agents did not come up")
        eps = ("--connect", e1, "--connect", e2)
        worlds = [
            _sme("world", "bench", "--id", f"f{k}", "--param", f"obs_bytes={obs_bytes}", *eps, "-q") for k in range(2)
        ]

        def of_a() -> list[str]:
            st = _status(e1, "a")
            return [ln.world_id for ln in st.links if ln.state == "attached" and ln.steps > 0] if st else []

        mine = _wait(of_a, 60)
        if not mine:
            raise RuntimeError("agent a answered no world")
        a.send_signal(signal.SIGKILL)
        a.wait()
        t0 = time.monotonic()

        def answered() -> bool:
            st = _status(e2, "b")
            if st is None:
                return False
            return all(
                any(ln.world_id == w and ln.state == "attached" and ln.steps > 0 for ln in st.links) for w in mine
            )

        ok = _wait(answered, 30)
        took = time.monotonic() - t0
    finally:
        for p in (*worlds, b, a):
            _stop(p)
    return {"bench": "failover", "worlds_moved": len(mine), "ok": bool(ok), "seconds": round(took, 2)}


def main_args(args: argparse.Namespace) -> int:
    try:
        counts = [int(x) for x in args.worlds.split(",") if x.strip()]
    except ValueError:
        print(f"sme bench scale: --worlds takes counts like 1,2,4,8, not {args.worlds!r}", file=sys.stderr)
        return 2
    if not counts or min(counts) < 1 or args.workers < 1 or args.seconds <= 0 or args.rounds < 1:
        print("sme bench scale: --worlds counts, --workers, --seconds and --rounds must be positive", file=sys.stderr)
        return 2
    if args.gap_seconds < 0:
        print("sme bench scale: --gap-seconds must be >= 0 (0 skips the gap measurement)", file=sys.stderr)
        return 2
    if not 0 <= args.agent_work_us <= 1e6:
        print("sme bench scale: --agent-work-us must be between 0 and 1e6", file=sys.stderr)
        return 2
    emit = (lambda r: print(json.dumps(r), flush=True)) if args.json else (lambda r: _print(r))
    try:
        by: dict[tuple[int, int], list[dict]] = {}
        for w in sorted({1, args.workers}):
            rounds = args.rounds if w == 1 else 0
            for r in scale_rows(w, counts, args.seconds, args.obs_bytes, rounds, emit, args.agent_work_us):
                by.setdefault((w, r["worlds"]), []).append(r)
        fo = None if args.no_failover else failover(args.obs_bytes)
        if fo is not None:
            emit(fo)
        gaps = gap.run_mode("background", args.gap_seconds, 50, 50) if args.gap_seconds > 0 else []
        for r in gaps:
            emit(r)
    except RuntimeError as e:
        print(f"sme bench scale: {e}", file=sys.stderr)
        return 1
    emit(summarize(by, counts, args.workers, fo, gaps))
    return 0


def summarize(
    by: dict[tuple[int, int], list[dict]],
    counts: list[int],
    workers: int,
    fo: dict | None,
    gaps: list[dict] | None = None,
) -> dict:
    """The run's figures against the targets (medians over the rounds where there are several)."""
    top = max(counts)
    summary: dict[str, Any] = {"bench": "scale-summary", "workers": workers}
    for r in gaps or []:
        summary[f"{r['world']}_max_gap_ms"] = r["max_ms"]
    first = next(iter(by.values()), [{}])[0]
    summary["agent_work_us"] = first.get("agent_work_us", 0.0)
    if (1, top) in by and (workers, top) in by:
        one, many = by[(1, top)][0], by[(workers, top)][0]
        if one["steps_per_s"] > 0:
            summary[f"speedup_at_{top}_worlds"] = round(many["steps_per_s"] / one["steps_per_s"], 2)
        busy = one.get("machine_cpu_busy")
        if busy:
            # with the cores this busy at one worker, and each step costing the same CPU, more workers
            # can add about 1/busy at most
            summary[f"machine_cpu_busy_at_{top}_worlds_workers_1"] = busy
            summary[f"speedup_cpu_estimate_at_{top}_worlds"] = round(1.0 / busy, 2)
        if one.get("world_cpu_cores"):
            summary[f"world_cpu_cores_at_{top}_worlds_workers_1"] = one["world_cpu_cores"]
    ones = by.get((1, 1), [])
    if ones:
        summary["single_world_steps_per_s"] = float(np.median([r["steps_per_s"] for r in ones]))
        for key in sorted(k for k in ones[0] if k.startswith("over_pingpong")):
            summary[f"single_world_{key}"] = float(np.median([r[key] for r in ones]))
        if "over_pingpong" in ones[0]:
            summary["rounds"] = len(ones)
    if fo is not None:
        summary["failover_seconds"] = fo["seconds"]
    summary["targets"] = {
        "speedup_at_8_worlds": 1.6,
        "single_world_steps_per_s": 2000,
        "single_world_over_pingpong": 0.6,
        "failover_seconds": 5.0,
        "gridworld_max_gap_ms": gap.TARGET_MAX_MS,
    }
    return summary


def _print(r: dict) -> None:
    if r["bench"] == "scale":
        if not r["steps_per_s"]:
            print(f"workers {r['workers']}  worlds {r['worlds']}: no world was answered in time (raise --seconds)")
            return
        print(
            f"workers {r['workers']}  worlds {r['worlds']}  {r['steps_per_s']:>9,.0f} steps/s in total  "
            f"p99 max {r['p99_ms_max']} ms  resends {r['resends']}  machine CPU busy {r['machine_cpu_busy']}  "
            f"worlds' own CPU {r['world_cpu_cores']} cores"
        )
        if "pingpong" in r:
            pp = r["pingpong"]
            print(
                f"  raw zenoh ping-pong ({pp['ping_bytes']} B / {pp['pong_bytes']} B via a router) just before: "
                f"{pp['round_trips_per_s']:,.0f} round trips/s waiting on the main thread "
                f"(one world: {r['over_pingpong']:.0%}), {pp['callback_round_trips_per_s']:,.0f} answering in "
                f"the callback ({r['over_pingpong_callback']:.0%})"
            )
    elif r["bench"] == "gap":
        print(
            f"gap: {r['world']} beside the other world, learning in the background: {r['steps']} steps, "
            f"{r['embeddings']} embeddings, observation->action gap p99 {r['p99_ms']} ms, max {r['max_ms']} ms"
        )
    elif r["bench"] == "failover":
        print(f"failover: {r['worlds_moved']} worlds answered again after {r['seconds']} s (ok: {r['ok']})")
    else:
        print(json.dumps(r))
