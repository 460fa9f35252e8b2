"""The generic program's saved state: everything `restore` needs to go on exactly where `state` was
taken (learners, sweep in progress, acceptance, background jobs in flight are the base's)."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.embedding.rotation_frames import Rotations
from sensorimotor.agent.learners.lspi_features import basis_state, set_basis
from sensorimotor.agent.learners.motor_map import MotorMap
from sensorimotor.agent.programs.generic_continuous import FEW_STARTS
from sensorimotor.agent.programs.generic_relearn import GenericRelearn


class GenericState(GenericRelearn):
    """The program as a checkpoint: `state` and `restore`."""

    def state(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            **super().state(),
            "lspi": self.lspi.state(),
            "phase": self.phase,
            "new_samples": self.new_samples,
            "relearn_at": self.relearn_at,
            "relearn_unconfirmed": self._relearn_unconfirmed,
            "prev": None if self._prev is None else list(self._prev),
            "prev_x": None if self._prev_x is None else self._prev_x.copy(),
            "prev_key": None if self._prev_key is None else self._prev_key.hex(),
            "sweep": self._sweep.state(),
            "perf": list(self._perf),
            "next_id": self._next_id,
            "seen_count": self._seen,
            "fitted_at": self._fitted_at,
            "said_no_starts": self._said_no_starts,
            "retried_total": self.retried_total,
            "chance_seen": self._chance_seen,
            "watching": self._watching,
            "pending_embedding": None if self._pending_embedding is None else dict(self._pending_embedding),
            # (observation, previous action) pairs met on the trace in progress: its cycle check
            "visited": sorted([key.hex(), a] for key, a in self._visited),
            "stochastic": self.stochastic,
            "ids": sorted([key.hex(), i] for key, i in self._ids.items()),
            "accepted": None if self._accepted is None else self._accepted.copy(),
            "best": None if self._best is None else [self._best[0], min(self._best[1], 1e300)],
            "best_disparity": self._best_disparity,
            "held": self._held,
            "ends": [[int(k), v[0].tolist(), v[1].tolist()] for k, v in self._ends.items()],
            "trace_from": None if self._trace_from is None else self._trace_from.tolist(),
            "checking": self._checking,
            "sweep_w": None if self._sweep_w is None else self._sweep_w.copy(),
            "accepted_basis": self._accepted_basis,
            "sweep_on_accepted_basis": self._sweep_rbf is not None,
            "sweep_basis": self._sweep_basis,
            "diverged": self._diverged,
            "accepted_traces": None if self._accepted_traces is None else [list(t) for t in self._accepted_traces],
            "accepted_reached": self._accepted_reached,
            "unfed": list(self._unfed),
            "candidate_traces": None if self._candidate_traces is None else [list(t) for t in self._candidate_traces],
            "published": None if self._published is None else [list(t) for t in self._published],
            "start_scores": list(self._start_scores),
            "start_fair": self._start_fair,
            "rotations": None
            if self._rotations is None
            else [self._rotations.order, [list(p) for p in self._rotations.powers]],
            **self.relearn_state(),
        }
        if self.model is not None:
            out["model"] = self.model.state()
            out.update(fresh=self._fresh, since_plan=self._since_plan, last_choice=self._last_choice)
            out["plan_exact"] = self._plan_exact
            out.update(swept_policy=self._swept_policy, since_sweep=self._since_sweep)
            out["plan_for_sweep"] = self._plan_for_sweep
        if self.planner is not None:
            out["moves"] = self.moves_state()  # the move size and trace distance settled (generic_continuous)
            out["planner"] = self.planner.state()
            out.update(start_lo=self._start_lo.copy(), start_hi=self._start_hi.copy(), starts_met=self._starts_met)
            out.update(warm=self._warm, seen_lo=self._seen_lo.copy(), seen_hi=self._seen_hi.copy())
            out.update(lo=self._lo.copy(), span=self._span.copy())
            # a checkpoint while the motor map's transitions are collected keeps none: they are
            # collected again (a fit in flight is kept, with them, as every background job is)
            out["motor_map"] = None if self._motor_map is None else self._motor_map.state()
        if self.sarsa is not None:
            out["sarsa"] = self.sarsa.state()
            out.update(warm=self._warm, seen_lo=self._seen_lo.copy(), seen_hi=self._seen_hi.copy())
            out.update(lo=self._lo.copy(), span=self._span.copy())
        elif self.learner == "lspi":
            out.update(store=self._store.copy(), reservoir=self._reservoir.copy(), basis=basis_state(self._rbf))
            out["store_hist"] = self._store_hist.copy()
        return out

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        self.stochastic = bool(state.get("stochastic", False))
        self._plan_for_chance()  # the capacity the saved samples were kept under
        self.take_layout(state)  # the basis the saved weights are over
        self.lspi.restore(state["lspi"])
        self.phase, self.new_samples = str(state["phase"]), int(state["new_samples"])
        self.relearn_at = None if state["relearn_at"] is None else int(state["relearn_at"])
        self._relearn_unconfirmed = int(state.get("relearn_unconfirmed", 0))  # absent in older checkpoints
        self._prev = None if state["prev"] is None else (int(state["prev"][0]), int(state["prev"][1]))
        px = state.get("prev_x")
        self._prev_x = None if px is None else np.asarray(px, dtype=np.float64)
        pk = state.get("prev_key")
        self._prev_key = None if pk is None else bytes.fromhex(str(pk))
        sws = state["sweep"]
        n_traces = int(sws["n_starts"])
        self._sweep = self._new_sweep(n_traces, int(sws.get("repeats", max(1, n_traces // max(1, self.spec.n_starts)))))
        self._sweep.restore(sws)
        self._perf = [float(v) for v in state["perf"]]
        self._next_id, self._seen = int(state["next_id"]), int(state["seen_count"])
        self._fitted_at = int(state["fitted_at"])
        self._said_no_starts = bool(state["said_no_starts"])
        self.retried_total = int(state.get("retried_total", 0))  # absent in older checkpoints
        self._chance_seen = bool(state.get("chance_seen", False))
        self._watching = bool(state["watching"])
        pending = state.get("pending_embedding")
        self._pending_embedding = None if pending is None else dict(pending)
        self._visited = {(bytes.fromhex(str(h)), int(a)) for h, a in state.get("visited", [])}
        self._ids = {bytes.fromhex(str(h)): int(i) for h, i in state.get("ids", [])}
        acc = state.get("accepted")
        self._accepted = None if acc is None else np.asarray(acc, dtype=np.float64)
        best = state.get("best")
        self._best = None if best is None else (float(best[0]), float(best[1]))
        bs = state.get("best_disparity")  # absent in older checkpoints
        self._best_disparity = None if bs is None else float(bs)
        self._held = int(state.get("held", 0))  # absent in older checkpoints
        self._ends = {
            int(k): (np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
            for k, a, b in state.get("ends", [])
        }
        tf = state.get("trace_from")
        self._trace_from = None if tf is None else np.asarray(tf, dtype=np.float64)
        self._checking = bool(state.get("checking", False))
        sw = state.get("sweep_w")
        self._sweep_w = None if sw is None else np.asarray(sw, dtype=np.float64)
        ab = state.get("accepted_basis")
        self._accepted_basis = None if ab is None else dict(ab)
        sb = state.get("sweep_basis")
        self._sweep_basis = None if sb is None else dict(sb)
        if self._sweep_basis is not None:
            self._sweep_rbf = self._rbf_of(self._sweep_basis)
        else:
            self._sweep_rbf = self._accepted_rbf() if state.get("sweep_on_accepted_basis") else None
        self._diverged = bool(state.get("diverged", False))
        at = state.get("accepted_traces")
        self._accepted_traces = None if at is None else [[int(a) for a in t] for t in at]
        ar = state.get("accepted_reached")
        self._accepted_reached = None if ar is None else [bool(r) for r in ar]
        self._unfed = [float(v) for v in state.get("unfed", [])]
        ct = state.get("candidate_traces")
        self._candidate_traces = None if ct is None else [[int(a) for a in t] for t in ct]
        pt = state.get("published")  # absent in older checkpoints
        self._published = None if pt is None else [[int(a) for a in t] for t in pt]
        self._start_scores = [float(v) for v in state.get("start_scores", [])]
        self._start_fair = bool(state.get("start_fair", True))
        rot = state.get("rotations")
        self._rotations = None if rot is None else Rotations(int(rot[0]), tuple((int(a), int(p)) for a, p in rot[1]))
        self.restore_relearn(state)
        if self.model is not None:
            self.model.restore(state["model"])
            self._fresh, self._since_plan = bool(state["fresh"]), int(state["since_plan"])
            self._plan_exact = bool(state.get("plan_exact", False))
            self._last_choice = int(state["last_choice"])
            sp_ = state.get("swept_policy")
            self._swept_policy = None if sp_ is None else np.asarray(sp_, dtype=np.int64)
            self._since_sweep = int(state["since_sweep"])
            self._plan_for_sweep = bool(state["plan_for_sweep"])
        if self.planner is not None:
            self.restore_moves(state.get("moves"))
            self.planner.restore(state["planner"])
            self._start_lo = np.asarray(state["start_lo"], dtype=np.float64)
            self._start_hi = np.asarray(state["start_hi"], dtype=np.float64)
            self._starts_met = int(state.get("starts_met", FEW_STARTS))  # (a checkpoint from before it was kept)
            self._warm = int(state["warm"])
            self._seen_lo = np.asarray(state["seen_lo"], dtype=np.float64)
            self._seen_hi = np.asarray(state["seen_hi"], dtype=np.float64)
            self._lo = np.asarray(state["lo"], dtype=np.float64)
            self._span = np.asarray(state["span"], dtype=np.float64)
            mm = state.get("motor_map")
            self._motor_map = None if mm is None else MotorMap.from_state(mm)
            self._motor_data, self._motor_starts, self._motor_prev = [], [], None
        if self.sarsa is not None:
            self.sarsa.restore(state["sarsa"])
            self._warm = int(state["warm"])
            self._seen_lo = np.asarray(state["seen_lo"], dtype=np.float64)
            self._seen_hi = np.asarray(state["seen_hi"], dtype=np.float64)
            self._lo = np.asarray(state["lo"], dtype=np.float64)
            self._span = np.asarray(state["span"], dtype=np.float64)
        elif self.learner == "lspi":
            self._store[...] = np.asarray(state["store"], dtype=np.float32)
            self._reservoir[...] = np.asarray(state["reservoir"], dtype=np.float32)
            if "store_hist" in state:  # (absent in older checkpoints: no history then)
                h = np.asarray(state["store_hist"], dtype=np.int64)
                if h.size and not (0 <= h.min() and h.max() < self._rbf.n_hist):
                    raise ValueError(f"saved history values outside 0..{self._rbf.n_hist - 1}")
                self._store_hist[...] = h
            set_basis(self._rbf, state["basis"])
