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
from dataclasses import replace

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, BusMessage, add_bus_arguments, bus_config_from_args
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import Control, WorldEvent, WorldEventKind, WorldSpec, clip
from sensorimotor.protocol.params import quote
from sensorimotor.tools.common import parse_params

#: the generic kinds, which every world our node serves takes (worlds.body_changes)
GENERIC_KINDS = {
    "reverse": "a motor's sign (a box dimension mirrored, or a discrete action swapped with its opposite)",
    "permute": "actions or action dimensions exchanged (--param order=rotate|a:b|2,0,1)",
    "gain": "a weaker or stronger motor (--param gain=G: a box dimension scaled, a discrete action repeated)",
    "lesion": "an action that no longer acts (--param index=K), or a sensor region that reads 0 (--param what=sensor)",
    "noise": "sensor noise (--param sd=0.05)",
    "delay": "actions applied late (--param steps=K)",
    "restore": "every generic change undone (and the world's own heal)",
}

#: the kinds some worlds have of their own (they take precedence over a generic kind of the same name)
KINDS = {
    "lesion": "retina: fields within --param radius=R px of (u, v) px read 0 (default a small off-centre part "
    "of the fovea: u=6 v=0 radius=6); arm: --param joint=NAME locked (where it is, or at=RAD)",
    "reverse": "retina: swap up/down motor commands (again to restore); arm: flip --param joint=NAME's sign",
    "noise": "retina: additive sensor noise, --param sd=0.05",
    "heal": "retina, rovingeye, arm, vergence, mountain car: undo every perturbation",
    "gain": "rovingeye: every move becomes --param gain=G times longer (default 1.5; a different eye muscle); "
    "arm: --param joint=NAME gain=G scales that joint's step",
    "morph": "mountain car/vergence: change the body, e.g. --baseline 1.4 or --vertical (same as --param "
    "baseline=1.4, --param vertical=true); arm: --param link=NAME scale=1.3 lengthens a link",
}


def list_perturbations() -> str:
    """Every world kind's perturbations with their parameter tables (types, defaults, ranges)."""
    from sensorimotor.protocol.params import table_text
    from sensorimotor.worlds.body_changes.kinds import GENERIC
    from sensorimotor.worlds.registry import WORLDS, world_perturbations

    out = [
        "generic (every world served by sme; a world's own kind of the same name takes precedence):\n"
        + "\n".join(
            table_text(cls, f"  {kind}: {' '.join((cls.__doc__ or '').split())}").replace("\n", "\n  ")
            for kind, cls in GENERIC.items()
        )
    ]
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
        help="perturb a running world (reverse, permute, gain, lesion, noise, delay, restore, morph...)",
        description="Publish a Control message to a running world; the agent is not told: it has to notice the "
        "change from its own reward. Every world served by sme (any World, any Gymnasium environment) takes the "
        "generic kinds: "
        + "; ".join(f"{k}: {v}" for k, v in GENERIC_KINDS.items())
        + ". Some worlds have kinds of their own, which take precedence over a generic kind of the same name: "
        + "; ".join(f"{k}: {v}" for k, v in KINDS.items())
        + ". `sme perturb --list --world ID` prints the kinds a running world takes.",
    )
    p.add_argument(
        "kind", nargs="?", help="perturbation kind: " + ", ".join({**GENERIC_KINDS, **KINDS}) + " (see --list)"
    )
    p.add_argument("--world", default=None, help="id of the running world (required unless --list)")
    p.add_argument(
        "--list",
        "--list-params",
        dest="list",
        action="store_true",
        help="print every world kind's perturbations and the generic ones with their parameters (type, default, "
        "range) and exit; with --world ID, the kinds that running world takes (its own and generic)",
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


def _declared(world_kind: str) -> dict[str, type] | None:
    """The declaration of world kind `world_kind` in this installation (None: not one it knows)."""
    from sensorimotor.protocol.params import ParamError
    from sensorimotor.worlds.registry import world_perturbations

    try:
        return world_perturbations(world_kind)
    except (ParamError, ImportError, AttributeError):
        return None


def refuse_locally(spec: WorldSpec, ctl: Control) -> str | None:
    """Why the running world already rules `ctl` out (None: it does not, or only the world can say).

    A world that advertises its kinds (our node: ``WorldSpec.params["perturbations"]``) refuses a
    kind it does not list; a generic kind's parameters are checked with its declaration, a world's
    own with its kind's declaration when this installation knows the kind. A world that does not
    advertise is checked against its kind's declaration alone (when known)."""
    from sensorimotor.worlds.base import PerturbationError, check_perturbation
    from sensorimotor.worlds.body_changes.advertise import advertised
    from sensorimotor.worlds.body_changes.kinds import GENERIC

    kinds = advertised(spec)
    declared = _declared(spec.kind)
    try:
        if kinds is None:
            if declared is not None:
                check_perturbation(spec.kind, declared, ctl)
            return None
        if ctl.kind not in kinds:
            check_perturbation(spec.kind, dict.fromkeys(kinds, type), ctl)  # raises, naming the valid kinds
        if kinds[ctl.kind].get("from") == "generic" and ctl.kind in GENERIC:
            check_perturbation(spec.kind, GENERIC, ctl)
        elif declared is not None and ctl.kind in declared:
            check_perturbation(spec.kind, declared, ctl)
    except PerturbationError as e:
        return str(e)
    return None


def list_world(args: argparse.Namespace) -> int:
    """`sme perturb --list --world ID`: the kinds the running world takes, with their parameters."""
    from sensorimotor.worlds.body_changes.advertise import advertised, listing

    try:
        with Bus(bus_config_from_args(args, "perturb")) as bus:
            if not bus.alive(keys.alive_world(args.world), timeout=2.0):
                print(f"sme perturb: no world {args.world!r} is alive on the bus (see `sme status`)", file=sys.stderr)
                return 1
            spec = _spec(bus, args.world)
    except BusError as e:
        print(f"sme perturb: {e}", file=sys.stderr)
        return 2
    if spec is None:
        print(f"sme perturb: world {args.world!r} did not answer its spec", file=sys.stderr)
        return 1
    kinds = advertised(spec)
    if kinds is None:  # a world served otherwise: what this installation knows of its kind
        from sensorimotor.worlds.body_changes.advertise import advertisement

        declared = _declared(spec.kind)
        if declared is None:
            print(f"world {args.world} ({spec.kind}) does not say which perturbations it takes; try one")
            return 0
        kinds = advertised(replace(spec, params={"perturbations": advertisement(declared, {})})) or {}
    print(listing(args.world, spec.kind, kinds))
    return 0


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
    if args.list and args.world:
        return list_world(args)
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
            why = refuse_locally(spec, ctl) if spec is not None else None
            if spec is not None and why is not None:
                print(f"sme perturb: not sent: {why} (world {args.world} is a {spec.kind})", file=sys.stderr)
                return 1
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
