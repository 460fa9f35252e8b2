"""Depth from vergence (ch. 7): a robot on a track with two cameras facing a stop sign, rendered
headless with PyBullet.

The cameras sit a baseline B apart (default 0.5 m) and start each episode parallel. Actions turn
both eyes inward (converge) or outward (diverge) by one step (0.01 rad each). Each camera sees
through a fovea (`fovea` x `fovea` px over `fovea_deg` degrees), published as tensors "left" and
"right". The perceptual goal is the vergence where the foveated left/right difference
d(r, l) = mean |f_l - f_r| (Eq 7.2) is minimal over the eyes' range: reaching it gives reward 1
and ends the episode. Start states are track positions (the sign is `sign_distance` m from the
track origin); truth = the true vergence angle per eye, atan((B/2) / Z) (Eq 7.5), and Z.
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pybullet as p
import pybullet_data

from sensorimotor.protocol.messages import ActionSpace, Control, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import HealParams, StepResult, World
from sensorimotor.worlds.bullet import direct_client, disconnect

CONVERGE, DIVERGE = 0, 1


def verge(k: int, action: np.ndarray, k_max: int) -> int:
    """The vergence (in steps, 0..k_max) after one converge (0) or diverge (1) action."""
    a = int(np.asarray(action).reshape(-1)[0])
    if a not in (CONVERGE, DIVERGE):
        raise ValueError(f"action must be 0 (converge) or 1 (diverge), got {a}")
    return min(k + 1, k_max) if a == CONVERGE else max(k - 1, 0)


def noise_texture(path: str, size: int, seed: int, sigmas: tuple[float, ...], tint: tuple[float, float, float]) -> None:
    """Write a square PNG of smooth noise (Gaussian-filtered, one octave per sigma in texels), tinted.

    Stored as 8-bit RGBA, each channel (x * 255) truncated and alpha 255: the pixels matplotlib's
    `imsave` wrote for the same array, so the textures (and what the robot sees) stay as they were."""
    from PIL import Image
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    img = np.zeros((size, size))
    for sigma in sigmas:
        n = gaussian_filter(rng.standard_normal((size, size)), sigma, mode="wrap")
        img += n / n.std()
    img = (img - img.min()) / (img.max() - img.min())
    rgb = np.clip(img[..., None] * np.asarray(tint)[None, None, :], 0.0, 1.0)
    rgba = np.empty((size, size, 4), np.uint8)
    rgba[..., :3] = (rgb * 255).astype(np.uint8)
    rgba[..., 3] = 255
    Image.fromarray(rgba, "RGBA").save(path, format="png")


def foveal_difference(left: np.ndarray, right: np.ndarray) -> float:
    """d(r, l) of Eq 7.2, as a mean over the fovea."""
    return float(np.abs(np.asarray(left, np.float64) - np.asarray(right, np.float64)).mean())


@dataclass(frozen=True)
class VergenceWorldParams:
    """Parameters of the vergence robot (ch. 7)."""

    baseline: float = option(0.5, "distance between the cameras, m (> 0)")
    sign_distance: float = option(3.0, "distance from the track origin to the stop sign, m")
    n_starts: int = option(20, "start states: track positions from `nearest` to the sign", min=2)
    nearest: float = option(0.8, "nearest start position's distance to the sign, m (0 < nearest < sign_distance)")
    step_rad: float = option(0.01, "eye turn per converge/diverge action, rad")
    fovea: int = option(16, "fovea side, px", min=1)
    fovea_deg: float = option(12.0, "fovea field of view, degrees")
    max_steps: int = option(40, "vergence steps per episode (the eyes' range)", min=1)
    vertical: bool = option(False, "cameras one above the other instead of side by side")
    sign_radius: float = option(0.375, "radius of the octagonal sign, m")
    room: bool = option(False, "a closed room with smooth-noise textures instead of a backdrop")


@dataclass(frozen=True)
class MorphParams:
    """Change the body while the world runs: camera baseline and/or orientation."""

    baseline: float | None = option(None, "new distance between the cameras, m (none: unchanged)", min=0.05, max=2.0)
    vertical: bool | None = option(None, "cameras one above the other (none: unchanged)")


class VergenceWorld(World):
    """Depth from vergence (ch. 7): two foveae in, converge or diverge out, reward 1 at the perceptual goal.

    Start states are track positions; the truth is the vergence angle that fixates the sign from
    each of them (Eq 7.5), which the agent's embedding of its vergence traces is scored against.

    Parameters
    ----------
    world_id : str, default="vergence"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (random starts).
    params : VergenceWorldParams or None, default=None
        The parameters (default: `VergenceWorldParams()`).
    **overrides
        Parameter values applied over `params` (``k=v`` strings or typed values), checked by
        `protocol.params.parse`.

    Examples
    --------
    >>> import numpy as np
    >>> with VergenceWorld(seed=0, n_starts=4) as w:
    ...     r = w.reset(start=0)
    ...     r = w.step(np.array([0.0]))  # converge one step
    """

    kind = "vergence"
    Params: ClassVar[type] = VergenceWorldParams
    Perturbations = {"morph": MorphParams, "heal": HealParams}

    def __init__(
        self, world_id: str = "vergence", seed: int = 0, params: VergenceWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(VergenceWorldParams, overrides, name=self.kind, base=params)
        baseline, sign_distance, n_starts, nearest = prm.baseline, prm.sign_distance, prm.n_starts, prm.nearest
        step_rad, fovea, fovea_deg, max_steps = prm.step_rad, prm.fovea, prm.fovea_deg, prm.max_steps
        vertical, sign_radius, room = prm.vertical, prm.sign_radius, prm.room
        self.sign_radius, self.room = sign_radius, room
        self._body0 = (baseline, vertical)
        if baseline <= 0 or not 0 < nearest < sign_distance or n_starts < 2:
            raise ValueError("baseline > 0, 0 < nearest < sign_distance and n_starts >= 2 are required")
        self.baseline, self.sign_distance, self.step_rad = baseline, sign_distance, step_rad
        self.fovea, self.fovea_deg, self.vertical = fovea, fovea_deg, vertical
        self.max_episode_steps = max_steps
        # start states: distances to the sign, evenly spaced from `nearest` to the sign's distance
        self.distances = np.linspace(nearest, sign_distance, n_starts)
        self.z = float(self.distances[-1])
        self.theta = 0.0
        self.k = 0  # vergence in steps
        self.goal = 0  # the step where d is minimal
        self.t = 0
        self._c = direct_client()
        self._build()
        self._proj = self._c.computeProjectionMatrixFOV(fovea_deg, 1.0, 0.05, 20.0)
        self._goal_cache: dict[int, int] = {}

    def _build(self) -> None:
        c = self._c
        # a red octagon (the stop sign), 0.75 m across by default, textured so the fovea sees structure
        r = self.sign_radius
        ang = np.pi / 8 + np.arange(8) * np.pi / 4
        ring = np.c_[np.zeros(8), r * np.cos(ang), r * np.sin(ang)]
        verts = np.vstack([[0.0, 0.0, 0.0], ring]).tolist()
        idx = []
        for i in range(8):
            idx += [0, 1 + i, 1 + (i + 1) % 8]
        uvs = [[0.5, 0.5]] + [[0.5 + 0.5 * math.cos(a), 0.5 + 0.5 * math.sin(a)] for a in ang]
        vis = c.createVisualShape(
            p.GEOM_MESH, vertices=verts, indices=idx + idx[::-1], uvs=uvs, rgbaColor=[1.0, 0.25, 0.2, 1.0]
        )
        self._sign = c.createMultiBody(0, baseVisualShapeIndex=vis, basePosition=[self.sign_distance, 0, 1.2])
        if self.room:
            self._build_room(vis)
            return
        tex = c.loadTexture(os.path.join(pybullet_data.getDataPath(), "tex256.png"))
        c.changeVisualShape(self._sign, -1, textureUniqueId=tex)
        pole = c.createVisualShape(p.GEOM_BOX, halfExtents=[0.02, 0.02, 0.6], rgbaColor=[0.6, 0.6, 0.6, 1])
        c.createMultiBody(0, baseVisualShapeIndex=pole, basePosition=[self.sign_distance + 0.03, 0, 0.6])
        # a textured backdrop: eyes that cross past the sign see different things, not a blank wall
        back = c.createVisualShape(p.GEOM_BOX, halfExtents=[0.01, 6, 6], rgbaColor=[0.7, 0.8, 0.7, 1])
        wall = c.createMultiBody(0, baseVisualShapeIndex=back, basePosition=[self.sign_distance + 4.0, 0, 1.2])
        c.changeVisualShape(
            wall, -1, textureUniqueId=c.loadTexture(os.path.join(pybullet_data.getDataPath(), "checker_grid.jpg"))
        )

    def _build_room(self, sign_visual: int) -> None:
        """Smooth-noise textures on the sign and on a closed room around the track. With eyes a metre
        apart, parallel or crossed gazes otherwise land on blank sky or a uniform patch, where d is 0
        and the minimum of Eq 7.2 is not on the sign any more."""
        c = self._c
        with tempfile.TemporaryDirectory() as tmp:
            sign_png, room_png = os.path.join(tmp, "sign.png"), os.path.join(tmp, "room.png")
            noise_texture(sign_png, 256, 1, (2.0, 6.0), (1.0, 0.3, 0.25))
            noise_texture(room_png, 512, 2, (1.5, 4.0), (0.6, 0.8, 0.6))
            c.changeVisualShape(self._sign, -1, rgbaColor=[1, 1, 1, 1], textureUniqueId=c.loadTexture(sign_png))
            tex = c.loadTexture(room_png)
        s = self.sign_distance
        walls = [
            ([0.01, 12, 12], [s + 6, 0, 1.2]),
            ([0.01, 12, 12], [s - 12, 0, 1.2]),
            ([12, 0.01, 12], [s - 3, 8, 1.2]),
            ([12, 0.01, 12], [s - 3, -8, 1.2]),
            ([12, 12, 0.01], [s - 3, 0, -0.01]),
            ([12, 12, 0.01], [s - 3, 0, 8]),
        ]
        for half, pos in walls:
            shape = c.createVisualShape(p.GEOM_BOX, halfExtents=half, rgbaColor=[1, 1, 1, 1])
            c.changeVisualShape(
                c.createMultiBody(0, baseVisualShapeIndex=shape, basePosition=pos), -1, textureUniqueId=tex
            )

    # geometry ----------------------------------------------------------------------------------
    def _eyes(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """(position, gaze direction) of left and right camera at the current vergence."""
        x = self.sign_distance - self.z
        h = self.baseline / 2
        out = []
        for side in (1.0, -1.0):  # left eye at +y (or up when vertical), turning toward the middle
            off = np.array([0.0, 0.0, side * h]) if self.vertical else np.array([0.0, side * h, 0.0])
            pos = np.array([x, 0.0, 1.2]) + off
            d = np.array([math.cos(self.theta), 0.0, 0.0])
            lateral = -side * math.sin(self.theta)
            if self.vertical:
                d[2] = lateral
            else:
                d[1] = lateral
            out.append((pos, d))
        return out

    def true_angle(self, z: float | np.ndarray) -> np.ndarray:
        """Per-eye vergence angle that fixates the sign centre from distance z (Eq 7.5)."""
        return np.arctan2(self.baseline / 2, np.asarray(z, dtype=np.float64))

    def render(self) -> tuple[np.ndarray, np.ndarray]:
        """The left and right foveae at the current position and vergence, float32 grey in [0, 1]."""
        imgs = []
        up = [0.0, 1.0, 0.0] if self.vertical else [0.0, 0.0, 1.0]
        for pos, d in self._eyes():
            view = self._c.computeViewMatrix(pos.tolist(), (pos + d).tolist(), up)
            _, _, rgb, _, _ = self._c.getCameraImage(
                self.fovea,
                self.fovea,
                view,
                self._proj,
                shadow=0,
                renderer=p.ER_TINY_RENDERER,
                flags=p.ER_NO_SEGMENTATION_MASK,
            )
            imgs.append(
                (
                    np.asarray(rgb, dtype=np.float32).reshape(self.fovea, self.fovea, 4)[..., :3].mean(axis=2) / 255.0
                ).astype(np.float32)
            )
        return imgs[0], imgs[1]

    def differences(self, ks: range | None = None) -> np.ndarray:
        """d(r, l) at vergence steps `ks` (default every step 0..max_episode_steps) from the current position."""
        saved = self.theta
        out = []
        try:
            for k in range(self.max_episode_steps + 1) if ks is None else ks:
                self.theta = k * self.step_rad
                out.append(foveal_difference(*self.render()))
        finally:
            self.theta = saved
        return np.array(out)

    # World interface ---------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """Two float32 foveae ``left`` and ``right``; actions converge (0) and diverge (1)."""
        f = (self.fovea, self.fovea)
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(
                SensorSpec("left", "float32", f, 0, 1, "left fovea"),
                SensorSpec("right", "float32", f, 0, 1, "right fovea"),
            ),
            action_space=ActionSpace(n=2, names=("converge", "diverge")),
            reward_min=0.0,
            reward_max=1.0,
            program="vergence",
            n_starts=len(self.distances),
            params={
                "baseline": str(self.baseline),
                "vertical": str(self.vertical).lower(),
                "step_rad": str(self.step_rad),
            },
        )

    def _obs(self, reward: float, done: bool) -> StepResult:
        left, right = self.render()
        return StepResult({"left": left, "right": right}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Move to track position `start` (or a random one) with the eyes parallel."""
        start = self.pick_start(seed, start, len(self.distances))
        self.z = float(self.distances[start])
        if start not in self._goal_cache:  # the goal of a start state is fixed until the body changes
            self._goal_cache[start] = int(np.argmin(self.differences()))
        self.goal = self._goal_cache[start]
        self.theta, self.k, self.t = 0.0, 0, 0
        return self._obs(0.0, False)

    def step(self, action: np.ndarray) -> StepResult:
        """Turn the eyes one step; reward 1 and done on reaching the perceptual goal."""
        self.k = verge(self.k, action, self.max_episode_steps)
        self.t += 1
        self.theta = self.k * self.step_rad
        if self.k == self.goal:
            return self._obs(1.0, True)
        return self._obs(0.0, self.t >= self.max_episode_steps)

    def perturb(self, control: Control) -> str:
        prm = self.perturbation_params(control)  # refuses a bad control before anything changes
        if isinstance(prm, MorphParams):
            if prm.baseline is not None:
                self.baseline = prm.baseline
            if prm.vertical is not None:
                self.vertical = prm.vertical
            what = "morph"
        else:  # heal
            self.baseline, self.vertical = self._body0
            what = "heal"
        self._goal_cache.clear()
        return f"{what}: baseline {self.baseline} m, cameras {'vertical' if self.vertical else 'horizontal'}"

    def truth(self) -> Truth:
        """The true per-eye vergence angle (``positions``) and distance to the sign per start state."""
        return Truth(
            self.world_id,
            "start_states",
            {"positions": self.true_angle(self.distances)[:, None], "distance": self.distances[:, None].copy()},
        )

    def close(self) -> None:
        """Disconnect the PyBullet client."""
        disconnect(self._c)
        self._c = None
