"""Finding, making and configuring a Gymnasium environment for `sme world gym:ENV_ID`: the world's
own parameters (`GymWorldParams`), the environment ids (``gym:`` and ``gym:module:`` forms, family
packages imported on demand), its keyword arguments typed from the constructor's defaults, and the
per-family tables (classic-control state grids, goal rules, opposite actions)."""

import importlib
import inspect
import logging
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np

from sensorimotor.protocol.messages import GoalRule
from sensorimotor.protocol.params import ParamError, _scalar, option, parse, suggest, table_text, unknown_name
from sensorimotor.worlds.names import GYM_PREFIX, import_user_module
from sensorimotor.worlds.quiet import pybullet_quiet

log = logging.getLogger("sme.world")

SENSOR = "observation"


@dataclass(frozen=True)
class GymWorldParams:
    """The world's own parameters (every other `--param` is an environment keyword argument)."""

    start_grid: int = option(9, "grid points per state variable for the start states of classic control", min=2)
    random_starts: bool = option(
        True, "a reset without a start state draws a declared one (false: the environment's own reset)"
    )
    max_episode_steps: int = option(0, "episode step limit (0: the environment's own, else 1000)", min=0)
    program: str = option("generic", "the program the world asks the agent for")
    goal: str = option(
        "auto", "how the goal is recognised (auto: by family, see the module docstring)", choices=("auto", *GoalRule)
    )
    observe: str = option(
        "state",
        "what the agent sees: the environment's observation, or its rendered frames",
        choices=("state", "pixels"),
    )
    pixels: int = option(64, "observe=pixels: frame side in pixels (grey)", min=8, max=512)
    camera_distance: float = option(
        1.0,
        "observe=pixels, panda-gym: metres from the held target to the camera (panda-gym's own view, "
        "1.4 m from the base, leaves the hand's 30 cm cube a sixth of the frame)",
        min=0.3,
        max=5.0,
    )
    hand_velocity: bool = option(False, "panda-gym: serve the hand's velocity too, beside its position")
    view: str = option(
        "auto",
        "MiniGrid: what the agent sees - full (the whole grid, MiniGrid's own FullyObsWrapper: one "
        "observation per cell and heading) or agent (its egocentric view ahead, which shows cells of a "
        "room wider than the view alike, so the same observation and action lead to different places); "
        "auto: full when the room inside the walls is longer than the agent sees ahead (6 cells by default: "
        "Empty-16x16, SimpleCrossingS9), else agent",
        choices=("auto", "full", "agent"),
    )
    headings: int = option(
        1,
        "MiniGrid: start headings per cell (1: every start faces east; 4: all four - each start's "
        "traces are then in the frame of its own heading, and one cell's four do not agree: see docs/zoo.md)",
        choices=(1, 4),
    )


@dataclass(frozen=True)
class StateGrid:
    """How start states of a classic-control environment are set: for each component of
    ``unwrapped.state``, a fixed value or a grid range ``(lo, hi, endpoint)``; the gridded ones (at
    most two) are the truth, named `names`."""

    names: tuple[str, ...]
    components: tuple[float | tuple[float, float, bool], ...]


# keyed by the unwrapped environment's class name; the ranges stay clear of terminal states
STATE_GRIDS: dict[str, StateGrid] = {
    "MountainCarEnv": StateGrid(("position", "velocity"), ((-1.2, 0.45, True), (-0.07, 0.07, True))),
    "Continuous_MountainCarEnv": StateGrid(("position", "velocity"), ((-1.2, 0.45, True), (-0.07, 0.07, True))),
    "CartPoleEnv": StateGrid(("x", "theta"), ((-2.0, 2.0, True), 0.0, (-0.18, 0.18, True), 0.0)),
    "AcrobotEnv": StateGrid(("theta1", "theta2"), ((-np.pi, np.pi, False), (-np.pi, np.pi, False), 0.0, 0.0)),
}

# packages that register ids when imported, tried in turn for an id Gymnasium does not know
FAMILY_PACKAGES = {"MiniGrid-": "minigrid", "BabyAI-": "minigrid", "Panda": "panda_gym"}

# goal rules of environments whose terminations are failures, or that have no goal state
GOALS: dict[str, GoalRule] = {
    "FrozenLakeEnv": GoalRule.REWARD,
    "CartPoleEnv": GoalRule.NONE,
    "PendulumEnv": GoalRule.NONE,
}

# opposite discrete actions (for the generic `reverse`), by the unwrapped environment's class name
OPPOSITES: dict[str, list[tuple[int, int]]] = {
    "FrozenLakeEnv": [(0, 2), (1, 3)],  # left/right, down/up
    "CliffWalkingEnv": [(0, 2), (1, 3)],  # up/down, right/left
    "TaxiEnv": [(0, 1), (2, 3), (4, 5)],  # south/north, east/west, pickup/dropoff
    "MountainCarEnv": [(0, 2)],  # push left/right
    "CartPoleEnv": [(0, 1)],
    "AcrobotEnv": [(0, 2)],  # torque -1/+1
}
MINIGRID_OPPOSITES = [(0, 1), (3, 4)]  # turn left/right, pick up/drop

# gym.make's own keyword arguments that a world must not pass through
_RESERVED = {"render_mode", "max_episode_steps", "disable_env_checker", "autoreset", "apply_api_compatibility"}


def env_id_of(name: str) -> str:
    """``gym:FrozenLake-v1`` -> ``FrozenLake-v1``; ``gym:panda_gym:PandaReach-v3`` -> ``PandaReach-v3``
    after importing ``panda_gym`` (which registers it)."""
    env_id = name[len(GYM_PREFIX) :] if name.startswith(GYM_PREFIX) else name
    module, sep, rest = env_id.partition(":")
    if sep and rest:
        try:
            with pybullet_quiet():
                import_user_module(module)
        except ImportError as e:
            raise ParamError(f"gym:{env_id}: cannot import {module!r}, which should register {rest!r}: {e}") from None
        return rest
    return env_id


def _import_family(env_id: str) -> None:
    """Import the package that registers `env_id` when Gymnasium does not know it yet."""
    if env_id in gym.envs.registry:
        return
    for prefix, module in FAMILY_PACKAGES.items():
        if env_id.startswith(prefix):
            try:
                with pybullet_quiet():
                    importlib.import_module(module)
            except ImportError:
                pass


def default_world_id(env_id: str) -> str:
    """A bus id for an environment id: characters a key chunk cannot hold become ``-``."""
    return re.sub(r"[^A-Za-z0-9_.-]", "-", env_id)[:64] or "gym"


def env_spec(env_id: str) -> gym.envs.registration.EnvSpec:
    """The registered spec of `env_id` (ParamError naming close ids when there is none)."""
    _import_family(env_id)
    try:
        return gym.spec(env_id)
    except gym.error.Error as e:
        best = suggest(env_id, list(gym.envs.registry))
        hint = f" (did you mean {best!r}?)" if best else ""
        raise ParamError(f"unknown Gymnasium environment {env_id!r}{hint}: {e}") from None


def _constructor(spec: gym.envs.registration.EnvSpec) -> Callable[..., Any] | None:
    ep = spec.entry_point
    if isinstance(ep, str):
        try:
            return gym.envs.registration.load_env_creator(ep)
        except Exception:  # noqa: BLE001 - an entry point that cannot load: gym.make reports it
            return None
    return ep


def env_kwarg_defaults(env_id: str) -> tuple[dict[str, Any], bool]:
    """The keyword arguments the environment's constructor takes, with their defaults (registered
    ones first; `inspect.Parameter.empty` when none), and whether it also takes any other (``**kw``)."""
    spec = env_spec(env_id)
    ctor = _constructor(spec)
    out: dict[str, Any] = {}
    open_ended = ctor is None
    if ctor is not None:
        try:
            sig = inspect.signature(ctor)
        except (TypeError, ValueError):
            sig = None
            open_ended = True
        for name, p in (sig.parameters if sig else {}).items():
            if p.kind is inspect.Parameter.VAR_KEYWORD:
                open_ended = True
            elif p.kind in (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY):
                if name not in ("self", *_RESERVED):
                    out[name] = p.default
    for k, v in (spec.kwargs or {}).items():
        if k not in _RESERVED:
            out[k] = v
    return out, open_ended


def _guess(raw: str) -> Any:
    """A value without a typed default: the most specific of bool, int, float, none, str."""
    s = raw.strip()
    for tp in (bool, int, float):
        try:
            return _scalar(s, tp)
        except ValueError:
            pass
    return None if s.lower() in ("none", "null") else raw


def _typed(key: str, raw: Any, default: Any, env_id: str) -> Any:
    if not isinstance(raw, str):
        return raw
    if raw.strip().lower() in ("none", "null"):
        return None
    try:
        if isinstance(default, bool | int | float | str) and not isinstance(default, np.generic):
            return _scalar(raw, type(default))
        if isinstance(default, tuple | list) and default:
            parts = [x.strip() for x in raw.strip("()[] ").split(",") if x.strip()]
            elem = type(default[0]) if isinstance(default[0], bool | int | float | str) else str
            return type(default)(_scalar(x, elem) for x in parts)
    except ValueError:
        raise ParamError(
            f"gym:{env_id}: parameter {key}={raw!r} is not a {type(default).__name__} (default {default!r})"
        ) from None
    return _guess(raw)


def split_params(env_id: str, values: Mapping[str, Any] | None) -> tuple[GymWorldParams, dict[str, Any]]:
    """`--param` values split into the world's own parameters and the environment's typed keyword
    arguments; a key neither takes is a ParamError listing the valid ones."""
    own_names = {f.name for f in fields(GymWorldParams)}
    values = dict(values or {})
    own = {k: v for k, v in values.items() if k in own_names}
    rest = {k: v for k, v in values.items() if k not in own_names}
    prm = parse(GymWorldParams, own, name=f"gym:{env_id}")
    defaults, open_ended = env_kwarg_defaults(env_id)
    kwargs: dict[str, Any] = {}
    for k, v in rest.items():
        if k not in defaults and not open_ended:
            raise ParamError(unknown_name(f"parameter of gym:{env_id}", k, sorted(own_names | set(defaults))))
        kwargs[k] = _typed(k, v, defaults.get(k, inspect.Parameter.empty), env_id)
    return prm, kwargs


def gym_params_text(name: str) -> str:
    """`sme world gym:ENV_ID --list-params`: the world's own parameters and the environment's
    keyword arguments with their defaults."""
    env_id = env_id_of(name)
    defaults, open_ended = env_kwarg_defaults(env_id)
    own = table_text(GymWorldParams, f"gym:{env_id}: the world's own parameters")
    rows = [
        f"  {k} = {'(required)' if v is inspect.Parameter.empty else repr(v)}"
        for k, v in defaults.items()
        if k not in {f.name for f in fields(GymWorldParams)}
    ]
    more = "\n  (and any other keyword: the constructor takes **kwargs)" if open_ended else ""
    return f"{own}\n\ngym:{env_id}: environment keyword arguments (defaults)\n" + ("\n".join(rows) or "  (none)") + more
