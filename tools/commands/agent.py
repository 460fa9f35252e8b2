"""`sme agent`: run the agent daemon (a zenoh router on tcp/127.0.0.1:7447 by default)."""

from __future__ import annotations

import argparse
import logging
import os
import signal
import subprocess
import sys
import threading
import time
from typing import Any

from sensorimotor.agent.daemon import AgentDaemon, DuplicateAgent
from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DETECTORS
from sensorimotor.agent.programs.registry import PROGRAMS, check_program_params, program_kind
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.params import ParamError, quote, table_text
from sensorimotor.tools.exit_guard import ExitGuard

log = logging.getLogger("sme.agent")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "agent",
        help="run the agent daemon",
        description="Run the agent daemon. It listens on the bus (embedded default: a zenoh "
        "router on tcp/127.0.0.1:7447, loopback only), attaches to every world that appears, "
        "learns each world's developmental program online, publishes every embedding version "
        "and its events, and answers `sme status`. Stop with Ctrl-C.",
    )
    p.add_argument("--id", default=keys.DEFAULT_AGENT_ID, help="agent id used in key expressions (default: a0)")
    p.add_argument("--seed", type=int, default=0, help="seed of every program's random generator (default: 0)")
    p.add_argument(
        "--state-dir",
        default=None,
        metavar="DIR",
        help="checkpoint each world's learned state here (atomically) and resume from it after a restart",
    )
    p.add_argument("--checkpoint-every", type=float, default=30.0, metavar="S", help="checkpoint period (s)")
    p.add_argument(
        "--share-on-embedding",
        type=float,
        default=2.0,
        metavar="S",
        help="while another agent (or worker) is alive, share a world's checkpoint on the bus soon after "
        "each new embedding version, at most once every S seconds per world (default: 2), so that a "
        "takeover after a kill -9 resumes from at most ~S s back; 0: after every version; the periodic "
        "share every --checkpoint-every seconds happens anyway",
    )
    p.add_argument(
        "--link-ttl",
        type=float,
        default=600.0,
        metavar="S",
        help="release the link of a world gone longer than S seconds (default: 600): checkpointed first "
        "with --state-dir and restored from there if the world returns, else it starts fresh",
    )
    p.add_argument(
        "--detector",
        default=DEFAULT_DETECTOR,
        choices=sorted(DETECTORS),
        help=f"reward-drop detector run on each world link (default: {DEFAULT_DETECTOR}, chosen by "
        "`sme bench detectors`)",
    )
    p.add_argument(
        "--program-param",
        action="append",
        metavar="PROGRAM.K=V",
        default=None,
        help="a program hyperparameter, repeatable, e.g. retina.embed_every=500, retina.rule=basic, "
        "gridworld.samples_per_iteration=200; checked at start-up (see --list-params)",
    )
    p.add_argument(
        "--list-params",
        nargs="?",
        const="",
        default=None,
        metavar="PROGRAM",
        help="print the programs' hyperparameters (name, type, default, doc) and exit; "
        "programs: " + ", ".join(sorted(PROGRAMS)),
    )
    p.add_argument(
        "--seconds", type=float, default=None, help="stop after this many seconds (default: run until Ctrl-C)"
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="spread this agent's worlds over N processes, each its own zenoh session claiming worlds "
        f"with the owner protocol (default: the number of cores, here {os.cpu_count() or 1}); this "
        "process is the router and worker 0, workers 1..N-1 (owner ids ID.w1...) are its clients",
    )
    p.add_argument(
        "--claim-settle",
        type=float,
        default=0.3,
        metavar="S",
        help="seconds a world's claim is held before answering it (default 0.3; raise it on buses where "
        "liveliness takes longer to cross, e.g. between hosts)",
    )
    p.add_argument("--owner-id", default=None, help=argparse.SUPPRESS)  # a worker: its owner id
    p.add_argument("--parent-pid", type=int, default=None, help=argparse.SUPPRESS)  # a worker: stop with it
    add_bus_arguments(p, "agent")
    p.set_defaults(func=main_args)


def parse_program_params(items: list[str] | None) -> dict[str, dict[str, Any]]:
    """`PROGRAM.KEY=VALUE` items as validated, typed overrides per program (ParamError otherwise:
    a malformed item, an unknown program or key, a value that is not of the declared type)."""
    raw: dict[str, dict[str, str]] = {}
    for item in items or []:
        name, _, kv = item.partition(".")
        key, eq, value = kv.partition("=")
        if not name.strip() or not key.strip() or not eq:
            raise ParamError(f"--program-param expects PROGRAM.KEY=VALUE, got {quote(item)}")
        given = raw.setdefault(name.strip(), {})
        if key.strip() in given:
            raise ParamError(f"--program-param {quote(name.strip() + '.' + key.strip())} is given twice: give it once")
        given[key.strip()] = value.strip()
    return check_program_params(raw)


def list_params(name: str) -> int:
    """Print the hyperparameter table of program `name` (every program when empty); exit code."""
    try:
        names = [name] if name else sorted(PROGRAMS)
        tables = [table_text(program_kind(n).params_type(), f"{n}: {program_kind(n).summary}") for n in names]
    except ParamError as e:
        print(f"sme agent: {e}", file=sys.stderr)
        return 2
    print("\n\n".join(tables))
    return 0


def _worker_endpoint(listen: tuple[str, ...]) -> str | None:
    """The endpoint a worker on this host connects to: the first listen endpoint (any-address -> loopback)."""
    for ep in listen:
        proto, _, rest = ep.partition("/")
        host, _, port = rest.rpartition(":")
        if host in ("0.0.0.0", "[::]", "::"):
            host = "127.0.0.1" if host == "0.0.0.0" else "[::1]"
        return f"{proto}/{host}:{port}"
    return None


def _worker_argv(args: argparse.Namespace, k: int, endpoint: str) -> list[str]:
    """The command line of worker `k`: the same agent settings, as a client of this router."""
    argv = [sys.executable, "-m", "sensorimotor.tools.cli"]
    argv += ["-v"] * max(0, getattr(args, "verbose", 0) or 0) + (["-q"] if getattr(args, "quiet", False) else [])
    argv += ["agent", "--id", args.id, "--owner-id", f"{args.id}.w{k}", "--workers", "1"]
    argv += ["--seed", str(args.seed), "--checkpoint-every", str(args.checkpoint_every)]
    argv += ["--share-on-embedding", str(args.share_on_embedding)]
    argv += ["--link-ttl", str(args.link_ttl), "--detector", args.detector, "--claim-settle", str(args.claim_settle)]
    argv += ["--parent-pid", str(os.getpid()), "--mode", "client", "--connect", endpoint]
    if args.state_dir:
        argv += ["--state-dir", args.state_dir]
    for item in args.program_param or []:
        argv += ["--program-param", item]
    # every bus option the agent was given, so that the worker opens its session the same way
    # (e.g. a zenoh config file with user/password authentication); mode and endpoints are the worker's own
    if getattr(args, "secure", None):
        argv += ["--secure", args.secure]
    if getattr(args, "config", None):
        argv += ["--config", args.config]
    if getattr(args, "multicast_scouting", False) and not getattr(args, "no_multicast_scouting", False):
        argv += ["--multicast-scouting"]
    if args.seconds is not None:
        argv += ["--seconds", str(args.seconds)]
    return argv


WORKER_EXIT_GRACE = 1.0  # seconds a worker's clean stop gets after its agent died or a signal (then it ends)
AGENT_EXIT_GRACE = 20.0  # the agent's, after a signal: its workers get 10 s before they are killed
WORKER_UP_WAIT = 30.0  # seconds the agent waits for a worker's owner token before it calls it missing


def _watch_workers(daemon: AgentDaemon, children: dict[str, subprocess.Popen], stop: threading.Event) -> None:
    """Say which workers actually run: each one's owner token appearing (up) or its process ending
    (with its exit code; its own error line says why), then once how many of them run."""
    t0 = time.monotonic()
    up: set[str] = set()
    ended: dict[str, int] = {}
    told = False
    while not stop.wait(0.2):
        owners = daemon.book.view().owners
        for wid, c in children.items():
            code = c.poll()
            if code is not None and wid not in ended:
                ended[wid] = code
                up.discard(wid)
                log.error(
                    "worker %s exited with code %d (its error is logged above); agent %s runs with %d of %d workers",
                    wid,
                    code,
                    daemon.agent_id,
                    len(children) + 1 - len(ended),
                    len(children) + 1,
                )
            elif code is None and wid in owners and wid not in up:
                up.add(wid)
        settled = len(up) + len(ended) == len(children)
        if not told and (settled or time.monotonic() - t0 > WORKER_UP_WAIT):
            told = True
            missing = sorted(set(children) - up - set(ended))
            log.info(
                "agent %s: %d of %d workers running%s",
                daemon.agent_id,
                len(up) + 1,
                len(children) + 1,
                f" (not up after {WORKER_UP_WAIT:g} s: {', '.join(missing)})" if missing else "",
            )
        if len(ended) == len(children):
            return


def run_agent(args: argparse.Namespace) -> int:
    try:
        program_params = parse_program_params(args.program_param)
    except ParamError as e:
        print(f"sme agent: {e}", file=sys.stderr)
        return 2
    if not args.link_ttl > 0:
        print(f"sme agent: --link-ttl must be > 0 seconds, not {args.link_ttl}", file=sys.stderr)
        return 2
    workers = os.cpu_count() or 1 if args.workers is None else args.workers
    if workers < 1:
        print(f"sme agent: --workers must be >= 1, not {args.workers}", file=sys.stderr)
        return 2
    if not args.share_on_embedding >= 0:  # also refuses nan
        print(f"sme agent: --share-on-embedding must be >= 0 seconds, not {args.share_on_embedding}", file=sys.stderr)
        return 2
    if not args.claim_settle >= 0:
        print(f"sme agent: --claim-settle must be >= 0 seconds, not {args.claim_settle}", file=sys.stderr)
        return 2
    try:
        owner_id = keys.check_id(args.owner_id or args.id, "agent id")
    except ValueError as e:
        print(f"sme agent: {e}", file=sys.stderr)
        return 2
    who = f"agent {args.id}" if owner_id == args.id else f"worker {owner_id}"
    # a worker watches its agent from the start: opening the session can take a while, and a worker
    # whose agent is gone must not live on (see tools.exit_guard)
    guard = ExitGuard(who, WORKER_EXIT_GRACE if args.parent_pid is not None else AGENT_EXIT_GRACE, args.parent_pid)
    if args.parent_pid is not None:
        guard.start()
    try:
        return _run_agent(args, guard, who, owner_id, workers, program_params)
    finally:
        if args.parent_pid is None:  # in-process callers get their wakeup fd back; a worker stays guarded
            guard.close()  # to its last instruction (interpreter shutdown with a session whose router is gone)


def _run_agent(
    args: argparse.Namespace,
    guard: ExitGuard,
    who: str,
    owner_id: str,
    workers: int,
    program_params: dict[str, dict[str, Any]],
) -> int:
    """`run_agent` once its arguments are checked: the bus, the daemon and its workers."""
    cfg = bus_config_from_args(args, "agent")
    endpoint = _worker_endpoint(cfg.listen) if cfg.mode == "router" else None
    if workers > 1 and endpoint is None:
        log.warning("--workers %d needs a router that listens (--listen); running one process", workers)
        workers = 1
    warning = cfg.exposure_warning()
    if warning:
        print(f"sme agent: WARNING: {warning}", file=sys.stderr, flush=True)
    try:
        bus = Bus(cfg)
    except BusError as e:
        log.error("%s: %s", who, e)
        return 2
    with bus:
        daemon = AgentDaemon(
            bus,
            args.id,
            seed=args.seed,
            state_dir=args.state_dir,
            checkpoint_every=args.checkpoint_every,
            detector=args.detector,
            program_params=program_params,
            link_ttl=args.link_ttl,
            owner_id=owner_id,
            claim_settle=args.claim_settle,
            share_on_embedding=args.share_on_embedding,
            workers=tuple(f"{args.id}.w{k}" for k in range(1, workers)),
            all_obs=args.owner_id is None,  # a worker hears only the worlds it claims
        )
        try:
            daemon.check_unique()  # before any worker starts
        except DuplicateAgent as e:
            print(f"sme agent: {e}", file=sys.stderr)
            return 1
        stop = threading.Event()
        children: dict[str, subprocess.Popen] = {}

        def on_signal(signum, frame):  # noqa: ARG001
            daemon.stop()
            stop.set()
            for c in children.values():  # the workers stop at the same time as this process
                if c.poll() is None:
                    c.send_signal(signal.SIGINT)

        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        guard.stop = daemon.stop
        guard.last_words = daemon.checkpoint
        guard.watch_signals()
        if args.parent_pid is None:
            guard.start()
        for k in range(1, workers):
            children[f"{args.id}.w{k}"] = subprocess.Popen(_worker_argv(args, k, str(endpoint)))
        try:
            with daemon:
                more = f", starting {workers - 1} more worker processes" if workers > 1 else ""
                log.info("%s up (%s%s); waiting for worlds", who, cfg.describe(), more)
                if children:
                    threading.Thread(
                        target=_watch_workers, args=(daemon, children, stop), name="watch-workers", daemon=True
                    ).start()
                daemon.run(args.seconds)
        finally:
            stop.set()
            for c in children.values():
                if c.poll() is None:
                    c.send_signal(signal.SIGINT)
            for c in children.values():
                try:
                    c.wait(10)
                except subprocess.TimeoutExpired:
                    c.kill()
                    c.wait()
        log.info("%s stopped", who)
    return 0


def main_args(args: argparse.Namespace) -> int:
    if args.list_params is not None:
        return list_params(args.list_params)
    return run_agent(args)
