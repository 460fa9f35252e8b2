"""`sme world NAME`: serve a world simulator on the bus."""

from __future__ import annotations

import argparse
import json
import logging
import sys

from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.params import ParamError, assignments, table_text
from sensorimotor.worlds.names import GYM_PREFIX
from sensorimotor.worlds.node import WorldNode
from sensorimotor.worlds.registry import WORLDS, make_world, world_kind

log = logging.getLogger("sme.world")


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "world",
        help="attach a world simulator",
        description="Serve a world on the bus in lockstep: publish observation k, wait for the "
        "agent's action k (resend after --resend seconds, then keep waiting). The agent "
        "discovers it by liveliness. Worlds: " + ", ".join(sorted(WORLDS)) + ", and gym:ENV_ID for any "
        "Gymnasium environment (gym:module:ENV_ID imports module first, from the current folder too; the "
        "environment's keyword arguments as --param k=v), and `ros2 --robot FILE.toml` for a ROS 2 robot over "
        "rmw_zenoh (docs/ros2.md). "
        "Stop with Ctrl-C; the agent pauses the link and resumes when the world returns.",
    )
    p.add_argument("name", nargs="?", help="world kind: " + ", ".join(sorted(WORLDS)) + ", or gym:ENV_ID")
    p.add_argument("--id", default=None, help="world id (default: the world name; for gym:ENV_ID, ENV_ID)")
    p.add_argument(
        "--param",
        action="append",
        metavar="K=V",
        help="world parameter, repeatable (e.g. gridworld: size=7 barrier=true actions=8 goal=3,3); "
        "unknown keys and bad values are refused; see --list-params",
    )
    p.add_argument(
        "--list-params",
        action="store_true",
        help="print the world's parameters (name, type, default, doc) and exit; without NAME, every world's",
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the world's random generator")
    p.add_argument(
        "--robot", default=None, metavar="FILE", help="ros2: the robot file (TOML) mapping its topics (docs/ros2.md)"
    )
    p.add_argument(
        "--external",
        action="store_true",
        help="leave the world to an outside controller (a Gymnasium BusEnv, see the README): the spec "
        "says program=external and agents on the bus do not attach to it",
    )
    p.add_argument(
        "--resend",
        type=float,
        default=0.5,
        metavar="S",
        help="republish an unanswered observation after S seconds (default 0.5)",
    )
    p.add_argument(
        "--lease-ttl",
        type=float,
        default=1.5,
        metavar="S",
        help="seconds without an action from the lease holder after which another owner may get the "
        "world's lease (default 1.5; a holder whose owner token vanishes loses it at once)",
    )
    p.add_argument("--steps", type=int, default=None, help="stop after this many steps")
    p.add_argument("--seconds", type=float, default=None, help="stop after this many seconds")
    p.add_argument(
        "--stats-json",
        default=None,
        metavar="FILE",
        help="write loop statistics (steps, steps/s, round-trip p50/p99) as JSON when done",
    )
    p.add_argument("--warmup", type=int, default=200, help="steps excluded from latency statistics")
    add_bus_arguments(p, "world")
    p.set_defaults(func=main_args)


def list_params(name: str | None) -> int:
    """Print the parameter table of world kind `name` (every kind when None); exit code."""
    if name and name.startswith(GYM_PREFIX):
        from sensorimotor.worlds.gym_world import gym_params_text

        try:
            print(gym_params_text(name))
        except ParamError as e:
            print(f"sme world: {e}", file=sys.stderr)
            return 2
        return 0
    try:
        names = [name] if name else sorted(WORLDS)
        tables = [table_text(world_kind(n).params_type(), f"{n}: {world_kind(n).summary}") for n in names]
    except ParamError as e:
        print(f"sme world: {e}", file=sys.stderr)
        return 2
    print("\n\n".join(tables))
    return 0


def main_args(args: argparse.Namespace) -> int:
    if args.list_params:
        return list_params(args.name)
    if not args.name:
        print("sme world: a world NAME is required (one of " + ", ".join(sorted(WORLDS)) + ")", file=sys.stderr)
        return 2
    if not args.lease_ttl > 0:
        print(f"sme world: --lease-ttl must be > 0 seconds, not {args.lease_ttl}", file=sys.stderr)
        return 2
    try:
        params = assignments(args.param)
        if args.robot is not None:
            params["robot"] = args.robot
        world_kind(args.name)
    except ParamError as e:
        print(f"sme world: {e}", file=sys.stderr)
        return 2
    try:
        world = make_world(args.name, args.id, args.seed, params)
    except ParamError as e:
        print(f"sme world: {e}", file=sys.stderr)
        return 2
    except ValueError as e:
        log.error("%s", e)
        return 2
    try:
        bus = Bus(bus_config_from_args(args, "world"))
    except BusError as e:
        log.error("%s", e)
        return 2
    with bus, world:
        node = WorldNode(
            world,
            bus,
            args.id or world.world_id,
            resend=args.resend,
            max_steps=args.steps,
            seconds=args.seconds,
            measure=args.stats_json is not None,
            warmup=args.warmup,
            external=args.external,
            lease_ttl=args.lease_ttl,
        )
        offer = getattr(world, "offer_embeddings", None)  # a ROS 2 robot: embeddings on a ROS 2 topic too
        if offer is not None:
            offer(bus, node.world_id)
        node.install_signal_handlers()
        stats = node.run()
    summary = stats.summary()
    log.info("world %s stopped: %s", node.world_id, summary)
    if args.stats_json:
        with open(args.stats_json, "w") as f:
            json.dump(summary, f)
    return 0
