"""Perceptual goals of the roving eye (ch. 5.2): a gradient policy on directional filters.

The intensity image is smoothed at the scale of the eye (`sigma` px), and `directions` steerable
derivative-of-Gaussian filters (one per move direction) are read at the eye's centre: their
responses are what the eye sees of the intensity gradient. The gradient policy moves `step_px` in
the direction of the strongest response and stops where no move raises the smoothed intensity (a
local maximum at the resolution of its moves). Followed from every point of a grid, it ends at far
fewer points; clustered, those are the perceptual goals, and the points that end in one cluster are
its region of attraction.

Positions are (u, v): u the column (right), v the row (down) of the eye's centre, in image px.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.cluster.hierarchy import fcluster, linkage


def directions(n: int = 16) -> np.ndarray:
    """Unit vectors of `n` move directions, [n, 2] in (u, v), the first pointing right."""
    a = 2 * np.pi * np.arange(n) / n
    return np.stack([np.cos(a), np.sin(a)], axis=1)


@dataclass(frozen=True)
class IntensitySurface:
    """The smoothed intensity S and its derivatives, sampled bilinearly at any eye position."""

    S: np.ndarray  # [H, W] smoothed intensity
    Su: np.ndarray  # dS/du (columns)
    Sv: np.ndarray  # dS/dv (rows)

    @classmethod
    def of(cls, image: np.ndarray, sigma: float) -> IntensitySurface:
        """Smooth the grey `image` (floats) with a Gaussian of `sigma` px and take its derivatives
        (the derivative-of-Gaussian filters are steerable: any direction is a mix of these two)."""
        img = np.asarray(image, dtype=np.float64)
        return cls(
            ndimage.gaussian_filter(img, sigma),
            ndimage.gaussian_filter(img, sigma, order=(0, 1)),
            ndimage.gaussian_filter(img, sigma, order=(1, 0)),
        )

    def _at(self, a: np.ndarray, pos: np.ndarray) -> np.ndarray:
        pos = np.atleast_2d(pos)
        return ndimage.map_coordinates(a, [pos[:, 1], pos[:, 0]], order=1, mode="nearest")

    def value(self, pos: np.ndarray) -> np.ndarray:
        """S at positions [n, 2] (u, v)."""
        return self._at(self.S, pos)

    def responses(self, pos: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """Directional filter responses [n, len(dirs)] at positions [n, 2]."""
        g = np.stack([self._at(self.Su, pos), self._at(self.Sv, pos)], axis=1)
        return g @ dirs.T


def gradient_step(surface: IntensitySurface, pos: np.ndarray, dirs: np.ndarray, step_px: float) -> np.ndarray:
    """The gradient policy's action index at each position [n, 2]: the strongest directional
    response, or -1 where the move it names would not raise S (a local maximum: stop)."""
    pos = np.atleast_2d(pos)
    k = np.argmax(surface.responses(pos, dirs), axis=1)
    nxt = pos + step_px * dirs[k]
    return np.where(surface.value(nxt) > surface.value(pos), k, -1)


def follow_gradient(
    surface: IntensitySurface,
    starts: np.ndarray,
    dirs: np.ndarray,
    step_px: float,
    lo: np.ndarray,
    hi: np.ndarray,
    max_steps: int = 400,
) -> tuple[np.ndarray, np.ndarray]:
    """Follow the gradient policy from every start [n, 2] at once, positions kept in [lo, hi].

    Returns the end points [n, 2] and the number of moves made [n]."""
    pos = np.array(starts, dtype=np.float64)
    moves = np.zeros(len(pos), dtype=np.int64)
    live = np.ones(len(pos), dtype=bool)
    for _ in range(max_steps):
        idx = np.flatnonzero(live)
        if idx.size == 0:
            break
        k = gradient_step(surface, pos[idx], dirs, step_px)
        go = k >= 0
        live[idx[~go]] = False
        j = idx[go]
        pos[j] = np.clip(pos[j] + step_px * dirs[k[go]], lo, hi)
        moves[j] += 1
    return pos, moves


@dataclass(frozen=True)
class Goals:
    """Perceptual goals and their regions of attraction over a grid of start points."""

    points: np.ndarray  # [n, 2] grid points (u, v)
    ends: np.ndarray  # [n, 2] where the gradient policy ends from each
    label: np.ndarray  # [n] goal index of each point (its region of attraction)
    centres: np.ndarray  # [g, 2] goal positions: the local maximum of S in each cluster
    sizes: np.ndarray  # [g] points in each region

    def largest(self) -> int:
        """Index of the goal with the largest region of attraction."""
        return int(np.argmax(self.sizes))

    def region(self, goal: int) -> np.ndarray:
        """The grid points [m, 2] of goal `goal`'s region of attraction."""
        return self.points[self.label == goal]


def find_goals(
    surface: IntensitySurface,
    lo: np.ndarray,
    hi: np.ndarray,
    grid_px: float = 4.0,
    step_px: float = 5.0,
    n_dirs: int = 16,
    cluster_px: float = 8.0,
) -> Goals:
    """Follow the gradient policy from a grid of points (spacing `grid_px`) over [lo, hi], cluster
    the end points (single linkage, `cluster_px`), and refine each cluster to the local maximum of
    S with 0.25-px moves; the clusters' members' starts are the regions of attraction."""
    dirs = directions(n_dirs)
    us = np.arange(lo[0], hi[0] + 1e-9, grid_px)
    vs = np.arange(lo[1], hi[1] + 1e-9, grid_px)
    uu, vv = np.meshgrid(us, vs)
    points = np.stack([uu.ravel(), vv.ravel()], axis=1)
    ends, _ = follow_gradient(surface, points, dirs, step_px, lo, hi)
    uniq, inverse = np.unique(np.round(ends), axis=0, return_inverse=True)  # to 1 px: few distinct ends
    inverse = inverse.reshape(-1)
    if len(uniq) == 1:
        cl = np.zeros(1, dtype=np.int64)
    else:
        cl = fcluster(linkage(uniq, "single"), t=cluster_px, criterion="distance") - 1
    label = cl[inverse]
    g = int(cl.max()) + 1
    values = surface.value(uniq)
    centres = np.array([uniq[cl == i][np.argmax(values[cl == i])] for i in range(g)])
    for step in (1.0, 0.25):  # hill-climb to the local maximum at finer resolution
        centres, _ = follow_gradient(surface, centres, dirs, step, lo, hi, max_steps=100)
    sizes = np.bincount(label, minlength=g)
    return Goals(points, ends, label, centres, sizes)


def reward(distance: np.ndarray | float, scale_px: float) -> np.ndarray:
    """Reward at the end of a trajectory: exp(-distance / scale_px), 1 on the goal."""
    return np.exp(-np.asarray(distance, dtype=np.float64) / scale_px)


def score(distance: np.ndarray | float, n_actions: np.ndarray | int, scale_px: float, discount: float) -> np.ndarray:
    """A trajectory's score (Table 5.1): its end reward discounted by the number of actions."""
    return reward(distance, scale_px) * np.power(discount, np.asarray(n_actions, dtype=np.float64))
