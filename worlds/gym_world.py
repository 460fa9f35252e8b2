"""Any Gymnasium environment with discrete actions as a world: `sme world gym:ENV_ID`.

The environment's observation is the world's one sensor ``observation`` (a Discrete space: an int32
state id; a Box: its values, as float32 or as they are for uint8 images; any other space: flattened
by `gymnasium.spaces.flatten`). Actions are the environment's Discrete actions. The world asks for the
generic program (ch. 6), which learns any world without world-specific code.

Start states and truth come from what the environment lets a world set:

* toy-text grids (FrozenLake, CliffWalking, Taxi: a transition table ``P`` and a state ``s``): every
  state reachable from the initial ones and not ended on entry (holes, the goal), truth the cell's
  (row, col) (Taxi: its decoded tuple);
* classic control whose ``unwrapped.state`` can be set (`STATE_GRIDS`: MountainCar, CartPole,
  Acrobot): a `start_grid` x `start_grid` grid over two state variables, truth those variables, each
  scaled to 0..1 over its grid (the raw values are the truth tensor ``state``);
* anything else: no start states and no truth; the world says so in its log and its spec's
  ``start_states`` parameter, and the generic program learns it without embedding it.

Environment keyword arguments are `--param k=v` pairs, typed by the environment's constructor
defaults (bool/int/float/str/tuple) or, without a default, read as the most specific of
bool/int/float/none/str; a key the constructor does not take is refused with the valid ones.
"""

from __future__ import annotations

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

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, _scalar, option, parse, suggest, table_text, unknown_name
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.registry import GYM_PREFIX

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
    "CartPoleEnv": StateGrid(("x", "theta"), ((-2.0, 2.0, True), 0.0, (-0.18, 0.18, True), 0.0)),
    "AcrobotEnv": StateGrid(("theta1", "theta2"), ((-np.pi, np.pi, False), (-np.pi, np.pi, False), 0.0, 0.0)),
}

# gym.make's own keyword arguments that a world must not pass through
_RESERVED = {"render_mode", "max_episode_steps", "disable_env_checker", "autoreset", "apply_api_compatibility"}


def env_id_of(name: str) -> str:
    """``gym:FrozenLake-v1`` -> ``FrozenLake-v1``."""
    return name[len(GYM_PREFIX) :] if name.startswith(GYM_PREFIX) else name


def default_world_id(env_id: str) -> str:
    """A bus id for an environment id: characters a key chunk cannot hold become ``-``."""
    return re.sub(r"[^A-Za-z0-9_.-]", "-", env_id)[:64] or "gym"


def env_spec(env_id: str) -> gym.envs.registration.EnvSpec:
    """The registered spec of `env_id` (ParamError naming close ids when there is none)."""
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
    """One (low, high) for the whole Box: its bounds when finite and moderate, else the range seen
    over random steps, widened by half its span."""
    lo, hi = np.asarray(box.low, float), np.asarray(box.high, float)
    if np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and max(np.abs(lo).max(), np.abs(hi).max()) <= 1e6:
        return float(lo.min()), float(hi.max())
    seen = np.stack([sample() for _ in range(500)])
    a, b = float(seen.min()), float(seen.max())
    pad = 0.5 * max(b - a, 1e-6)
    return a - pad, b + pad


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
        For an unknown environment, an unknown keyword argument, or an action space that is not
        Discrete (a world of this kind serves discrete actions only).

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
        try:
            self.env = gym.make(env_id, max_episode_steps=self.max_episode_steps, **self.env_kwargs)
        except TypeError as e:  # a keyword the constructor refused after all
            raise ParamError(f"gym:{env_id}: {e}") from None
        except gym.error.Error as e:  # e.g. DependencyNotInstalled (Box2D, MuJoCo, ALE...)
            raise ParamError(f"gym:{env_id} cannot be made here: {e}") from None
        self.kind = GYM_PREFIX + env_id
        act = self.env.action_space
        if not isinstance(act, spaces.Discrete):
            self.env.close()
            raise ParamError(
                f"gym:{env_id} has a {type(act).__name__} action space ({act}); `sme world gym:` serves "
                "Discrete actions only (wrap the environment to discretise its actions)"
            )
        self._a0, self._na = int(act.start), int(act.n)
        self._first_reset = True
        self._obs_fn, self._sensor = self._observation_sensor()
        self.u: Any = self.env.unwrapped
        self._starts: list[Any] = []
        self._truth: np.ndarray | None = None
        self._raw: np.ndarray | None = None
        self._set_start: Callable[[Any], Any] | None = None
        self.how = self._declare_starts()
        if not self._starts:
            log.warning("gym:%s: %s: no start states, no truth (learned, not embedded)", env_id, self.how)
        self.pos: Any = None

    # observations ------------------------------------------------------------------------------
    def _observation_sensor(self) -> tuple[Callable[[Any], np.ndarray], SensorSpec]:
        space = self.env.observation_space
        if isinstance(space, spaces.Discrete):
            lo, n = int(space.start), int(space.n)
            return (
                lambda o: np.array([int(o)], dtype=np.int32),
                SensorSpec(SENSOR, "int32", (1,), lo, lo + n - 1, f"{self.env_id} state id"),
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
            flat = spaces.flatten_space(space)
            if not isinstance(flat, spaces.Box):
                raise ParamError(f"gym:{self.env_id}: observation space {space} cannot be flattened to a vector")
            box = flat
            conv = lambda o: np.asarray(spaces.flatten(space, o), dtype=np.float32)  # noqa: E731
            dtype = "float32"

        low, high = (0.0, 255.0) if dtype == "uint8" else _box_range(box, self._random_observations(conv))
        return conv, SensorSpec(
            SENSOR, dtype, tuple(int(d) for d in box.shape), low, high, f"{self.env_id} observation"
        )

    def _random_observations(self, conv: Callable[[Any], np.ndarray]) -> Callable[[], np.ndarray]:
        """Observations of random steps (seeded by the world), for estimating an unbounded range."""
        rng = np.random.default_rng([self.seed, 7])
        state = {"obs": conv(self.env.reset(seed=int(rng.integers(2**31)))[0])}

        def nxt() -> np.ndarray:
            o, _, term, trunc, _ = self.env.step(self._a0 + int(rng.integers(self._na)))
            out = state["obs"]
            state["obs"] = conv(self.env.reset()[0] if term or trunc else o)
            return out

        return nxt

    # start states ------------------------------------------------------------------------------
    def _declare_starts(self) -> str:
        """Fill the start states, their truth and the setter; return how (for the spec and logs)."""
        u: Any = self.env.unwrapped  # the environment's own attributes (P, s, state) are not typed
        grid = STATE_GRIDS.get(type(u).__name__)
        if grid is not None and hasattr(u, "state"):
            return self._grid_starts(grid)
        if hasattr(u, "P") and isinstance(self.env.observation_space, spaces.Discrete):
            return self._table_starts()
        return "its state cannot be set"

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
        """One sensor ``observation``; the environment's discrete actions; its start states."""
        rr = getattr(self.u, "reward_range", None) or (-np.inf, np.inf)
        params = {"env_id": self.env_id, "start_states": self.how}
        params.update({k: str(v) for k, v in self.env_kwargs.items()})
        params.update({f.name: str(getattr(self.params, f.name)).lower() for f in fields(GymWorldParams)})
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(self._sensor,),
            action_space=ActionSpace(n=self._na),
            reward_min=float(rr[0]),
            reward_max=float(rr[1]),
            program=self.params.program,
            n_starts=len(self._starts),
            params=params,
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Reset the environment (seeded on the first reset), then set start state `start` (a random
        declared one when None and `random_starts`; the environment's own reset otherwise)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        env_seed = seed if seed is not None else (self.seed if self._first_reset else None)
        self._first_reset = False
        obs, _ = self.env.reset(seed=env_seed)
        n = len(self._starts)
        if n and (start is not None and start >= 0 or self.params.random_starts):
            k = self.pick_start(None, start, n)
            assert self._set_start is not None
            obs = self._set_start(self._starts[k])
        elif start is not None and start >= 0:
            raise ValueError(f"gym:{self.env_id} declares no start states ({self.how})")
        return StepResult({SENSOR: self._obs_fn(obs)})

    def step(self, action: np.ndarray) -> StepResult:
        """One environment step; ``done`` when it terminates or is truncated."""
        a = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= a < self._na:
            raise ValueError(f"action {a} out of range 0..{self._na - 1}")
        obs, reward, term, trunc, info = self.env.step(self._a0 + a)
        return StepResult(
            {SENSOR: self._obs_fn(obs)},
            float(reward),
            bool(term or trunc),
            {"terminated": bool(term), "truncated": bool(trunc)},
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


__all__ = ["GymWorld", "GymWorldParams", "STATE_GRIDS", "make_gym_world", "split_params"]
