"""`sme perturb KIND --world ID`: change a running world's body or sensors. The agent is not told.

The command answers with the world's words: it sends a Control with a fresh request id, waits for
the world's `control_applied` or `control_refused` WorldEvent carrying that id, prints what the
world said and exits 0 (applied) or 1 (refused, or no answer in --timeout). What the declaration of
the running world's kind (`World.Perturbations`, read from its spec's kind) already rules out, an
unknown kind or a parameter out of range, is refused before anything is sent (exit 2).
`sme perturb --list` prints every world kind's perturbations and their parameter tables."""

from __future__ import annotations

import argparse
import queue
import secrets
import sys
import time

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, BusMessage, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import Control, WorldEvent, WorldEventKind, WorldSpec, clip
from sensorimotor.protocol.params import quote
from sensorimotor.tools.common import parse_params

KINDS = {
    "lesion": "retina: fields within --param radius=R px of (u, v) px read 0 (default a small off-centre part "
    "of the fovea: u=6 v=0 radius=6); arm: --param joint=NAME locked (where it is, or at=RAD)",
    "reverse": "retina: swap up/down motor commands (again to restore); arm: flip --param joint=NAME's sign",
    "noise": "retina: additive sensor noise, --param sd=0.05",
    "heal": "undo every perturbation",
    "gain": "rovingeye: every move becomes --param gain=G times longer (default 1.5; a different eye muscle); "
    "arm: --param joint=NAME gain=G scales that joint's step",
    "morph": "mountain car/vergence: change the body, e.g. --baseline 1.4 or --vertical (same as --param "
    "baseline=1.4, --param vertical=true); arm: --param link=NAME scale=1.3 lengthens a link",
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
    p.add_argument(
        "--timeout",
        type=float,
        default=10.0,
        metavar="S",
        help="seconds to wait for the world's answer (default 10; a world applies controls between steps, "
        "so it answers once something steps it)",
    )
    add_bus_arguments(p, "perturb")
    p.set_defaults(func=main_args)


def refuse_locally(world_kind: str, ctl: Control) -> str | None:
    """Why the declaration of world kind `world_kind` already rules `ctl` out (None: it does not, or
    the kind is not one this installation knows, e.g. a world written elsewhere: then only the world
    can say)."""
    from sensorimotor.protocol.params import ParamError
    from sensorimotor.worlds.base import PerturbationError, check_perturbation
    from sensorimotor.worlds.registry import world_perturbations

    try:
        declared = world_perturbations(world_kind)
    except (ParamError, ImportError, AttributeError):
        return None
    try:
        check_perturbation(world_kind, declared, ctl)
    except PerturbationError as e:
        return str(e)
    return None


def _spec(bus: Bus, world: str) -> WorldSpec | None:
    try:
        replies = bus.get(keys.world_spec(world), timeout=2.0)
        return codec.decode(WorldSpec, replies[0].payload) if replies else None
    except (BusError, ProtocolError):
        return None


def answers(ctl: Control, ev: WorldEvent) -> bool:
    """Whether world event `ev` is the world's answer to `ctl` (by request id; a world that does not
    echo ids, `control_id` 0, is matched by the control's kind)."""
    if ev.kind not in (WorldEventKind.CONTROL_APPLIED, WorldEventKind.CONTROL_REFUSED):
        return False
    return ev.control_id == ctl.id if ev.control_id else ev.reason == ctl.kind


def main_args(args: argparse.Namespace) -> int:
    if args.list:
        print(list_perturbations())
        return 0
    if not args.kind or not args.world:
        print("sme perturb: KIND and --world ID are required (see `sme perturb --list`)", file=sys.stderr)
        return 2
    if not args.timeout > 0:
        print("sme perturb: --timeout must be > 0", file=sys.stderr)
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
    ctl = Control(args.world, args.kind, params, secrets.randbits(63) | 1, time.time())
    got: queue.Queue[WorldEvent] = queue.Queue()

    def on_event(msg: BusMessage) -> None:
        try:
            ev = codec.decode(WorldEvent, msg.payload)
        except ProtocolError:
            return
        if answers(ctl, ev):
            got.put(ev)

    try:
        with Bus(bus_config_from_args(args, "perturb")) as bus:
            if not bus.alive(keys.alive_world(args.world), timeout=2.0):
                print(f"sme perturb: no world {args.world!r} is alive on the bus (see `sme status`)", file=sys.stderr)
                return 1
            spec = _spec(bus, args.world)
            why = refuse_locally(spec.kind, ctl) if spec is not None else None
            if spec is not None and why is not None:
                print(f"sme perturb: not sent: {why} (world {args.world} is a {spec.kind})", file=sys.stderr)
                return 2
            bus.subscribe(keys.world_event(args.world), on_event)
            bus.put(keys.world_ctl(args.world), codec.encode(ctl), codec.schema_name(Control))
            shown = ", ".join(f"{k}={quote(v)}" for k, v in ctl.params.items())  # bounded: never a 100 KB echo
            print(f"sent {clip(args.kind, 64)} {shown} to world {args.world}".replace("  ", " "), flush=True)
            try:
                ev = got.get(timeout=args.timeout)
            except queue.Empty:
                print(
                    f"sme perturb: world {args.world} did not answer within {args.timeout:g} s. A world applies "
                    "controls between steps, so it answers once an agent steps it: is one attached (`sme status`)? "
                    "The control stays queued and is applied at the world's next step.",
                    file=sys.stderr,
                )
                return 1
    except BusError as e:
        print(f"sme perturb: {e}", file=sys.stderr)
        return 2
    if ev.kind == WorldEventKind.CONTROL_APPLIED:
        print(f"world {args.world} applied {args.kind}: {clip(ev.detail)}")
        return 0
    print(f"sme perturb: world {args.world} refused {clip(args.kind, 64)}: {clip(ev.detail)}", file=sys.stderr)
    return 1
