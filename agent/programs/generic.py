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
of each bound (0, the default: whole moves, or half moves where the planner's warm-up finds the body
carries them out more faithfully, as panda-gym's hand, in the motor coordinates over camera frames;
`agent.programs.box_moves`); their traces are
the continuous actions sent, compared with the padded sum (Eq 3.1) or dynamic time warping
(`distance=dtw`, with a cost per repeated step so trace length stays in it), or by the distance
between their sums (`distance=net`: the net move commanded, blind to the order of the moves, for
bodies whose moves add up; `auto`, the default: net where a planner's sweep shows they do, else the
padded sum). Discrete traces are compared with the edit distance, or, over a table of
states with one trace a start (a deterministic world: `discrete_distance=auto`), by how many times each action occurs in
them (turns left out), embedded by weighted MDS (`embedding=auto`): a map of places round walls
and holes, where the edit distance maps the ways round them (`agent.embedding.move_counts`).

Egocentric actions: the tabular learner finds which actions are rotations (repeated, they come
back to where they started) and compares traces in the frame of their start
(`agent.embedding.rotation_frames`; `frames=off` to compare them as they are).

A world whose transitions are seen to be stochastic (the same observation and action led to
different observations) is embedded from `samples` traces per start state with the ch. 9.4
estimators (`estimator`: the mode trace or the mean pairwise distance) or the padded sum between
mean traces (`mean_trace`, the default for discrete actions: `auto`); the embedding says so. The tabular learner there plans with discount
`stochastic_gamma` over up to `stochastic_samples` samples. A sweep whose samples are one trace for
every start takes the world back to one trace per start.

Phases alternate: *learn*, then *embed* (the greedy policy swept from every start state, trace
distances, classical MDS, Embedding vN); which sweep's policy is accepted, published and watched by
the drop detector is `agent.programs.generic_sweeps`' (its rules: `agent.programs.acceptance`). On
a drop the samples and policy are dropped and the policy relearned from fresh experience; the first
good embedding after it says `relearned`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.learners.lspi import LSPI
from sensorimotor.agent.learners.lspi_features import iterate_job
from sensorimotor.agent.programs.acceptance import end_disparity
from sensorimotor.agent.programs.base import Decision, EventOutput
from sensorimotor.agent.programs.generic_choice import choose_learner
from sensorimotor.agent.programs.generic_continuous import GenericContinuous
from sensorimotor.agent.programs.generic_jobs import action_table, embed_job, motor_job
from sensorimotor.agent.programs.generic_params import LEARNERS, GenericProgramParams
from sensorimotor.agent.programs.generic_publish import GenericPublish
from sensorimotor.agent.programs.generic_state import GenericState
from sensorimotor.agent.programs.generic_sweeps import GenericSweeps
from sensorimotor.agent.programs.generic_tables import GenericTables
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import EventKind, Observation, WorldSpec
from sensorimotor.protocol.params import parse


class GenericProgram(GenericSweeps, GenericPublish, GenericTables, GenericContinuous, GenericState):
    """Learns any world that declares start states: see the module docstring."""

    name = "generic"
    Params = GenericProgramParams
    detector_params = {"warmup": 30, "rate": 0.05}

    def __init__(
        self, spec: WorldSpec, seed: int = 0, params: GenericProgramParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(spec, seed)
        self.params = prm = parse(GenericProgramParams, overrides, name=self.name, base=params)
        if not spec.sensors:
            raise SpecMismatch(f"generic program: world {spec.world_id} declares no sensors")
        self.actions = action_table(spec, prm.action_levels, prm.action_scale or 1.0)  # 0: whole until measured
        #: the stochastic-world estimator and traces per start in force (`auto` and 0 resolved)
        self.estimator = prm.estimator if prm.estimator != "auto" or spec.action_space.discrete else "mode"
        mean_trace = self.estimator in ("mean_trace", "auto")
        self.samples = prm.samples or (int(np.clip(768 // max(1, spec.n_starts), 8, 64)) if mean_trace else 8)
        self._motor_actions = action_table(spec, prm.action_levels, prm.motor_scale or prm.action_scale or 1.0)
        self.n_actions = self.actions.shape[0]
        self.discrete = spec.action_space.discrete
        self.goal = str(spec.goal)
        choice = choose_learner(spec, prm)
        self.learner, d = choice.learner, choice.values
        self.tabular = choice.learner == "tabular" or choice.table_class is not None  # a table of states
        self.keyed = self.tabular and not choice.ids  # a table of distinct observations, not given state ids
        self._ids, self._said_table_full = {}, False
        self.stochastic = False
        self._transitions, self._rotations = {}, None
        lo = np.concatenate([np.full(int(np.prod(s.shape)), s.low, float) for s in spec.sensors])
        hi = np.concatenate([np.full(int(np.prod(s.shape)), s.high, float) for s in spec.sensors])
        self._lo, self._span = lo, np.where(hi > lo, hi - lo, 1.0)
        self._raw_lo, self._raw_span = self._lo, self._span
        # planner over more values than it can grid: motor coordinates of the frames (one per action value)
        self.motor = choice.learner == "planner" and d > prm.planner_max_dims
        if self.motor and not choice.box:
            raise SpecMismatch(
                f"generic program: learner planner over {d} observed values needs a box action of 2+ values "
                "(its motor coordinates are the moves sent)"
            )
        self._motor_map, self._motor_data, self._motor_starts, self._motor_prev = None, [], [], None
        self.sarsa, self.planner, self.model = None, None, None
        basis: Any
        if self.tabular:
            basis = self._init_table(choice.table_class, choice.ids)
        elif choice.learner == "sarsa":
            basis = self._init_sarsa(d)
        elif choice.learner == "planner":
            basis, d = self._init_planner(d)
        elif choice.learner == "reach":  # many action dimensions, a short state vector
            basis, d = self._init_reach()
        else:
            basis = self._init_lspi(d)
        declared = spec.params.get("max_episode_steps", "")
        limit = int(declared) if declared.isdigit() else 0
        self.max_trace = prm.max_trace or (min(limit, 250) if limit > 0 else 60)
        tdims = spec.params.get("truth_dims", "")
        self.dims = prm.dims or (int(tdims) if tdims.isdigit() and int(tdims) > 0 else 2)
        self._next_id, self._seen, self._fitted_at = 0, 0, 0
        self.lspi = LSPI(basis, gamma=prm.gamma, ridge=prm.ridge, capacity=prm.max_samples)
        if self.model is not None:
            # near-ties of the plan's exact values: a quarter of the gap between the shortest way and
            # a detour of two steps (1 - gamma^2); the LSPI weights are unused
            self.lspi.gamma = prm.model_gamma
            self.lspi.tie_tolerance = 0.25 * (1.0 - prm.model_gamma**2)
        self._tie_tolerance = self.lspi.tie_tolerance
        self._init_sweeps()
        self._prev, self._prev_x, self._prev_key = None, None, None  # the step in progress (Sarsa: scaled vector)
        self._said_no_starts = False
        self.detector_params = {"warmup": max(30, spec.n_starts), "rate": 0.05}
        self._since_plan, self._fresh = 0, False  # planner / model learner: transitions since the last plan
        self._plan_exact = False  # model learner: the plan installed was made from the complete model as it is
        self._start_lo, self._start_hi = np.full(d, np.inf), np.full(d, -np.inf)  # start observations met warming up
        self._early = []  # the model planner's transitions before the first sweep (generic_continuous)
        self._swept_policy, self._since_sweep = None, 0  # model learner: the policy swept last, transitions since
        self._plan_for_sweep = False  # the plan in flight is swept when it is swapped in
        self.use_background(prm.learn_lag)

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

    def act(self, obs: Observation) -> Decision:
        self._history_before(obs)  # (generic_relearn: a state that remembers the last action)
        return self._history_after(self._act(obs))

    def _act(self, obs: Observation) -> Decision:
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
        return self._act_lspi(obs)

    def performance(self, obs: Observation) -> float | None:
        return self._perf.pop(0) if self._perf else None

    def on_drop(self, step: int) -> None:
        """The body changed: what was learned no longer holds; relearn from fresh samples."""
        self.relearn_at = step
        self._keep_for_relearn()
        self.lspi.reset()
        if self.sarsa is not None:
            self.sarsa.reset()
        if self.planner is not None:
            self.planner.reset()
        if self.model is not None:
            self.model.reset()
            self._fresh, self._since_plan, self._plan_exact = False, 0, False
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
        self._relearn_unconfirmed, self._chance_seen = 0, False
        self._accepted_basis, self._sweep_rbf, self._sweep_basis = None, None, None
        self._transitions.clear()
        self._rotations = None
        self.emit(
            EventOutput(EventKind.RELEARNING, "samples and policy dropped; relearning from fresh experience", step)
        )

    def world_restarted(self) -> None:
        self._prev, self._prev_x, self._prev_key = None, None, None
        self._sweep.interrupted()
        self._visited = set()


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
