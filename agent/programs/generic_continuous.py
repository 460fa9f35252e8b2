"""The generic program's learners of continuous observations: tile-coded Sarsa(lambda), which learns
on every step, and the model planner (over the observation, or over motor coordinates of camera
frames fitted after a warm-up of random moves); both measure the observation's ranges first. The
planner's warm-up also measures how faithfully the body carries out its moves, and its sweeps
whether the moves add up (`agent.programs.box_moves`: the move size and trace distance it picks)."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.learners.lspi import TabularBasis
from sensorimotor.agent.learners.model_planner import ModelPlanner, plan_job
from sensorimotor.agent.learners.motor_map import MotorMap
from sensorimotor.agent.learners.reach import ReachLearner, state_sensors
from sensorimotor.agent.learners.reach import plan_job as reach_plan_job
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.agent.programs.base import Decision, EventOutput
from sensorimotor.agent.programs.box_moves import (
    SPILLS,
    axis_gains,
    move_scale,
    moves_add_up,
    probe_half_moves,
    spill,
    spill_scale,
    unexplained,
)
from sensorimotor.agent.programs.generic_base import GenericBase
from sensorimotor.agent.programs.generic_jobs import action_table, motor_job
from sensorimotor.agent.programs.goal import failed, reached
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation

#: a start nearer the planner's grid edge than this share of it (the grid spans the starts met with
#: half their span on either side: a quarter of that margin) is not held, and the grid is laid again
HOLD = 0.125
#: over camera frames, the starts met from which on their range is trusted: the motor map places a
#: start with its own error, so after that many a start near the edge is the map's noise, not a
#: start the range missed (over the observation itself, a start is where it is, and always counts)
FEW_STARTS = 8


class GenericContinuous(GenericBase):
    """Sarsa(lambda) and the model planner: warm-ups, ranges, learning steps."""

    #: the planner's warm-up, `action_scale=0`: its (move sent, displacement, the move before it in
    #: the episode) steps, the step in progress, what a whole move measured (share unexplained; over
    #: camera frames its spill), and the half moves it probes (None: no probe)
    _probe: list[tuple[np.ndarray, np.ndarray, np.ndarray | None]] | None = None
    _probe_prev: tuple[np.ndarray, np.ndarray, np.ndarray | None] | None = None
    _probe_whole: float | None = None
    _half_actions: np.ndarray | None = None
    #: `distance=auto` resolved (None: not yet; a box planner's sweeps decide, see `_trace_distance`)
    _distance: str | None = None
    _regauge = False  # the distance changed after the policy was watched: its map is published again
    _distance_now: str = "padded"
    #: the fraction of each bound the plan's moves span now
    _scale: float = 1.0

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
        self.planner = self._new_planner(d)
        self._scale = prm.action_scale or 1.0
        if prm.action_scale == 0 and not self.discrete and prm.sarsa_warmup >= 4:
            self._probe, self._half_actions = [], action_table(self.spec, prm.action_levels, 0.5)
        self._seen_lo, self._seen_hi, self._warm = np.full(d, np.inf), np.full(d, -np.inf), 0
        return TabularBasis(1, self.n_actions), d  # the basis is unused: LSPI keeps the program's shape uniform

    def _new_planner(self, d: int, seed: int | None = None) -> ModelPlanner:
        prm = self.params
        grid = prm.planner_grid or max(2, min(16, int(np.floor(4096 ** (1.0 / d) + 1e-9))))
        return ModelPlanner(
            d,
            self.actions,
            self.discrete,
            grid,
            gamma=prm.sarsa_gamma,
            epsilon=prm.planner_epsilon,
            effort=prm.planner_effort,
            seed=int(self.rng.integers(2**31)) if seed is None else seed,
        )

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
        over those ranges (widened by a tenth of their span on each side). The planner's, with
        `action_scale=0`: whole moves, then half moves if a whole one was not carried out faithfully
        (`box_moves`), each step kept to measure it."""
        x = self._motor_map(self._raw(obs)) if self._motor_map is not None else self._flat(obs)
        self._seen_lo, self._seen_hi = np.minimum(self._seen_lo, x), np.maximum(self._seen_hi, x)
        if obs.t == 0:
            self._start_lo, self._start_hi = np.minimum(self._start_lo, x), np.maximum(self._start_hi, x)
            self._starts_met += 1
        prev = self._probe_prev if obs.t > 0 else None
        if self._probe is not None and prev is not None:
            self._probe.append((prev[1], x - prev[0], prev[2]))
        self._warm += 1
        if self._probe is not None and self._warm == self.params.sarsa_warmup // 2:
            self._probe_whole = self._probe_measure()
            self._probe = []
            if not self._probe_lags(self._probe_whole):  # whole moves followed: no half moves to try
                self._choose_scale(obs.step)
        if self._warm >= self.params.sarsa_warmup:
            self._set_ranges()
            if self._probe is not None:
                self._choose_scale(obs.step)
        if obs.done:
            self._probe_prev = None
            return Decision(reset=True, start=-1)
        probing_half = self._probe is not None and self._probe_whole is not None and self._half_actions is not None
        table = self._half_actions if probing_half and self._half_actions is not None else self.actions
        move = table[int(self.rng.integers(self.n_actions))]
        self._probe_prev = (x, move, None if prev is None else prev[1]) if self._probe is not None else None
        return Decision(tuple(float(v) for v in move))

    def _probe_measure(self) -> float | None:
        """What the probe's steps so far say of the moves sent: the share a linear fit leaves
        unexplained, or over camera frames (the motor map's coordinates) how much of a move spills
        into the next step (`box_moves`: the map's own error would read as unfaithful small moves)."""
        probe = self._probe or []
        d = self.actions.shape[1]
        if self.motor:
            rows = [p for p in probe if p[2] is not None]
            moves, before = (np.array([p[i] for p in rows]).reshape(-1, d) for i in (0, 2))
            return spill(moves, before, np.array([p[1] for p in rows]).reshape(len(rows), -1))
        return unexplained(
            np.array([p[0] for p in probe]).reshape(-1, d), np.array([p[1] for p in probe]).reshape(len(probe), -1)
        )

    def _probe_lags(self, whole: float | None) -> bool:
        """Whether a whole move was carried out unfaithfully, so half moves are tried."""
        return whole is not None and whole > SPILLS if self.motor else probe_half_moves(whole)

    def _choose_scale(self, step: int) -> None:
        """The warm-up's end (`action_scale=0`): the plan takes half moves when the body carried
        them out more faithfully than whole ones (`box_moves.move_scale`, over camera frames
        `box_moves.spill_scale`); said in an event."""
        half = self._probe_measure() if self._probe_lags(self._probe_whole) else None
        scale = spill_scale(self._probe_whole, half) if self.motor else move_scale(self._probe_whole, half)
        self._probe, self._probe_prev = None, None
        self._set_scale(scale)
        w = self._probe_whole
        if self.motor:
            what = f"in the motor coordinates a whole move spilled {'?' if w is None else f'{w:.2g}'} of itself into"
            what += " the next step" + ("" if half is None else f", a half move {half:.2g}")
        else:
            what = f"a linear fit of the moves sent left {'?' if w is None else f'{w:.0%}'} of a whole move's step"
            what += " unexplained" + ("" if half is None else f" and {half:.0%} of a half move's")
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                what + f": the plan takes {'half' if scale != 1.0 else 'whole'} moves",
                step,
                reason="move_scale",
            )
        )

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
                self._starts_met += 1
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
        # `action_scale=0`: the warm-up's probe of whole then half moves runs on in the motor
        # coordinates (frames say nothing of a move until they are mapped)
        self._warm = 0 if self._probe is not None else max(self._warm, self.params.sarsa_warmup)
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
            self._keep_early(self._prev_x, self._prev[1], x, outcome)
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
            self._hold_start(obs)
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

    def _keep_early(self, x0: np.ndarray, a: int, x1: np.ndarray, outcome: str) -> None:
        """Before the first sweep, the model planner's transitions are kept unscaled (at most
        `embed_every` of them): a grid laid again (`_hold_start`) learns them again."""
        if (
            self.lspi.iterations == 0
            and isinstance(self.planner, ModelPlanner)
            and len(self._early) < self.params.embed_every
        ):
            self._early.append((x0 * self._span + self._lo, a, x1 * self._span + self._lo, outcome))

    def _hold_start(self, obs: Observation) -> None:
        """A start at or past the planner's grid edge (`HOLD`: the warm-up met too few starts to
        span them, in a world of long episodes or one whose first episodes start at a home pose)
        leaves its traces no room: they run off the grid, where every state is planned as the
        edge, and fail. Before the first sweep, the grid is then laid again over the starts met,
        the planner learns the transitions so far again on it, and an event (`grid`) says so;
        later, the accepted map's ends are in the grid's units, and the sweeps have met every
        start. Over camera frames, only while fewer than `FEW_STARTS` were met."""
        if not isinstance(self.planner, ModelPlanner) or self.lspi.iterations > 0:
            self._early = []
            return
        if self.motor and self._starts_met >= FEW_STARTS:
            return
        self._starts_met += 1
        x = self._motor_map(self._raw(obs)) if self._motor_map is not None else self._flat(obs)
        self._start_lo, self._start_hi = np.minimum(self._start_lo, x), np.maximum(self._start_hi, x)
        v = (x - self._lo) / self._span
        if np.all((v >= HOLD) & (v <= 1.0 - HOLD)):
            return
        self._set_ranges()
        assert self.background is not None
        self.background.discard("plan")
        self.planner = self._new_planner(self.planner.dims)
        for x0, a, x1, outcome in self._early:  # what was learned, on the new grid
            self.planner.observe((x0 - self._lo) / self._span, a, (x1 - self._lo) / self._span, outcome)
        self._fresh, self._since_plan = True, 0
        where = ", ".join(f"{u:.2f}" for u in v)
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"a start at ({where}) of the planner's grid lies at or past its edge ({self._starts_met - 1} starts "
                "met before it): the grid is laid again over the starts met, and what was learned is learned on it",
                obs.step,
                reason="grid",
                values={f"start_{i}": float(u) for i, u in enumerate(v)},
            )
        )

    def _set_scale(self, scale: float, seed: int | None = None) -> None:
        """The plan's moves span `scale` of each bound: a new action table and a new planner (the
        warm-up's end, before it learned anything; or a restore, whose planner state follows)."""
        if scale == self._scale:
            return
        self._scale = scale
        self.actions = action_table(self.spec, self.params.action_levels, scale)
        assert self.planner is not None
        self.planner = self._new_planner(self.planner.dims, seed)

    def moves_state(self) -> dict[str, Any]:
        """What `action_scale=0` and `distance=auto` settled, and the move-size probe in progress,
        for a checkpoint."""

        def listed(row: tuple[np.ndarray, np.ndarray, np.ndarray | None]) -> list[Any]:
            return [row[0].tolist(), row[1].tolist(), None if row[2] is None else row[2].tolist()]

        probe = None if self._probe is None else [listed(r) for r in self._probe]
        prev = None if self._probe_prev is None else listed(self._probe_prev)
        return {
            "scale": self._scale,
            "distance": self._distance,
            "distance_now": self._distance_now,
            "probe": probe,
            "probe_prev": prev,
            "probe_whole": self._probe_whole,
            "gains": None if self._gains is None else self._gains.tolist(),
        }

    def restore_moves(self, state: dict[str, Any] | None) -> None:
        """Back to what a checkpoint's `moves_state` settled (before the planner's own state)."""
        if state is None:
            return
        if self.planner is not None and not isinstance(self.planner, ReachLearner):
            self._set_scale(float(state["scale"]), seed=0)  # the planner's rng comes with its state
        self._distance, self._distance_now = state["distance"], str(state["distance_now"])
        gains = state.get("gains")
        self._gains = None if gains is None else np.asarray(gains, dtype=np.float64)
        if "probe" in state:
            probe, prev = state["probe"], state["probe_prev"]

            def row(r: list[Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
                return (
                    np.asarray(r[0], float),
                    np.asarray(r[1], float),
                    None if r[2] is None else np.asarray(r[2], float),
                )

            self._probe = None if probe is None else [row(r) for r in probe]
            self._probe_prev = None if prev is None else row(prev)
            self._probe_whole = None if state["probe_whole"] is None else float(state["probe_whole"])

    def _sweep_moves(self) -> tuple[np.ndarray, np.ndarray]:
        """The sweep's net moves (each trace's summed moves) and displacements (its end less its
        start, in the coordinates planned in), a row per start whose trace ended."""
        traces, k = self._sweep.traces, max(1, self._sweep.repeats)
        rows = [(i, v) for i, v in sorted(self._ends.items()) if (i + 1) * k <= len(traces)]
        nets = np.array(
            [self.actions[np.asarray(traces[(i + 1) * k - 1], dtype=np.int64)].sum(axis=0) for i, _ in rows]
        ).reshape(len(rows), -1)
        return nets, np.array([v[1] - v[0] for _, v in rows]).reshape(len(rows), -1)

    def _measure_gains(self, step: int, distance: str) -> None:
        """The move axes' gains over the sweep about to be embedded (`box_moves.axis_gains`), where
        the planner plans over the observation itself, in its units (not motor coordinates of frames,
        which are in the moves' units by construction); None elsewhere, where the fit does not hold,
        or with `axis_gains=off`. Said in an event when first measured under net moves, or when one
        moved by over 0.1."""
        before, self._gains = self._gains, None
        if self.params.axis_gains == "off" or self.discrete or self.motor or not self._ends:
            return
        if not isinstance(self.planner, ModelPlanner):
            return
        nets, moved = self._sweep_moves()
        if moved.shape[1] == nets.shape[1]:
            self._gains = axis_gains(nets, moved * self._span)
        if distance != "net" or self._gains is None:
            return
        if before is not None and float(np.abs(self._gains - before).max()) <= 0.1:
            return
        gains = ", ".join(f"{g:.2f}" for g in self._gains)
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"each move axis's gain over this sweep, relative to their mean: {gains}: the net moves are "
                "scaled by them (the map in the units the body senses)",
                step,
                reason="axis_gains",
                values={f"gain_{i}": float(g) for i, g in enumerate(self._gains)},
            )
        )

    def _trace_distance(self, step: int | None = None) -> str:
        """The distance between box traces in force: `distance` when named; `auto`: the net move
        when a planner's sweep shows that the moves add up (`box_moves.moves_add_up`, on each
        trace's summed moves and displacement), else the padded sum. With `step` (a sweep just
        ended) the rule is evaluated on that sweep, until it says net moves or the policy is watched;
        then it is settled (a policy's rank by where its traces end follows it: `_by_ends`)."""
        if self.params.distance != "auto":
            return self.params.distance
        if self._distance == "net" or step is None:
            return self._distance or self._distance_now
        if self.discrete or self.learner != "planner" or not self._ends:
            return self._distance or "padded"
        nets, moved = self._sweep_moves()
        adds = moves_add_up(nets, moved)
        if self._distance == "padded":
            # settled on a sweep whose ends were not linear in the moves, which over camera frames
            # can be the motor coordinates' own error on a poorer policy: a later sweep whose moves
            # add up changes it (the accepted map is published again under the net move: `_swept`)
            if not adds:
                return "padded"
            self._regauge = True
        self._distance_now = "net" if adds else "padded"
        if adds is not None and (self._watching or adds):
            self._distance = self._distance_now
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    f"where the traces ended is {'' if adds else 'not '}linear in their summed moves: traces "
                    + ("are compared by their net move" if adds else "are compared step by step (padded sum)"),
                    step,
                    reason="net_moves" if adds else "padded_moves",
                )
            )
        return self._distance_now
