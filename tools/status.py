"""`sme status`: every agent on the bus (its health, counters and the worlds it owns), or one agent."""

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
        help="ask the agents on the bus for their status",
        description="Query every agent on the bus (each daemon, and each worker of `sme agent --workers N`): "
        "uptime, the worlds it owns (its claims), each world link (state, steps, episodes, embedding version, "
        "last Procrustes error, rejected inputs by kind) and daemon counters; then the worlds alive that no "
        "agent owns. With --agent ID, only that agent.",
    )
    p.add_argument("--agent", default=None, help="only this agent id (default: every agent that answers)")
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: the agent's status with --agent, else "
        '{"agents": [...], "owners": {world: [owner, ...]}, "worlds": [...], "unowned": [...]}',
    )
    p.add_argument("--timeout", type=float, default=3.0, help="seconds to wait for the reply")
    add_bus_arguments(p, "tool")
    p.set_defaults(func=main_args)


def fetch_status(bus: Bus, agent: str, timeout: float) -> AgentStatus | None:
    replies = bus.get(keys.agent_status(agent), timeout=timeout)
    return codec.decode(AgentStatus, replies[0].payload) if replies else None


def _claims(names: list[str]) -> dict[str, list[str]]:
    owners: dict[str, list[str]] = {}
    for key in names:
        parts = key.split("/")
        owners.setdefault(parts[-2], []).append(parts[-1])
    return {w: sorted(o) for w, o in sorted(owners.items())}


def fetch_bus(bus: Bus, timeout: float) -> dict:
    """The whole bus: every agent status that answers, who claims which world, the worlds alive."""
    replies = bus.get(keys.ALL_STATUS, timeout=timeout)
    agents = sorted((status_dict(codec.decode(AgentStatus, r.payload)) for r in replies), key=lambda d: d["agent"])
    owners = _claims(bus.alive(keys.ALL_CLAIMS, timeout=min(timeout, 2.0)))
    worlds = sorted(keys.last_chunk(k) for k in bus.alive(keys.ALL_ALIVE_WORLDS, timeout=min(timeout, 2.0)))
    for d in agents:
        d["owns"] = sorted(w for w, o in owners.items() if d["agent"] in o)
        if d["counters"].get("workers"):  # its status adds its workers' links: each is listed by its worker
            d["links"] = [ln for ln in d["links"] if ln["world"] in d["owns"] or ln["world"] not in owners]
    return {"agents": agents, "owners": owners, "worlds": worlds, "unowned": [w for w in worlds if w not in owners]}


def print_agent(d: dict) -> None:
    """One agent's status as text (see `status_dict`)."""
    owns = f"  owns {', '.join(d['owns']) or 'nothing'}" if "owns" in d else ""
    print(f"agent {d['agent']}  up {d['uptime']:.1f} s{owns}  counters {d['counters']}")
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


def main_args(args: argparse.Namespace) -> int:
    try:
        with Bus(bus_config_from_args(args, "tool")) as bus:
            if args.agent is None:
                everything = fetch_bus(bus, args.timeout)
                st = None
            else:
                st = fetch_status(bus, args.agent, args.timeout)
    except (BusError, ProtocolError) as e:
        print(f"sme status: {e}", file=sys.stderr)
        return 2
    if args.agent is None:
        if not everything["agents"]:
            print(f"sme status: no agent answered within {args.timeout} s", file=sys.stderr)
            return 1
        if args.json:
            print(json.dumps(everything))
            return 0
        for d in everything["agents"]:
            print_agent(d)
        twice = {w: o for w, o in everything["owners"].items() if len(o) > 1}
        if twice:
            print(f"claimed by several owners (being settled): {twice}")
        if everything["unowned"]:
            print(f"worlds alive that no agent owns (yet): {', '.join(everything['unowned'])}")
        return 0
    if st is None:
        print(f"sme status: no agent {args.agent!r} answered within {args.timeout} s", file=sys.stderr)
        return 1
    d = status_dict(st)
    if args.json:
        print(json.dumps(d))
        return 0
    print_agent(d)
    return 0
