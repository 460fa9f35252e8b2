"""The generic program's learners of continuous observations: tile-coded Sarsa(lambda), which learns
on every step, and the model planner (over the observation, or over motor coordinates of camera
frames fitted after a warm-up of random moves); both measure the observation's ranges first."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.learners.lspi import TabularBasis
from sensorimotor.agent.learners.model_planner import ModelPlanner, plan_job
from sensorimotor.agent.learners.motor_map import MotorMap
from sensorimotor.agent.learners.reach import ReachLearner, state_sensors
from sensorimotor.agent.learners.reach import plan_job as reach_plan_job
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.agent.programs.base import Decision
from sensorimotor.agent.programs.generic_base import GenericBase
from sensorimotor.agent.programs.generic_jobs import motor_job
from sensorimotor.agent.programs.goal import failed, reached
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import Observation


class GenericContinuous(GenericBase):
    """Sarsa(lambda) and the model planner: warm-ups, ranges, learning steps."""

    def _init_sarsa(self, d: int) -> TabularBasis:
        """Tile-coded Sarsa(lambda) over `d` values, laid over the ranges the warm-up measures."""
        prm = self.params
        self.n_states = 0
        coder = TileCoder(np.zeros(d), np.ones(d), prm.tiles, prm.tilings, memory=prm.memory)
        self.sarsa = SarsaLambda(
            coder,
            self.n_actions,
            prm.alpha,
            prm.sarsa_gamma,
            prm.lam,
            prm.epsilon,
            seed=int(self.rng.integers(2**31)),
            trace_cutoff=1e-4,
        )
        # per-value ranges, measured over the first `sarsa_warmup` random steps: a sensor's one
        # declared range may span values of very different scales (position and velocity)
        self._seen_lo, self._seen_hi, self._warm = np.full(d, np.inf), np.full(d, -np.inf), 0
        return TabularBasis(1, self.n_actions)  # unused: LSPI keeps the program's shape uniform

    def _init_planner(self, d: int) -> tuple[TabularBasis, int]:
        """The model planner over `d` observed values, or over motor coordinates (one per action
        value) when there are more than it can grid; returns the basis and the planned dimensions."""
        prm = self.params
        self.n_states = 0
        if self.motor:
            d = self.actions.shape[1]
            self._lo, self._span = np.zeros(d), np.ones(d)
        grid = prm.planner_grid or max(2, min(16, int(np.floor(4096 ** (1.0 / d) + 1e-9))))
        self.planner = ModelPlanner(
            d,
            self.actions,
            self.discrete,
            grid,
            gamma=prm.sarsa_gamma,
            epsilon=prm.planner_epsilon,
            effort=prm.planner_effort,
            seed=int(self.rng.integers(2**31)),
        )
        self._seen_lo, self._seen_hi, self._warm = np.full(d, np.inf), np.full(d, -np.inf), 0
        return TabularBasis(1, self.n_actions), d  # the basis is unused: LSPI keeps the program's shape uniform

    def _init_reach(self) -> tuple[TabularBasis, int]:
        """The reach learner (`agent.learners.reach`) over the world's short continuous vectors (an
        arm's joint angles) alone; returns the basis and the values it plans over."""
        self.n_states = 0
        self._reach_sensors = tuple(state_sensors(self.spec))
        if not self._reach_sensors:
            raise SpecMismatch(
                f"generic program: learner reach needs a sensor of at most 16 continuous values; world "
                f"{self.spec.world_id} has {', '.join(s.name for s in self.spec.sensors)}"
            )
        chosen = [s for s in self.spec.sensors if s.name in self._reach_sensors]
        lo = np.concatenate([np.full(int(np.prod(s.shape)), s.low, float) for s in chosen])
        hi = np.concatenate([np.full(int(np.prod(s.shape)), s.high, float) for s in chosen])
        d = lo.size
        self._lo, self._span = lo, np.where(hi > lo, hi - lo, 1.0)
        self._raw_lo, self._raw_span = self._lo, self._span
        self.planner = ReachLearner(d, self.n_actions, seed=int(self.rng.integers(2**31)))
        self._seen_lo, self._seen_hi, self._warm = np.full(d, np.inf), np.full(d, -np.inf), 0
        return TabularBasis(1, self.n_actions), d  # the basis is unused: LSPI keeps the program's shape uniform

    def _warmup(self, obs: Observation) -> Decision:
        """A random step that measures the range of every value; at its end the tiles are laid
        over those ranges (widened by a tenth of their span on each side)."""
        x = self._flat(obs)
        self._seen_lo, self._seen_hi = np.minimum(self._seen_lo, x), np.maximum(self._seen_hi, x)
        if obs.t == 0:
            self._start_lo, self._start_hi = np.minimum(self._start_lo, x), np.maximum(self._start_hi, x)
        self._warm += 1
        if self._warm >= self.params.sarsa_warmup:
            self._set_ranges()
        if obs.done:
            return Decision(reset=True, start=-1)
        return Decision(tuple(float(v) for v in self.actions[int(self.rng.integers(self.n_actions))]))

    def _set_ranges(self) -> None:
        """Lay the tiles (or the planner's grid) over the ranges the warm-up measured."""
        lo, hi = self._seen_lo, self._seen_hi
        span = np.where(hi > lo, hi - lo, 1.0)
        self._lo, self._span = lo - 0.1 * span, 1.2 * span
        if self.planner is not None:
            # the planner's grid is spent where traces run: over the span of the start states
            # met, widened by half of it on each side (random walks wander far wider); a value
            # the starts do not vary keeps the range the walks showed
            s_lo, s_hi = self._start_lo, self._start_hi
            s_span = s_hi - s_lo
            wide = np.isfinite(s_span) & (s_span > 1e-6 * np.maximum(span, 1e-12))
            self._lo = np.where(wide, s_lo - 0.5 * s_span, self._lo)
            self._span = np.where(wide, 2.0 * s_span, self._span)

    def _motor_warmup(self, obs: Observation) -> Decision:
        """A random move whose transition is kept; after `motor_warmup` of them the motor map is
        fitted off the act path (random moves go on meanwhile), then the planner's ranges are
        measured in its coordinates over the warm-up's frames and starts."""
        assert self.background is not None
        for name, result in self.background.tick():
            if name == "motor":
                self._install_motor(result)
        if self._motor_map is not None:
            return self.act(obs)
        x = self._raw(obs).astype(np.float32)
        if self.background.pending("motor"):
            pass  # random moves while the map is fitted
        elif len(self._motor_data) < self.params.motor_warmup:
            if obs.t > 0 and self._motor_prev is not None:
                self._motor_data.append((self._motor_prev[0], self._motor_prev[1], x))
            elif obs.t == 0 and len(self._motor_starts) < 4 * self.spec.n_starts + 64:
                self._motor_starts.append(x)
        else:
            self.background.submit(
                "motor",
                motor_job,
                before=np.array([t[0] for t in self._motor_data]),
                actions=self._motor_actions[[t[1] for t in self._motor_data]],
                after=np.array([t[2] for t in self._motor_data]),
                starts=np.array(self._motor_starts),
                components=self.params.motor_components,
                seed=int(self.rng.integers(2**31)),
            )
            self._motor_data, self._motor_starts = [], []  # the job holds them now
        self._warm += 1
        if obs.done:
            self._motor_prev = None
            return Decision(reset=True, start=-1)
        a = int(self.rng.integers(self.n_actions))
        self._motor_prev = (x, a)
        return Decision(tuple(float(v) for v in self._motor_actions[a]))

    def _install_motor(self, result: dict[str, Any]) -> None:
        self._motor_map = MotorMap.from_state(result["map"])
        self._seen_lo, self._seen_hi = result["seen_lo"], result["seen_hi"]
        self._start_lo, self._start_hi = result["start_lo"], result["start_hi"]
        self._set_ranges()
        self._warm = max(self._warm, self.params.sarsa_warmup)
        self._motor_prev = None

    def _sarsa_update(self, obs: Observation, px: np.ndarray, pa: int, x: np.ndarray, a: int | None) -> None:
        """The Sarsa(lambda) update for the step that led to `obs` (scaled `x`): a cost of 1, 0 at
        the goal, a failure worth as little as never arriving; a time limit bootstraps from the next
        action `a` (the greedy one when None: the state goes on)."""
        assert self.sarsa is not None
        if self._terminal(obs):
            r = 0.0 if reached(self.goal, obs) else -1.0 / (1.0 - self.sarsa.gamma)
            self.sarsa.learn_one(px, pa, r, x, None)
        else:
            self.sarsa.learn_one(px, pa, -1.0, x, a if a is not None else self.sarsa.greedy(x))

    def _learn_sarsa(self, obs: Observation) -> Decision:
        """One on-policy step of Sarsa(lambda): cost 1 per step, 0 at the goal, a failure as never arriving."""
        assert self.sarsa is not None
        x = self._vector(obs)
        key = self._key(obs)
        if obs.t == 0:
            self.sarsa.begin_episode()
            self._prev_x = None
        terminal = obs.t > 0 and self._terminal(obs)
        a2: int | None = None if terminal or obs.done else self.sarsa.act(x)
        if self._prev_x is not None and obs.t > 0:
            pa = self._prev[1] if self._prev is not None else 0
            if self._prev_key is not None:
                self._note_transition(self._prev_key, pa, obs)
            self._sarsa_update(obs, self._prev_x, pa, x, a2)
            self.new_samples += 1
        self._prev_x, self._prev_key, self._prev = None, None, None
        if self.new_samples >= self.params.embed_every:
            self.new_samples = 0
            self.lspi.iterations += 1  # sweeps of the Sarsa policy count as its iterations
            if self.spec.n_starts >= 2:
                return self._start_sweep(check=False)
            self._no_starts(obs.step)
        if obs.done:
            return Decision(reset=True, start=-1)
        assert a2 is not None
        self._prev_x, self._prev_key, self._prev = x, key, (0, a2)
        return Decision(tuple(float(v) for v in self.actions[a2]))

    def _learn_in_sweep(self, obs: Observation, a: int | None) -> None:
        """Sarsa learns from a sweep of its newest policy too: with optimistic values and no
        exploration noise the greedy actions are its own on-policy actions (the accepted policy's
        check sweeps are not)."""
        assert self.sarsa is not None
        x = self._vector(obs)
        if obs.t > 0 and self._prev_x is not None and self._prev is not None:
            self._sarsa_update(obs, self._prev_x, self._prev[1], x, a)
        if obs.t == 0:
            self.sarsa.begin_episode()
        self._prev_x, self._prev = (x, (0, a)) if a is not None else (None, None)

    def _model_step(self, obs: Observation, a: int | None) -> None:
        """The planner records the transition that led to `obs` (from the previous state and action)
        and remembers this state and the action `a` taken from it (None: the episode ends here);
        every `planner_every` transitions a new plan is started off the act path."""
        assert self.planner is not None and self.background is not None
        x = self._vector(obs)
        if obs.t > 0 and self._prev_x is not None and self._prev is not None:
            outcome = "goal" if reached(self.goal, obs) else "failure" if failed(self.goal, obs) else "continue"
            fresh = self.planner.observe(self._prev_x, self._prev[1], x, outcome)
            self.new_samples += 1
            self._since_plan += 1
            self._fresh = self._fresh or fresh
            due = self._fresh or self._since_plan >= self.params.planner_every
            if due and not self.background.pending("plan"):
                self._fresh = False
                self._since_plan = 0
                job = reach_plan_job if isinstance(self.planner, ReachLearner) else plan_job
                self.background.submit("plan", job, **self.planner.job_args())
        self._prev_x, self._prev = (x, (0, a)) if a is not None else (None, None)

    def _learn_planner(self, obs: Observation) -> Decision:
        """One learning step of the planner: record, plan now and then, act epsilon-greedily."""
        assert self.planner is not None
        if obs.t == 0:
            self._prev_x, self._prev = None, None
        terminal = obs.t > 0 and self._terminal(obs)
        a = None if terminal or obs.done else self.planner.act(self._vector(obs))
        if self._prev_x is not None and self._prev is not None and obs.t > 0 and self._prev_key is not None:
            self._note_transition(self._prev_key, self._prev[1], obs)
        self._model_step(obs, a)
        self._prev_key = self._key(obs) if a is not None else None
        if self.new_samples >= self.params.embed_every:
            self.new_samples = 0
            self.lspi.iterations += 1  # sweeps of the plan count as its iterations
            if self.spec.n_starts >= 2:
                return self._start_sweep(check=False)
            self._no_starts(obs.step)
        if obs.done or a is None:
            return Decision(reset=True, start=-1)
        return Decision(tuple(float(v) for v in self.actions[a]))
