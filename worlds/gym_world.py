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

import logging
from collections.abc import Callable, Mapping
from dataclasses import fields
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.protocol.messages import ActionSpace, Control, GoalRule, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.body_changes import hook as perturb_hook
from sensorimotor.worlds.gym_hooks import EmbeddableEnv, _hooked, _layers
from sensorimotor.worlds.gym_setup import (
    FAMILY_PACKAGES,
    GOALS,
    MINIGRID_OPPOSITES,
    OPPOSITES,
    SENSOR,
    STATE_GRIDS,
    GymWorldParams,
    StateGrid,
    default_world_id,
    env_id_of,
    env_kwarg_defaults,
    env_spec,
    gym_params_text,
    split_params,
)
from sensorimotor.worlds.gym_starts import GymStarts
from sensorimotor.worlds.names import GYM_PREFIX
from sensorimotor.worlds.quiet import pybullet_quiet

log = logging.getLogger("sme.world")


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


class GymWorld(GymStarts, World):
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


def make_gym_world(name: str, world_id: str | None, seed: int, params: Mapping[str, Any] | None) -> GymWorld:
    """`sme world gym:ENV_ID`: the world, its `--param` values split by `split_params`."""
    env_id = env_id_of(name)
    prm, kwargs = split_params(env_id, params)
    return GymWorld(env_id, world_id, seed, prm, kwargs)


__all__ = [
    "FAMILY_PACKAGES",
    "GOALS",
    "MINIGRID_OPPOSITES",
    "OPPOSITES",
    "SENSOR",
    "STATE_GRIDS",
    "EmbeddableEnv",
    "GymStarts",
    "GymWorld",
    "GymWorldParams",
    "StateGrid",
    "default_world_id",
    "env_id_of",
    "env_kwarg_defaults",
    "env_spec",
    "gym_params_text",
    "make_gym_world",
    "split_params",
]
