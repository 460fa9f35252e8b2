"""`sme status`: every agent on the bus (its health, counters and the worlds it owns), or one agent."""

from __future__ import annotations

import argparse
import json
import sys

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import AgentStatus, clip
from sensorimotor.tools.common import status_dict


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "status",
        help="ask the agents on the bus for their status",
        description="Query every agent on the bus (each daemon, and each worker of `sme agent --workers N`): "
        "uptime, the worlds it owns (its claims), each world link (state, steps, episodes, embedding version, "
        "last Procrustes error, rejected inputs by kind) and daemon counters; then the worlds alive that no "
        "agent owns. An agent alive on the bus that gives no status is listed as NOT ANSWERING, and an id "
        "answered by two processes is flagged; either makes the command exit 1 (2: the bus cannot be "
        "reached). With --agent ID, only that agent.",
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


SAME_START = 0.05  # seconds: two status replies of one id whose start times differ more come from two processes


def fetch_bus(bus: Bus, timeout: float) -> dict:
    """The whole bus: every agent status that answers, who claims which world, the worlds alive;
    also the agents alive on the bus (liveliness token) that gave no readable status
    (`not_answering`: never hidden) and the ids answered by several processes (`duplicates`)."""
    failed: dict[str, str] = {}
    try:
        replies = bus.get(keys.ALL_STATUS, timeout=timeout)
    except BusError as e:  # only error replies: the agents alive are listed as not answering below
        replies, query_error = [], str(e)
    else:
        query_error = ""
    statuses: dict[str, list[AgentStatus]] = {}
    for r in replies:
        try:
            st = codec.decode(AgentStatus, r.payload)
        except ProtocolError as e:
            parts = r.key.split("/")
            failed[parts[-2] if len(parts) >= 2 else r.key] = f"its status reply does not decode: {clip(str(e), 200)}"
            continue
        started = st.timestamp - st.uptime
        seen = statuses.setdefault(st.agent_id, [])
        if all(abs(started - (o.timestamp - o.uptime)) > SAME_START for o in seen):  # not the same reply twice
            seen.append(st)
    alive = {keys.last_chunk(k) for k in bus.alive(keys.ALL_ALIVE_AGENTS, timeout=min(timeout, 2.0))}
    silent = {}
    for a in sorted(alive | set(failed)):
        if a not in statuses:
            silent[a] = failed.get(a) or (
                f"alive on the bus, but no status reply within {timeout:g} s"
                + (f" ({query_error})" if query_error else "")
            )
    duplicates = {a: len(sts) for a, sts in sorted(statuses.items()) if len(sts) > 1}
    agents = sorted((status_dict(st) for sts in statuses.values() for st in sts), key=lambda d: d["agent"])
    owners = _claims(bus.alive(keys.ALL_CLAIMS, timeout=min(timeout, 2.0)))
    worlds = sorted(keys.last_chunk(k) for k in bus.alive(keys.ALL_ALIVE_WORLDS, timeout=min(timeout, 2.0)))
    for d in agents:
        d["owns"] = sorted(w for w, o in owners.items() if d["agent"] in o)
        if d["counters"].get("workers"):  # its status adds its workers' links: each is listed by its worker
            d["links"] = [ln for ln in d["links"] if ln["world"] in d["owns"] or ln["world"] not in owners]
    return {
        "agents": agents,
        "not_answering": [{"agent": a, "why": why} for a, why in silent.items()],
        "duplicates": duplicates,
        "owners": owners,
        "worlds": worlds,
        "unowned": [w for w in worlds if w not in owners],
    }


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
    """Exit 0 when every agent alive answered (once per id), 1 when one did not or an id answers
    from several processes, 2 when the bus cannot be reached."""
    try:
        with Bus(bus_config_from_args(args, "tool")) as bus:
            if args.agent is None:
                everything = fetch_bus(bus, args.timeout)
                st = None
            else:
                try:
                    st = fetch_status(bus, args.agent, args.timeout)
                except (BusError, ProtocolError) as e:
                    print(f"sme status: agent {args.agent!r} is not answering: {clip(str(e), 200)}", file=sys.stderr)
                    return 1
    except (BusError, ProtocolError) as e:
        print(f"sme status: {e}", file=sys.stderr)
        return 2
    if args.agent is None:
        return _print_bus(everything, args)
    if st is None:
        print(f"sme status: no agent {args.agent!r} answered within {args.timeout} s", file=sys.stderr)
        return 1
    d = status_dict(st)
    if args.json:
        print(json.dumps(d))
        return 0
    print_agent(d)
    return 0


def _print_bus(everything: dict, args: argparse.Namespace) -> int:
    """Print what `fetch_bus` found; the exit code (1: an agent not answering or a duplicate id)."""
    silent, twice_ids = everything["not_answering"], everything["duplicates"]
    if not everything["agents"] and not silent:
        print(f"sme status: no agent answered within {args.timeout} s", file=sys.stderr)
        return 1
    code = 1 if silent or twice_ids else 0
    if args.json:
        print(json.dumps(everything))
        return code
    for d in everything["agents"]:
        print_agent(d)
    for s in silent:
        print(f"agent {s['agent']}: NOT ANSWERING: {s['why']}")
    for a, n in twice_ids.items():
        print(
            f"agent id {a!r} is answered by {n} processes (started at different times): each agent on a bus needs its own --id"
        )
    twice = {w: o for w, o in everything["owners"].items() if len(o) > 1}
    if twice:
        print(f"claimed by several owners (being settled): {twice}")
    if everything["unowned"]:
        print(f"worlds alive that no agent owns (yet): {', '.join(everything['unowned'])}")
    return code
