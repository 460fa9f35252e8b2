"""World kinds by name, so that `sme world NAME` and the demo can build them, and `--list-params`,
`sme perturb --list` and the README can show each kind's declared parameters and perturbations.

World modules are imported lazily (PyBullet loads only for the worlds that need it). A name
``gym:ENV_ID`` is any Gymnasium environment (`worlds.gym_world`): its parameters are the world's
own (`GymWorldParams`) and the environment's keyword arguments. A World subclass from another
package is named ``package.module:Class``, or by the name its package declares in the
``sensorimotor.worlds`` entry-point group (``[project.entry-points."sensorimotor.worlds"]``)."""

from __future__ import annotations

import importlib
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol

from sensorimotor.protocol.params import ParamError, parse, unknown_name
from sensorimotor.worlds.base import World
from sensorimotor.worlds.names import GYM_PREFIX, import_user_module
from sensorimotor.worlds.quiet import pybullet_quiet


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
    absolute: bool = False  # `module` is a full import path (a world from another package)

    def _module(self) -> Any:
        with pybullet_quiet():  # the PyBullet worlds: its import line is no output of ours
            return importlib.import_module(self.module if self.absolute else f"sensorimotor.worlds.{self.module}")

    def world_class(self) -> WorldClass:
        """Import the world's module and return its World class."""
        return getattr(self._module(), self.cls)

    def params_type(self) -> type[Any]:
        """Import the world's module and return its parameter dataclass."""
        if self.absolute:
            return self.world_class().Params
        return getattr(self._module(), self.params)


WORLDS: dict[str, WorldKind] = {
    "gridworld": WorldKind("gridworld", "GridWorld", "GridWorldParams", "gridworld of Fig 5.1 (ch. 5)"),
    "gridworld-barrier": WorldKind(
        "gridworld", "GridWorld", "BarrierGridWorldParams", "the gridworld with the S-shaped barrier of Fig 5.1b"
    ),
    "retina": WorldKind("retina", "RetinaWorld", "RetinaWorldParams", "foveated retina on a pan/tilt camera (ch. 4)"),
    "retina-natural": WorldKind(
        "natural_retina",
        "NaturalRetinaWorld",
        "NaturalRetinaParams",
        "the ch. 4 retina over a natural picture (Table 4.1)",
    ),
    "vergence": WorldKind("vergence", "VergenceWorld", "VergenceWorldParams", "depth from vergence (ch. 7)"),
    "stereo": WorldKind(
        "stereo_pair", "StereoPairWorld", "StereoPairParams", "vergence on the Middlebury motorcycle pair (ch. 7.2.2)"
    ),
    "mountaincar": WorldKind(
        "mountaincar", "MountainCarWorld", "MountainCarWorldParams", "the visual mountain car (ch. 8)"
    ),
    "rovingeye": WorldKind(
        "roving_eye", "RovingEyeWorld", "RovingEyeParams", "a 128x128 eye over a bundled natural image (ch. 5.2)"
    ),
    "objectpose": WorldKind(
        "objectpose", "ObjectPoseWorld", "ObjectPoseWorldParams", "a textured box turned in pitch and yaw (ch. 6)"
    ),
    "arm": WorldKind("arm", "ArmWorld", "ArmWorldParams", "a robot arm from any URDF, seen by a fixed camera"),
    "bench": WorldKind("bench", "BenchWorld", "BenchWorldParams", "fixed-size observation for `sme bench loop`"),
}


#: the entry-point group through which installed packages offer World subclasses by name
ENTRY_POINT_GROUP = "sensorimotor.worlds"


def _outside_kind(name: str) -> WorldKind | None:
    """A World subclass from outside this project: ``package.module:Class`` (by path), or a name
    that an installed package declares in the ``sensorimotor.worlds`` entry-point group."""
    target = name
    if ":" not in name:
        from importlib.metadata import entry_points

        found = [ep for ep in entry_points(group=ENTRY_POINT_GROUP) if ep.name == name]
        if not found:
            return None
        target = found[0].value
    module, _, cls = target.partition(":")
    if not module or not cls:
        raise ParamError(f"world {name!r}: expected package.module:Class")
    try:
        mod = import_user_module(module)
    except ImportError as e:
        raise ParamError(f"world {name!r}: cannot import {module!r}: {e}") from None
    klass = getattr(mod, cls, None)
    if not (isinstance(klass, type) and issubclass(klass, World)):
        raise ParamError(f"world {name!r}: {module}.{cls} is not a World subclass")
    return WorldKind(module, cls, klass.Params.__name__, (klass.__doc__ or cls).strip().splitlines()[0], absolute=True)


GYM_KIND = WorldKind("gym_world", "GymWorld", "GymWorldParams", "any Gymnasium environment")
#: a ROS 2 robot (`sme world ros2 --robot FILE.toml`, docs/ros2.md): not in WORLDS, which lists the
#: kinds that build from their defaults alone
ROS2_KIND = WorldKind(
    "ros2.world", "Ros2World", "Ros2WorldParams", "a ROS 2 robot over rmw_zenoh, mapped by a robot file (--robot FILE)"
)


def world_kind(name: str) -> WorldKind:
    """The registry entry of world kind `name` (`GYM_KIND` for ``gym:ENV_ID``); a ParamError naming
    the known kinds otherwise."""
    if name.startswith(GYM_PREFIX):
        return GYM_KIND
    if name == "ros2":
        return ROS2_KIND
    if name in WORLDS:
        return WORLDS[name]
    outside = _outside_kind(name)
    if outside is not None:
        return outside
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
        A world kind of `WORLDS` (``gridworld``, ``retina``, ``vergence``...) or ``gym:ENV_ID``.
    world_id : str or None, default=None
        The world's id on the bus (default: `name`; for ``gym:ENV_ID``, ENV_ID made a valid id).
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
    if name.startswith(GYM_PREFIX):
        from sensorimotor.worlds.gym_world import make_gym_world

        return make_gym_world(name, world_id, seed, params)
    kind = world_kind(name)
    prm = parse(kind.params_type(), params or {}, name=name)
    if world_id is None and kind.absolute:  # a path is no bus id: the class's kind (or name) is
        klass: Any = kind.world_class()
        world_id = re.sub(
            r"[^A-Za-z0-9_.-]",
            "-",
            getattr(klass, "kind", "") if getattr(klass, "kind", "world") != "world" else kind.cls.lower(),
        )
    return kind.world_class()(world_id or name, seed, prm)
