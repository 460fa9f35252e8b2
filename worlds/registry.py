"""World kinds by name, so that `sme world NAME` and the demo can build them, and `--list-params`,
`sme perturb --list` and the README can show each kind's declared parameters and perturbations.

World modules are imported lazily (PyBullet loads only for the worlds that need it)."""

from __future__ import annotations

import importlib
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from sensorimotor.protocol.params import ParamError, parse, unknown_name
from sensorimotor.worlds.base import World


class WorldClass(Protocol):
    """A World subclass seen as a constructor: every world kind takes `(world_id, seed, params)`
    (the base `World.__init__` takes no parameters, so `type[World]` cannot be called this way)."""

    Params: type
    Perturbations: Mapping[str, type]

    def __call__(self, world_id: str, seed: int = 0, params: Any = None, /) -> World: ...


@dataclass(frozen=True)
class WorldKind:
    """Where a world kind lives: module, World class and its parameter dataclass (by name)."""

    module: str
    cls: str
    params: str
    summary: str

    def world_class(self) -> WorldClass:
        """Import the world's module and return its World class."""
        return getattr(importlib.import_module(f"sensorimotor.worlds.{self.module}"), self.cls)

    def params_type(self) -> type[Any]:
        """Import the world's module and return its parameter dataclass."""
        return getattr(importlib.import_module(f"sensorimotor.worlds.{self.module}"), self.params)


WORLDS: dict[str, WorldKind] = {
    "gridworld": WorldKind("gridworld", "GridWorld", "GridWorldParams", "gridworld of Fig 5.1 (ch. 5)"),
    "gridworld-barrier": WorldKind(
        "gridworld", "GridWorld", "BarrierGridWorldParams", "the gridworld with the S-shaped barrier of Fig 5.1b"
    ),
    "retina": WorldKind("retina", "RetinaWorld", "RetinaWorldParams", "foveated retina on a pan/tilt camera (ch. 4)"),
    "vergence": WorldKind("vergence", "VergenceWorld", "VergenceWorldParams", "depth from vergence (ch. 7)"),
    "stereo": WorldKind(
        "stereo_pair", "StereoPairWorld", "StereoPairParams", "vergence on the Middlebury motorcycle pair (ch. 7.2.2)"
    ),
    "mountaincar": WorldKind(
        "mountaincar", "MountainCarWorld", "MountainCarWorldParams", "the visual mountain car (ch. 8)"
    ),
    "objectpose": WorldKind(
        "objectpose", "ObjectPoseWorld", "ObjectPoseWorldParams", "a textured box turned in pitch and yaw (ch. 6)"
    ),
    "bench": WorldKind("bench", "BenchWorld", "BenchWorldParams", "fixed-size observation for `sme bench loop`"),
}


def world_kind(name: str) -> WorldKind:
    """The registry entry of world kind `name`; a ParamError naming the known kinds otherwise."""
    try:
        return WORLDS[name]
    except KeyError:
        raise ParamError(unknown_name("world", name, sorted(WORLDS))) from None


def world_params(name: str) -> type[Any]:
    """The parameter dataclass of world kind `name`."""
    return world_kind(name).params_type()


def world_perturbations(name: str) -> dict[str, type]:
    """World kind `name`'s perturbations: Control kind -> its parameter dataclass (may be empty)."""
    return dict(world_kind(name).world_class().Perturbations)


def parse_world_params(name: str, params: Mapping[str, Any] | None = None) -> Any:
    """World kind `name`'s parameters from `k=v` strings or typed values (ParamError if invalid)."""
    return parse(world_params(name), params or {}, name=name)


def make_world(name: str, world_id: str | None = None, seed: int = 0, params: Mapping[str, Any] | None = None) -> World:
    """Build a world by kind name; `params` are validated against its declaration first.

    Parameters
    ----------
    name : str
        A world kind of `WORLDS` (``gridworld``, ``retina``, ``vergence``...).
    world_id : str or None, default=None
        The world's id on the bus (default: `name`).
    seed : int, default=0
        Seeds the world's random generator.
    params : mapping or None, default=None
        Parameters as ``k=v`` strings or typed values (default: the kind's defaults).

    Returns
    -------
    World

    Raises
    ------
    ParamError
        For an unknown kind (with a suggestion) or an invalid parameter.

    Examples
    --------
    >>> w = make_world("gridworld", "grid0", seed=1, params={"size": "5"})
    >>> w.spec().n_starts
    25
    """
    kind = world_kind(name)
    prm = parse(kind.params_type(), params or {}, name=name)
    return kind.world_class()(world_id or name, seed, prm)
