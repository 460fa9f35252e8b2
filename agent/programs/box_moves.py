"""How the generic program fits box actions to the body it finds, with no truth: whether traces
are compared by their net move (`distance=auto`), and how large a move the planner takes
(`action_scale=0`). Pure functions of what the program saw; the rules in docs/zoo.md.

* **Moves that add up.** On a body moved by increments (a hand, a point, joints commanded by
  steps) where a trace ends less where it started is the sum of its moves times the body's gain,
  whatever their order: the net move is then the start's place in the moves' units (the traces
  end at one goal), which is what a map of the starts should show. On a body whose moves are
  forces (a car on a hill) the sum says little of where it went. The program fits, over a sweep's
  traces, the displacement (end less start, in the coordinates it plans in) as linear in the
  summed moves: when the fit explains at least `ADDS_UP` of the displacement's variance, the moves
  add up and traces are compared by their net move.
* **Moves the body carries out.** A body that lags or saturates (panda-gym's hand: a whole move is
  not done by the next step, and the rest spills into the steps after) follows a half move more
  faithfully. The planner's warm-up of random moves measures, over its first half of whole moves,
  the share of each step's displacement that a linear fit of the moves sent leaves unexplained;
  above `UNFAITHFUL` the second half takes half moves, and the plan takes half moves when they
  leave at least `BETTER` less unexplained. A body that follows its moves keeps whole moves (its
  warm-up is whole moves throughout).
* **Over camera frames** the probe runs once the motor map is fitted, in its coordinates (a frame
  says nothing of a move until it is mapped). Those coordinates carry the map's own error, about
  the same for every step, which leaves more of a half move's smaller step unexplained than of a
  whole one's whether the body lags or not. What lag leaves instead is a *spill*: part of each move
  arrives one step late, so a fit of each step's displacement on the move sent and the move before
  it finds a coefficient on the move before; the map's error, uncorrelated with the moves, does not
  bias it. A whole move spills when that coefficient's size is over `SPILLS` of the move's own;
  the plan takes half moves when theirs spills at most `LESS` as much.
* **Axes the body carries out unevenly.** A net move counts moves sent, so an axis the body carries
  out at two thirds of another's gain (panda-gym's hand, across the table) stretches the map along
  it. Where the program plans over the observation itself and it has one value per move axis, the
  sweep's displacements tell each axis's gain: `axis_gains` fits them as linear in the net moves,
  and when each axis's displacement follows its own axis's moves (the other axes' terms under
  `CROSS` of its own) the net moves are scaled by those gains, so the map is in the units the body
  senses. Motor coordinates of camera frames are in the units of the moves sent by construction:
  a gain fitted there would measure the map's error, not the body, so they keep the moves' units.
"""

from __future__ import annotations

import numpy as np

#: the moves add up when the summed moves explain at least this share of the displacement's variance
ADDS_UP = 0.9
#: a step of whole moves is carried out unfaithfully when a linear fit leaves more than this share
UNFAITHFUL = 0.25
#: half moves are taken when they leave at least this much less of a step unexplained
BETTER = 0.1
#: over camera frames: a whole move spills into the next step when its coefficient there is over this share
SPILLS = 0.2
#: over camera frames: half moves are taken when they spill at most this share of a whole move's spill
LESS = 0.75
#: `axis_gains`: an axis's gain is its own when the other axes' terms in its fit are under this share of it
CROSS = 0.2


def unexplained(moves: np.ndarray, displacements: np.ndarray) -> float | None:
    """The share of the displacements' variance (about their mean) that a least-squares fit linear
    in the moves (with a constant) leaves unexplained: 0 when they are the moves times a gain;
    None with too few rows to tell (twice the fit's coefficients) or no displacement at all."""
    m = np.asarray(moves, dtype=np.float64)
    d = np.asarray(displacements, dtype=np.float64)
    if m.ndim != 2 or d.ndim != 2 or len(m) != len(d) or len(m) < 2 * (m.shape[1] + 1):
        return None
    centred = d - d.mean(axis=0)
    total = float(np.square(centred).sum())
    if total <= 1e-18:
        return None
    x = np.hstack([m, np.ones((len(m), 1))])
    w = np.linalg.lstsq(x, d, rcond=None)[0]
    return float(np.square(d - x @ w).sum() / total)


def spill(moves: np.ndarray, previous: np.ndarray, displacements: np.ndarray) -> float | None:
    """How much of a move arrives one step late: the least-squares fit of each step's displacement
    on the move sent and the move before it (with a constant), the size of the coefficient on the
    move before over that of the move sent (Frobenius norms): 0 for a body that carries each move
    out by the next step; None with too few rows to tell or no response to the moves sent."""
    m, p = np.asarray(moves, dtype=np.float64), np.asarray(previous, dtype=np.float64)
    d = np.asarray(displacements, dtype=np.float64)
    if m.ndim != 2 or m.shape != p.shape or d.ndim != 2 or len(m) != len(d) or len(m) < 4 * (m.shape[1] + 1):
        return None
    x = np.hstack([m, p, np.ones((len(m), 1))])
    w = np.linalg.lstsq(x, d, rcond=None)[0]
    own = float(np.linalg.norm(w[: m.shape[1]]))
    return None if own <= 1e-12 else float(np.linalg.norm(w[m.shape[1] : 2 * m.shape[1]]) / own)


def spill_scale(whole: float | None, half: float | None) -> float:
    """Over camera frames, the fraction of each bound the plan's moves span: 0.5 when a whole move
    spilled (over `SPILLS`) and a half one spilled at most `LESS` as much, else 1."""
    if whole is None or half is None or whole <= SPILLS:
        return 1.0
    return 0.5 if half <= LESS * whole else 1.0


def moves_add_up(nets: np.ndarray, displacements: np.ndarray) -> bool | None:
    """Whether each trace's displacement is linear in its net move (summed moves) across a sweep:
    the `distance=auto` rule (None: too few traces to tell)."""
    share = unexplained(nets, displacements)
    return None if share is None else share <= 1.0 - ADDS_UP


def axis_gains(nets: np.ndarray, displacements: np.ndarray) -> np.ndarray | None:
    """Each move axis's gain, relative to their mean: the least-squares fit of the displacements
    (end less start, one column per move axis, in the units the body senses) on the net moves with
    a constant; None when the displacements are not one value per axis, the moves do not add up
    (`moves_add_up`), an axis's displacement leans on another axis's moves (an off-diagonal term
    over `CROSS` of its diagonal one), or an axis does not move. An axis that runs against its moves
    (a reversed motor) has the magnitude of its gain: the map differs by a reflection, which
    Procrustes and every distance ignore."""
    m = np.asarray(nets, dtype=np.float64)
    d = np.asarray(displacements, dtype=np.float64)
    if m.ndim != 2 or d.shape != m.shape or not moves_add_up(m, d):
        return None
    w = np.linalg.lstsq(np.hstack([m, np.ones((len(m), 1))]), d, rcond=None)[0][: m.shape[1]]
    gains = np.abs(np.diag(w))
    if np.any(gains <= 1e-12):
        return None
    cross = np.abs(w - np.diag(np.diag(w))).max(axis=0)  # column k: the other axes' moves in axis k's fit
    if np.any(cross > CROSS * gains):
        return None
    return gains / gains.mean()


def probe_half_moves(whole_share: float | None) -> bool:
    """Whether the warm-up goes on with half moves: a whole move was carried out unfaithfully."""
    return whole_share is not None and whole_share > UNFAITHFUL


def move_scale(whole_share: float | None, half_share: float | None) -> float:
    """The fraction of each bound the plan's moves span: 0.5 when half moves were carried out more
    faithfully than whole ones (by at least `BETTER` of a step), else 1."""
    if whole_share is None or half_share is None or not probe_half_moves(whole_share):
        return 1.0
    return 0.5 if half_share <= whole_share - BETTER else 1.0


__all__ = [
    "ADDS_UP",
    "BETTER",
    "CROSS",
    "LESS",
    "SPILLS",
    "UNFAITHFUL",
    "axis_gains",
    "move_scale",
    "moves_add_up",
    "probe_half_moves",
    "spill",
    "spill_scale",
    "unexplained",
]
