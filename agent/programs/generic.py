"""The generic developmental program (the recipe of ch. 6, for any world): learn to reach the
world's goal, run the greedy policy from every start state the world declares, embed the action
traces.

Success is what the world declares (`WorldSpec.goal`, see `agent.programs.goal`): a positive
reward, a terminal state that is not a time limit, or the world's success flag. Every learner
learns the shortest way to that goal (reward 1 at the goal and 0 elsewhere for LSPI, a cost of 1
per step for Sarsa); a termination that is not the goal is a failure, worth as little as never
arriving; a truncation is neither.

The learner follows the observation (`learner=auto`; the attach event says which):

* ``model`` - one integer sensor with few values is a state id (the gridworld of ch. 5); integer
  sensors with at most `symbol_values` values each (a symbolic grid such as MiniGrid's) are
  tabulated by distinct observation. Over the table: a model counted from experience (where each
  action led, how often it reached the goal) and value iteration on it, exploring by optimism about
  actions not yet tried `model_known` times (`agent.learners.tabular_model`); a stochastic world's
  probabilities are its counts. ``tabular`` is LSPI over the same table with random exploration
  (ch. 5's recipe); the name of a table learner from an installed package (entry-point group
  ``sensorimotor.learners``, `agent.learners.registry`) is driven the same way as ``model``.
* ``sarsa`` - a continuous observation of at most `sarsa_max_dims` values: tile-coded Sarsa(lambda)
  with optimistic initial values (the classic mountain-car recipe, ch. 8's CMAC; hashed tiles above
  `memory`), which explores toward sparse goals by itself.
* ``reach`` - an action of 5 or more dimensions (a box's, or a discrete space's pairs of +-moves: an
  arm commanded in 6 or 7 joints) and a sensor of at most 16 continuous values (its joint angles):
  each action's mean move of that vector, the goal states met, and steps toward their medoid, the
  joints moved one after another (`agent.learners.reach`); the other sensors are not read. Box
  actions of more than 4 dimensions are coded per axis (2 per dimension), not as a product.
* ``planner`` - a continuous observation of at most `planner_max_dims` values and a box action of
  two or more dimensions (whose discretised table is a product of moves: 27 for three): a model of
  each action's effect, linear in the action and fitted per node of a grid over the observation,
  and value iteration over that grid with the value interpolated between nodes, optimistic about
  nodes never met (`agent.learners.model_planner`). The model generalises across the actions a
  model-free learner would have to try one by one, and its plan is the shortest way under the
  model (the smaller of equally quick moves), so traces are a function of the start. A camera
  frame (a sensor of two or more axes) with such actions is planned over too, in *motor
  coordinates*: the first `motor_warmup` random moves fit a map from the frames to coordinates
  whose differences are the actions sent (`agent.learners.motor_map`), and the plan runs over them
  (the warm-up's moves may be larger than the plan's, `motor_scale`: a half move can change a small
  frame by less than a pixel).
* ``lspi`` - anything else (images, long vectors): flattened, scaled by the sensors' ranges,
  randomly projected to at most `projection` dimensions, reduced by PCA fitted on a reservoir
  sample, fed through Gaussian radial basis functions (ch. 6: PCA + RBF), LSPI over random samples.

Box action spaces are discretised into `action_levels` values per dimension, spanning `action_scale`
of each bound (a hand that follows small moves more faithfully than large ones draws finer traces
with half moves: panda-gym's, `docs/zoo.md`); their traces are the
continuous actions sent, compared with the padded sum (Eq 3.1) or dynamic time warping
(`distance=dtw`, with a cost per repeated step so trace length stays in it), or by the distance
between their sums (`distance=net`: the net move commanded, blind to the order of the moves, for
bodies whose moves add up). Discrete traces are compared with the edit distance.

Egocentric actions: the tabular learner finds which actions are rotations (repeated, they come
back to where they started) and compares traces in the frame of their start
(`agent.embedding.rotation_frames`; `frames=off` to compare them as they are).

A world whose transitions are seen to be stochastic (the same observation and action led to
different observations) is embedded from `samples` traces per start state with the ch. 9.4
estimators (`estimator`: the mode trace or the mean pairwise distance) or the padded sum between
mean traces (`mean_trace`, the default for discrete actions: `auto`); the embedding says so. The tabular learner there plans with discount
`stochastic_gamma` over up to `stochastic_samples` samples. A sweep whose samples are one trace for
every start takes the world back to one trace per start.

Phases alternate: *learn* until `samples_per_iteration` new samples (LSPI: then features are
refitted and LSPI iterates off the act path; a table learner: a plan, swept only once the model is
complete and its greedy policy changed, or once watched) or `embed_every` steps (Sarsa, which
learns on every step); *embed*: the greedy policy from each start state (`StartStateSweep`), trace
distances, classical MDS, Embedding vN. A sweep that repeats the accepted traces once watched
publishes nothing: every version is a new map. Which policy is better is decided by the pure rules
of `agent.programs.acceptance`. Until the policy is *watched* every sweep's policy is published
and accepted in a deterministic world; in a stochastic one only a policy better beyond the noise of
the sampled goal fractions (1.64 standard errors) is. A sweep that reaches the goal from
`watch_after` of the starts makes the policy watched; so does, in a stochastic world, an accepted
policy that `settle` newer policies in a row did not beat beyond the noise (the best there is where
no policy reaches `watch_after`: the event says `settled`). Once watched, a new policy is embedded
only when its sweep is better (stochastic: beyond the noise), else the accepted policy is swept
again - a stochastic world's sweep of the accepted policy is another draw of its traces and is never
a new map - so embeddings hold once learned, and the drop detector sees only the accepted policy's
trace scores, never the program's own experiments: in a deterministic world 0 for a start whose
goal the accepted policy reached and no longer does (twice: the start is run once more first), else
1; in a stochastic one gamma^length at the goal, else 0. On a drop the samples and policy are
dropped, the policy relearned from fresh experience and the first good embedding after it (in a
stochastic world that settles below `watch_after`: the settled policy's map, published again) says
`relearned`.
"""

from __future__ import annotations

import hashlib
from typing import Any

import numpy as np

from sensorimotor.agent.embedding.rotation_frames import Rotations, find_rotations
from sensorimotor.agent.learners.base import TableLearner
from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.agent.learners.lspi_features import RBFFeatures, basis_state, iterate_job, set_basis
from sensorimotor.agent.learners.model_planner import ModelPlanner, plan_job
from sensorimotor.agent.learners.motor_map import MotorMap
from sensorimotor.agent.learners.reach import ReachLearner, state_sensors
from sensorimotor.agent.learners.reach import fits as reach_fits
from sensorimotor.agent.learners.reach import plan_job as reach_plan_job
from sensorimotor.agent.learners.registry import outside_learners, table_learner_class
from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.agent.learners.tabular_model import TabularModel
from sensorimotor.agent.programs.acceptance import Score, Verdict, compare, compare_ends, end_disparity, sweep_score
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.agent.programs.generic_jobs import action_table, embed_job, motor_job
from sensorimotor.agent.programs.generic_params import LEARNERS, OWN_LEARNERS, GenericProgramParams
from sensorimotor.agent.programs.goal import failed, reached
from sensorimotor.agent.programs.sweep import StartStateSweep
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation, Trigger, WorldSpec
from sensorimotor.protocol.params import parse


class GenericProgram(Program):
    """Learns any world that declares start states: see the module docstring."""

    name = "generic"
    Params = GenericProgramParams
    _rbf: RBFFeatures  # the LSPI basis when observations are neither state ids nor symbols
    detector_params = {"warmup": 30, "rate": 0.05}
    #: transitions remembered to tell a stochastic world (bounded memory)
    TRANSITIONS = 50_000
    RELEARN_CONFIRM = 3  # good sweeps after a drop that may go unpublished while their traces still change

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: GenericProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(GenericProgramParams, overrides, name=self.name, base=params)
        if not spec.sensors:
            raise SpecMismatch(f"generic program: world {spec.world_id} declares no sensors")
        self.actions = action_table(spec, prm.action_levels, prm.action_scale)
        #: the stochastic-world estimator and traces per start in force (`auto` and 0 resolved)
        self.estimator = prm.estimator if prm.estimator != "auto" or spec.action_space.discrete else "mode"
        mean_trace = self.estimator in ("mean_trace", "auto")
        self.samples = prm.samples or (int(np.clip(768 // max(1, spec.n_starts), 8, 64)) if mean_trace else 8)
        self._motor_actions = action_table(spec, prm.action_levels, prm.motor_scale or prm.action_scale)
        self.n_actions = self.actions.shape[0]
        self.discrete = spec.action_space.discrete
        self.goal = str(spec.goal)
        s0 = spec.sensors[0]
        ids = (
            len(spec.sensors) == 1
            and np.dtype(s0.dtype).kind in "iu"
            and int(np.prod(s0.shape)) == 1
            and 0 < s0.high - s0.low + 1 <= prm.max_categories
        )
        symbols = all(
            np.dtype(s.dtype).kind in "iub" and 0 <= s.high - s.low + 1 <= prm.symbol_values for s in spec.sensors
        )
        d = sum(int(np.prod(s.shape)) for s in spec.sensors)
        frames = any(len(s.shape) >= 2 for s in spec.sensors)  # a camera: its frames are planned over by motor map
        box = not spec.action_space.discrete and len(spec.action_space.low) >= 2
        learner = prm.learner
        if learner == "auto":
            learner = (
                "model"
                if ids or symbols
                else "reach"
                if reach_fits(spec)
                else "planner"
                if box and (d <= prm.planner_max_dims or frames)
                else "sarsa"
                if d <= prm.sarsa_max_dims
                else "lspi"
            )
        table_class = None if learner in OWN_LEARNERS else table_learner_class(learner)
        if learner not in OWN_LEARNERS and table_class is None:
            valid = ", ".join([*LEARNERS, *outside_learners()])
            raise SpecMismatch(f"generic program: no learner {learner!r}; valid: {valid}")
        if table_class is not None and not (ids or symbols):
            raise SpecMismatch(
                f"generic program: learner {learner!r} learns over a table of states; world {spec.world_id} "
                "observes neither a state id nor integer symbols (learner=auto picks one that fits)"
            )
        self.learner = learner
        self.tabular = learner == "tabular" or table_class is not None  # a table of states
        self.keyed = self.tabular and not ids  # a table of distinct observations, not given state ids
        self._ids: dict[bytes, int] = {}
        self.stochastic = False
        self._transitions: dict[tuple[bytes, int], tuple[bytes, bytes | None]] = {}
        self._said_table_full = False
        self._rotations: Rotations | None = None  # the rotations among the actions, once found
        lo = np.concatenate([np.full(int(np.prod(s.shape)), s.low, float) for s in spec.sensors])
        hi = np.concatenate([np.full(int(np.prod(s.shape)), s.high, float) for s in spec.sensors])
        span = np.where(hi > lo, hi - lo, 1.0)
        self._lo, self._span = lo, span
        # planner over more values than it can grid: motor coordinates of the frames (one per action value)
        self.motor = learner == "planner" and d > prm.planner_max_dims
        if self.motor and not box:
            raise SpecMismatch(
                f"generic program: learner planner over {d} observed values needs a box action of 2+ values "
                "(its motor coordinates are the moves sent)"
            )
        self._raw_lo, self._raw_span = lo, span
        self._motor_map: MotorMap | None = None
        self._motor_data: list[tuple[np.ndarray, int, np.ndarray]] = []  # warm-up transitions
        self._motor_starts: list[np.ndarray] = []  # warm-up frames at an episode's start
        self._motor_prev: tuple[np.ndarray, int] | None = None
        basis: Any
        self.sarsa: SarsaLambda | None = None
        self.planner: ModelPlanner | ReachLearner | None = None
        self._reach_sensors: list[str] = []  # reach: the short vectors it plans over (the others unread)
        self.model: TableLearner | None = None
        if self.tabular:
            if ids:
                self.low = int(s0.low)
                self.n_states = int(s0.high - s0.low) + 1
            else:
                self.low, self.n_states = 0, prm.table_size
            basis = TabularBasis(self.n_states, self.n_actions)
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
        elif learner == "sarsa":
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
            basis = TabularBasis(1, self.n_actions)  # unused: LSPI keeps the program's shape uniform
            # per-value ranges, measured over the first `sarsa_warmup` random steps: a sensor's one
            # declared range may span values of very different scales (position and velocity)
            self._seen_lo = np.full(d, np.inf)
            self._seen_hi = np.full(d, -np.inf)
            self._warm = 0
        elif learner == "reach":  # many action dimensions, a short state vector (agent.learners.reach)
            self.n_states = 0
            self._reach_sensors = state_sensors(spec)
            if not self._reach_sensors:
                raise SpecMismatch(
                    f"generic program: learner reach needs a sensor of at most 16 continuous values; world "
                    f"{spec.world_id} has {', '.join(s.name for s in spec.sensors)}"
                )
            chosen = [s for s in spec.sensors if s.name in self._reach_sensors]
            lo = np.concatenate([np.full(int(np.prod(s.shape)), s.low, float) for s in chosen])
            hi = np.concatenate([np.full(int(np.prod(s.shape)), s.high, float) for s in chosen])
            d = lo.size
            self._lo, self._span = lo, np.where(hi > lo, hi - lo, 1.0)
            self._raw_lo, self._raw_span = self._lo, self._span
            self.planner = ReachLearner(d, self.n_actions, seed=int(self.rng.integers(2**31)))
            basis = TabularBasis(1, self.n_actions)  # unused: LSPI keeps the program's shape uniform
            self._seen_lo = np.full(d, np.inf)
            self._seen_hi = np.full(d, -np.inf)
            self._warm = 0
        elif learner == "planner":
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
            basis = TabularBasis(1, self.n_actions)  # unused: LSPI keeps the program's shape uniform
            self._seen_lo = np.full(d, np.inf)
            self._seen_hi = np.full(d, -np.inf)
            self._warm = 0
        else:
            self.n_states = 0
            self.dim = min(d, prm.projection)
            proj_rng = np.random.default_rng([seed, 6])  # fixed per seed: stored vectors stay comparable
            self._proj = proj_rng.standard_normal((d, self.dim)) / np.sqrt(self.dim) if d > prm.projection else None
            self._store = np.zeros((2 * prm.max_samples + 2, self.dim), dtype=np.float32)
            self._reservoir = np.zeros((prm.reservoir, self.dim), dtype=np.float32)
            self._rbf = basis = RBFFeatures(self._store, self.n_actions, prm.centres)
        declared = spec.params.get("max_episode_steps", "")
        limit = int(declared) if declared.isdigit() else 0
        self.max_trace = prm.max_trace or (min(limit, 250) if limit > 0 else 60)
        tdims = spec.params.get("truth_dims", "")
        self.dims = prm.dims or (int(tdims) if tdims.isdigit() and int(tdims) > 0 else 2)
        self._next_id = 0
        self._seen = 0
        self._fitted_at = 0
        self.lspi = LSPI(basis, gamma=prm.gamma, ridge=prm.ridge, capacity=prm.max_samples)
        if self.model is not None:
            # near-ties of the plan's exact values: a quarter of the gap between the shortest way and
            # a detour of two steps (1 - gamma^2); the LSPI weights are unused
            self.lspi.gamma = prm.model_gamma
            self.lspi.tie_tolerance = 0.25 * (1.0 - prm.model_gamma**2)
        self._tie_tolerance = self.lspi.tie_tolerance
        self.phase = "explore"
        self.new_samples = 0
        self.relearn_at: int | None = None
        self._prev: tuple[int, int] | None = None
        self._prev_x: np.ndarray | None = None  # Sarsa: the previous observation's scaled vector
        self._prev_key: bytes | None = None
        self._sweep = self._new_sweep()
        self._visited: set[tuple[bytes, int]] = set()
        self._perf: list[float] = []
        self._said_no_starts = False
        self._watching = False  # the detector sees trace scores only once the policy is good
        self._held = 0  # stochastic: newer policies since the accepted one, none better beyond noise
        self._accepted: np.ndarray | None = None  # the accepted policy's weights (see the module docstring)
        self._best: tuple[float, float] | None = None
        self._best_disparity: float | None = None  # planner, distance=net: the accepted sweep's end disparity
        self._checking = False  # this sweep runs the accepted policy, not the newest one
        self._sweep_w: np.ndarray | None = None  # the weights the sweep in progress follows
        self._accepted_basis: dict[str, Any] | None = None  # lspi: the RBF basis the accepted weights are over
        self._sweep_rbf: RBFFeatures | None = None  # the basis the sweep in progress computes features with
        self._sweep_basis: dict[str, Any] | None = None  # and its state (lspi)
        self._accepted_traces: list[list[int]] | None = None  # the accepted policy's last sweep
        self._accepted_reached: list[bool] | None = None  # and which of its traces reached the goal
        self._candidate_traces: list[list[int]] | None = None  # a better policy's traces, not yet confirmed
        self._relearn_unconfirmed = 0  # good sweeps since a drop whose traces the next one did not keep
        self._diverged = False  # the trace in progress left the accepted policy's choices
        self._unfed: list[float] = []  # trace scores of this sweep held back from the detector
        self._start_scores: list[float] = []  # scores of the start state in progress (one per sample)
        self._start_fair = True  # all of them came from the accepted policy's choices
        self._trace_from: np.ndarray | None = None  # planner: where the trace in progress started
        self._ends: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # planner: each start's (start, end) this sweep
        self.detector_params = {"warmup": max(30, spec.n_starts), "rate": 0.05}
        self._pending_embedding: dict[str, Any] | None = None  # what the embed job in flight is of
        self._since_plan = 0  # planner: transitions since the last plan started
        self._start_lo = np.full(d, np.inf)  # the range of start observations met while warming up
        self._start_hi = np.full(d, -np.inf)
        self._fresh = False  # planner: a node met for the first time since the last plan started
        self._last_choice = 0  # the action table's row the last sweep step sent
        self.retried_total = 0  # traces run once more before they counted (`_in_doubt`), every sweep
        self._swept_policy: np.ndarray | None = None  # model learner: the greedy policy swept last
        self._since_sweep = 0  # model learner: transitions since the last sweep (by plans)
        self._plan_for_sweep = False  # the plan in flight is swept when it is swapped in
        self.use_background(prm.learn_lag)

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

    def describe(self) -> str:
        """The learner chosen for the world's observation (said in the attach event)."""
        what = {
            "tabular": "a table of distinct observations" if self.keyed else "a table of state ids",
            "model": "a counted model of "
            + ("a table of distinct observations" if self.keyed else "a table of state ids")
            + ", value iteration on it, optimistic about untried actions",
            "sarsa": f"tile-coded Sarsa(lambda), {self.sarsa.coder.dims if self.sarsa else 0} values"
            + (", hashed tiles" if self.sarsa and self.sarsa.coder.hashed else ""),
            "lspi": "LSPI over PCA + RBF features",
            "reach": "a learned move per action over the sensors "
            + ", ".join(self._reach_sensors)
            + ", steps toward the goal states met",
            "planner": f"a learned local-linear model and interpolated value iteration, "
            f"{getattr(self.planner, 'grid', 0)}^{self.planner.dims if self.planner else 0} nodes"
            + (", over motor coordinates of the frames" if self.motor else ""),
        }.get(
            self.learner,
            f"{type(self.model).__module__}.{type(self.model).__name__} over "
            + ("a table of distinct observations" if self.keyed else "a table of state ids"),
        )
        return f"learner {self.learner} ({what}), goal {self.goal}, {self.n_actions} actions"

    def _new_sweep(self, n: int | None = None, repeats: int | None = None) -> StartStateSweep:
        """A sweep of every start state, `samples` traces each in a stochastic world (or `n` traces,
        `repeats` per start: the shape of a saved sweep, which the world may since have changed)."""
        k = repeats if repeats is not None else self.samples if self.stochastic else 1
        n = n if n is not None else self.spec.n_starts * k
        return StartStateSweep(n, self.max_trace, goal=lambda o: reached(self.goal, o), repeats=k)

    # observations -> states --------------------------------------------------------------------
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

    def _state(self, obs: Observation) -> int:
        """The LSPI state of an observation met while exploring: a table row, or a new store id."""
        if self.tabular:
            return self._table_id(obs)
        x = self._vector(obs)
        i = self._next_id
        self._next_id += 1
        self._store[i % self._store.shape[0]] = x
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
        f = rbf.features(self._vector(obs))[0]
        return w.reshape(self.n_actions, -1) @ f

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
        self.stochastic = True
        self._transitions.clear()
        self._plan_for_chance()

        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"the world is stochastic (one observation and action led to different observations): "
                f"{self.samples} traces per start state, {self.estimator} estimator",
                obs.step,
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

    # the program -------------------------------------------------------------------------------
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
            fit={"components": prm.components, "centres": prm.centres, "width": prm.width},
            tie_tolerance=self.lspi.tie_tolerance,
        )

    def _iterated(self, result: dict[str, Any], step: int) -> None:
        """The job's basis and weights swapped in; report the policy iteration."""
        if result["basis"] is not None:
            set_basis(self._rbf, result["basis"])
        self.lspi.w = np.asarray(result["w"], dtype=np.float64)
        self.lspi.iterations += int(result["iterations"])
        self.emit_lspi_iteration(self.lspi, result["change"], step)

    def _key(self, obs: Observation) -> bytes:
        """The observation's bytes; a digest of them when longer than 64 (a camera frame: the
        transitions remembered would otherwise hold two frames each)."""
        key = b"".join(np.ascontiguousarray(obs.tensors[s.name]).tobytes() for s in self.spec.sensors)
        return key if len(key) <= 64 else hashlib.blake2b(key, digest_size=16).digest()

    def _choose(self, obs: Observation, trace: list[int]) -> int:
        if not trace:
            self._visited = set()
        self._visited.add((self._key(obs), trace[-1] if trace else -1))
        prefer = trace[-1] if trace else None
        a = self.lspi.choose(self._q(obs, self._sweep_w), prefer)
        if self._watching and not self._checking and self._accepted is not None and not self._diverged:
            rbf, self._sweep_rbf = self._sweep_rbf, self._accepted_rbf()
            try:
                self._diverged = a != self.lspi.choose(self._q(obs, self._accepted), prefer)
            finally:
                self._sweep_rbf = rbf
        return a

    def _rbf_of(self, basis: dict[str, Any] | None) -> RBFFeatures | None:
        """An RBF basis in the state `basis` (None for None)."""
        if basis is None:
            return None
        rbf = RBFFeatures(self._store, self.n_actions, self.params.centres)
        set_basis(rbf, basis)
        return rbf

    def _accepted_rbf(self) -> RBFFeatures | None:
        """The RBF basis the accepted weights are over, when it is not the current one."""
        return self._rbf_of(self._accepted_basis)

    def _cycle(self, obs: Observation, trace: list[int]) -> bool:
        """A deterministic greedy policy that meets the same observation after the same action again
        is in a loop that never ends: the trace stops there (not in a stochastic world, where the
        next step may differ)."""
        return bool(trace) and not self.stochastic and (self._key(obs), trace[-1]) in self._visited

    def _start_sweep(self, check: bool) -> Decision:
        """Sweep the start states with the newest policy, or (`check`) with the accepted one."""
        self._prev, self._prev_x, self._prev_key = None, None, None
        self.phase = "embed"
        self._checking = check
        w = self._accepted if check and self._accepted is not None else self._weights()
        self._sweep_w = np.array(w, copy=True)
        if self.learner == "lspi":
            # the basis is frozen for the sweep, as its weights are: a refit swapped in mid-sweep would
            # give the weights features they were not fitted on, and the accepted policy's basis would
            # not be the one its traces were made with (a check sweep then differs: a false drop)
            use = self._accepted_basis if check and self._accepted_basis is not None else basis_state(self._rbf)
            self._sweep_basis = use
            self._sweep_rbf = self._rbf_of(use)
        else:
            self._sweep_basis, self._sweep_rbf = None, None
        self._sweep = self._new_sweep()
        self._diverged = False
        self._unfed = []
        self._start_scores, self._start_fair = [], True
        self._ends, self._trace_from = {}, None
        # a random order: the detector then sees trace scores in no spatial order (a run of far
        # starts, long traces, would look like a drop)
        return self._sweep.begin([int(i) for i in self.rng.permutation(self.spec.n_starts)])

    def _swept(self, step: int) -> Decision | None:
        """A sweep finished: accept, publish, feed the detector, or sweep the accepted policy again."""
        sw = self._sweep
        k = sw.repeats
        self.retried_total += sw.retries
        if self.stochastic and k > 1 and all(sw.traces[i] == sw.traces[i - i % k] for i in range(len(sw.traces))):
            # every start's samples were the same trace: the policy controls whatever made the
            # transitions differ (or distinct states looked alike), so one trace per start will do
            # (ch. 9.4); the transitions are watched again from here
            n_sampled = len(sw.traces)
            sw.traces, sw.reached = sw.traces[::k], sw.reached[::k]
            if self._accepted_traces is not None and len(self._accepted_traces) == n_sampled:
                self._accepted_traces = self._accepted_traces[::k]  # one per start, as the sweep's
            if self._accepted_reached is not None and len(self._accepted_reached) == n_sampled:
                self._accepted_reached = self._accepted_reached[::k]
            sw.repeats, k, sw.rewarded = 1, 1, sum(sw.reached)
            self.stochastic = False
            self._plan_for_chance()
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    "the sampled traces from every start state were the same: one trace per start state again",
                    step,
                    reason="deterministic",
                )
            )
        new = sweep_score(sw.reached, sw.traces)
        score = (new.fraction, new.length)
        good = new.fraction >= self.params.watch_after
        best = self._best
        disparity = end_disparity(self._ends)
        if self._by_ends() and disparity is not None and self._best_disparity is not None:
            verdict = compare_ends(disparity, self._best_disparity, good)  # (agent.programs.acceptance)
        elif self.stochastic and (best is None or self._accepted_reached is None):
            verdict = Verdict(True, True)  # nothing sampled to compare with yet
        else:
            accepted = None if best is None else Score(best[0], best[1], len(self._accepted_reached or ()))
            verdict = compare(new, accepted, self.stochastic)
        better, equal = verdict.better, verdict.equal
        same = self._accepted_traces is not None and [list(t) for t in sw.traces] == self._accepted_traces
        self.phase = "explore"
        if self.stochastic and not (self._watching or self._checking or better) and best is not None:
            # not better beyond the noise: the accepted map stays the published one; when `settle`
            # newer policies in a row were not, the accepted policy has converged (the best there is
            # in a world where no policy reaches `watch_after` of the starts) and is watched
            self._hold(step)
            return None
        if self._watching and not self._checking and self._accepted is not None and not (better or same):
            if equal:
                # as good as the accepted policy but other traces (ties broken another way): the
                # accepted map stays the published one; its scores are fair for the detector only
                # where they are absolute (a stochastic world), not relative to the accepted traces
                if self.stochastic:
                    self._perf.extend(self._unfed)
                return None
            # the newest policy is worse than the accepted one: not published, not judged by the
            # detector; the accepted policy is swept again, so that a changed world still shows
            return self._start_sweep(check=True)
        traces = [list(t) for t in sw.traces]
        # scores held back as their traces ended (see `_sweep_act`) are fed when they are absolute
        # (a stochastic world, or nothing accepted yet), never when relative to the accepted traces
        absolute = self.stochastic or self._accepted_reached is None
        if self._watching and not self._checking and better and not same and self.tabular and not self.stochastic:
            if traces != self._candidate_traces:
                # a better policy, seen once: published when the next policy iteration keeps its
                # traces - a policy still changing from one iteration to the next has not converged,
                # and the maps of its passing detours can be far worse than the accepted one
                self._candidate_traces = traces
                if absolute:
                    self._perf.extend(self._unfed)  # better than the accepted policy: its scores are fair
                return None
        if (
            good
            and self.relearn_at is not None
            and not self.stochastic
            and traces != self._candidate_traces
            and self._relearn_unconfirmed < self.RELEARN_CONFIRM
        ):
            # relearning after a body change: the first policies that reach the goal again still
            # change from one iteration to the next, and the map of their detours can be far off
            # the new body; the relearned map is published once an iteration keeps the traces of
            # the one before (or after RELEARN_CONFIRM good sweeps that never settled)
            self._candidate_traces = traces
            self._relearn_unconfirmed += 1
            if absolute:
                self._perf.extend(self._unfed)
            return None
        if (self._watching or good) and absolute:
            self._perf.extend(self._unfed)
        if self._checking and self.stochastic:
            # a re-draw of the accepted policy's traces: its scores are the detector's, but it is no
            # new map (the published one was drawn from the same policy; publishing each draw would
            # only publish the noise of the sampling)
            self._checking = False
            return None
        relearned = good and self.relearn_at is not None
        if self._watching and same and not relearned:
            # the accepted policy's own traces again: the published map stands (a version is a new map)
            self._checking = False
            return None
        if relearned:
            self._relearn_unconfirmed = 0
        if not self._checking and (better or not self._watching):
            self._accepted, self._best, self._held = np.array(self._sweep_w, copy=True), score, 0
            self._best_disparity = disparity if self._by_ends() else None
            self._accepted_traces = traces
            self._accepted_reached = [bool(r) for r in sw.reached]
            self._candidate_traces = None
            self._accepted_basis = None if self.learner != "lspi" else self._sweep_basis
        self._watching = self._watching or good
        self._embed(step, relearned, k)
        self._checking = False
        return None

    def _hold(self, step: int) -> None:
        """A newer policy was not better beyond the noise (stochastic world): one more round the
        accepted policy held; after `settle` of them it has converged and is watched."""
        assert self._best is not None
        self._held += 1
        if self._held >= self.params.settle:
            self._watching = True
            self.emit(
                EventOutput(
                    EventKind.POLICY_ITERATION,
                    f"the accepted policy (goal from {self._best[0]:.0%} of sampled traces) held through "
                    f"{self._held} newer policies, none better beyond the noise: watched from here",
                    step,
                    reason="settled",
                )
            )
            if self.relearn_at is not None and self._accepted_traces and self._accepted_reached:
                # after a drop, the settled policy is the relearned one: its map (published when
                # it was accepted) again, now saying so
                self._checking = True
                acc = (self._accepted_traces, self._accepted_reached)
                self._embed(step, True, len(acc[0]) // self.spec.n_starts, of=acc)
                self._checking = False

    def _by_ends(self) -> bool:
        """Whether policies are ranked by where their traces end (`end_disparity`) once watched: the
        planner's net-move maps in a deterministic world (`generic.rank=auto`), or when told."""
        rank = self.params.rank
        chosen = rank == "ends" or (rank == "auto" and self.params.distance == "net")
        return chosen and self.planner is not None and not self.stochastic

    def _find_rotations(self, step: int) -> Rotations | None:
        """Tabular learner, discrete actions, `frames=auto`: the rotations among the actions, found
        again at each embedding from the transitions seen so far (an event says when they change);
        forgotten on a drop."""
        if self.tabular and self.discrete and self.params.frames == "auto" and self._transitions:
            nxt = {k: first for k, (first, other) in self._transitions.items() if other is None}
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
        rot = self._find_rotations(step)
        n = len(traces) // k
        per_start = [traces[i * k : (i + 1) * k] for i in range(n)]
        assert self.background is not None
        prm = self.params
        self.background.submit(
            "embed",
            embed_job,
            traces=per_start,
            reached=[list(flags[i * k : (i + 1) * k]) for i in range(n)],
            actions=None if self.discrete or self.learner == "reach" else self.actions.copy(),
            dims=self.dims,
            estimator=self.estimator,
            distance=prm.distance,
            dtw_penalty=prm.dtw_penalty,
            rotations=None if rot is None else (rot.order, [list(p) for p in rot.powers]),
            n_actions=self.n_actions,
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

    def act(self, obs: Observation) -> Decision:
        assert self.background is not None
        continuous = self.sarsa is not None or self.planner is not None
        if self.motor and self._motor_map is None:
            return self._motor_warmup(obs)
        if continuous and self._warm < self.params.sarsa_warmup:
            return self._warmup(obs)
        if self.phase == "explore" and self.planner is not None:
            for name, result in self.background.tick():
                if name == "embed":
                    self._embedded(result)
                elif name == "plan":
                    self.planner.install(result)
            return self._learn_planner(obs)
        if self.phase == "explore" and self.sarsa is not None:
            for name, result in self.background.tick():
                if name == "embed":
                    self._embedded(result)
            return self._learn_sarsa(obs)
        if self.model is not None:
            return self._act_model(obs)
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

    def _sweep_act(self, obs: Observation) -> Decision:
        n_before = len(self._sweep.traces)
        # the trace in progress's start (`started` is put back in start order once the sweep ends)
        start = self._sweep.current
        if self.planner is not None and obs.t == 0:
            self._trace_from = self._vector(obs)
        dec = self._sweep.step(obs, self._choose, self._cycle, self._in_doubt)
        if len(self._sweep.traces) > n_before:
            if self._trace_from is not None:
                self._ends[start] = (self._trace_from, self._vector(obs))
            # a trace ended: its score goes to the detector now when it is the accepted policy's own
            # trace (a check sweep, or a newer policy that chose as the accepted one at every step),
            # else only if the newer policy is accepted when the sweep ends
            assert self._sweep.last is not None
            trace, ok = self._sweep.last
            self._start_scores.append(self._trace_score(start, trace, ok))
            self._start_fair = self._start_fair and (self._checking or not self._diverged)
            if len(self._start_scores) >= self._sweep.repeats:
                # one value per start state: its samples' mean (samples of one start run in a row,
                # and a run of like scores would read as a drop)
                score = float(np.mean(self._start_scores))
                if self._watching and self._start_fair:
                    self._perf.append(score)
                else:
                    self._unfed.append(score)
                self._start_scores, self._start_fair = [], True
            self._diverged = False
        if self.sarsa is not None and not self._checking and self.params.epsilon == 0.0:
            self._learn_in_sweep(obs, None if dec.reset else int(dec.values[0]))
        if self.planner is not None:  # a model learns from every transition, whoever chose it
            self._model_step(obs, None if dec.reset else int(dec.values[0]))
        if not dec.reset:
            self._last_choice = int(dec.values[0])
            dec = Decision(tuple(float(v) for v in self.actions[self._last_choice]))
        if self._sweep.finished:
            again = self._swept(obs.step)
            if again is not None:
                return again
        return dec

    def _in_doubt(self, start: int, trace: list[int], ok: bool) -> bool:
        """A deterministic world's trace that misses a goal the accepted policy reached from its
        start is run once more before it counts (the sweep keeps the second run): a simulator that
        is not bit-repeatable (panda-gym's contacts, ~0.1 mm) can tip one trace off its goal once,
        and a constant stream of 1s would read that single 0 as a drop. A changed body fails twice.
        Only traces whose score the detector would see are doubted (a newer policy that chose
        otherwise than the accepted one is not judged by it)."""
        if ok or self.stochastic or self._accepted_reached is None or start >= len(self._accepted_reached):
            return False
        return bool(self._accepted_reached[start]) and (self._checking or not self._diverged)

    def _trace_score(self, start: int, trace: list[int], ok: bool) -> float:
        """The detector's value of a trace. In a deterministic world, relative to the accepted
        policy's own sweep: 0 for a start whose goal it reached and no longer does, else 1 - so an
        unchanged world gives a constant stream, however long or varied the traces (a sweep of many
        starts in random order would otherwise show runs of long traces that read as drops), and a
        change that breaks the policy shows at once. Lengths do not count: a trace that still
        reaches the goal another way is not a drop. Otherwise (stochastic, or nothing accepted
        yet) gamma^length at the goal, else 0."""
        if self.stochastic or self._accepted_reached is None or start >= len(self._accepted_reached):
            return self.lspi.gamma ** len(trace) if ok else 0.0
        if not ok:
            return 0.0 if self._accepted_reached[start] else 1.0
        return 1.0

    def performance(self, obs: Observation) -> float | None:
        return self._perf.pop(0) if self._perf else None

    def on_drop(self, step: int) -> None:
        """The body changed: what was learned no longer holds; relearn from fresh samples."""
        self.relearn_at = step
        self.lspi.reset()
        if self.sarsa is not None:
            self.sarsa.reset()
        if self.planner is not None:
            self.planner.reset()
        if self.model is not None:
            self.model.reset()
            self._fresh, self._since_plan = False, 0
            self._swept_policy, self._since_sweep = None, 0
        assert self.background is not None
        self.background.discard("model")
        self.background.discard("plan")
        self.background.discard("lspi")  # an iteration over the dropped samples is never swapped in
        self.new_samples = 0
        self._prev, self._prev_x, self._prev_key = None, None, None
        self.phase = "explore"
        self._perf.clear()
        self._watching, self._held = False, 0
        self._accepted, self._best, self._checking = None, None, False
        self._best_disparity = None
        self._accepted_traces, self._accepted_reached, self._candidate_traces = None, None, None
        self._relearn_unconfirmed = 0
        self._accepted_basis, self._sweep_rbf = None, None
        self._transitions.clear()
        self._rotations = None
        self.emit(
            EventOutput(EventKind.RELEARNING, "samples and policy dropped; relearning from fresh experience", step)
        )

    def world_restarted(self) -> None:
        self._prev, self._prev_x, self._prev_key = None, None, None
        self._sweep.interrupted()
        self._visited = set()

    # saved state ---------------------------------------------------------------------------------
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
            "start_scores": list(self._start_scores),
            "start_fair": self._start_fair,
            "rotations": None
            if self._rotations is None
            else [self._rotations.order, [list(p) for p in self._rotations.powers]],
        }
        if self.model is not None:
            out["model"] = self.model.state()
            out.update(fresh=self._fresh, since_plan=self._since_plan, last_choice=self._last_choice)
            out.update(swept_policy=self._swept_policy, since_sweep=self._since_sweep)
            out["plan_for_sweep"] = self._plan_for_sweep
        if self.planner is not None:
            out["planner"] = self.planner.state()
            out.update(start_lo=self._start_lo.copy(), start_hi=self._start_hi.copy())
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
        return out

    def restore(self, state: dict[str, Any]) -> None:
        super().restore(state)
        self.stochastic = bool(state.get("stochastic", False))
        self._plan_for_chance()  # the capacity the saved samples were kept under
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
        self._start_scores = [float(v) for v in state.get("start_scores", [])]
        self._start_fair = bool(state.get("start_fair", True))
        rot = state.get("rotations")
        self._rotations = None if rot is None else Rotations(int(rot[0]), tuple((int(a), int(p)) for a, p in rot[1]))
        if self.model is not None:
            self.model.restore(state["model"])
            self._fresh, self._since_plan = bool(state["fresh"]), int(state["since_plan"])
            self._last_choice = int(state["last_choice"])
            sp_ = state.get("swept_policy")
            self._swept_policy = None if sp_ is None else np.asarray(sp_, dtype=np.int64)
            self._since_sweep = int(state["since_sweep"])
            self._plan_for_sweep = bool(state["plan_for_sweep"])
        if self.planner is not None:
            self.planner.restore(state["planner"])
            self._start_lo = np.asarray(state["start_lo"], dtype=np.float64)
            self._start_hi = np.asarray(state["start_hi"], dtype=np.float64)
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
            set_basis(self._rbf, state["basis"])


# jobs saved in flight name their function by module: the names they had here still resolve
__all__ = [
    "LEARNERS",
    "GenericProgram",
    "GenericProgramParams",
    "embed_job",
    "end_disparity",
    "iterate_job",
    "motor_job",
]
