"""Object pose (ch. 6): a textured box turned by the agent in front of a fixed camera, rendered
headless with PyBullet.

The box's six faces carry scikit-image's bundled photographs (astronaut, coffee, chelsea, rocket,
immunohistochemistry, camera), written once to a temporary PNG atlas; it is lit from the camera's
side. Actions turn it by +-pi/16 in pitch or yaw (4 actions); a turn past the declared range is
refused by the box (it stays). The observation is the camera image only: grey, `image` x `image`
px, float32 in [0, 1]. Start states are every pose of the pitch x yaw lattice within the range;
truth = (pitch, yaw) in radians.

Perceptual goal (section 6.2): for each lattice pose the box is seen as it is and turned a little
(`goal_turn`) both ways, at `goal_image` px; ORB features, RANSAC fundamental matrix, RANSAC
homography; the score is the mean interpoint distance of the coplanar inliers (`coplanar_spread`),
averaged over the two pairs. The goal is the pose where it is largest (a face seen head-on):
reaching it gives reward 1 and ends the episode. The score is
expensive, so it is computed once per pose, the first time the world needs the goal, and kept in
memory for every world of the process with the same rendering parameters (nothing is written).
"""

from __future__ import annotations

import math
import os
import tempfile
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np
import pybullet as p
from threadpoolctl import threadpool_limits

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, option, parse
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.bullet import direct_client, disconnect
from sensorimotor.worlds.coplanar_spread import coplanar_spread

STEP = math.pi / 16
ACTIONS = ((1, 0), (-1, 0), (0, 1), (0, -1))  # lattice steps of (pitch, yaw)
NAMES = ("pitch+", "pitch-", "yaw+", "yaw-")
FACES = ("immunohistochemistry", "coffee", "chelsea", "rocket", "astronaut", "camera")


@dataclass(frozen=True)
class ObjectPoseWorldParams:
    """Parameters of the object-pose world (ch. 6)."""

    image: int = option(
        100, "observed camera image side, px (grey; 100: the 10,000 dimensions of Fig 6.5)", min=8, max=128
    )
    supersample: int = option(1, "render at this many times the image side, then average down", min=1, max=8)
    half_range: int = option(3, "pitch and yaw range: +-half_range steps of pi/16; start grid (2n+1)^2", min=1, max=7)
    goal_image: int = option(192, "image side, px, the perceptual goal is computed on", min=64, max=512)
    goal_turn: float = option(math.pi / 32, "turn between the two views of the goal score, rad", min=0.001, max=0.3)
    keypoints: int = option(500, "ORB keypoints per view for the goal score", min=20, max=2000)
    distance: float = option(6.0, "camera distance from the box centre (box side 1)", min=1.5, max=20.0)
    fov: float = option(15.0, "camera field of view, degrees", min=5.0, max=120.0)
    goal: tuple[int, int] | None = option(
        None, "goal pose, pitch,yaw in steps of pi/16 (none: the perceptual goal, the largest coplanar spread)"
    )
    max_episode_steps: int = option(50, "actions after which an episode ends without the goal", min=1)


# lattice pose (i, j) -> coplanar spread, per rendering (the parameters that change the views)
_SCORES: dict[tuple[Any, ...], dict[tuple[int, int], float]] = {}


def _atlas(cell: int = 256) -> np.ndarray:
    """The six face photographs, centre-cropped square, in a 3 x 2 RGB atlas (uint8)."""
    from skimage import data, transform
    from skimage.color import gray2rgb

    out = np.zeros((2 * cell, 3 * cell, 3), np.uint8)
    for k, name in enumerate(FACES):
        im = getattr(data, name)()
        im = gray2rgb(im) if im.ndim == 2 else im[..., :3]
        h, w = im.shape[:2]
        s = min(h, w)
        im = im[(h - s) // 2 : (h - s) // 2 + s, (w - s) // 2 : (w - s) // 2 + s]
        im = (transform.resize(im, (cell, cell), anti_aliasing=True) * 255).astype(np.uint8)
        r, c = divmod(k, 3)
        out[r * cell : (r + 1) * cell, c * cell : (c + 1) * cell] = im
    return out


def _box_mesh(half: float = 0.5) -> tuple[list[list[float]], list[int], list[list[float]], list[list[float]]]:
    """Vertices, triangle indices, atlas uvs and normals of a cube, one atlas cell per face."""
    faces = (  # outward normal, u axis, v axis (right-handed: u x v = n)
        ((1, 0, 0), (0, 1, 0), (0, 0, 1)),
        ((-1, 0, 0), (0, -1, 0), (0, 0, 1)),
        ((0, 1, 0), (-1, 0, 0), (0, 0, 1)),
        ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (0, 1, 0), (-1, 0, 0)),
        ((0, 0, -1), (0, 1, 0), (1, 0, 0)),
    )
    verts: list[list[float]] = []
    idx: list[int] = []
    uvs: list[list[float]] = []
    normals: list[list[float]] = []
    for k, (n, u, v) in enumerate(faces):
        nn, uu, vv = np.array(n, float), np.array(u, float), np.array(v, float)
        r, c = divmod(k, 3)
        base = len(verts)
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            verts.append((half * (nn + su * uu + sv * vv)).tolist())
            normals.append(nn.tolist())
            uvs.append([(c + (su + 1) / 2) / 3, (1 - r + (sv - 1) / 2) / 2 + 0.5])  # GL: v = 0 is the atlas' last row
        idx += [base, base + 1, base + 2, base, base + 2, base + 3]
    return verts, idx, uvs, normals


class ObjectPoseWorld(World):
    """A textured box turned in pitch and yaw by +-pi/16: the camera image in, 4 turns out.

    Parameters
    ----------
    world_id : str, default="objectpose"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (random starts).
    params : ObjectPoseWorldParams or None, default=None
        The parameters (default: `ObjectPoseWorldParams()`).
    **overrides
        Parameter values applied over `params`, checked by `protocol.params.parse`.

    Examples
    --------
    >>> import numpy as np
    >>> with ObjectPoseWorld(seed=0, half_range=1) as w:
    ...     r = w.reset(start=0)
    ...     r = w.step(np.array([2.0]))  # yaw + pi/16
    """

    kind = "objectpose"
    Params: ClassVar[type] = ObjectPoseWorldParams

    def __init__(
        self, world_id: str = "objectpose", seed: int = 0, params: ObjectPoseWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(ObjectPoseWorldParams, overrides, name=self.kind, base=params)
        n = prm.half_range
        self.max_episode_steps = prm.max_episode_steps
        self.poses = [(i, j) for i in range(-n, n + 1) for j in range(-n, n + 1)]  # (pitch, yaw) steps
        self.pose = (0, 0)
        self.t = 0
        self._goal: tuple[int, int] | None = None
        if prm.goal is not None:
            if max(abs(prm.goal[0]), abs(prm.goal[1])) > n:
                raise ParamError(f"objectpose: goal {prm.goal} is outside the range +-{n}")
            self._goal = (int(prm.goal[0]), int(prm.goal[1]))
        self._frame: np.ndarray | None = None
        self._views: dict[tuple[int, int], np.ndarray] = {}
        self._c = direct_client()
        verts, idx, uvs, normals = _box_mesh()
        vis = self._c.createVisualShape(
            p.GEOM_MESH, vertices=verts, indices=idx, uvs=uvs, normals=normals, rgbaColor=[1, 1, 1, 1]
        )
        self._body = self._c.createMultiBody(0, baseVisualShapeIndex=vis)
        from PIL import Image

        with tempfile.TemporaryDirectory() as tmp:
            png = os.path.join(tmp, "faces.png")
            Image.fromarray(_atlas()).save(png)
            self._c.changeVisualShape(self._body, -1, textureUniqueId=self._c.loadTexture(png))
        self._eye = [prm.distance, 0.0, 0.0]
        self._view = self._c.computeViewMatrix(self._eye, [0, 0, 0], [0, 0, 1])
        self._proj = self._c.computeProjectionMatrixFOV(prm.fov, 1.0, 0.1, prm.distance + 5.0)
        self._score_key = (prm.goal_image, prm.goal_turn, prm.keypoints, prm.distance, prm.fov)

    # rendering ---------------------------------------------------------------------------------
    def render(self, pitch: float, yaw: float, size: int) -> np.ndarray:
        """The camera's grey view (float64 in [0, 1], size x size) of the box at (pitch, yaw) rad."""
        q = self._c.getQuaternionFromEuler([0.0, pitch, yaw])
        self._c.resetBasePositionAndOrientation(self._body, [0, 0, 0], q)
        _, _, rgba, _, _ = self._c.getCameraImage(
            size,
            size,
            self._view,
            self._proj,
            shadow=0,
            lightDirection=[1.0, 0.0, 0.0],  # from the front (the camera's side)
            renderer=p.ER_TINY_RENDERER,
            flags=p.ER_NO_SEGMENTATION_MASK,
        )
        rgb = np.asarray(rgba, dtype=np.float64).reshape(size, size, 4)[..., :3]
        return rgb @ np.array([0.2125, 0.7154, 0.0721]) / 255.0

    def observe(self, pose: tuple[int, int]) -> np.ndarray:
        """The observation at lattice pose `pose`: float32 grey, image x image (rendered once per
        pose: the scene is static, so the view of a pose never changes)."""
        img = self._views.get(pose)
        if img is None:
            prm = self.params
            s = prm.image * prm.supersample
            big = self.render(pose[0] * STEP, pose[1] * STEP, s)
            img = big.reshape(prm.image, prm.supersample, prm.image, prm.supersample).mean(axis=(1, 3))
            img = self._views[pose] = img.astype(np.float32)
            img.flags.writeable = False
        return img

    # the perceptual goal -----------------------------------------------------------------------
    def goal_score(self, pose: tuple[int, int]) -> float:
        """The coplanar spread at lattice pose `pose` (computed once per process and rendering)."""
        cache = _SCORES.setdefault(self._score_key, {})
        if pose not in cache:
            prm = self.params
            pitch, yaw = pose[0] * STEP, pose[1] * STEP
            first = self.render(pitch, yaw, prm.goal_image)
            d = prm.goal_turn
            second = [self.render(pitch + d, yaw + d, prm.goal_image), self.render(pitch - d, yaw - d, prm.goal_image)]
            with threadpool_limits(1):  # small SVDs in RANSAC: BLAS threads only add overhead
                cache[pose] = coplanar_spread(first, second, seed=0, n_keypoints=prm.keypoints, residual=1.5).spread
        return cache[pose]

    def scores(self) -> np.ndarray:
        """The goal score of every start state, in start-state order."""
        return np.array([self.goal_score(q) for q in self.poses])

    @property
    def goal(self) -> tuple[int, int]:
        """The lattice pose where the coplanar spread is largest (computed on first use), unless the
        `goal` parameter names one."""
        if self._goal is None:
            self._goal = self.poses[int(np.argmax(self.scores()))]
        return self._goal

    # World interface ---------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """One float32 grey image ``camera``; actions pitch+, pitch-, yaw+, yaw- (pi/16 each)."""
        n = self.params.image
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=(SensorSpec("camera", "float32", (n, n), 0, 1, "grey camera image of the box"),),
            action_space=ActionSpace(n=len(ACTIONS), names=NAMES),
            reward_min=0.0,
            reward_max=1.0,
            program="generic",
            n_starts=len(self.poses),
            params={"half_range": str(self.params.half_range), "step_rad": repr(STEP)},
        )

    def _obs(self, reward: float, done: bool) -> StepResult:
        img = self.observe(self.pose)
        self._frame = (img * 255).astype(np.uint8)
        return StepResult({"camera": img}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Turn the box to lattice pose `start` (in `truth` order) or a random one; ``done`` at once on the goal."""
        start = self.pick_start(seed, start, len(self.poses))
        self.pose = self.poses[start]
        self.t = 0
        return self._obs(0.0, self.pose == self.goal)

    def step(self, action: np.ndarray) -> StepResult:
        """Turn by pi/16 (``action[0]``: 0 pitch+, 1 pitch-, 2 yaw+, 3 yaw-); beyond the range the box stays."""
        a = int(np.asarray(action).reshape(-1)[0])
        if not 0 <= a < len(ACTIONS):
            raise ValueError(f"action {a} out of range 0..{len(ACTIONS) - 1}")
        n = self.params.half_range
        nxt = (self.pose[0] + ACTIONS[a][0], self.pose[1] + ACTIONS[a][1])
        if max(abs(nxt[0]), abs(nxt[1])) <= n:
            self.pose = nxt
        self.t += 1
        at_goal = self.pose == self.goal
        return self._obs(1.0 if at_goal else 0.0, at_goal or self.t >= self.max_episode_steps)

    def truth(self) -> Truth:
        """(pitch, yaw) in radians of every start state, row i for start state i."""
        return Truth(self.world_id, "start_states", {"positions": np.array(self.poses, dtype=np.float64) * STEP})

    def frame(self) -> np.ndarray | None:
        """The latest observation as uint8 grey."""
        return self._frame

    def close(self) -> None:
        """Disconnect the PyBullet client."""
        disconnect(self._c)
        self._c = None


__all__ = ["ObjectPoseWorld", "ObjectPoseWorldParams", "STEP"]
