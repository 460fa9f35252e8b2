"""Where the car is, read by its eyes (ch. 7-8): the 1-D embedding of vergence traces, and the
reading of one position at a time from it.

The sweep's vergence traces are embedded by classical MDS (indel edit distance, Eq 7.3); the MDS
model then places any new trace without re-embedding, and that coordinate is the position. A
reading can go below one vergence step (`substep`): at the fixation the eyes look one step either
side, and the three foveal differences place the minimum between steps (equiangular fit of a V).
A reading is remembered by the parallel-eye view it began with (`recall`): while the vergence policy
and the embedding are fixed, the view depends only on where the car is and the greedy trace only on
the views it meets, so the same view gives the same position; every `recall_check`-th reuse is
verged again, and a reading that differs forgets them all.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, fit_similarity, trace_cross_distances, trace_distances
from sensorimotor.agent.embedding.classical_mds import MDSModel
from sensorimotor.agent.embedding.procrustes import SimilarityTransform
from sensorimotor.agent.snapshot import array_or_none
from sensorimotor.protocol.messages import Observation

CONVERGE, DIVERGE = 0, 1
RECALL_SIZE = 100_000  # remembered readings at most (a world whose views never repeat adds no more)


class VergenceReading:
    """The vergence embedding (landmark traces, MDS model, alignment to the first embedding) and
    the state of the reading in progress: the eyes' vergence, the foveal differences met, the
    fixation, and the remembered readings.

    `k_max`: the eyes' largest vergence in steps (None: unbounded); `recall_check`: every Nth reuse
    of a remembered reading is verged again (0: never recall).
    """

    def __init__(self, k_max: int | None, recall_check: int) -> None:
        self.k_max, self.recall_check = k_max, recall_check
        self.landmarks: list[list[int]] = []
        self.model: MDSModel | None = None
        self.align: SimilarityTransform | None = None
        self.coords0: np.ndarray | None = None
        self.positions: dict[tuple[int, ...], float] = {}
        self.quantum = 1.0  # one vergence step, in embedding coordinates
        self.slope = 0.0  # embedding coordinate per vergence step (signed), to place a sub-step offset
        self.k = 0  # the eyes' vergence, in steps from parallel, during a reading
        self.ds: dict[int, float] = {}  # foveal difference per vergence met in the reading in progress
        self.goal: int | None = None  # the vergence the reading fixated at, while looking either side
        self.recall: dict[bytes, float] = {}  # the position each parallel-eye view led to
        self.recalls = 0  # reuses so far (every recall_check-th is verged again to check)
        self.view: bytes | None = None  # the parallel-eye view of the reading in progress
        self.checking: float | None = None  # the recalled position that reading is checking

    # the embedding -------------------------------------------------------------------------------
    def embed(self, traces: list[list[int]]) -> tuple[np.ndarray, tuple[float, ...], bool]:
        """Embed the sweep's traces; returns their coordinates, the leading MDS eigenvalues and
        whether this is the first embedding. A later one is put in the first one's coordinates by a
        similarity fit over the same start states, so what was learned on top stays valid."""
        D = trace_distances(traces, kind="edit", substitution_cost=2)
        mds = classical_mds(D, 1)
        coords = mds.coordinates
        first = self.coords0 is None
        if self.coords0 is not None:
            self.align = fit_similarity(self.coords0, coords)
            coords = self.align.apply(coords)
        else:
            self.align = None
            self.coords0 = coords.copy()
            lengths = [len(t) for t in traces]
            span = float(coords.max() - coords.min())
            self.quantum = span / max(max(lengths) - min(lengths), 1)
        self.landmarks, self.model, self.positions = traces, mds.model, {}
        ks = np.array([self.vergence_after(t) for t in traces], dtype=np.float64)
        # the embedding is ~linear in the fixating vergence (Eq 7.3 over converge-only traces)
        self.slope = float(np.polyfit(ks, coords[:, 0], 1)[0]) if np.ptp(ks) > 0 else 0.0
        self.forget()
        n = len(traces)
        return coords, tuple(float(e) for e in mds.eigenvalues[: min(10, n)]), first

    def position(self, trace: list[int]) -> float:
        """The embedding coordinate of a vergence trace (out of sample)."""
        key = tuple(trace)
        p = self.positions.get(key)
        if p is None:
            assert self.model is not None, "positions are read once the first embedding is made"
            d = trace_cross_distances([list(trace)], self.landmarks, kind="edit", substitution_cost=2)
            y = self.model.transform(d)
            if self.align is not None:
                y = self.align.apply(y)
            p = self.positions[key] = float(y[0, 0])
        return p

    def vergence_after(self, trace: list[int]) -> int:
        """The eyes' vergence, in steps from parallel, after the actions of `trace`."""
        k = 0
        for a in trace:
            k = self._turned(k, a)
        return k

    def _turned(self, k: int, a: int) -> int:
        k = k + 1 if a == CONVERGE else max(k - 1, 0)
        return k if self.k_max is None else min(k, self.k_max)

    # a reading -----------------------------------------------------------------------------------
    def begin(self) -> None:
        """A reading starts with the eyes parallel."""
        self.k, self.ds, self.goal = 0, {}, None

    def move(self, a: int) -> None:
        """The eyes turned by vergence action `a`."""
        self.k = self._turned(self.k, a)

    def substep(self) -> float:
        """Where between vergence steps the foveal difference is least, from the differences at the
        fixated vergence and one step either side (equiangular fit of a V; in [-0.5, 0.5] steps,
        positive toward converging). 0 when a side is out of the eyes' range."""
        g = self.goal
        assert g is not None, "a sub-step offset is read once the reading fixated"
        dm, d0, dp = self.ds.get(g - 1), self.ds.get(g), self.ds.get(g + 1)
        if dm is None or d0 is None or dp is None:
            return 0.0
        den = max(dm, dp) - d0
        return float(np.clip(0.5 * (dm - dp) / den, -0.5, 0.5)) if den > 0 else 0.0

    def look_aside(self) -> int | None:
        """The vergence action toward the next side of the fixation not yet seen, or None when both
        are seen (or out of the eyes' range)."""
        g = self.goal
        assert g is not None, "the eyes look aside once the reading fixated"
        for k in (g + 1, g - 1):
            if k >= 0 and (self.k_max is None or k <= self.k_max) and k not in self.ds:
                return CONVERGE if k > self.k else DIVERGE
        return None

    def abandon(self) -> None:
        """The reading in progress is dropped (the world restarted)."""
        self.view = self.checking = None
        self.goal = None

    # remembered readings -------------------------------------------------------------------------
    def forget(self) -> None:
        """Drop every remembered reading (the vergence policy, the embedding or the body changed)."""
        self.recall, self.view, self.checking = {}, None, None

    def recalled(self, obs: Observation) -> float | None:
        """At the parallel-eye view that begins a reading: the position this view led to before,
        unless this reuse is one that is verged again to check it (or recall is off)."""
        n = self.recall_check
        self.view, self.checking = None, None
        if not n:
            return None
        view = obs.tensors["left"].tobytes() + obs.tensors["right"].tobytes()
        p = self.recall.get(view)
        self.view = view
        if p is None:
            return None
        self.recalls += 1
        if self.recalls % n:
            return p
        self.checking = p
        return None

    def remember(self, p: float) -> None:
        """Keep the position the reading just finished gave for its first view; a check that
        differs forgets every remembered reading (something changed that the views do not show)."""
        if self.view is None:
            return
        if self.checking is not None and self.checking != p:
            self.forget()
        elif len(self.recall) < RECALL_SIZE:
            self.recall[self.view] = p
        self.view, self.checking = None, None

    # saved state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The embedding and the reading in progress, under the mountain car program's keys."""
        model = None if self.model is None else {"basis": self.model.basis.copy(), "mean_sq": self.model.mean_sq.copy()}
        al = self.align
        align = (
            None
            if al is None
            else {"scale": al.scale, "rotation": al.rotation.copy(), "translation": al.translation.copy()}
        )
        return {
            "landmarks": [list(t) for t in self.landmarks],
            "model": model,
            "align": align,
            "coords0": array_or_none(self.coords0),
            "positions": [[list(k), v] for k, v in self.positions.items()],
            "quantum": self.quantum,
            "slope": self.slope,
            "k": self.k,
            "ds": [[k, d] for k, d in self.ds.items()],
            "goal": self.goal,
            # the remembered readings, so a restored program recalls (and checks) as this one would
            "recall_views": np.array([np.frombuffer(v, dtype=np.uint8) for v in self.recall], dtype=np.uint8)
            if self.recall
            else None,
            "recall_positions": [float(p) for p in self.recall.values()],
            "recalls": self.recalls,
            "view": None if self.view is None else np.frombuffer(self.view, dtype=np.uint8).copy(),
            "checking": self.checking,
        }

    def restore(self, state: dict[str, Any], trace: list[int] | None) -> None:
        """Continue from `state()`; `trace` is the reading in progress (its vergence, for a
        checkpoint saved before the vergence was kept)."""
        self.landmarks = [[int(a) for a in t] for t in state["landmarks"]]
        m, al = state["model"], state["align"]
        self.model = None if m is None else MDSModel(np.array(m["basis"]), np.array(m["mean_sq"]))
        self.align = (
            None
            if al is None
            else SimilarityTransform(float(al["scale"]), np.array(al["rotation"]), np.array(al["translation"]))
        )
        self.coords0 = array_or_none(state["coords0"])
        self.positions = {tuple(int(a) for a in k): float(v) for k, v in state["positions"]}
        self.quantum = float(state["quantum"])
        if "slope" in state:
            self.slope = float(state["slope"])
        else:  # a checkpoint from before the sub-step reading: the slope from its landmarks
            self.slope = 0.0
            if self.model is not None and self.landmarks:
                ks = np.array([self.vergence_after(t) for t in self.landmarks], dtype=np.float64)
                ys = np.array([self.position(t) for t in self.landmarks])
                self.slope = float(np.polyfit(ks, ys, 1)[0]) if np.ptp(ks) > 0 else 0.0
        self.ds = {int(k): float(d) for k, d in state.get("ds", [])}
        self.goal = None if state.get("goal") is None else int(state["goal"])
        self.k = int(state["k"]) if "k" in state else self.vergence_after(trace or [])
        views = state.get("recall_views")
        self.recall = (
            {}
            if views is None
            else {
                np.asarray(v, dtype=np.uint8).tobytes(): float(p)
                for v, p in zip(views, state["recall_positions"], strict=True)
            }
        )
        self.recalls = int(state.get("recalls", 0))
        view = state.get("view")
        self.view = None if view is None else np.asarray(view, dtype=np.uint8).tobytes()
        self.checking = None if state.get("checking") is None else float(state["checking"])
