"""Vergence on a real stereo pair (ch. 7.2.2): the Middlebury "motorcycle" pair that scikit-image
ships with its ground-truth disparity (no download).

Two foveal windows look at the same row: the left one rests on a salient point, the right one
starts at the same column (disparity 0) and moves one pixel per converge action. As in the
dissertation ("the agent can perform a single action, convergence by one pixel"), converge is the
only action by default; `diverge=true` adds the action that moves it back (then the policy must be
learned, and LSPI over the foveal difference alone does not always learn it: ch. 7 in
docs/reproduce.md). The perceptual goal is the shift where the foveated difference (Eq 7.2) is minimal over the
scan range; reaching it gives reward 1. The trace length is then the disparity. Start states are
salient points: local maxima of the gradient energy of the blurred left image (a bottom-up
saliency map), spread apart, with valid ground truth, whose best match along the row is distinct
(its difference below `uniqueness` times the best one more than 3 px away: an image-only stereo
confidence that repeated texture and occlusions fail). Truth: the dataset's disparity there - the
Middlebury 2014 ground truth (structured light, subpixel; Scharstein et al., GCPR 2014) that
scikit-image ships down-sampled by 4 with the images (0 to 59.9 px; NaN, 7 % of pixels, where the
dataset has none: start points are taken only where it is finite). The swept range, 0 to
`max_shift` = 80 px, covers every disparity in the map.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import ndimage

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.vergence import foveal_difference, verge


def salient_points(
    img: np.ndarray, disp: np.ndarray, n: int, radius: int, max_shift: int, spacing: int = 25, sigma: float = 2.0
) -> np.ndarray:
    """[n, 2] (row, col) of the strongest gradient-energy maxima, at least `spacing` px apart."""
    g = ndimage.gaussian_filter(img, sigma)
    energy = ndimage.gaussian_filter(ndimage.sobel(g, 0) ** 2 + ndimage.sobel(g, 1) ** 2, 3 * sigma)
    h, w = img.shape
    valid = np.zeros_like(img, dtype=bool)
    valid[radius : h - radius, radius + max_shift : w - radius] = True
    valid &= np.isfinite(disp)
    peaks = (energy == ndimage.maximum_filter(energy, size=spacing)) & valid
    rows, cols = np.nonzero(peaks)
    order = np.argsort(energy[rows, cols])[::-1][:n]
    return np.stack([rows[order], cols[order]], axis=1)


@dataclass(frozen=True)
class StereoPairParams:
    """Parameters of the stereo-pair vergence world (ch. 7.2.2)."""

    n_starts: int = option(30, "start states: salient points kept", min=2)
    radius: int = option(10, "fovea half-width, px (the fovea is 2 radius + 1 px wide)", min=1)
    max_shift: int = option(80, "largest right-fovea shift (disparity) scanned, px", min=1)
    uniqueness: float = option(0.7, "keep a point if its best match beats every other by this factor", min=0.0, max=1.0)
    diverge: bool = option(False, "offer a diverge action besides converge (the dissertation's agent only converges)")


class StereoPairWorld(World):
    """Vergence on the Middlebury motorcycle stereo pair (ch. 7.2.2): two foveal windows in,
    converge or diverge (one pixel) out, reward 1 at the perceptual goal.

    Parameters
    ----------
    world_id : str, default="stereo"
        The world's id on the bus.
    seed : int, default=0
        Seeds the world's random generator (random starts).
    params : StereoPairParams or None, default=None
        The parameters (default: `StereoPairParams()`).
    **overrides
        Parameter values applied over `params` (``k=v`` strings or typed values), checked by
        `protocol.params.parse`.
    """

    kind = "stereo"
    Params = StereoPairParams

    def __init__(
        self, world_id: str = "stereo", seed: int = 0, params: StereoPairParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(StereoPairParams, overrides, name=self.kind, base=params)
        n_starts, radius, max_shift, uniqueness = prm.n_starts, prm.radius, prm.max_shift, prm.uniqueness
        from skimage import data

        left, right, disp = data.stereo_motorcycle()
        self.left = left.mean(axis=2).astype(np.float32) / 255.0
        self.right = right.mean(axis=2).astype(np.float32) / 255.0
        self.disparity = disp
        self.diverge = prm.diverge
        self.radius, self.max_shift = radius, max_shift
        self.max_episode_steps = max_shift + 20
        self.row = self.col = 0
        self.k = self.goal = self.t = 0
        self.points = salient_points(self.left, disp, 10 * n_starts, radius, max_shift)
        keep = [i for i, (r, c) in enumerate(self.points) if self._distinct(int(r), int(c), uniqueness)]
        self.points = self.points[keep[:n_starts]]
        if len(self.points) < 2:
            raise ValueError("too few salient points with ground truth")
        self._goals: dict[int, int] = {}

    def _differences(self) -> np.ndarray:
        return np.array([foveal_difference(*self._patches(k)) for k in range(self.max_shift + 1)])

    def _distinct(self, row: int, col: int, uniqueness: float) -> bool:
        self.row, self.col = row, col
        d = self._differences()
        k = int(np.argmin(d))
        others = np.r_[d[: max(k - 3, 0)], d[k + 4 :]]
        return others.size == 0 or d[k] < uniqueness * others.min()

    def _patches(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        r, c, R = self.row, self.col, self.radius
        return (
            self.left[r - R : r + R + 1, c - R : c + R + 1].copy(),
            self.right[r - R : r + R + 1, c - k - R : c - k + R + 1].copy(),
        )

    def spec(self) -> WorldSpec:
        """Two float32 foveae ``left`` and ``right``; actions converge (0) and, with `diverge`, diverge (1)."""
        f = (2 * self.radius + 1,) * 2
        return WorldSpec(
            self.world_id,
            self.kind,
            (
                SensorSpec("left", "float32", f, 0, 1, "left fovea"),
                SensorSpec("right", "float32", f, 0, 1, "right fovea"),
            ),
            ActionSpace(n=2, names=("converge", "diverge")) if self.diverge else ActionSpace(n=1, names=("converge",)),
            0.0,
            1.0,
            "vergence",
            len(self.points),
            {"dataset": "Middlebury motorcycle (scikit-image)"},
        )

    def _obs(self, reward: float, done: bool) -> StepResult:
        left, right = self._patches(self.k)
        return StepResult({"left": left, "right": right}, reward, done)

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Rest the left window on salient point `start` (or a random one), the right one at disparity 0."""
        start = self.pick_start(seed, start, len(self.points))
        self.row, self.col = (int(v) for v in self.points[start])
        if start not in self._goals:
            self._goals[start] = int(np.argmin(self._differences()))
        self.goal = self._goals[start]
        self.k = self.t = 0
        return self._obs(0.0, self.goal == 0)

    def step(self, action: np.ndarray) -> StepResult:
        """Shift the right window one pixel; reward 1 and done on reaching the perceptual goal."""
        if not self.diverge and int(np.asarray(action).reshape(-1)[0]) != 0:
            raise ValueError(f"this stereo pair has one action, 0 (converge); got {action} (diverge=true offers 1)")
        self.k = verge(self.k, action, self.max_shift)
        self.t += 1
        if self.k == self.goal:
            return self._obs(1.0, True)
        return self._obs(0.0, self.t >= self.max_episode_steps)

    def truth(self) -> Truth:
        """The dataset disparity at each start point (``positions``) and the points (``pixels``, row, col)."""
        d = self.disparity[self.points[:, 0], self.points[:, 1]].astype(np.float64)
        return Truth(self.world_id, "start_states", {"positions": d[:, None], "pixels": self.points.astype(np.float64)})
