"""The visual mountain car (ch. 8): the vergence robot drives along its track under the
mountain-car dynamics (Eq 8.1-8.6), and sees only its two foveae.

Track position x in (-2, 2) is `track_scale` metres per unit; the stop sign stands
`sign_distance` m ahead of x = 0, so the robot's distance to it is Z = sign_distance - x *
track_scale (1.1 m at the goal x = 1.9, 5 m at the left wall with the defaults). Observations are
the tensors "left" and "right" (foveae) and nothing else: no position, no velocity.

Actions (discrete, 5): 0 converge, 1 diverge (the vergence motor: the eyes turn by `step_rad`,
the car does not move), 2 reverse, 3 coast, 4 forward (one mountain-car step with a = -1, 0, 1;
the eyes return to parallel, a fixed eye width, so every position is read by a fresh vergence
trace). Reward: 1 when a vergence action reaches the perceptual goal at the current position (the
vergence where the foveated difference of Eq 7.2 is minimal), 1 with done when a drive action
reaches the goal x > 1.9, else 0; an episode also ends (done, reward 0) after `max_car_steps`.

Start states: 0..n_positions-1 are evenly spaced track positions at rest (the vergence sweep);
the next n_eval are fixed random (x, v) states drawn with `eval_seed`, the same for every world so
evaluations compare; a reset to -1 draws a random (x, v) from the world's generator.

Bodies (`morph` control, also at runtime): baseline (default 1.0 m; the dissertation also uses
1.4 m) and vertical cameras. Rendering is cached per `render_grid` metres of track (the eyes
render from the cell's centre), so a position revisited costs no render.
"""

from __future__ import annotations

import collections
from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, Control, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import StepResult
from sensorimotor.worlds.mountaincar_dynamics import EVAL_SEED, MountainCarParams, evaluation_states, random_state
from sensorimotor.worlds.mountaincar_dynamics import step as car_step
from sensorimotor.worlds.vergence import VergenceWorld, VergenceWorldParams, verge

CONVERGE, DIVERGE, REVERSE, COAST, FORWARD = range(5)


@dataclass(frozen=True)
class MountainCarWorldParams:
    """Parameters of the visual mountain car (ch. 8)."""

    baseline: float = option(1.0, "distance between the cameras, m (the dissertation also uses 1.4)")
    vertical: bool = option(False, "cameras one above the other instead of side by side")
    sign_distance: float = option(3.0, "the stop sign's distance ahead of x = 0, m")
    track_scale: float = option(1.0, "metres of track per unit of x")
    n_positions: int = option(20, "sweep start states: evenly spaced track positions at rest", min=2)
    n_eval: int = option(100, "evaluation start states: fixed random (x, v) drawn with eval_seed", min=0)
    eval_seed: int = option(EVAL_SEED, "seed of the evaluation states (the same for every world)")
    fovea: int = option(16, "fovea side, px", min=1)
    fovea_deg: float = option(12.0, "fovea field of view, degrees")
    max_vergence: int = option(70, "vergence steps (the eyes' range)", min=2)
    max_car_steps: int = option(1000, "car steps after which an episode ends", min=1)
    render_grid: float = option(0.005, "render cache cell, m of track (> 0)")
    goal_window: int = option(10, "perceptual-goal search, steps either side of the geometric fixation", min=0)
    cache_size: int = option(60_000, "rendered eye pairs kept in the cache", min=1)
    thrust_noise: float = option(
        0.0, "std of Gaussian noise added to each drive's thrust, in units of the engine's push (ch. 9.4)", min=0.0
    )


class MountainCarWorld(VergenceWorld):
    """The visual mountain car (ch. 8): the vergence robot drives along its track under the
    mountain-car dynamics and sees only its two foveae.

    Actions: 0 converge, 1 diverge (the eyes move, the car does not), 2 reverse, 3 coast,
    4 forward (one car step; the eyes return to parallel).

    Parameters
    ----------
    world_id : str, default="mountaincar"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (random starts).
    params : MountainCarWorldParams or None, default=None
        The parameters (default: `MountainCarWorldParams()`).
    **overrides
        Parameter values applied over `params` (``k=v`` strings or typed values), checked by
        `protocol.params.parse`.

    Raises
    ------
    ValueError
        If the sign comes within 0.2 m of the robot anywhere on the track.
    """

    kind = "mountaincar"
    Params = MountainCarWorldParams

    def __init__(
        self,
        world_id: str = "mountaincar",
        seed: int = 0,
        params: MountainCarWorldParams | None = None,
        **overrides: Any,
    ) -> None:
        prm = parse(MountainCarWorldParams, overrides, name=self.kind, base=params)
        baseline, vertical, sign_distance, track_scale = prm.baseline, prm.vertical, prm.sign_distance, prm.track_scale
        n_positions, n_eval, eval_seed, fovea, fovea_deg = (
            prm.n_positions,
            prm.n_eval,
            prm.eval_seed,
            prm.fovea,
            prm.fovea_deg,
        )
        max_vergence, max_car_steps, render_grid = prm.max_vergence, prm.max_car_steps, prm.render_grid
        goal_window, cache_size = prm.goal_window, prm.cache_size
        self.car = MountainCarParams()
        if track_scale <= 0 or sign_distance - self.car.x_max * track_scale <= 0.2:
            raise ValueError("the sign must stay at least 0.2 m ahead of the robot over the whole track")
        if n_positions < 2 or n_eval < 0 or max_car_steps < 1 or render_grid <= 0 or max_vergence < 2:
            raise ValueError(
                "need n_positions >= 2, n_eval >= 0, max_car_steps >= 1, render_grid > 0, max_vergence >= 2"
            )
        self.track_scale, self.render_grid, self.goal_window = track_scale, render_grid, goal_window
        self.max_car_steps, self.n_positions, self.n_eval = max_car_steps, n_positions, n_eval
        super().__init__(
            world_id,
            seed,
            VergenceWorldParams(
                baseline=baseline,
                sign_distance=sign_distance,
                n_starts=n_positions,
                nearest=0.5,
                fovea=fovea,
                fovea_deg=fovea_deg,
                max_steps=max_vergence,
                vertical=vertical,
                sign_radius=0.9,
                room=True,
            ),
        )
        self.params = prm
        xs = np.linspace(self.car.x_min, self.car.goal, n_positions + 1)[:-1]
        self.starts = np.vstack([np.c_[xs, np.zeros_like(xs)], evaluation_states(n_eval, eval_seed, self.car)])
        self.distances = self.z_of(self.starts[:, 0])
        self.x, self.v = float(xs[0]), 0.0
        self.car_t = 0
        self._cache_size = cache_size
        self._images: collections.OrderedDict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = (
            collections.OrderedDict()
        )
        self._goals: dict[int, int] = {}
        self.renders = 0

    # geometry ----------------------------------------------------------------------------------
    def z_of(self, x: float | np.ndarray) -> np.ndarray:
        """The robot's distance to the sign, in m, at track position(s) `x`."""
        return self.sign_distance - np.asarray(x, dtype=np.float64) * self.track_scale

    def _cell(self) -> int:
        return int(round((self.sign_distance - self.x * self.track_scale) / self.render_grid))

    def render(self) -> tuple[np.ndarray, np.ndarray]:
        """The foveae at the current cell of track and vergence, from the render cache when possible."""
        key = (self._cell(), int(round(self.theta / self.step_rad)))
        hit = self._images.get(key)
        if hit is not None:
            self._images.move_to_end(key)
            return hit
        saved = self.z
        self.z = key[0] * self.render_grid
        try:
            out = super().render()
        finally:
            self.z = saved
        self.renders += 1
        self._images[key] = out
        if len(self._images) > self._cache_size:
            self._images.popitem(last=False)
        return out

    def perceptual_goal(self) -> int:
        """The perceptual goal at the current position: the vergence (in steps) where d of Eq 7.2 is
        minimal, searched within `goal_window` steps of the geometric fixation of the sign."""
        cell = self._cell()
        if cell not in self._goals:
            centre = int(round(float(self.true_angle(cell * self.render_grid)) / self.step_rad))
            ks = range(max(centre - self.goal_window, 0), min(centre + self.goal_window, self.max_episode_steps) + 1)
            self._goals[cell] = ks[int(np.argmin(self.differences(ks)))]
        return self._goals[cell]

    # World interface ---------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """Two float32 foveae ``left`` and ``right``; five actions (see the class)."""
        f = (self.fovea, self.fovea)
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(
                SensorSpec("left", "float32", f, 0, 1, "left fovea"),
                SensorSpec("right", "float32", f, 0, 1, "right fovea"),
            ),
            action_space=ActionSpace(n=5, names=("converge", "diverge", "reverse", "coast", "forward")),
            reward_min=0.0,
            reward_max=1.0,
            program="mountaincar",
            n_starts=len(self.starts),
            params={
                "baseline": str(self.baseline),
                "vertical": str(self.vertical).lower(),
                "step_rad": str(self.step_rad),
                "n_positions": str(self.n_positions),
                "n_eval": str(self.n_eval),
                "max_car_steps": str(self.max_car_steps),
                "max_vergence": str(self.max_episode_steps),
            },
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Start at state `start`: an evenly spaced position at rest (< n_positions), a fixed
        evaluation state, or a random (x, v) for None or -1; the eyes parallel.
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if start is None or start < 0:
            self.x, self.v = random_state(self.rng, self.car)
        elif start >= len(self.starts):
            raise ValueError(f"start {start} out of range 0..{len(self.starts) - 1}")
        else:
            self.x, self.v = (float(c) for c in self.starts[start])
        self.z = float(self.z_of(self.x))
        self.theta, self.k, self.t, self.car_t = 0.0, 0, 0, 0
        return self._obs(0.0, False)

    def step(self, action: np.ndarray) -> StepResult:
        """A vergence step (reward 1 on the perceptual goal) or a car step (reward 1 and done at the
        goal; done after `max_car_steps`).
        """
        a = int(np.asarray(action).reshape(-1)[0])
        self.t += 1
        if a in (CONVERGE, DIVERGE):
            self.k = verge(self.k, np.array([a]), self.max_episode_steps)
            self.theta = self.k * self.step_rad
            return self._obs(1.0 if self.k == self.perceptual_goal() else 0.0, False)
        if a not in (REVERSE, COAST, FORWARD):
            raise ValueError(f"action must be 0..4 (converge, diverge, reverse, coast, forward), got {a}")
        noise = float(self.rng.normal(0.0, self.params.thrust_noise)) if self.params.thrust_noise > 0 else 0.0
        self.x, self.v, reached = car_step(self.x, self.v, a - COAST, self.car, noise)
        self.z = float(self.z_of(self.x))
        self.theta, self.k = 0.0, 0
        self.car_t += 1
        return self._obs(1.0 if reached else 0.0, reached or self.car_t >= self.max_car_steps)

    def perturb(self, control: Control) -> str:
        out = super().perturb(control)  # morph or heal, validated before anything changes
        self._images.clear()
        self._goals.clear()
        return out

    def truth(self) -> Truth:
        """The vergence angle (``positions``), distance and car state (``x``, ``v``) per start state."""
        return Truth(
            self.world_id,
            "start_states",
            {
                "positions": self.true_angle(self.distances)[:, None],
                "distance": self.distances[:, None].copy(),
                "x": self.starts[:, :1].copy(),
                "v": self.starts[:, 1:].copy(),
            },
        )
