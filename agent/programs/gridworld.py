"""The gridworld program (ch. 5): LSPI toward the goal, then sensorimotor embedding of the greedy
policy's action traces from every start state.

Phases alternate: *explore* (uniformly random actions, samples stored for LSPI) until
`samples_per_iteration` new samples have arrived, one LSPI iteration, then *embed*: run the greedy
policy from each start state in turn (the world resets to it), record the action traces, edit
distances, classical MDS to 2-D, emit Embedding vN. Error falls as LSPI iterates (Fig 5.4).

The LSPI iteration and the distances + MDS run off the act path (`agent.programs.background`):
each is swapped in `learn_lag` acts after it starts, and the program goes on exploring meanwhile
(samples taken while LSPI runs count toward the next iteration).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import classical_mds, trace_distances, update_trace_distances
from sensorimotor.agent.embedding.probabilistic import estimate_distances, relative_change
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, Program
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.agent.snapshot import array_or_none, tuple_or_none
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import option, parse


@dataclass(frozen=True)
class GridworldProgramParams:
    """Hyperparameters of the gridworld program (ch. 5)."""

    samples_per_iteration: int = option(400, "new random-walk samples between LSPI iterations", min=1)
    max_trace: int = option(60, "longest greedy trace recorded from a start state", min=1)
    gamma: float = option(0.9, "LSPI discount", min=0.0, max=1.0)
    ridge: float = option(1e-3, "LSPI ridge regulariser", min=0.0)
    dims: int = option(2, "embedding dimensions (classical MDS)", min=1)
    policy: str = option("lspi", "policy whose traces are embedded", choices=("lspi", "random"))
    substitution_cost: int = option(2, "edit-distance cost of a substitution (2: indel distance)", min=1)
    policy_map: int = option(0, "clusters of a policy map emitted after each embedding (0: none; ch. 9.6)", min=0)
    estimator: str = option(
        "plain",
        "trace distances: one trace per start (plain), or for stochastic worlds the mode of sampled traces "
        "or the mean distance over sampled pairs, sweeping again until the distances settle (ch. 9.4)",
        choices=("plain", "mode", "mean"),
    )
    settle_tol: float = option(0.02, "sampling stops when the distances change by less than this (relative)", min=0.0)
    max_samples: int = option(64, "most sampled traces per start state (estimators mode, mean)", min=2)
    learn_lag: int | None = option(
        None,
        "acts between the start of a background learning job (LSPI, MDS) and the act that uses it "
        "(none: samples_per_iteration, the learning pace of a program without background jobs)",
        min=1,
    )


def lspi_job(n_states: int, n_actions: int, gamma: float, ridge: float, samples: dict[str, Any]) -> dict[str, Any]:
    """One LSPI iteration over a snapshot of the samples (`LSPI.samples`): the new weights and
    their change. A pure function, run off the act path."""
    lspi = LSPI(TabularBasis(n_states, n_actions), gamma=gamma, ridge=ridge, capacity=max(1, len(samples["s"])))
    lspi.restore(samples)
    change = lspi.iterate()
    return {"w": lspi.w, "change": change}


def embed_job(
    traces: list[list[int]],
    last_traces: list[list[int]],
    D: np.ndarray | None,
    dims: int,
    substitution_cost: int,
    estimate: np.ndarray | None = None,
) -> dict[str, Any]:
    """Edit distances between the traces (only rows whose trace changed since `last_traces` are
    recomputed when `D` is theirs), or a settled `estimate` of them (estimators mode/mean), and
    classical MDS to `dims`. A pure function, run off the act path."""
    if estimate is not None:
        D = np.asarray(estimate)
    elif D is None or len(last_traces) != len(traces):
        D = trace_distances(traces, kind="edit", substitution_cost=substitution_cost)
    else:
        changed = [i for i, (a, b) in enumerate(zip(last_traces, traces, strict=False)) if list(a) != list(b)]
        # update_trace_distances writes into D: a copy, a job never changes its arguments (they are
        # the saved state of the job in flight)
        D = update_trace_distances(
            np.array(D, copy=True), traces, changed, kind="edit", substitution_cost=substitution_cost
        )
    mds = classical_mds(D, dims)
    return {"D": D, "coordinates": mds.coordinates, "eigenvalues": mds.eigenvalues}


class GridworldProgram(Program):
    """The gridworld program (ch. 5): LSPI toward the goal, 2-D embedding of greedy traces.

    Built by `make_program` as `GridworldProgram(spec, seed, params=None, **overrides)`; the
    hyperparameters are `GridworldProgramParams`. Needs discrete actions, an integer "state"
    sensor and >= 3 start states.
    """

    name = "gridworld"
    Params = GridworldProgramParams

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: GridworldProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(GridworldProgramParams, overrides, name=self.name, base=params)
        samples_per_iteration, max_trace, gamma, ridge = prm.samples_per_iteration, prm.max_trace, prm.gamma, prm.ridge
        dims, policy, substitution_cost = prm.dims, prm.policy, prm.substitution_cost
        if not spec.action_space.discrete:
            raise SpecMismatch(f"gridworld program needs discrete actions; world {spec.world_id} has a box")
        if spec.n_starts < 3:
            raise SpecMismatch(f"gridworld program needs >= 3 start states, world offers {spec.n_starts}")
        sensor = spec.sensor("state")
        if policy not in ("lspi", "random"):
            raise ValueError("policy must be 'lspi' or 'random'")
        self.n_states = int(sensor.high) + 1
        self.n_actions = spec.action_space.n
        self.samples_per_iteration = samples_per_iteration
        self.max_trace = max_trace
        self.dims = dims
        self.policy = policy
        self.substitution_cost = substitution_cost
        self.lspi = LSPI(TabularBasis(self.n_states, self.n_actions), gamma=gamma, ridge=ridge)
        self.phase = "explore"
        self.new_samples = 0
        self.version = 0
        self._prev: tuple[int, int] | None = None
        self._sweep = StartStateSweep(spec.n_starts, max_trace)
        self._seen: set[tuple[int, int]] = set()
        self._last_traces: list[list[int]] = []
        self._D: np.ndarray | None = None
        # estimators mode/mean: sampled traces per start, the last estimate, consecutive settled rounds
        self._samples: list[list[list[int]]] = []
        self._estimate: np.ndarray | None = None
        self._calm = 0
        self._pending_embedding: dict[str, Any] | None = None  # what the embed job in flight is of
        self.use_background(prm.learn_lag or prm.samples_per_iteration)

    # helpers -----------------------------------------------------------------------------------
    def _state(self, obs: Observation) -> int:
        s = int(obs.tensors["state"].reshape(-1)[0])
        if not 0 <= s < self.n_states:
            raise SpecMismatch(f"state id {s} outside 0..{self.n_states - 1}")
        return s

    def _choose(self, obs: Observation, trace: list[int]) -> int:
        s = self._state(obs)
        if not trace:
            self._seen = set()
        self._seen.add((s, trace[-1] if trace else -1))
        if self.policy == "random":
            return int(self.rng.integers(self.n_actions))
        return self.lspi.greedy(s, trace[-1] if trace else None)

    def _cycle(self, obs: Observation, trace: list[int]) -> bool:
        """The greedy policy is a deterministic function of (state, previous action): a repeat is a
        cycle that never reaches the goal, so the trace ends there."""
        stochastic = self.params.estimator != "plain"  # a repeat is no cycle when the world may slip
        return bool(trace) and self.policy == "lspi" and not stochastic and (self._state(obs), trace[-1]) in self._seen

    def _settled(self) -> bool:
        """Estimators mode/mean: add this sweep's traces as one more sample per start; True once the
        distance estimate has moved by less than `settle_tol` twice running (or at `max_samples`)."""
        traces = self._sweep.traces
        if len(self._samples) != len(traces):
            self._samples = [[] for _ in traces]
        for s, t in zip(self._samples, traces, strict=True):
            s.append(list(t))
        D = estimate_distances(self._samples, self.params.estimator, self.substitution_cost)
        if self._estimate is not None:
            self._calm = self._calm + 1 if relative_change(D, self._estimate) < self.params.settle_tol else 0
        self._estimate = D
        return self._calm >= 2 or len(self._samples[0]) >= self.params.max_samples

    def _finish_embedding(self, step: int) -> None:
        """The sweep is over: start the distances + MDS job; `_embedded` emits its result."""
        traces = [list(t) for t in self._sweep.traces]
        assert self.background is not None
        self.background.submit(
            "embed",
            embed_job,
            traces=traces,
            last_traces=[list(t) for t in self._last_traces],
            D=None if self._D is None else self._D.copy(),
            estimate=None if self.params.estimator == "plain" else self._estimate,
            dims=self.dims,
            substitution_cost=self.substitution_cost,
        )
        self._pending_embedding = {
            "step": step,
            "traces": traces,
            "iteration": 0 if self.policy == "random" else self.lspi.iterations,
            "lspi_iterations": float(self.lspi.iterations),
            "samples": float(self.lspi.n_samples),
            "goal_reached_fraction": self._sweep.rewarded / len(traces),
            "mean_trace_length": float(np.mean([len(t) for t in traces])),
            "samples_per_start": float(len(self._samples[0]) if self._samples else 1),
        }

    def _embedded(self, result: dict[str, Any]) -> None:
        """The distances + MDS job's result swapped in: emit Embedding vN."""
        pending = self._pending_embedding
        assert pending is not None
        self._pending_embedding = None
        self._last_traces, self._D = [list(t) for t in pending["traces"]], np.asarray(result["D"])
        eigenvalues = np.asarray(result["eigenvalues"])
        self.version += 1
        trigger = Trigger.RANDOM_POLICY if self.policy == "random" else Trigger.POLICY_ITERATION
        self.emit(
            EmbeddingOutput(
                trigger=trigger,
                iteration=int(pending["iteration"]),
                ids=tuple(range(len(pending["traces"]))),
                coordinates=np.asarray(result["coordinates"]),
                eigenvalues=tuple(float(e) for e in eigenvalues[: min(10, len(eigenvalues))]),
                step=int(pending["step"]),
                metrics={
                    k: float(pending.get(k, 1.0))  # a job saved before samples_per_start existed
                    for k in (
                        "lspi_iterations",
                        "samples",
                        "goal_reached_fraction",
                        "mean_trace_length",
                        "samples_per_start",
                    )
                },
            )
        )
        if self.params.policy_map and self.policy == "lspi":
            traces = pending["traces"]
            self.emit_policy_map(traces, tuple(range(len(traces))), int(pending["step"]), self.params.policy_map)

    def _iterated(self, result: dict[str, Any], step: int) -> Decision:
        """The LSPI job's weights swapped in: report the iteration and sweep with the new policy."""
        self.lspi.w = np.asarray(result["w"], dtype=np.float64)
        self.lspi.iterations += 1
        self.emit_lspi_iteration(self.lspi, result["change"], step)
        return self._begin_sweep()

    def _begin_sweep(self) -> Decision:
        self._prev = None
        self.phase, self._seen = "embed", set()
        self._sweep = StartStateSweep(self.spec.n_starts, self.max_trace)
        return self._sweep.begin()

    # the program -------------------------------------------------------------------------------
    def act(self, obs: Observation) -> Decision:
        """Explore (storing LSPI samples) or sweep the start states with the greedy policy; LSPI and
        the embedding run in the background and are swapped in `learn_lag` acts after they start."""
        s = self._state(obs)
        if self.phase == "explore" and obs.t > 0 and self._prev is not None:
            ps, pa = self._prev
            self.lspi.learn_one(ps, pa, obs.reward, s, obs.done)
            self.new_samples += 1
        self._prev = None
        assert self.background is not None
        sweep: Decision | None = None
        for name, result in self.background.tick():
            if name == "embed":
                self._embedded(result)
            elif name == "lspi":
                sweep = self._iterated(result, obs.step)
        if sweep is not None:
            return sweep
        if self.phase == "explore":
            # the embed job of the last sweep may still run: it is due before the next sweep ends
            busy = self.background.pending("lspi" if self.policy == "lspi" else "embed")
            if self.new_samples >= self.samples_per_iteration and not busy:
                self.new_samples = 0
                if self.policy != "lspi":
                    return self._begin_sweep()
                lspi = self.lspi
                self.background.submit(
                    "lspi",
                    lspi_job,
                    n_states=self.n_states,
                    n_actions=self.n_actions,
                    gamma=lspi.gamma,
                    ridge=lspi.ridge,
                    samples=lspi.samples(),
                )
            if obs.done:
                return Decision(reset=True, start=-1)
            a = int(self.rng.integers(self.n_actions))
            self._prev = (s, a)
            return Decision((float(a),))

        # phase == "embed": run the greedy policy from every start state
        dec = self._sweep.step(obs, self._choose, self._cycle)
        if self._sweep.finished:
            if self.params.estimator != "plain" and not self._settled():
                self._sweep, self._seen = StartStateSweep(self.spec.n_starts, self.max_trace), set()
                return self._sweep.begin()  # sample every start state once more
            self._finish_embedding(obs.step)
            self._samples, self._estimate, self._calm = [], None, 0
            self.phase = "explore"
        return dec

    # saved state ---------------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        """The base snapshot plus LSPI, phase, sweep and traces (see `agent.programs.base`)."""
        return {
            **super().state(),
            "lspi": self.lspi.state(),
            "phase": self.phase,
            "new_samples": self.new_samples,
            "version": self.version,
            "prev": None if self._prev is None else list(self._prev),
            "sweep": self._sweep.state(),
            "seen": sorted(list(p) for p in self._seen),
            "last_traces": [list(t) for t in self._last_traces],
            "D": array_or_none(self._D),
            "samples": [[list(t) for t in s] for s in self._samples],
            "estimate": array_or_none(self._estimate),
            "calm": self._calm,
            "pending_embedding": None if self._pending_embedding is None else dict(self._pending_embedding),
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a program built with the same spec and params."""
        super().restore(state)
        self.lspi.restore(state["lspi"])
        self.phase, self.new_samples, self.version = (
            str(state["phase"]),
            int(state["new_samples"]),
            int(state["version"]),
        )
        self._prev = tuple_or_none(state["prev"])
        self._sweep = StartStateSweep(self.spec.n_starts, self.max_trace)
        self._sweep.restore(state["sweep"])
        self._seen = {(int(s), int(a)) for s, a in state["seen"]}
        self._last_traces = [[int(a) for a in t] for t in state["last_traces"]]
        self._D = array_or_none(state["D"])
        self._samples = [[[int(a) for a in t] for t in s] for s in state.get("samples", [])]
        self._estimate = array_or_none(state.get("estimate"))
        self._calm = int(state.get("calm", 0))
        pending = state.get("pending_embedding")
        self._pending_embedding = None if pending is None else dict(pending)

    def world_restarted(self) -> None:
        """Drop the pending sample and restart the trace in progress."""
        self._prev = None
        self._sweep.interrupted()
        self._seen = set()
