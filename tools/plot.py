"""A picture of a learned map without the Rerun GUI: one PNG per world with the true positions, the
embedding aligned onto them (Procrustes: translation, scale, rotation/reflection) in the truth's own
units with every point coloured by where it truly is, the Procrustes error and goal fraction of
every version against the world step (when the run's versions are given), and the MDS eigenvalue
spectrum. A good map shows the truth's colour gradient on the truth's axes; the curve shows when
it came; the spectrum shows how many dimensions the map really has.

Used by `sme demo --plot DIR` and `sme replay FILE --offline --plot DIR`. matplotlib (a core
dependency: the first commands a new user runs draw with it) draws off-screen (the Agg backend)."""

from __future__ import annotations

import os
from collections.abc import Sequence
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
    aligned : ndarray or None
        The map as drawn: aligned onto the truth, in the truth's units [n, d] (None without truth).
    curve_points : int
        Versions on the error-versus-step curve (0: no curve drawn).
    """

    path: str
    n_points: int
    coloured_by_truth: bool
    aligned: np.ndarray | None = None
    curve_points: int = 0


def in_truth_units(pos: np.ndarray, coords: np.ndarray) -> np.ndarray:
    """`coords` aligned onto the true positions `pos` [n, d] (translation, scale and
    rotation/reflection, as the Procrustes error removes them), in the truth's own units: a
    perfect map lands on the truth. A map of fewer dimensions than the truth is padded with zeros;
    of more, its extra dimensions are dropped after the alignment."""
    pos = np.asarray(pos, dtype=np.float64)
    pos = pos.reshape(-1, 1) if pos.ndim == 1 else pos
    fit = procrustes(pos, coords)
    d = max(pos.shape[1], np.asarray(coords).reshape(len(pos), -1).shape[1])
    padded = np.pad(pos, ((0, 0), (0, d - pos.shape[1])))
    centred = padded - padded.mean(axis=0)
    units = fit.aligned * np.linalg.norm(centred) + padded.mean(axis=0)
    return units[:, : pos.shape[1]]


def _curves(ax, history: Sequence[Embedding]) -> int:
    """The Procrustes error (log axis) and the goal fraction (right axis) of each version by step."""
    pts = [
        (e.step, float(e.procrustes_error), e.metrics.get("goal_reached_fraction"))
        for e in history
        if e.procrustes_error is not None and np.isfinite(e.procrustes_error)
    ]
    if not pts:
        ax.set_axis_off()
        ax.set_title("no scored versions")
        return 0
    steps = [p[0] for p in pts]
    ax.plot(steps, [max(p[1], 1e-6) for p in pts], "o-", color="C0", ms=3, lw=1.2, label="Procrustes error")
    ax.set_yscale("log")
    ax.set_xlabel("world step")
    ax.set_ylabel("Procrustes error (0 perfect, about 1 random)", color="C0")
    goals = [(s, g) for s, _, g in pts if g is not None]
    if goals:
        g_ax = ax.twinx()
        g_ax.plot([s for s, _ in goals], [g for _, g in goals], "s--", color="C2", ms=3, lw=1.0)
        g_ax.set_ylim(-0.05, 1.05)
        g_ax.set_ylabel("goal reached from (fraction of starts)", color="C2")
    ax.set_title(f"error{' and goal fraction' if goals else ''} per version")
    return len(pts)


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


def plot_embedding(emb: Embedding, truth: Truth | None, out_dir: str, history: Sequence[Embedding] = ()) -> Plotted:
    """Write `out_dir/<world>.png`: truth, the embedding aligned onto it in its units and coloured
    by truth, the error and goal fraction per version (from `history`), the spectrum.

    Parameters
    ----------
    emb : Embedding
        The embedding to draw (its `ids` index the rows of the truth's ``positions``).
    truth : Truth or None
        The world's ground truth; without it the points are drawn in one colour, as learned.
    out_dir : str
        The directory (made if missing).
    history : sequence of Embedding, default=()
        The run's versions (this one included), for the error-versus-step curve; none: no curve.

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
    panels = (3 if pos is not None else 2) + (1 if history else 0)
    fig, axes = plt.subplots(1, panels, figsize=(4.4 * panels, 4.2))
    aligned = None
    curve_points = 0
    if pos is not None:
        colours = truth_colours(pos)
        d = pos.shape[1]
        ax = axes[0]
        ax.scatter(pos[:, 0], pos[:, 1] if d > 1 else np.zeros(n), c=colours, s=size, edgecolors="none")
        ax.set_title(f"truth ({truth.kind or 'positions'}, {n} points)" if truth is not None else "truth")
        ax.set_aspect("equal", adjustable="datalim")
        ax = axes[1]
        try:
            aligned = in_truth_units(pos, coords)
        except ValueError:  # all points identical: nothing to align
            aligned = None
        shown = aligned if aligned is not None else coords[:, :d]
        if d == 1:
            ax.scatter(pos[:, 0], shown[:, 0], c=colours, s=size, edgecolors="none")
            ax.set_xlabel("true position")
            ax.set_ylabel("map, aligned (same units)")
        else:
            ax.scatter(shown[:, 0], shown[:, 1], c=colours, s=size, edgecolors="none")
            both = np.vstack([pos[:, :2], shown[:, :2]])
            lo, hi = both.min(axis=0), both.max(axis=0)
            pad = 0.05 * np.maximum(hi - lo, 1e-9)
            for a in (axes[0], ax):  # the same axes for truth and map: the map is read in the truth's units
                a.set_xlim(lo[0] - pad[0], hi[0] + pad[0])
                a.set_ylim(lo[1] - pad[1], hi[1] + pad[1])
                a.set_aspect("equal", adjustable="box")
        ax.set_title(f"map v{emb.version}, aligned onto the truth (its units)")
    else:
        colours = np.tile([0.2, 0.35, 0.7], (n, 1))
        ax = axes[0]
        ax.scatter(coords[:, 0], coords[:, 1] if coords.shape[1] > 1 else np.zeros(n), c=colours, s=size)
        ax.set_title(f"embedding v{emb.version} (no truth to colour by)")
    if history:
        curve_points = _curves(axes[-2], history)
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
    return Plotted(path, n, pos is not None, aligned, curve_points)
