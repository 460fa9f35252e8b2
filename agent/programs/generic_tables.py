"""The generic program's table learners and LSPI: the model learner's steps (count, plan off the
act path, explore optimistically, sweep when the plan is worth it) and LSPI's (random exploration,
refit + policy iteration off the act path), which also carries every other learner's sweep steps."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.learners.base import TableLearner
from sensorimotor.agent.learners.lspi import TabularBasis
from sensorimotor.agent.learners.lspi_features import RBFFeatures, basis_state, iterate_job, set_basis
from sensorimotor.agent.learners.tabular_model import TabularModel
from sensorimotor.agent.programs.base import Decision
from sensorimotor.agent.programs.generic_base import GenericBase
from sensorimotor.agent.programs.goal import failed, reached
from sensorimotor.protocol.messages import Observation


class GenericTables(GenericBase):
    """Tables of states (the model learner, tabular LSPI) and LSPI over features."""

    def _init_table(self, table_class: type[TableLearner] | None, ids: bool) -> TabularBasis:
        """A table of state ids (`ids`) or of distinct observations; the table learner over it."""
        prm, s0 = self.params, self.spec.sensors[0]
        if ids:
            self.low, self.n_states = int(s0.low), int(s0.high - s0.low) + 1
        else:
            self.low, self.n_states = 0, prm.table_size
        if table_class is TabularModel:
            self.model = TabularModel(
                self.n_states,
                self.n_actions,
                gamma=prm.model_gamma,
                known_stochastic=prm.model_known,
                epsilon=prm.model_epsilon,
                seed=int(self.rng.integers(2**31)),
            )
        elif table_class is not None:
            self.model = table_class(self.n_states, self.n_actions, seed=int(self.rng.integers(2**31)))  # type: ignore[call-arg]
        return TabularBasis(self.n_states, self.n_actions)

    def _init_lspi(self, d: int) -> RBFFeatures:
        """LSPI over features: `d` observed values randomly projected to at most `projection`, kept
        in a store (the samples' states) and a reservoir (to fit PCA + RBF centres on)."""
        prm = self.params
        self.n_states = 0
        self.dim = min(d, prm.projection)
        proj_rng = np.random.default_rng([self.seed, 6])  # fixed per seed: stored vectors stay comparable
        self._proj = proj_rng.standard_normal((d, self.dim)) / np.sqrt(self.dim) if d > prm.projection else None
        self._store = np.zeros((2 * prm.max_samples + 2, self.dim), dtype=np.float32)
        self._reservoir = np.zeros((prm.reservoir, self.dim), dtype=np.float32)
        self._store_hist = np.zeros(self._store.shape[0], dtype=np.int16)
        self._rbf = self._new_rbf()
        return self._rbf

    def _iterate(self) -> None:
        """Start the refit + policy iteration job on a snapshot; `_iterated` swaps its result in."""
        prm = self.params
        refit = None
        if not self.tabular and self._seen >= 2 * self._fitted_at:
            # refit while experience still doubles; later fits would only reshuffle a settled basis
            n = min(self._seen, self._reservoir.shape[0])
            refit = self._reservoir[:n].astype(np.float64)
            self._fitted_at = self._seen
        assert self.background is not None
        n_hist = 1 if self.tabular else self._rbf.n_hist
        self.background.submit(
            "lspi",
            iterate_job,
            n_states=self.n_states if self.tabular else 0,
            n_actions=self.n_actions,
            gamma=self.lspi.gamma,
            ridge=self.lspi.ridge,
            capacity=self.lspi.capacity,
            iterations=prm.lspi_iterations,
            samples=self.lspi.samples(),
            store=None if self.tabular else self._store.copy(),
            basis=None if self.tabular else basis_state(self._rbf),
            refit=refit,
            fit={"components": prm.components, "centres": prm.centres, "width": prm.width, "n_hist": n_hist},
            tie_tolerance=self.lspi.tie_tolerance,
            hist=self._store_hist.copy() if n_hist > 1 else None,
        )

    def _iterated(self, result: dict[str, Any], step: int) -> None:
        """The job's basis and weights swapped in; report the policy iteration."""
        if result["basis"] is not None:
            set_basis(self._rbf, result["basis"])
        self.lspi.w = np.asarray(result["w"], dtype=np.float64)
        self.lspi.iterations += int(result["iterations"])
        self.emit_lspi_iteration(self.lspi, result["change"], step)

    def _act_model(self, obs: Observation) -> Decision:
        """The model learner: count every transition (in sweeps too: a model learns from whatever
        chose the action), plan off the act path when new actions became known or after
        `samples_per_iteration` transitions (then the plan's greedy policy is swept), explore
        optimistically between sweeps."""
        assert self.model is not None and self.background is not None
        sweep = False
        for name, result in self.background.tick():
            if name == "embed":
                self._embedded(result)
            elif name == "model":
                self.model.install(result)
                # nothing new learned since the plan was asked for, and nothing left untried: the
                # plan is exact for the body as it is (generic_sweeps: the best a changed body allows)
                self._plan_exact = self.model.complete() and not self._fresh
                sweep = (self._plan_for_sweep and self._model_sweep_due(obs.step)) or sweep
        s = self._table_id(obs)
        if obs.t > 0 and self._prev is not None:
            ps, pa = self._prev
            if self._prev_key is not None:
                self._note_transition(self._prev_key, pa, obs)
            outcome = "goal" if reached(self.goal, obs) else "failure" if failed(self.goal, obs) else "continue"
            self._fresh = self.model.learn_one(ps, pa, s, outcome) or self._fresh
            self._since_plan += 1
            if self.phase == "explore":  # a sweep's steps are counted by the model, not toward the next sweep
                self.new_samples += 1
        self._prev, self._prev_key = None, None
        if self.phase == "explore":
            if sweep and self.spec.n_starts >= 2:
                self.lspi.iterations += 1  # sweeps of the plan count as its iterations
                return self._start_sweep(check=False)
            if not self.background.pending("model"):
                due = self.new_samples >= self.params.samples_per_iteration
                if due or (self._fresh and self._since_plan >= self.params.model_every):
                    self.background.submit("model", type(self.model).plan_job, **self.model.job_args())
                    self._fresh, self._since_plan, self._plan_for_sweep = False, 0, due
                    if due:
                        self.new_samples = 0
                        self._no_starts(obs.step)
            if obs.done:
                return Decision(reset=True, start=-1)
            a = self.model.act(s)
            self._prev, self._prev_key = (s, a), self._key(obs)
            return Decision(tuple(float(v) for v in self.actions[a]))
        return self._model_sweep_act(obs, s)

    def _model_sweep_due(self, step: int) -> bool:
        """Whether the plan just installed is worth a sweep: once watched always (the detector's
        sweeps); before, when the model is complete (every action of every state met was tried
        `known` times) and its greedy policy is not the one swept last, or when exploration has
        gone on for 20 plans' worth of transitions. A complete model whose policy is unchanged in a
        stochastic world is one more round that the accepted policy held (`_hold`)."""
        assert self.model is not None
        self._since_sweep += self.params.samples_per_iteration
        if self._watching:
            return True
        complete = self.model.complete()
        q = np.asarray(self.model.q)
        top = q.max(axis=1, keepdims=True)
        met = np.arange(q.shape[0]) < max(len(self._ids), 0 if self.keyed else q.shape[0])
        policy = np.where(met, (q >= top - self.lspi.tie_tolerance * np.abs(top) - 1e-12).argmax(axis=1), -1)
        changed = self._swept_policy is None or not np.array_equal(policy, self._swept_policy)
        if complete and changed or self._since_sweep >= 20 * self.params.samples_per_iteration:
            self._swept_policy, self._since_sweep = policy, 0
            return True
        if complete and self.stochastic and self._best is not None:
            self._hold(step)
        return False

    def _model_sweep_act(self, obs: Observation, s: int) -> Decision:
        """A sweep's step, whose transition the model counts as well."""
        dec = self._sweep_act(obs)
        if self.phase == "embed" and not dec.reset and not obs.done:
            self._prev, self._prev_key = (s, self._last_choice), self._key(obs)
        return dec

    def _act_lspi(self, obs: Observation) -> Decision:
        """LSPI's step (a random action while exploring; an iteration off the act path every
        `samples_per_iteration` samples, then a sweep), and every learner's sweep step but the
        model learner's: background results swapped in first."""
        assert self.background is not None
        s: int | None = None
        if self.phase == "explore":
            s = self._state(obs)
            if obs.t > 0 and self._prev is not None:
                ps, pa = self._prev
                if self._prev_key is not None:
                    self._note_transition(self._prev_key, pa, obs)
                self.lspi.learn_one(ps, pa, self._goal_reward(obs), s, self._terminal(obs))
                self.new_samples += 1
            self._prev, self._prev_key = None, None
        iterated = False
        for name, result in self.background.tick():
            if name == "embed":
                self._embedded(result)
            elif name == "lspi":
                self._iterated(result, obs.step)
                iterated = True
            elif name == "plan" and self.planner is not None:
                self.planner.install(result)
        if self.phase == "explore":
            assert s is not None
            if iterated and self.spec.n_starts >= 2:
                return self._start_sweep(check=False)
            if self.new_samples >= self.params.samples_per_iteration and not self.background.pending("lspi"):
                self.new_samples = 0
                self._iterate()
                self._no_starts(obs.step)
            if obs.done:
                return Decision(reset=True, start=-1)
            a = int(self.rng.integers(self.n_actions))
            self._prev = (s, a)
            self._prev_key = self._key(obs)
            return Decision(tuple(float(v) for v in self.actions[a]))
        return self._sweep_act(obs)
