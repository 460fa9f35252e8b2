"""The generic program's embeddings: the distances + MDS job started on a sweep's traces (in the
frame of their start where some actions are rotations) and Embedding vN emitted when it returns."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.embedding.rotation_frames import Rotations, find_rotations
from sensorimotor.agent.programs.acceptance import end_disparity, sweep_score
from sensorimotor.agent.programs.base import EmbeddingOutput, EventOutput
from sensorimotor.agent.programs.generic_jobs import embed_job
from sensorimotor.agent.programs.generic_relearn import GenericRelearn
from sensorimotor.protocol.messages import EventKind, Trigger


class GenericPublish(GenericRelearn):
    """Embedding jobs and the embeddings (and `relearned` events) they give."""

    def _find_rotations(self, step: int) -> Rotations | None:
        """Tabular learner, discrete actions, `frames=auto`: the rotations among the actions, found
        again at each embedding from the transitions seen so far (an event says when they change);
        forgotten on a drop."""
        if self.tabular and self.discrete and self.params.frames == "auto" and self._transitions:
            nxt = self._moves({k: first for k, (first, other) in self._transitions.items() if other is None})
            found = find_rotations(nxt, range(self.n_actions))
            if found != self._rotations and found is not None:
                turns = ", ".join(f"action {a} = {p} turn(s)" for a, p in found.powers)
                self.emit(
                    EventOutput(
                        EventKind.POLICY_ITERATION,
                        f"some actions are rotations ({turns}; {found.order} make a full turn): "
                        "traces are compared in the frame of their start",
                        step,
                        reason="rotations",
                    )
                )
            self._rotations = found
        return self._rotations

    def _embed(self, step: int, relearned: bool, k: int, of: tuple[list[list[int]], list[bool]] | None = None) -> None:
        """Start the distances + MDS job on the sweep's traces (or `of`: traces, `k` per start, and
        whether each reached the goal); `relearned`: the first good (or settled) policy after a drop
        (the trigger will say so, with the drop's step)."""
        traces, flags = of if of is not None else (self._sweep.traces, self._sweep.reached)
        traces = [list(t) for t in traces]
        self._published = traces
        rot = self._find_rotations(step)
        n = len(traces) // k
        per_start = [traces[i * k : (i + 1) * k] for i in range(n)]
        assert self.background is not None
        prm = self.params
        distance = self._trace_distance()
        if of is None and self.planner is not None:
            self._measure_gains(step, distance)  # a republished map keeps its own sweep's gains
        self.background.submit(
            "embed",
            embed_job,
            traces=per_start,
            reached=[list(flags[i * k : (i + 1) * k]) for i in range(n)],
            actions=None if self.discrete or self.learner == "reach" else self.actions.copy(),
            dims=self.dims,
            estimator=self.estimator,
            distance=distance,
            gains=None if distance != "net" or self._gains is None else self._gains.tolist(),
            dtw_penalty=prm.dtw_penalty,
            rotations=None if rot is None else (rot.order, [list(p) for p in rot.powers]),
            n_actions=self.n_actions,
            # auto: moves only over a table of states, where an action is a step between them
            discrete_distance="edit"
            if not self.discrete or (prm.discrete_distance == "auto" and not self.tabular)
            else prm.discrete_distance,
            embedding=prm.embedding,
        )
        frac = sweep_score(list(flags), traces).fraction
        self._pending_embedding = {
            "step": step,
            "n": n,
            "relearned": relearned,
            "drop_step": self.relearn_at if relearned else None,
            "iteration": self.lspi.iterations,
            "lspi_iterations": float(self.lspi.iterations),
            "samples": float(self.lspi.n_samples if self.model is None else getattr(self.model, "n_transitions", 0)),
            "goal_reached_fraction": frac,
            "mean_trace_length": float(np.mean([len(t) for t in traces])),
            "rewarded": sum(bool(r) for r in flags),
            "traces": len(traces),
            "samples_per_start": float(1 if self.estimator == "plain" else k),
            "stochastic": float(self.stochastic),
            "accepted_policy": float(self._checking),
            "watched": float(self._watching),
            "rotation_order": float(rot.order if rot is not None else 0),
            "retried_traces": float(self._sweep.retries if of is None else 0),
        }
        disparity = end_disparity(self._ends) if of is None else None  # `of`: not this sweep's ends
        if disparity is not None:
            self._pending_embedding["end_disparity"] = disparity
        if relearned:
            self.relearn_at = None

    def _embedded(self, result: dict[str, Any]) -> None:
        """The distances + MDS job's result swapped in: emit Embedding vN (and `relearned`)."""
        p = self._pending_embedding
        assert p is not None
        self._pending_embedding = None
        if p.get("repeat"):
            return
        n, step = int(p["n"]), int(p["step"])
        eig = np.asarray(result["eigenvalues"])
        keys = (
            "lspi_iterations",
            "samples",
            "goal_reached_fraction",
            "mean_trace_length",
            "samples_per_start",
            "stochastic",
            "accepted_policy",
            "watched",
            "rotation_order",
            "retried_traces",
        )
        self.emit(
            EmbeddingOutput(
                Trigger.RELEARNED if p["relearned"] else Trigger.POLICY_ITERATION,
                tuple(range(n)),
                np.asarray(result["coordinates"]),
                tuple(float(e) for e in eig[: min(10, len(eig))]),
                step,
                {k: float(p.get(k, 0.0)) for k in keys}
                | ({"end_disparity": p["end_disparity"]} if "end_disparity" in p else {}),
                iteration=int(p["iteration"]),
                drop_step=None if p["drop_step"] is None else int(p["drop_step"]),
            )
        )
        if p["relearned"]:
            self.emit(
                EventOutput(
                    EventKind.RELEARNED,
                    f"the policy reaches the goal again from {int(p['rewarded'])} of {int(p.get('traces', n))} traces",
                    step,
                    {"drop_step": float(p["drop_step"] or 0)},
                )
            )
