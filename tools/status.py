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


def table(rows: list[list[str]], header: list[str], indent: str = "  ") -> list[str]:
    """Rows as left-aligned text columns under a header (numbers right-aligned)."""
    cols = list(zip(header, *rows, strict=False)) if rows else [(h,) for h in header]
    widths = [max(len(c) for c in col) for col in cols]
    numeric = [
        bool(rows) and all(r[i].replace(",", "").replace(".", "").isdigit() for r in rows) for i in range(len(header))
    ]

    def line(cells: list[str]) -> str:
        out = [c.rjust(w) if num else c.ljust(w) for c, w, num in zip(cells, widths, numeric, strict=True)]
        return (indent + "  ".join(out)).rstrip()

    return [line(header)] + [line(r) for r in rows]


def agent_lines(d: dict) -> list[str]:
    """One agent's status (see `status_dict`) as text: a heading, its counters, one row per world."""
    owns = f"; owns {', '.join(d['owns']) or 'no world'}" if "owns" in d else ""
    out = [f"agent {d['agent']}: up {d['uptime']:.1f} s{owns}"]
    counters = {k: v for k, v in sorted(d["counters"].items()) if v}
    if counters:
        out.append("  counters: " + ", ".join(f"{k} {v:,}" for k, v in counters.items()) + " (zeros not shown)")
    else:
        out.append("  counters: all 0")
    rows = []
    for ln in d["links"]:
        err = ln["last_procrustes_error"]
        rejected = ", ".join(f"{k} {v}" for k, v in sorted(ln["rejected"].items()) if v) or "-"
        rows.append(
            [
                ln["world"],
                ln["kind"],
                ln["program"],
                ln["state"],
                f"{ln['steps']:,}",
                f"{ln['episodes']:,}",
                f"v{ln['embedding_version']}" if ln["embedding_version"] else "-",
                "-" if err is None else f"{err:.4f}",
                f"{ln['reward_mean']:.4f}",
                f"{ln['dropped']:,}",
                rejected,
            ]
        )
    if rows:
        out += table(
            rows,
            [
                "world",
                "kind",
                "program",
                "state",
                "steps",
                "episodes",
                "embedding",
                "procrustes",
                "reward",
                "dropped",
                "rejected",
            ],
        )
    else:
        out.append("  no worlds attached (start one with `sme world gridworld`)")
    return out


def print_agent(d: dict) -> None:
    """One agent's status as text (see `agent_lines`)."""
    print("\n".join(agent_lines(d)))


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
