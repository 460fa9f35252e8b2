"""`sme status`: ask the agent daemon for its health and counters."""

from __future__ import annotations

import argparse
import json
import sys

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentStatus
from sensorimotor.tools.common import status_dict


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "status",
        help="ask the agent daemon for its status",
        description="Query the daemon's status: uptime, each world link (state, steps, "
        "episodes, embedding version, last Procrustes error, rejected inputs by kind) and "
        "daemon counters.",
    )
    p.add_argument("--agent", default=keys.DEFAULT_AGENT_ID, help="agent id (default: a0)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the reply")
    add_bus_arguments(p, "tool")
    p.set_defaults(func=main_args)


def fetch_status(bus: Bus, agent: str, timeout: float) -> AgentStatus | None:
    replies = bus.get(keys.agent_status(agent), timeout=timeout)
    return codec.decode(AgentStatus, replies[0].payload) if replies else None


def main_args(args: argparse.Namespace) -> int:
    try:
        with Bus(bus_config_from_args(args, "tool")) as bus:
            st = fetch_status(bus, args.agent, args.timeout)
    except (BusError, ProtocolError) as e:
        print(f"sme status: {e}", file=sys.stderr)
        return 2
    if st is None:
        print(f"sme status: no agent {args.agent!r} answered within {args.timeout} s", file=sys.stderr)
        return 1
    d = status_dict(st)
    if args.json:
        print(json.dumps(d))
        return 0
    print(f"agent {d['agent']}  up {d['uptime']:.1f} s  counters {d['counters']}")
    for ln in d["links"]:
        err = ln["last_procrustes_error"]
        print(
            f"  world {ln['world']:<12} {ln['kind']:<10} {ln['state']:<8} program={ln['program']:<10} "
            f"steps={ln['steps']:<8} episodes={ln['episodes']:<6} embedding v{ln['embedding_version']:<4} "
            f"procrustes={'n/a' if err is None else f'{err:.4f}'} reward_mean={ln['reward_mean']:.4f} "
            f"rejected={ln['rejected'] or '{}'} dropped={ln['dropped']}"
        )
    if not d["links"]:
        print("  no worlds attached (start one with `sme world gridworld`)")
    return 0
