"""Any Gymnasium environment as a world: `sme world gym:ENV_ID` (or `gym:module:ENV_ID`, which
imports `module` first, as `gymnasium.make` does; MiniGrid and panda-gym ids are found without it).

Observations: a Discrete space is one int32 state id; a Box is its values (float32, or uint8 for
images); a Dict serves each key as its own sensor (a key that cannot be flattened to numbers, such
as MiniGrid's text `mission`, is left out with a warning); anything else is flattened.
`observe=pixels` serves the rendered frame instead (`pixels` x `pixels` grey uint8), so a world
whose state vector is its truth is learned from what a camera sees. Actions: Discrete, or a Box
(the values the agent sends, clipped to the bounds). The world asks for the generic program (ch. 6).

The goal (`WorldSpec.goal`, param `goal`): ``auto`` picks by family - a success flag where the
environment reports ``is_success`` (panda-gym, Gymnasium-Robotics), a positive reward where
terminations can be failures (FrozenLake's holes, MiniGrid's lava), ``terminated`` otherwise
(MountainCar, Acrobot, CliffWalking, Taxi) and ``none`` for CartPole and Pendulum, which have no
goal state.

Start states and truth come from the first of these that fits:

* a hook on the environment (any wrapper layer or the unwrapped env; see `EmbeddableEnv`):
  ``sme_start_states()``, ``sme_reset_to(start) -> observation``, ``sme_truth() -> [n, d]``, and
  optionally ``sme_goal`` - for a user's own environment, with no change to this project;
* toy-text grids (a transition table ``P`` and a state ``s``): every state reachable from the
  initial ones and not ended on entry, truth the cell's (row, col) (Taxi: its decoded tuple);
* classic control whose ``unwrapped.state`` can be set (`STATE_GRIDS`): a `start_grid` x
  `start_grid` grid over two state variables, truth those variables scaled to 0..1;
* MiniGrid: every free cell the agent can stand on (facing east, or in all four headings with
  `headings=4`), truth the cell; the layout is the one the world's seed draws, at every reset
  (LavaGap's gap, SimpleCrossing's walls), and a room longer than the agent sees ahead is served whole
  (`view`);
* panda-gym reach tasks: the target held at the middle of its range, start states a lattice of
  hand positions (`start_grid` per axis, at most 4) reached by inverse kinematics, truth the hand
  position;
* anything else: no start states and no truth; the world says so, and is learned, not embedded.

Body changes of the environment's own: ``sme_perturb(kind, params) -> str`` and
``sme_perturbations`` on any layer (see `worlds.body_changes.hook`; `EmbeddableEnv` takes both);
served by our node, the world also takes the generic changes of `worlds.body_changes`.

Environment keyword arguments are `--param k=v` pairs, typed by the environment's constructor
defaults (bool/int/float/str/tuple) or, without a default, read as the most specific of
bool/int/float/none/str; a key the constructor does not take is refused with the valid ones.
"""

from __future__ import annotations

import importlib
import inspect
import itertools
import logging
import re
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, fields
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.protocol.messages import ActionSpace, Control, GoalRule, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, _scalar, option, parse, suggest, table_text, unknown_name
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.body_changes import hook as perturb_hook
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


def _box_range(box: spaces.Box, sample: Callable[[], np.ndarray]) -> tuple[float, float]:
    """One (low, high) for the whole Box: its bounds when finite and not far wider than the range
    seen over random steps, else that range widened by half its span."""
    lo, hi = np.asarray(box.low, float), np.asarray(box.high, float)
    seen = np.stack([sample() for _ in range(500)])
    a, b = float(seen.min()), float(seen.max())
    pad = 0.5 * max(b - a, 1e-6)
    finite = np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and max(np.abs(lo).max(), np.abs(hi).max()) <= 1e6
    if finite and float(hi.max() - lo.min()) <= 4 * (b - a + 2 * pad):
        return float(lo.min()), float(hi.max())
    # bounds far wider than anything the environment does (panda-gym's +-10 m around a 30 cm
    # workspace) would leave a learner that scales by them almost blind
    return a - pad, b + pad


class EmbeddableEnv(gym.Wrapper):
    """The hook that makes any environment embeddable, as a wrapper: its start states, how to reset
    to one, and their truth (and, optionally, how its goal is recognised).

    Parameters
    ----------
    env : gymnasium.Env
        The environment.
    starts : sequence
        The start states, as whatever `reset_to` takes.
    reset_to : callable
        ``reset_to(env, start) -> observation``: after ``env.reset()``, put the environment into
        `start` and return its observation.
    truth : array-like
        ``[len(starts), d]`` true coordinates of the start states.
    goal : str or None, default=None
        A `GoalRule` token, when the family default does not fit.
    perturb : callable or None, default=None
        ``perturb(env, kind, params) -> str``: apply a body change of the environment's own and
        say what changed (see `worlds.body_changes.hook`); raise ValueError to refuse it.
    perturbations : mapping or None, default=None
        The kinds `perturb` offers: kind -> parameter dataclass (`params` is then its parsed
        instance) or a one-line description (`params` is then a dict of strings).

    An environment can offer the same by itself, with methods ``sme_start_states()``,
    ``sme_reset_to(start)``, ``sme_truth()``, ``sme_perturb(kind, params)`` and attributes
    ``sme_goal`` and ``sme_perturbations``, on any wrapper layer.

    Examples
    --------
    ::

        env = EmbeddableEnv(MyEnv(), starts=cells, reset_to=lambda e, c: e.unwrapped.place(c), truth=cells)
        gymnasium.register("my/Env-v0", entry_point=lambda **kw: EmbeddableEnv(MyEnv(**kw), ...))
        # sme world gym:my_package:my/Env-v0
    """

    def __init__(
        self,
        env: gym.Env,
        starts: Any,
        reset_to: Callable[[gym.Env, Any], Any],
        truth: Any,
        goal: str | None = None,
        perturb: Callable[[gym.Env, str, Any], str] | None = None,
        perturbations: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__(env)
        self._starts, self._reset_to = list(starts), reset_to
        self._truth = np.asarray(truth, dtype=np.float64)
        if self._truth.ndim != 2 or self._truth.shape[0] != len(self._starts):
            raise ValueError(f"truth must be [len(starts), d]; got {self._truth.shape} for {len(self._starts)} starts")
        if goal is not None:
            self.sme_goal = GoalRule(goal)
        if (perturb is None) != (perturbations is None):
            raise ValueError("perturb and perturbations go together: the hook and the kinds it offers")
        if perturb is not None:
            self.sme_perturbations = dict(perturbations or {})
            self._perturb = perturb

    def sme_perturb(self, kind: str, params: Any) -> str:
        """Apply the environment's own body change `kind` (the `perturb` given)."""
        if getattr(self, "_perturb", None) is None:
            raise ValueError("this EmbeddableEnv was given no perturb hook")
        return self._perturb(self.env, kind, params)

    def sme_start_states(self) -> list[Any]:
        return list(self._starts)

    def sme_reset_to(self, start: Any) -> Any:
        return self._reset_to(self.env, start)

    def sme_truth(self) -> np.ndarray:
        return self._truth


def _layers(env: gym.Env) -> list[Any]:
    """The wrapper layers of `env`, outermost first, down to the unwrapped environment."""
    out: list[Any] = []
    e: Any = env
    while e is not None and e not in out:
        out.append(e)
        e = getattr(e, "env", None) if isinstance(e, gym.Wrapper) else None
    return out


def _hooked(env: gym.Env, name: str) -> Any:
    """Attribute `name` of the first wrapper layer (or the unwrapped environment) that has it."""
    for layer in _layers(env):
        try:
            return getattr(layer, name)
        except AttributeError:
            continue
    return None


class GymWorld(World):
    """A Gymnasium environment served as a world (see the module docstring).

    Parameters
    ----------
    env_id : str
        A registered Gymnasium id (``FrozenLake-v1``, ``MountainCar-v0``...), with or without ``gym:``.
    world_id : str or None, default=None
        The world's id on the bus (default: `env_id` made a valid id).
    seed : int, default=0
        Seeds the environment (its first reset) and the world's draw of start states.
    params : GymWorldParams or None, default=None
        The world's own parameters.
    env_kwargs : mapping or None, default=None
        Keyword arguments of `gymnasium.make`, already typed (`split_params` types strings).

    Raises
    ------
    ParamError
        For an unknown environment, an unknown keyword argument, or an action or observation
        space that cannot be served (a Box action space of more than 4 dimensions is served; the
        generic program then refuses it).

    Examples
    --------
    >>> w = GymWorld("FrozenLake-v1", seed=0, env_kwargs={"is_slippery": False})
    >>> w.spec().n_starts, w.truth().tensors["positions"][0].tolist()
    (11, [0.0, 0.0])
    """

    kind = "gym"
    Params = GymWorldParams

    def __init__(
        self,
        env_id: str,
        world_id: str | None = None,
        seed: int = 0,
        params: GymWorldParams | None = None,
        env_kwargs: Mapping[str, Any] | None = None,
    ) -> None:
        env_id = env_id_of(env_id)
        super().__init__(world_id or default_world_id(env_id), seed)
        self.env_id = env_id
        self.params = prm = params or GymWorldParams()
        self.env_kwargs = dict(env_kwargs or {})
        spec = env_spec(env_id)
        limit = prm.max_episode_steps or spec.max_episode_steps or 1000
        self.max_episode_steps = int(limit)
        make_kw = dict(self.env_kwargs)
        if prm.observe == "pixels":
            make_kw["render_mode"] = "rgb_array"
            if env_id.startswith("Panda"):  # panda-gym renders at the size asked (720x480 by default)
                make_kw.setdefault("render_width", prm.pixels)
                make_kw.setdefault("render_height", prm.pixels)
        try:
            with pybullet_quiet():  # panda-gym's PyBullet start-up lines are no output of ours
                self.env = gym.make(env_id, max_episode_steps=self.max_episode_steps, **make_kw)
        except TypeError as e:  # a keyword the constructor refused after all
            raise ParamError(f"gym:{env_id}: {e}") from None
        except gym.error.Error as e:  # e.g. DependencyNotInstalled (Box2D, MuJoCo, ALE...)
            raise ParamError(f"gym:{env_id} cannot be made here: {e}") from None
        self.kind = GYM_PREFIX + env_id
        self.u: Any = self.env.unwrapped
        self._full_view: Any = None  # MiniGrid's FullyObsWrapper, when the whole grid is served
        if type(self.u).__module__.startswith("minigrid") and self._wants_full_view():
            from minigrid.wrappers import FullyObsWrapper

            self.env = self._full_view = FullyObsWrapper(self.env)
        act = self.env.action_space
        if isinstance(act, spaces.Discrete):
            self._a0, self._na = int(act.start), int(act.n)
            self._box: spaces.Box | None = None
        elif (
            isinstance(act, spaces.Box)
            and len(act.shape) == 1
            and np.all(np.isfinite(act.low))
            and np.all(np.isfinite(act.high))
        ):
            self._a0, self._na, self._box = 0, 0, act
        else:
            self.env.close()
            raise ParamError(
                f"gym:{env_id} has a {type(act).__name__} action space ({act}); `sme world gym:` serves Discrete "
                "actions and bounded one-dimensional Box actions (wrap the environment to change its actions)"
            )
        self._perturb_fn, self._own_kinds = self._perturb_hook()
        self._first_reset = True
        self._starts: list[Any] = []
        self._truth: np.ndarray | None = None
        self._raw: np.ndarray | None = None
        self._set_start: Callable[[Any], Any] | None = None
        self._family = ""
        self.how = self._declare_starts()
        self._obs_fn, self._sensors = self._observation_sensors()
        self.goal = self._goal_rule()
        if not self._starts:
            log.warning("gym:%s: %s: no start states, no truth (learned, not embedded)", env_id, self.how)
        self.pos: Any = None

    # the environment's own body changes --------------------------------------------------------
    def _perturb_hook(self) -> tuple[Callable[[str, Any], Any] | None, dict[str, type]]:
        """The first layer's ``sme_perturb`` and the kinds its ``sme_perturbations`` declares."""
        for layer in _layers(self.env):
            decl = getattr(layer, perturb_hook.DECLARED, None)
            if decl is None:
                continue
            fn = getattr(layer, perturb_hook.HOOK, None)
            try:
                if not callable(fn):
                    raise ValueError(
                        f"{type(layer).__name__} declares {perturb_hook.DECLARED} but has no {perturb_hook.HOOK}"
                    )
                return fn, perturb_hook.declared(decl)
            except ValueError as e:
                self.env.close()
                raise ParamError(f"gym:{self.env_id}: {e}") from None
        for layer in _layers(self.env):
            if callable(getattr(layer, perturb_hook.HOOK, None)) and not isinstance(layer, EmbeddableEnv):
                self.env.close()
                raise ParamError(
                    f"gym:{self.env_id}: {type(layer).__name__} defines {perturb_hook.HOOK} but not "
                    f"{perturb_hook.DECLARED} (kind -> parameter dataclass or a one-line description): "
                    "declare the kinds it offers"
                )
        return None, {}

    def opposite_actions(self) -> list[tuple[int, int]] | None:
        """The environment's ``sme_opposites`` (pairs of actions), else its family's (`OPPOSITES`)."""
        hooked = _hooked(self.env, "sme_opposites")
        if hooked is not None:
            return [(int(i), int(j)) for i, j in (hooked() if callable(hooked) else hooked)]
        if type(self.u).__module__.startswith("minigrid"):
            return list(MINIGRID_OPPOSITES)
        return OPPOSITES.get(type(self.u).__name__)

    def own_perturbations(self) -> dict[str, type]:
        """The kinds the environment offers through its ``sme_perturb`` hook (none without one)."""
        return dict(self._own_kinds)

    def perturb(self, control: Control) -> str:
        """Apply one of the environment's own kinds through its hook (refused with the valid kinds)."""
        return perturb_hook.apply(self._perturb_fn, self._own_kinds, self.kind, control)

    # goal --------------------------------------------------------------------------------------
    def _goal_rule(self) -> GoalRule:
        if self.params.goal != "auto":
            return GoalRule(self.params.goal)
        hooked = _hooked(self.env, "sme_goal")
        if hooked is not None:
            return GoalRule(hooked)
        if self._family == "panda" or "is_success" in self._reset_info:
            return GoalRule.SUCCESS
        if self._family == "minigrid":
            return GoalRule.REWARD
        return GOALS.get(type(self.u).__name__, GoalRule.TERMINATED)

    # observations ------------------------------------------------------------------------------
    def _observation_sensors(self) -> tuple[Callable[[Any], dict[str, np.ndarray]], tuple[SensorSpec, ...]]:
        if self.params.observe == "pixels":
            n = self.params.pixels

            def frame(_: Any) -> dict[str, np.ndarray]:
                return {"pixels": _grey(self._panda_frame(n) if self._family == "panda" else self.env.render(), n)}

            return frame, (SensorSpec("pixels", "uint8", (n, n), 0.0, 255.0, f"{self.env_id} rendered frame, grey"),)
        space = self.env.observation_space
        if self._family == "panda" and isinstance(space, spaces.Dict):
            # the target is held at one place and `achieved_goal` repeats the hand position; with hand
            # control (`control_type=ee`) the arm goes where it is sent, so its state is the hand's
            # position (`hand_velocity=true` adds the velocity as a second sensor)
            obs_box: Any = space["observation"]
            sensors = []
            parts = [("position", slice(0, 3))] + ([("velocity", slice(3, 6))] if self.params.hand_velocity else [])
            for name, part in parts:
                box = spaces.Box(obs_box.low[part], obs_box.high[part], dtype=np.float32)
                conv_part = lambda o, part=part: np.asarray(o[part], dtype=np.float32)  # noqa: E731
                low, high = _box_range(box, self._random_observations(conv_part, "observation"))
                sensors.append(SensorSpec(name, "float32", (3,), low, high, f"{self.env_id} hand {name}"))
            return (
                lambda o: {
                    "position": np.asarray(o["observation"][:3], np.float32),
                    "velocity": np.asarray(o["observation"][3:6], np.float32),
                },
                tuple(sensors),
            )
        pick = lambda o: o  # noqa: E731
        if isinstance(space, spaces.Dict):
            convs, sensors = [], []
            for key, sub in space.spaces.items():
                try:
                    conv, sensor = self._sensor_of(sub, str(key))
                except ParamError as e:
                    log.warning("gym:%s: observation key %r left out: %s", self.env_id, key, e)
                    continue
                convs.append((key, conv))
                sensors.append(sensor)
            if not sensors:
                raise ParamError(f"gym:{self.env_id}: no part of the observation space {space} can be served")
            return (lambda o: {s.name: c(o[k]) for (k, c), s in zip(convs, sensors, strict=True)}), tuple(sensors)
        conv, sensor = self._sensor_of(space, SENSOR)
        return (lambda o: {SENSOR: conv(pick(o))}), (sensor,)

    def _sensor_of(self, space: spaces.Space, name: str) -> tuple[Callable[[Any], np.ndarray], SensorSpec]:
        if isinstance(space, spaces.Discrete):
            lo, n = int(space.start), int(space.n)
            return (
                lambda o: np.array([int(o)], dtype=np.int32),
                SensorSpec(name, "int32", (1,), lo, lo + n - 1, f"{self.env_id} {name} (state id)"),
            )
        conv: Callable[[Any], np.ndarray]
        if isinstance(space, spaces.Box):
            box = space
            if box.dtype == np.uint8:
                conv = lambda o: np.asarray(o, dtype=np.uint8)  # noqa: E731
                dtype = "uint8"
            else:
                conv = lambda o: np.asarray(o, dtype=np.float32)  # noqa: E731
                dtype = "float32"
        else:
            try:
                flat = spaces.flatten_space(space)
            except NotImplementedError:
                raise ParamError(f"{type(space).__name__} cannot be flattened to numbers") from None
            if not isinstance(flat, spaces.Box):
                raise ParamError(f"observation space {space} cannot be flattened to a vector")
            box = flat
            conv = lambda o: np.asarray(spaces.flatten(space, o), dtype=np.float32)  # noqa: E731
            dtype = "float32"
        if dtype == "uint8":
            low, high = 0.0, 255.0
            if self._family == "minigrid" and name == "image":
                low, high = 0.0, 10.0  # object, colour and state indices: the largest is 10 (the object table)
        else:
            low, high = _box_range(box, self._random_observations(conv, name))
        return conv, SensorSpec(name, dtype, tuple(int(d) for d in box.shape), low, high, f"{self.env_id} {name}")

    def _random_observations(self, conv: Callable[[Any], np.ndarray], key: str) -> Callable[[], np.ndarray]:
        """Observations of random steps (seeded by the world), for estimating an unbounded range."""
        rng = np.random.default_rng([self.seed, 7])
        part = (
            (lambda o: o[key])
            if isinstance(self.env.observation_space, spaces.Dict) and key != SENSOR
            else ((lambda o: o["observation"]) if self._family == "panda" else (lambda o: o))
        )
        state = {"obs": conv(part(self.env.reset(seed=int(rng.integers(2**31)))[0]))}

        def nxt() -> np.ndarray:
            o, _, term, trunc, _ = self.env.step(self._random_action(rng))
            out = state["obs"]
            state["obs"] = conv(part(self.env.reset()[0] if term or trunc else o))
            return out

        return nxt

    def _random_action(self, rng: np.random.Generator) -> Any:
        if self._box is not None:
            return rng.uniform(self._box.low, self._box.high).astype(self._box.dtype)
        return self._a0 + int(rng.integers(self._na))

    # start states ------------------------------------------------------------------------------
    def _declare_starts(self) -> str:
        """Fill the start states, their truth and the setter; return how (for the spec and logs)."""
        u: Any = self.u  # the environment's own attributes (P, s, state) are not typed
        _, self._reset_info = self.env.reset(seed=self.seed)
        starts = _hooked(self.env, "sme_start_states")
        if starts is not None and _hooked(self.env, "sme_reset_to") is not None:
            return self._hook_starts()
        if type(u).__module__.startswith("minigrid"):
            self._family = "minigrid"
            return self._minigrid_starts()
        if type(u).__module__.startswith("panda_gym") and hasattr(u, "robot") and hasattr(u, "task"):
            self._family = "panda"
            return self._panda_starts()
        grid = STATE_GRIDS.get(type(u).__name__)
        if grid is not None and hasattr(u, "state"):
            return self._grid_starts(grid)
        if hasattr(u, "P") and isinstance(self.env.observation_space, spaces.Discrete):
            return self._table_starts()
        return "its state cannot be set (add the hook: see EmbeddableEnv)"

    def _hook_starts(self) -> str:
        self._family = "hook"
        self._starts = list(_hooked(self.env, "sme_start_states")())
        truth = _hooked(self.env, "sme_truth")
        if truth is not None:
            t = np.asarray(truth(), dtype=np.float64)
            if t.ndim != 2 or t.shape[0] != len(self._starts):
                raise ParamError(f"gym:{self.env_id}: sme_truth() gives {t.shape} for {len(self._starts)} start states")
            self._truth = t
        reset_to = _hooked(self.env, "sme_reset_to")
        self._set_start = lambda start: reset_to(start)
        return f"{len(self._starts)} start states from the environment's own hook"

    def _wants_full_view(self) -> bool:
        """MiniGrid: serve the whole grid (`view`; auto: when the room inside the walls is longer than
        the agent sees ahead, `agent_view_size` - 1 cells: then cells far from every wall look alike).
        The whole grid costs a quarter of the world's step rate (it is encoded at every step)."""
        if self.params.view != "auto":
            return self.params.view == "full"
        u: Any = self.u
        ahead = int(getattr(u, "agent_view_size", 7)) - 1
        return max(int(getattr(u, "width", 0)), int(getattr(u, "height", 0))) - 2 > ahead

    def _minigrid_starts(self) -> str:
        u: Any = self.u
        cells = [
            (x, y)
            for y in range(1, u.height - 1)
            for x in range(1, u.width - 1)
            if u.grid.get(x, y) is None
            or u.grid.get(x, y).can_overlap()
            and u.grid.get(x, y).type != "goal"
            and u.grid.get(x, y).type != "lava"
        ]
        self._starts = [(c, d) for c in cells for d in range(self.params.headings)]
        self._truth = np.array([c for c, _ in self._starts], dtype=np.float64)

        def set_state(start: Any) -> Any:
            (x, y), d = start
            u.agent_pos, u.agent_dir = (int(x), int(y)), int(d)
            obs = u.gen_obs()
            return obs if self._full_view is None else self._full_view.observation(obs)

        self._set_start = set_state
        return (
            f"{len(self._starts)} starts: {len(cells)} free cells x {self.params.headings} heading(s), truth the cell"
        )

    def _panda_starts(self) -> str:
        """A cube lattice of hand positions as wide as the task's goal range, centred on the held
        target and lifted so that its lowest layer clears the table by the reach tolerance (a hand
        resting on the table moves by contact). Contacts are made repeatable: pybullet orders the
        overlapping pairs of its broadphase by the history of the simulation unless told to sort
        them, so the same moves from the same start pressed the hand on the table differently from
        one episode to the next (`sensorimotor.tools.experiments.repeatable` measures it)."""
        u: Any = self.u
        u.sim.physics_client.setPhysicsEngineParameter(deterministicOverlappingPairs=1)
        lo, hi = np.asarray(u.task.goal_range_low, float), np.asarray(u.task.goal_range_high, float)
        clearance = float(getattr(u.task, "distance_threshold", 0.05))
        side = hi - lo
        centre = (lo + hi) / 2
        centre[2] = lo[2] + clearance + side[2] / 2
        self._goal = centre
        n = min(self.params.start_grid, 4)
        axes = [np.linspace(c - s / 2, c + s / 2, n) for c, s in zip(centre, side, strict=True)]
        points = [np.array(p) for p in itertools.product(*axes)]
        down = np.array([1.0, 0.0, 0.0, 0.0])  # the hand orientation panda-gym's hand control keeps
        angles = []
        truth = []
        for p in points:
            u.reset(seed=self.seed)
            for _ in range(8):  # pybullet's IK is one linearisation: repeat it from where it got to
                q = u.robot.inverse_kinematics(link=u.robot.ee_link, position=p, orientation=down)
                u.robot.set_joint_angles(q)
                if np.linalg.norm(u.robot.get_ee_position() - p) < 1e-3:
                    break
            angles.append(np.asarray(q, dtype=np.float64))
            truth.append(np.asarray(u.robot.get_ee_position(), dtype=np.float64))
        self._starts = angles
        self._truth = np.array(truth)

        def set_state(q: np.ndarray) -> Any:
            u.robot.set_joint_angles(q)
            u.task.goal = self._goal.copy()
            u.sim.set_base_pose("target", self._goal, np.array([0.0, 0.0, 0.0, 1.0]))
            return u._get_obs()

        self._set_start = set_state
        return (
            f"{len(points)} hand positions on a {n}x{n}x{n} lattice (inverse kinematics), "
            f"target held at its centre {np.round(self._goal, 3).tolist()}"
        )

    def _panda_frame(self, n: int) -> np.ndarray:
        """panda-gym's camera (yaw 45, pitch -30, field of view 60) aimed at the held target from
        `camera_distance`, without shadows: pybullet's TinyRenderer spends about 40 % of a frame on them
        (`sme bench world` measures the frame rate), and they move with the arm, not the hand."""
        import pybullet as p

        pc = self.u.sim.physics_client
        view = pc.computeViewMatrixFromYawPitchRoll(
            cameraTargetPosition=self._goal.tolist(),
            distance=self.params.camera_distance,
            yaw=45,
            pitch=-30,
            roll=0,
            upAxisIndex=2,
        )
        proj = pc.computeProjectionMatrixFOV(fov=60, aspect=1.0, nearVal=0.1, farVal=100.0)
        _, _, rgba, _, _ = pc.getCameraImage(
            n, n, view, proj, shadow=False, renderer=p.ER_TINY_RENDERER, flags=p.ER_NO_SEGMENTATION_MASK
        )
        return np.asarray(rgba, dtype=np.uint8).reshape(n, n, 4)[..., :3]

    def _grid_starts(self, grid: StateGrid) -> str:
        n = self.params.start_grid
        axes = [np.linspace(c[0], c[1], n, endpoint=c[2]) for c in grid.components if isinstance(c, tuple)]
        points = np.array(list(itertools.product(*axes)), dtype=np.float64)
        states = []
        for p in points:
            vals, it = [], iter(p)
            for c in grid.components:
                vals.append(next(it) if isinstance(c, tuple) else float(c))
            states.append(np.array(vals, dtype=np.float64))
        self._starts = states
        self._raw = points
        lo, hi = points.min(axis=0), points.max(axis=0)
        self._truth = (points - lo) / np.where(hi > lo, hi - lo, 1.0)
        u: Any = self.env.unwrapped  # the environment's own attributes (P, s, state) are not typed

        def set_state(state: np.ndarray) -> Any:
            u.state = np.array(state, dtype=np.float64)
            return u._get_ob() if hasattr(u, "_get_ob") else np.array(u.state, dtype=np.float32)

        self._set_start = set_state
        return f"{len(states)} starts on a {n} x {n} grid of ({', '.join(grid.names)})"

    def _table_starts(self) -> str:
        u: Any = self.env.unwrapped  # the environment's own attributes (P, s, state) are not typed
        P: Mapping[int, Mapping[int, list]] = u.P
        init = np.flatnonzero(np.asarray(getattr(u, "initial_state_distrib", []), dtype=float) > 0).tolist()
        if not init:
            init = [int(self.env.reset(seed=self.seed)[0])]
        ended = {int(nxt) for s in P for a in P[s] for (_, nxt, _, term) in P[s][a] if term}
        seen, todo = set(init), deque(init)
        while todo:
            s = todo.popleft()
            if s in ended:
                continue
            for a in P[s]:
                for prob, nxt, _, _ in P[s][a]:
                    if prob > 0 and int(nxt) not in seen:
                        seen.add(int(nxt))
                        todo.append(int(nxt))
        self._starts = sorted(s for s in seen if s not in ended)
        if hasattr(u, "ncol") and hasattr(u, "nrow"):
            self._truth = np.array([divmod(s, int(u.ncol)) for s in self._starts], dtype=np.float64)
            what = "(row, col)"
        elif hasattr(u, "shape"):
            self._truth = np.array([np.unravel_index(s, tuple(u.shape)) for s in self._starts], dtype=np.float64)
            what = "(row, col)"
        elif hasattr(u, "decode"):
            self._truth = np.array([list(u.decode(s)) for s in self._starts], dtype=np.float64)
            what = "decoded state"
        else:
            what = "no truth"

        def set_state(s: int) -> Any:
            u.s = int(s)
            if hasattr(u, "lastaction"):
                u.lastaction = None
            return int(s)

        self._set_start = set_state
        return f"{len(self._starts)} reachable non-terminal states, truth {what}"

    # the World interface ---------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """The sensors; the environment's actions (discrete or a box); its start states and goal rule."""
        rr = getattr(self.u, "reward_range", None) or (-np.inf, np.inf)
        params = {"env_id": self.env_id, "start_states": self.how}
        if self._truth is not None:
            params["truth_dims"] = str(self._truth.shape[1])
        params.update({k: str(v) for k, v in self.env_kwargs.items()})
        params.update({f.name: str(getattr(self.params, f.name)).lower() for f in fields(GymWorldParams)})
        params["max_episode_steps"] = str(
            self.max_episode_steps
        )  # the limit in force (the parameter's 0 means "the environment's")
        if self._box is not None:
            b = self._box
            action_space = ActionSpace(low=tuple(float(v) for v in b.low), high=tuple(float(v) for v in b.high))
        else:
            action_space = ActionSpace(n=self._na)
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=self._sensors,
            action_space=action_space,
            reward_min=float(rr[0]),
            reward_max=float(rr[1]),
            program=self.params.program,
            n_starts=len(self._starts),
            params=params,
            goal=self.goal,
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Reset the environment (seeded on the first reset), then set start state `start` (a random
        declared one when None and `random_starts`; the environment's own reset otherwise)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        # a MiniGrid layout is drawn at reset (LavaGap's gap, SimpleCrossing's walls): every reset
        # draws the seed's one, so the start states and their truth stay those of the served world
        fixed = self._first_reset or self._family == "minigrid"
        env_seed = seed if seed is not None else (self.seed if fixed else None)
        self._first_reset = False
        obs, _ = self.env.reset(seed=env_seed)
        n = len(self._starts)
        if n and (start is not None and start >= 0 or self.params.random_starts):
            k = self.pick_start(None, start, n)
            assert self._set_start is not None
            obs = self._set_start(self._starts[k])
        elif start is not None and start >= 0:
            raise ValueError(f"gym:{self.env_id} declares no start states ({self.how})")
        return StepResult(self._obs_fn(obs))

    def step(self, action: np.ndarray) -> StepResult:
        """One environment step; ``done`` when it terminates or is truncated (``truncated`` says
        which), ``success`` from the environment's ``is_success``."""
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if self._box is not None:
            if a.size != self._box.shape[0]:
                raise ValueError(f"action has {a.size} values; the box has {self._box.shape[0]}")
            act: Any = np.clip(a, self._box.low, self._box.high).astype(self._box.dtype)
        else:
            i = int(a[0])
            if not 0 <= i < self._na:
                raise ValueError(f"action {i} out of range 0..{self._na - 1}")
            act = self._a0 + i
        obs, reward, term, trunc, info = self.env.step(act)
        if self._family == "panda":
            self.u.task.goal = self._goal.copy()  # held: panda-gym never moves it within an episode, but be sure
        success = bool(np.asarray(info.get("is_success", False)).any()) if isinstance(info, dict) else False
        return StepResult(
            self._obs_fn(obs),
            float(reward),
            bool(term or trunc),
            {"terminated": bool(term), "truncated": bool(trunc)},
            truncated=bool(trunc and not term),
            success=success,
        )

    def truth(self) -> Truth | None:
        """The start states' coordinates (see the module docstring), or None."""
        if self._truth is None:
            return None
        tensors = {"positions": self._truth}
        if self._raw is not None:
            tensors["state"] = self._raw
        return Truth(self.world_id, "start_states", tensors)

    def close(self) -> None:
        self.env.close()


def _grey(frame: Any, n: int) -> np.ndarray:
    """An RGB(A) frame as an n x n grey uint8 image (area-averaged, no extra dependency)."""
    a = np.asarray(frame, dtype=np.float64)
    if a.ndim == 3:
        a = a[..., :3] @ np.array([0.299, 0.587, 0.114])
    h, w = a.shape
    ys = (np.arange(n + 1) * h) // n
    xs = (np.arange(n + 1) * w) // n
    out = np.add.reduceat(np.add.reduceat(a, ys[:-1], axis=0), xs[:-1], axis=1)
    counts = np.outer(np.diff(ys), np.diff(xs))
    return np.clip(out / np.maximum(counts, 1), 0, 255).astype(np.uint8)


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


def make_gym_world(name: str, world_id: str | None, seed: int, params: Mapping[str, Any] | None) -> GymWorld:
    """`sme world gym:ENV_ID`: the world, its `--param` values split by `split_params`."""
    env_id = env_id_of(name)
    prm, kwargs = split_params(env_id, params)
    return GymWorld(env_id, world_id, seed, prm, kwargs)


__all__ = ["EmbeddableEnv", "GymWorld", "GymWorldParams", "STATE_GRIDS", "make_gym_world", "split_params"]
