"""The generic program's work that is not learning a policy: the action table it chooses among,
and the jobs it runs off the act path (pure functions of a snapshot, `agent.programs.background`):
trace distances + classical MDS of a sweep, and the motor map of a camera's frames."""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, trace_distances
from sensorimotor.agent.embedding.move_counts import move_count_distances
from sensorimotor.agent.embedding.probabilistic import mean_pair_distances, mean_trace_distances, mode_trace
from sensorimotor.agent.embedding.rotation_frames import Rotations, frame_trace
from sensorimotor.agent.embedding.weighted_mds import weighted_mds
from sensorimotor.agent.learners.motor_map import fit_motor_map
from sensorimotor.protocol.messages import WorldSpec

#: box actions of more dimensions than this are coded per axis (`axis_moves`), not as a product
PRODUCT_MAX_DIMS = 4


def axis_moves(low: tuple[float, ...], high: tuple[float, ...], scale: float) -> np.ndarray:
    """Two moves per axis (+ then -, in axis order), each `scale` of the way from the box's middle to
    one bound with every other axis at its middle: 2 x dims rows, where a product of 3 values per
    axis would grow as 3^dims (2,187 rows for 7 joints)."""
    lo, hi = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
    mid = (lo + hi) / 2
    rows = np.repeat(mid[None, :], 2 * len(lo), axis=0)
    for k in range(len(lo)):
        rows[2 * k, k] = mid[k] + scale * (hi[k] - mid[k])
        rows[2 * k + 1, k] = mid[k] - scale * (mid[k] - lo[k])
    return rows


def action_table(spec: WorldSpec, levels: int, scale: float = 1.0) -> np.ndarray:
    """The action values the program chooses among: (n_actions, dims); box values span `scale`
    of each bound about the box's middle: every combination of `levels` values per axis up to
    `PRODUCT_MAX_DIMS` axes, one move per axis and direction beyond (`axis_moves`)."""
    a = spec.action_space
    if a.discrete:
        return np.arange(a.n, dtype=np.float64)[:, None]
    if len(a.low) > PRODUCT_MAX_DIMS:
        return axis_moves(a.low, a.high, scale)
    grids = [
        (lo + hi) / 2 + scale * (np.linspace(lo, hi, levels) - (lo + hi) / 2)
        for lo, hi in zip(a.low, a.high, strict=True)
    ]
    return np.array(list(itertools.product(*grids)), dtype=np.float64)


#: `embedding=auto`: weighted MDS up to this many starts (its cost grows as n^3: about 4 s at 1,000; classical MDS beyond)
WEIGHTED_MAX = 1000

#: `estimator=auto`: the mode trace stands for a start when it is at least this share of its samples
MODE_SHARE = 0.5


def mode_share(traces: list[list[list[int]]]) -> float:
    """The mean over starts of the share of a start's samples that are its most common trace: near 1
    where the policy controls the world's chance (the mode trace is what the start does), low on
    slippery ice (every sample another trace: their mean is the better summary)."""
    shares = []
    for per in traces:
        if per:
            counts: dict[tuple[int, ...], int] = {}
            for t in per:
                counts[tuple(t)] = counts.get(tuple(t), 0) + 1
            shares.append(max(counts.values()) / len(per))
    return float(np.mean(shares)) if shares else 1.0


def embed_job(
    traces: list[list[list[int]]],
    actions: np.ndarray | None,
    dims: int,
    estimator: str = "mode",
    distance: str = "padded",
    dtw_penalty: float = 1.0,
    rotations: tuple[int, list[list[int]]] | None = None,
    n_actions: int = 0,
    reached: list[list[bool]] | None = None,
    discrete_distance: str = "edit",
    embedding: str = "classical",
    gains: list[float] | None = None,
) -> dict[str, Any]:
    """Trace distances and classical MDS of each start's sampled traces (one sample each in a
    deterministic world): edit distance of discrete actions (in the start's frame when `rotations`,
    (order, [[action, power], ...]), says which actions turn: `frame_trace`); the padded sum or DTW
    of the action values when `actions` is the table of a discretised box. Several samples: the mode
    trace, or the mean pairwise distance (ch. 9.4), or the padded sum between mean traces; `auto`:
    the mode trace where it is what a start mostly does (`mode_share`), else mean traces. Discrete
    traces of one sample a start (`discrete_distance=auto`) or `moves`: the distance between their
    action counts, turns left out (`move_counts`). Then classical MDS, or weighted MDS from it
    (`embedding=weighted`; `auto`: where the moves distance was used; the eigenvalues are classical
    MDS's either way). Net moves are scaled by the move axes' `gains` when given
    (`box_moves.axis_gains`). A pure function, run off the act path."""
    symbols = n_actions
    if rotations is not None and actions is None:
        rot = Rotations(int(rotations[0]), tuple((int(a), int(p)) for a, p in rotations[1]))
        traces = [[frame_trace(t, rot, n_actions) for t in s] for s in traces]
        symbols = n_actions * (1 + rot.order)  # the labels frame_trace gives
    if estimator == "auto":
        estimator = "mode" if actions is not None or mode_share(traces) >= MODE_SHARE else "mean_trace"
    if estimator == "plain":  # one sampled trace per start, as if the world were deterministic
        traces, reached = [s[:1] for s in traces], None if reached is None else [r[:1] for r in reached]
    moves = False
    if any(len(t) > 1 for t in traces) and estimator == "mean_trace" and actions is None:
        D = mean_trace_distances(traces, symbols, reached)
    elif any(len(t) > 1 for t in traces) and estimator == "mean" and actions is None:
        D = mean_pair_distances(traces, substitution_cost=2)
    else:
        canon = [list(mode_trace(t)) for t in traces]
        one = all(len(t) <= 1 for t in traces)
        moves = actions is None and (discrete_distance == "moves" or (discrete_distance == "auto" and one))
        if moves:
            skip = [] if rotations is None else [int(a) for a, _ in rotations[1]]  # turns: frame, not place
            D = move_count_distances(canon, max(symbols, 1 + max((max(t, default=0) for t in canon), default=0)), skip)
        elif actions is None:
            D = trace_distances(canon, kind="edit", substitution_cost=2)
        else:
            table = np.asarray(actions)
            cont = [table[np.asarray(t, dtype=np.int64)].reshape(len(t), table.shape[1]) for t in canon]
            if distance == "dtw":
                D = trace_distances(cont, kind="dtw", dtw_penalty=dtw_penalty)
            elif distance == "net":  # the order of the moves does not count, only where they add up to
                net = np.array([c.sum(axis=0) for c in cont])
                if gains is not None:
                    net = net * np.asarray(gains, dtype=np.float64)
                D = np.linalg.norm(net[:, None, :] - net[None, :, :], axis=2)
            else:
                D = trace_distances(cont, kind="continuous")
    mds = classical_mds(D, dims)
    if embedding == "weighted" or (embedding == "auto" and moves and len(D) <= WEIGHTED_MAX):
        return {"coordinates": weighted_mds(D, dims, init=mds.coordinates).coordinates, "eigenvalues": mds.eigenvalues}
    return {"coordinates": mds.coordinates, "eigenvalues": mds.eigenvalues}


def motor_job(
    before: np.ndarray,
    actions: np.ndarray,
    after: np.ndarray,
    starts: np.ndarray,
    components: int,
    seed: int,
) -> dict[str, Any]:
    """Fit the motor map (`agent.learners.motor_map`) on the warm-up's transitions and measure,
    in its coordinates, the range the random moves covered and the range of the starts met."""
    m = fit_motor_map(before, actions, after, components=components, seed=seed)
    z = m(np.vstack([before, after]))
    zs = m(starts) if len(starts) else z
    return {
        "map": m.state(),
        "seen_lo": z.min(axis=0),
        "seen_hi": z.max(axis=0),
        "start_lo": zs.min(axis=0),
        "start_hi": zs.max(axis=0),
    }


__all__ = ["MODE_SHARE", "PRODUCT_MAX_DIMS", "action_table", "axis_moves", "embed_job", "mode_share", "motor_job"]
