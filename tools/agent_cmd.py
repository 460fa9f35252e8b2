"""`sme agent`: run the agent daemon (a zenoh router on tcp/127.0.0.1:7447 by default)."""

from __future__ import annotations

import argparse
import ast
import logging
from typing import Any
import signal
import threading

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DETECTORS
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args

log = logging.getLogger("sme.agent")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("agent", help="run the agent daemon",
                       description="Run the agent daemon. It listens on the bus (embedded default: a zenoh "
                       "router on tcp/127.0.0.1:7447, loopback only), attaches to every world that appears, "
                       "learns each world's developmental program online, publishes every embedding version "
                       "and its events, and answers `sme status`. Stop with Ctrl-C.")
    p.add_argument("--id", default=keys.DEFAULT_AGENT_ID, help="agent id used in key expressions (default: a0)")
    p.add_argument("--seed", type=int, default=0, help="seed of every program's random generator (default: 0)")
    p.add_argument("--state-dir", default=None, metavar="DIR",
                   help="checkpoint each world's learned state here (atomically) and resume from it after a restart")
    p.add_argument("--checkpoint-every", type=float, default=30.0, metavar="S", help="checkpoint period (s)")
    p.add_argument("--detector", default=DEFAULT_DETECTOR, choices=sorted(DETECTORS),
                   help=f"reward-drop detector run on each world link (default: {DEFAULT_DETECTOR}, chosen by "
                   "`sme bench detectors`)")
    p.add_argument("--program-param", action="append", metavar="PROGRAM.K=V", default=None,
                   help="a program hyperparameter, repeatable, e.g. retina.embed_every=500, retina.rule=basic, "
                   "gridworld.samples_per_iteration=200")
    p.add_argument("--seconds", type=float, default=None, help="stop after this many seconds (default: run until Ctrl-C)")
    add_bus_arguments(p, "agent")
    p.set_defaults(func=main_args)


def parse_program_params(items: list[str] | None) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for item in items or []:
        name, _, kv = item.partition(".")
        key, eq, raw = kv.partition("=")
        if not name or not key or not eq:
            raise ValueError(f"--program-param expects PROGRAM.KEY=VALUE, got {item!r}")
        try:
            value: Any = ast.literal_eval(raw)
        except (ValueError, SyntaxError):
            value = raw
        out.setdefault(name, {})[key] = value
    return out


def run_agent(args: argparse.Namespace) -> int:
    try:
        program_params = parse_program_params(args.program_param)
    except ValueError as e:
        log.error("%s", e)
        return 2
    cfg = bus_config_from_args(args, "agent")
    try:
        bus = Bus(cfg)
    except BusError as e:
        log.error("%s", e)
        return 2
    with bus:
        daemon = AgentDaemon(bus, args.id, seed=args.seed, state_dir=args.state_dir,
                             checkpoint_every=args.checkpoint_every, detector=args.detector,
                             program_params=program_params)
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
    return run_agent(args)
