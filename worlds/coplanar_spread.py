"""The perceptual goal of ch. 6 (section 6.2): the mean interpoint distance of coplanar features.

Two views of an object a small turn apart (or one view and several turned ones, averaged): ORB features in each (scikit-image), matched by
appearance (cross-checked), RANSAC keeps the matches consistent with one fundamental matrix (a
rigid scene), RANSAC again keeps those that also fit one homography (one plane). The mean distance
between those coplanar points, in the first view, is largest when a flat face is seen head-on: a
face turned away is foreshortened and its points draw together. Pure function; seeded.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.spatial.distance import pdist
from skimage.feature import ORB, match_descriptors
from skimage.measure import ransac
from skimage.transform import FundamentalMatrixTransform, ProjectiveTransform


@dataclass(frozen=True)
class CoplanarSpread:
    """The score of one pair of views and how it was reached.

    Attributes
    ----------
    spread : float
        Mean pairwise distance (px of the first view) of the coplanar inliers; 0 when fewer than
        `min_points` survive.
    matches, rigid, coplanar : int
        Appearance matches, fundamental-matrix inliers, homography inliers.
    """

    spread: float
    matches: int
    rigid: int
    coplanar: int


def _orb(img: np.ndarray, n_keypoints: int) -> tuple[np.ndarray, np.ndarray]:
    orb = ORB(
        n_keypoints=n_keypoints, fast_threshold=0.05, n_scales=1
    )  # one scale: precise positions; the views differ little
    try:
        orb.detect_and_extract(img)
    except (RuntimeError, ValueError, IndexError):  # a blank or tiny image has no keypoints
        return np.zeros((0, 2)), np.zeros((0, 256), dtype=bool)
    return np.asarray(orb.keypoints), np.asarray(orb.descriptors)


def _pair(
    ka: np.ndarray,
    da: np.ndarray,
    second: np.ndarray,
    rng: np.random.Generator,
    n_keypoints: int,
    residual: float,
    trials: int,
    min_points: int,
) -> CoplanarSpread:
    kb, db = _orb(second, n_keypoints)
    if len(ka) < min_points or len(kb) < min_points:
        return CoplanarSpread(0.0, 0, 0, 0)
    m = match_descriptors(da, db, cross_check=True)
    if len(m) < min_points:
        return CoplanarSpread(0.0, len(m), 0, 0)
    pa, pb = ka[m[:, 0]][:, ::-1].astype(np.float64), kb[m[:, 1]][:, ::-1].astype(np.float64)  # (x, y)
    _, rigid = ransac(
        (pa, pb),
        FundamentalMatrixTransform,
        min_samples=8,
        residual_threshold=residual,
        max_trials=trials,
        stop_probability=0.999,
        rng=rng,
    )
    if rigid is None or rigid.sum() < min_points:
        return CoplanarSpread(0.0, len(m), 0 if rigid is None else int(rigid.sum()), 0)
    pa, pb = pa[rigid], pb[rigid]
    _, flat = ransac(
        (pa, pb),
        ProjectiveTransform,
        min_samples=4,
        residual_threshold=1.5 * residual,
        max_trials=trials,
        stop_probability=0.999,
        rng=rng,
    )
    if flat is None or flat.sum() < min_points:
        return CoplanarSpread(0.0, len(m), len(pa), 0 if flat is None else int(flat.sum()))
    return CoplanarSpread(float(pdist(pa[flat]).mean()), len(m), len(pa), int(flat.sum()))


def coplanar_spread(
    first: np.ndarray,
    second: np.ndarray | Sequence[np.ndarray],
    seed: int = 0,
    n_keypoints: int = 300,
    residual: float = 1.0,
    trials: int = 200,
    min_points: int = 8,
) -> CoplanarSpread:
    """Score the view `first` (grey float image) against `second`, a slightly turned view (or
    several: the scores are averaged, which halves the noise of which features survive).

    Parameters
    ----------
    first : ndarray
        Grey image [H, W] in [0, 1].
    second : ndarray or sequence of ndarray
        The same object turned a little; one image or several.
    seed : int, default=0
        Seeds the RANSAC runs (the score is deterministic).
    n_keypoints : int, default=300
        ORB keypoints per view.
    residual : float, default=1.0
        RANSAC inlier threshold of the fundamental matrix, px (the homography's is 1.5 times it).
    trials : int, default=200
        RANSAC trials of each model.
    min_points : int, default=8
        Fewer matches or inliers than this score 0.

    Returns
    -------
    CoplanarSpread
        Means over the second views (counts rounded down).
    """
    seconds = [second] if isinstance(second, np.ndarray) else list(second)
    ka, da = _orb(first, n_keypoints)
    rng = np.random.default_rng(seed)
    pairs = [_pair(ka, da, s, rng, n_keypoints, residual, trials, min_points) for s in seconds]
    return CoplanarSpread(
        float(np.mean([q.spread for q in pairs])),
        int(np.mean([q.matches for q in pairs])),
        int(np.mean([q.rigid for q in pairs])),
        int(np.mean([q.coplanar for q in pairs])),
    )


__all__ = ["CoplanarSpread", "coplanar_spread"]
