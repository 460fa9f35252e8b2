"""A picture of a learned map without the Rerun GUI: one PNG per world with the true positions, the
embedding aligned onto them (Procrustes: translation, scale, rotation/reflection) with every point
coloured by where it truly is, and the MDS eigenvalue spectrum. A good map shows the truth's
colour gradient; the spectrum shows how many dimensions the map really has.

Used by `sme demo --plot DIR` and `sme replay FILE --offline --plot DIR`. matplotlib (a core
dependency: the first commands a new user runs draw with it) draws off-screen (the Agg backend)."""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from sensorimotor.agent.embedding.procrustes import procrustes
from sensorimotor.protocol.messages import Embedding, Truth


@dataclass(frozen=True)
class Plotted:
    """What `plot_embedding` drew.

    Attributes
    ----------
    path : str
        The PNG written.
    n_points : int
        Points of the embedding drawn.
    coloured_by_truth : bool
        Whether the points are coloured by their true positions (the world gave truth for them).
    """

    path: str
    n_points: int
    coloured_by_truth: bool


def truth_colours(positions: np.ndarray) -> np.ndarray:
    """RGB colours in [0, 1] from true positions [n, d]: 1-D positions along viridis, 2-D (or the
    first two dimensions of more) as a plane of colour (red grows with the first coordinate, blue
    with the second), so neighbours in the world have similar colours."""
    pos = np.asarray(positions, dtype=np.float64)
    pos = pos.reshape(-1, 1) if pos.ndim == 1 else pos
    span = np.ptp(pos, axis=0)
    unit = (pos - pos.min(axis=0)) / np.where(span > 0, span, 1.0)
    if unit.shape[1] == 1:
        from matplotlib import colormaps

        return np.asarray(colormaps["viridis"](unit[:, 0]))[:, :3]
    x, y = unit[:, 0], unit[:, 1]
    return np.clip(np.stack([0.15 + 0.8 * x, 0.25 + 0.5 * (1 - np.abs(x - y)), 0.15 + 0.8 * y], axis=1), 0, 1)


def _safe(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name) or "world"


def plot_embedding(emb: Embedding, truth: Truth | None, out_dir: str) -> Plotted:
    """Write `out_dir/<world>.png`: truth, the aligned embedding coloured by truth, the spectrum.

    Parameters
    ----------
    emb : Embedding
        The embedding to draw (its `ids` index the rows of the truth's ``positions``).
    truth : Truth or None
        The world's ground truth; without it the points are drawn in one colour, as learned.
    out_dir : str
        The directory (made if missing).

    Returns
    -------
    Plotted
    """
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{_safe(emb.world_id)}.png")
    coords = np.asarray(emb.coordinates, dtype=np.float64)
    coords = coords.reshape(-1, 1) if coords.ndim == 1 else coords
    n = coords.shape[0]
    size = float(np.clip(2500.0 / max(n, 1), 3.0, 28.0))  # many points: smaller markers
    pos = None
    if truth is not None and "positions" in truth.tensors and n >= 2:
        allpos = np.asarray(truth.tensors["positions"], dtype=np.float64)
        allpos = allpos.reshape(-1, 1) if allpos.ndim == 1 else allpos
        ids = np.asarray(emb.ids, dtype=np.int64)
        if ids.size == n and ids.min(initial=0) >= 0 and ids.max(initial=-1) < allpos.shape[0]:
            pos = allpos[ids]
    err = "" if emb.procrustes_error is None else f", Procrustes error {emb.procrustes_error:.4f}"
    fig, axes = plt.subplots(1, 3 if pos is not None else 2, figsize=(13 if pos is not None else 9, 4.2))
    if pos is not None:
        colours = truth_colours(pos)
        d = pos.shape[1]
        ax = axes[0]
        ax.scatter(pos[:, 0], pos[:, 1] if d > 1 else np.zeros(n), c=colours, s=size, edgecolors="none")
        ax.set_title(f"truth ({truth.kind or 'positions'}, {n} points)" if truth is not None else "truth")
        ax.set_aspect("equal", adjustable="datalim")
        ax = axes[1]
        one_d = coords.shape[1] == 1 or d == 1
        try:
            fit = procrustes(pos[:, :1], coords[:, :1]) if one_d else procrustes(pos, coords)
            ref, aligned = fit.truth, fit.aligned
        except ValueError:  # all points identical: nothing to align
            ref, aligned = pos, coords
        if one_d:
            ax.scatter(ref[:, 0], aligned[:, 0], c=colours, s=size, edgecolors="none")
            ax.set_xlabel("truth (standardised)")
            ax.set_ylabel("embedding (aligned)")
        else:
            ax.scatter(aligned[:, 0], aligned[:, 1], c=colours, s=size, edgecolors="none")
            ax.set_aspect("equal", adjustable="datalim")
        ax.set_title(f"embedding v{emb.version}, aligned, coloured by truth")
    else:
        colours = np.tile([0.2, 0.35, 0.7], (n, 1))
        ax = axes[0]
        ax.scatter(coords[:, 0], coords[:, 1] if coords.shape[1] > 1 else np.zeros(n), c=colours, s=size)
        ax.set_title(f"embedding v{emb.version} (no truth to colour by)")
    ax = axes[-1]
    eig = np.asarray(emb.eigenvalues, dtype=np.float64)
    if eig.size:
        ax.bar(np.arange(1, eig.size + 1), eig, color="0.35")
        ax.set_xticks(np.arange(1, eig.size + 1))
    ax.set_title("MDS eigenvalues")
    ax.set_xlabel("component")
    fig.suptitle(f"{emb.world_id}: {emb.trigger} at step {emb.step}{err}")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return Plotted(path, n, pos is not None)
