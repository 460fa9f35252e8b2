"""`sme perturb KIND --world ID`: change a running world's body or sensors. The agent is not told.

The world checks the parameters against its declaration (`World.Perturbations`) and refuses a bad
control with a `control_refused` world event before anything changes; `sme perturb --list` prints
every world kind's perturbations and their parameter tables."""

from __future__ import annotations

import argparse
import sys
import time

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.messages import Control
from sensorimotor.tools.common import parse_params

KINDS = {
    "lesion": "retina: fields within --param radius=R px of (u, v) px read 0 (default a small off-centre part "
    "of the fovea: u=6 v=0 radius=6)",
    "reverse": "retina: swap up/down motor commands (again to restore)",
    "noise": "retina: additive sensor noise, --param sd=0.05",
    "heal": "undo every perturbation",
    "gain": "rovingeye: every move becomes --param gain=G times longer (default 1.5; a different eye muscle)",
    "morph": "mountain car/vergence: change the body, e.g. --baseline 1.4 or --vertical (same as --param "
    "baseline=1.4, --param vertical=true)",
}


def list_perturbations() -> str:
    """Every world kind's perturbations with their parameter tables (types, defaults, ranges)."""
    from sensorimotor.protocol.params import table_text
    from sensorimotor.worlds.registry import WORLDS, world_perturbations

    out = []
    for name in sorted(WORLDS):
        kinds = world_perturbations(name)
        if not kinds:
            out.append(f"{name}: no perturbations")
            continue
        out.append(
            f"{name}:\n"
            + "\n".join(
                table_text(cls, f"  {kind}: {(cls.__doc__ or '').strip()}").replace("\n", "\n  ")
                for kind, cls in kinds.items()
            )
        )
    return "\n\n".join(out)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "perturb",
        help="perturb a running world (lesion, reverse, noise, heal, morph)",
        description="Publish a Control message to a running world. Kinds: "
        + "; ".join(f"{k}: {v}" for k, v in KINDS.items())
        + ". The agent is not told: it has to notice the change from its own reward.",
    )
    p.add_argument("kind", nargs="?", help="perturbation kind: " + ", ".join(KINDS) + " (see --list)")
    p.add_argument("--world", default=None, help="id of the running world (required unless --list)")
    p.add_argument(
        "--list",
        "--list-params",
        dest="list",
        action="store_true",
        help="print every world kind's perturbations and their parameters (type, default, range) and exit",
    )
    p.add_argument("--param", action="append", metavar="K=V", help="perturbation parameter, repeatable")
    p.add_argument("--baseline", type=float, default=None, metavar="M", help="morph: camera baseline in metres")
    p.add_argument(
        "--vertical",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="morph: cameras one above the other (--no-vertical: side by side)",
    )
    add_bus_arguments(p, "perturb")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    if args.list:
        print(list_perturbations())
        return 0
    if not args.kind or not args.world:
        print("sme perturb: KIND and --world ID are required (see `sme perturb --list`)", file=sys.stderr)
        return 2
    try:
        keys.check_id(args.world, "world id")
    except ValueError as e:
        print(f"sme perturb: {e}", file=sys.stderr)
        return 2
    params = parse_params(args.param)
    if args.baseline is not None or args.vertical is not None:
        if args.kind != "morph":
            print("sme perturb: --baseline and --vertical belong to morph", file=sys.stderr)
            return 2
        if args.baseline is not None:
            if not args.baseline > 0:
                print("sme perturb: --baseline must be > 0", file=sys.stderr)
                return 2
            params["baseline"] = str(args.baseline)
        if args.vertical is not None:
            params["vertical"] = str(args.vertical).lower()
    ctl = Control(args.world, args.kind, params, time.time_ns() & 0xFFFFFFFF, time.time())
    try:
        with Bus(bus_config_from_args(args, "perturb")) as bus:
            if not bus.alive(keys.alive_world(args.world), timeout=2.0):
                print(f"sme perturb: no world {args.world!r} is alive on the bus (see `sme status`)", file=sys.stderr)
                return 1
            bus.put(keys.world_ctl(args.world), codec.encode(ctl), codec.schema_name(Control))
            time.sleep(0.2)  # let the put leave before the session closes
    except BusError as e:
        print(f"sme perturb: {e}", file=sys.stderr)
        return 2
    print(f"sent {args.kind} {dict(ctl.params) or ''} to world {args.world}")
    return 0
