"""`sme agent`: run the agent daemon (a zenoh router on tcp/127.0.0.1:7447 by default)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys
import threading
from typing import Any

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DETECTORS
from sensorimotor.agent.programs.registry import PROGRAMS, check_program_params, program_kind
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.params import ParamError, table_text

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
            raise ParamError(f"--program-param expects PROGRAM.KEY=VALUE, got {item!r}")
        raw.setdefault(name.strip(), {})[key.strip()] = value.strip()
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


def run_agent(args: argparse.Namespace) -> int:
    try:
        program_params = parse_program_params(args.program_param)
    except ParamError as e:
        print(f"sme agent: {e}", file=sys.stderr)
        return 2
    if not args.link_ttl > 0:
        print(f"sme agent: --link-ttl must be > 0 seconds, not {args.link_ttl}", file=sys.stderr)
        return 2
    cfg = bus_config_from_args(args, "agent")
    warning = cfg.exposure_warning()
    if warning:
        print(f"sme agent: WARNING: {warning}", file=sys.stderr, flush=True)
    try:
        bus = Bus(cfg)
    except BusError as e:
        log.error("%s", e)
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
        )
        stop = threading.Event()

        def on_signal(signum, frame):  # noqa: ARG001
            daemon.stop()
            stop.set()

        signal.signal(signal.SIGINT, on_signal)
        signal.signal(signal.SIGTERM, on_signal)
        with daemon:
            log.info("agent %s up (%s); waiting for worlds", args.id, cfg.describe())
            daemon.run(args.seconds)
        log.info("agent %s stopped", args.id)
    return 0


def main_args(args: argparse.Namespace) -> int:
    if args.list_params is not None:
        return list_params(args.list_params)
    return run_agent(args)
