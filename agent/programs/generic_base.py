"""The generic program's shared state and its view of observations (`agent.programs.generic`).

The program is one object whose parts live in one module per job: this base (what every part
reads, observations as vectors, table rows and keys, transitions watched for chance),
`generic_sweeps` (sweeps and acceptance), `generic_publish` (embeddings), `generic_tables` (the
model learner, tabular LSPI and LSPI over features), `generic_continuous` (Sarsa(lambda) and the
model planner) and `generic_state` (checkpoints). The hooks at the end are what one part calls in
another.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from sensorimotor.agent.embedding.rotation_frames import Rotations
from sensorimotor.agent.learners.base import TableLearner
from sensorimotor.agent.learners.lspi import LSPI
from sensorimotor.agent.learners.lspi_features import RBFFeatures, set_basis
from sensorimotor.agent.learners.model_planner import ModelPlanner
from sensorimotor.agent.learners.motor_map import MotorMap
from sensorimotor.agent.learners.reach import ReachLearner
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda
from sensorimotor.agent.programs.base import Decision, EventOutput, Program
from sensorimotor.agent.programs.generic_params import GenericProgramParams
from sensorimotor.agent.programs.goal import failed, reached
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation


class GenericBase(Program):
    """The state the generic program's parts share (set up by `GenericProgram.__init__` and each
    part's `_init_*`), its observation helpers, and the hooks the parts implement."""

    #: transitions remembered to tell a stochastic world (bounded memory)
    TRANSITIONS = 50_000
    params: GenericProgramParams
    # what the world is and how the program acts in it
    actions: np.ndarray
    _motor_actions: np.ndarray
    n_actions: int
    discrete: bool
    goal: str
    estimator: str
    samples: int
    max_trace: int
    dims: int
    # the learner
    learner: str
    tabular: bool
    keyed: bool
    motor: bool
    lspi: LSPI
    model: TableLearner | None
    sarsa: SarsaLambda | None
    planner: ModelPlanner | ReachLearner | None
    _reach_sensors: tuple[str, ...] = ()  # reach: the short vectors it plans over (the other sensors unread)
    _tie_tolerance: float
    # observations -> states
    low: int
    n_states: int
    dim: int
    _ids: dict[bytes, int]
    _said_table_full: bool
    _transitions: dict[tuple[bytes, int], tuple[bytes, bytes | None]]
    _rotations: Rotations | None
    _lo: np.ndarray
    _span: np.ndarray
    _raw_lo: np.ndarray
    _raw_span: np.ndarray
    _seen_lo: np.ndarray
    _seen_hi: np.ndarray
    _start_lo: np.ndarray
    _start_hi: np.ndarray
    _warm: int
    _proj: np.ndarray | None
    _store: np.ndarray
    _reservoir: np.ndarray
    _rbf: RBFFeatures
    _store_hist: np.ndarray  # lspi: each stored row's history value (generic_relearn; 0: none)
    _history: bool  # the state is the observation with the action sent last (generic_relearn)
    _hist: int  # that action (-1: none yet this episode)
    _next_id: int
    _seen: int
    _fitted_at: int
    _motor_map: MotorMap | None
    _motor_data: list[tuple[np.ndarray, int, np.ndarray]]
    _motor_starts: list[np.ndarray]
    _motor_prev: tuple[np.ndarray, int] | None
    # learning
    phase: str
    new_samples: int
    relearn_at: int | None
    _prev: tuple[int, int] | None
    _prev_x: np.ndarray | None
    _prev_key: bytes | None
    _said_no_starts: bool
    _since_plan: int
    _fresh: bool
    _plan_exact: bool
    _swept_policy: np.ndarray | None
    _since_sweep: int
    _plan_for_sweep: bool
    # sweeps and acceptance (`generic_sweeps`)
    _sweep: StartStateSweep
    _visited: set[tuple[bytes, int]]
    _perf: list[float]
    _watching: bool
    _held: int
    _accepted: np.ndarray | None
    _best: tuple[float, float] | None
    _best_disparity: float | None
    _checking: bool
    _sweep_w: np.ndarray | None
    _accepted_basis: dict[str, Any] | None
    _sweep_rbf: RBFFeatures | None
    _sweep_basis: dict[str, Any] | None
    _accepted_traces: list[list[int]] | None
    _accepted_reached: list[bool] | None
    _candidate_traces: list[list[int]] | None
    _published: list[list[int]] | None
    _relearn_unconfirmed: int
    _diverged: bool
    _unfed: list[float]
    _start_scores: list[float]
    _start_fair: bool
    _trace_from: np.ndarray | None
    _ends: dict[int, tuple[np.ndarray, np.ndarray]]
    #: the move axes' gains of the last sweep embedded (`box_moves.axis_gains`; None: the moves' units)
    _gains: np.ndarray | None = None
    #: start states met before the first sweep (`generic_continuous.FEW_STARTS`): the planner's
    #: grid spans theirs
    _starts_met: int = 0
    #: the planner's transitions before the first sweep, unscaled (generic_continuous._hold_start)
    _early: list[tuple[np.ndarray, int, np.ndarray, str]]
    _pending_embedding: dict[str, Any] | None
    _last_choice: int
    retried_total: int
    _chance_seen: bool  # outcomes alternated while watched: the accepted policy is checked first
    _regauge: bool  # `distance=auto` changed after the policy was watched (generic_continuous)

    @property
    def stochastic(self) -> bool:
        """Whether the world was seen to be stochastic (traces are then sampled, `samples` per start)."""
        return getattr(self, "_stochastic", False)

    @stochastic.setter
    def stochastic(self, value: bool) -> None:
        if bool(value) != self.stochastic:
            # trace scores change their measure (absolute vs relative to the accepted traces): the
            # detector's reference must be learned afresh, or the change of scale reads as a drop
            self.rebase_performance()
            self._held = 0
            best = getattr(self, "_best", None)
            if not value and (best is None or best[0] < self.params.watch_after):
                self._watching = False  # watched only as settled: a deterministic world asks for more
        self._stochastic = bool(value)

    def _new_sweep(self, n: int | None = None, repeats: int | None = None) -> StartStateSweep:
        """A sweep of every start state, `samples` traces each in a stochastic world (or `n` traces,
        `repeats` per start: the shape of a saved sweep, which the world may since have changed)."""
        k = repeats if repeats is not None else self.samples if self.stochastic else 1
        n = n if n is not None else self.spec.n_starts * k
        return StartStateSweep(n, self.max_trace, goal=lambda o: reached(self.goal, o), repeats=k)

    def _vector(self, obs: Observation) -> np.ndarray:
        if self.motor:
            assert self._motor_map is not None
            return (self._motor_map(self._raw(obs)) - self._lo) / self._span
        x = (self._flat(obs) - self._lo) / self._span
        if self.learner == "lspi" and self._proj is not None:
            return x @ self._proj
        return x

    def _raw(self, obs: Observation) -> np.ndarray:
        """The observation scaled by the sensors' declared ranges (what the motor map takes)."""
        return (self._flat(obs) - self._raw_lo) / self._raw_span

    def _flat(self, obs: Observation) -> np.ndarray:
        parts = []
        for s in self.spec.sensors:
            if self._reach_sensors and s.name not in self._reach_sensors:
                continue
            a = obs.tensors.get(s.name)
            if a is None:
                raise SpecMismatch(f"observation step {obs.step} has no tensor {s.name!r}")
            parts.append(np.asarray(a, dtype=np.float64).reshape(-1))
        return np.concatenate(parts)

    def _table_id(self, obs: Observation) -> int:
        """A table row: the state id, or the row of this distinct observation (new rows as met)."""
        if not self.keyed:
            s = int(np.asarray(obs.tensors[self.spec.sensors[0].name]).reshape(-1)[0]) - self.low
            if not 0 <= s < self.n_states:
                raise SpecMismatch(f"state id {s + self.low} outside the declared range")
            return s
        key = self._key(obs)
        i = self._ids.get(key)
        if i is None:
            i = len(self._ids)
            if i >= self.n_states:
                if not self._said_table_full:
                    self._said_table_full = True
                    self.emit(
                        EventOutput(
                            EventKind.POLICY_ITERATION,
                            f"more than {self.n_states} distinct observations: later ones share the last row "
                            "(raise generic.table_size)",
                            obs.step,
                            reason="table_full",
                        )
                    )
                return self.n_states - 1
            self._ids[key] = i
        return i

    def _key(self, obs: Observation) -> bytes:
        """The observation's bytes; a digest of them when longer than 64 (a camera frame: the
        transitions remembered would otherwise hold two frames each)."""
        key = b"".join(np.ascontiguousarray(obs.tensors[s.name]).tobytes() for s in self.spec.sensors)
        return key if len(key) <= 64 else hashlib.blake2b(key, digest_size=16).digest()

    def _state(self, obs: Observation) -> int:
        """The LSPI state of an observation met while exploring: a table row, or a new store id."""
        if self.tabular:
            return self._table_id(obs)
        x = self._vector(obs)
        i = self._next_id
        self._next_id += 1
        self._store[i % self._store.shape[0]] = x
        self._store_hist[i % self._store.shape[0]] = self._hist_value()
        self._rbf.forget(i % self._store.shape[0])
        self._seen += 1  # reservoir sampling: every observation seen is equally likely to be kept
        r = self._reservoir.shape[0]
        if self._seen <= r:
            self._reservoir[self._seen - 1] = x
        else:
            j = int(self.rng.integers(self._seen))
            if j < r:
                self._reservoir[j] = x
        return i

    def _weights(self) -> np.ndarray:
        if self.model is not None:
            return self.model.q.ravel()
        if self.planner is not None:
            return self.planner.w
        return self.sarsa.w if self.sarsa is not None else self.lspi.w

    def _q(self, obs: Observation, w: np.ndarray | None = None) -> np.ndarray:
        if self.planner is not None:
            return self.planner.q(self._vector(obs), w)
        if self.sarsa is not None:
            tiles = self.sarsa.coder.active(self._vector(obs))
            return (self.sarsa.w if w is None else w)[:, tiles].sum(axis=1)
        w = self.lspi.w if w is None else w
        if self.tabular:
            return np.asarray(w).reshape(self.n_states, self.n_actions)[self._table_id(obs)]
        rbf = self._sweep_rbf if self._sweep_rbf is not None else self._rbf
        return rbf.q(w, self._vector(obs), self._hist_value())

    def _hist_value(self) -> int:
        """The history value of the observation at hand: the action sent last plus one (0: none, or
        not remembering)."""
        return self._hist + 1 if self._history else 0

    def _goal_reward(self, obs: Observation) -> float:
        return 1.0 if reached(self.goal, obs) else 0.0

    def _terminal(self, obs: Observation) -> bool:
        return reached(self.goal, obs) or failed(self.goal, obs)

    def _note_transition(self, key: bytes, a: int, obs: Observation) -> None:
        """Remember where (observation, action) led. Outcomes that alternate (the first comes back
        after another, or a third appears) mean a stochastic world; one change that stays is a body
        change, for the drop detector."""
        if self.stochastic or obs.t == 0:
            return
        nxt = self._key(obs)
        seen = self._transitions.get((key, a))
        if seen is None:
            if len(self._transitions) < self.TRANSITIONS:
                self._transitions[(key, a)] = (nxt, None)
            return
        first, other = seen
        if nxt == first and other is None:
            return
        if other is None:
            # a second outcome may be a body change rather than chance: wait until the first one
            # comes back (or a third appears)
            self._transitions[(key, a)] = (first, nxt)
            return
        if nxt == other:
            return
        self._transitions.clear()
        if self._watching and self._accepted is not None:
            # outcomes alternate in a world watched as deterministic: its body changed (an action
            # that acts late, a lesion that makes states look alike), or distinct states looked alike
            # all along. The accepted policy is swept once more, scored as before (`_swept`): a
            # changed body misses goals it reached, which the detector sees as a drop; an unchanged
            # one reaches them all, and the world is taken as stochastic from there
            self._chance_seen = True
            return
        self._become_stochastic(obs.step)

    def _become_stochastic(self, step: int) -> None:
        """Traces are sampled from here (`samples` per start), and the learner plans for chance."""
        self.stochastic = True
        self._transitions.clear()
        self._plan_for_chance()
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"the world is stochastic (one observation and action led to different observations): "
                f"{self.samples} traces per start state, {self.estimator} estimator",
                step,
                reason="stochastic",
            )
        )

    def _plan_for_chance(self) -> None:
        """The tabular learner in a stochastic world learns the expected outcome over a long horizon
        (`stochastic_gamma`) from more of its experience (`stochastic_samples`); as given otherwise."""
        if self.model is not None:
            self.model.set_stochastic(self.stochastic)
            return
        if self.tabular:
            chance = self.stochastic
            self.lspi.gamma = g = self.params.stochastic_gamma if chance else self.params.gamma
            # near-ties: a quarter of the gap 1 - gamma^2 between an optimal action and a detour
            # (0.05 at the default 0.9; at 0.99 a detour is within 2 % and would pass for a tie)
            self.lspi.tie_tolerance = 0.25 * (1.0 - g * g) if chance else self._tie_tolerance
            self.lspi.capacity = cap = self.params.stochastic_samples if chance else self.params.max_samples
            smp = self.lspi.samples()
            if len(smp["s"]) > cap:  # back to fewer: the newest are kept
                self.lspi.restore(
                    {k: v[-cap:] if k in ("s", "a", "r", "s_next", "done") else v for k, v in smp.items()}
                )

    def _no_starts(self, step: int) -> None:
        if self.spec.n_starts < 2 and not self._said_no_starts:
            self._said_no_starts = True
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    f"world declares {self.spec.n_starts} start states: it is learned, not embedded",
                    step,
                    reason="no_start_states",
                )
            )

    def _rbf_of(self, basis: dict[str, Any] | None) -> RBFFeatures | None:
        """An RBF basis in the state `basis` (None for None)."""
        if basis is None:
            return None
        rbf = self._new_rbf()
        set_basis(rbf, basis)
        return rbf

    def _new_rbf(self) -> RBFFeatures:
        """An (unfitted) RBF basis over the store, of the observation with the action sent last
        when the program remembers it."""
        if self._history:
            return RBFFeatures(self._store, self.n_actions, self.params.centres, self._store_hist, self.n_actions + 1)
        return RBFFeatures(self._store, self.n_actions, self.params.centres)

    def _accepted_rbf(self) -> RBFFeatures | None:
        """The RBF basis the accepted weights are over, when it is not the current one."""
        return self._rbf_of(self._accepted_basis)

    # hooks: implemented by the part named ---------------------------------------------------------
    def _start_sweep(self, check: bool) -> Decision:  # generic_sweeps
        raise NotImplementedError

    def _sweep_act(self, obs: Observation) -> Decision:  # generic_sweeps
        raise NotImplementedError

    def _hold(self, step: int) -> None:  # generic_sweeps
        raise NotImplementedError

    def _embed(
        self, step: int, relearned: bool, k: int, of: tuple[list[list[int]], list[bool]] | None = None
    ) -> None:  # generic_publish
        raise NotImplementedError

    def _embedded(self, result: dict[str, Any]) -> None:  # generic_publish
        raise NotImplementedError

    def _model_step(self, obs: Observation, a: int | None) -> None:  # generic_continuous
        raise NotImplementedError

    def _trace_distance(self, step: int | None = None) -> str:  # generic_continuous
        raise NotImplementedError

    def moves_state(self) -> dict[str, Any]:  # generic_continuous
        raise NotImplementedError

    def _measure_gains(self, step: int, distance: str) -> None:  # generic_continuous
        raise NotImplementedError

    def restore_moves(self, state: dict[str, Any] | None) -> None:  # generic_continuous
        raise NotImplementedError

    def _learn_in_sweep(self, obs: Observation, a: int | None) -> None:  # generic_continuous
        raise NotImplementedError
