"""The generic program's parameters: one typed, defaulted, documented declaration, checked at
start-up (`--program-param generic.KEY=V`) and listed in docs/worlds.md."""

from __future__ import annotations

from dataclasses import dataclass

from sensorimotor.protocol.params import option

#: the learners the program drives itself; any table learner of `agent.learners.registry` too
LEARNERS = ("auto", "model", "tabular", "lspi", "sarsa", "planner", "reach")
OWN_LEARNERS = ("tabular", "lspi", "sarsa", "planner", "reach")


@dataclass(frozen=True)
class GenericProgramParams:
    """Hyperparameters of the generic program (ch. 6 recipe)."""

    learner: str = option(
        "auto",
        "auto (by the observation: see the module docstring), model (a counted model of a table, planned on), "
        "tabular (LSPI over a table), lspi, sarsa, planner or reach (many action dimensions and a short state vector: "
        "agent.learners.reach), or the name of a table learner an installed "
        "package declares (entry-point group sensorimotor.learners)",
    )
    samples_per_iteration: int = option(500, "tabular/lspi: new random-action samples between policy iterations", min=1)
    lspi_iterations: int = option(8, "at most this many LSPI iterations after each exploration phase", min=1)
    max_trace: int = option(
        0,
        "longest greedy trace recorded from a start state (0: the world's episode limit, at most 250; else 60)",
        min=0,
    )
    gamma: float = option(0.9, "LSPI discount", min=0.0, max=0.999)
    ridge: float = option(1e-3, "LSPI ridge regulariser", min=0.0)
    dims: int = option(
        0, "embedding dimensions (0: the truth's, as the world declares it in `truth_dims`, else 2)", min=0
    )
    components: int = option(8, "PCA components of the observations", min=1)
    centres: int = option(60, "radial basis functions in the PCA space", min=1)
    width: float = option(1.0, "RBF width, in units of the median spacing of the centres", min=0.01)
    projection: int = option(256, "observations longer than this are randomly projected to it first", min=8)
    reservoir: int = option(1000, "observations kept (a uniform sample of all seen) to fit PCA and centres", min=10)
    max_samples: int = option(5000, "LSPI samples kept (the newest)", min=10)
    max_categories: int = option(4096, "an integer sensor with at most this many values is a state id", min=2)
    symbol_values: int = option(
        32, "integer sensors with at most this many values each are tabulated by distinct observation", min=2
    )
    table_size: int = option(2048, "distinct observations a table holds (later ones share its last row)", min=2)
    model_gamma: float = option(
        0.99,
        "model learner: discount of the plan (the values are the discounted chance of reaching the goal: a long "
        "horizon takes the safe way round in a stochastic world, and the shortest way in a deterministic one)",
        min=0.5,
        max=0.9999,
    )
    model_known: int = option(
        30, "model learner, stochastic world: tries of an action before its counted outcomes are trusted", min=1
    )
    model_epsilon: float = option(
        0.05, "model learner: random-action rate while exploring, once no action nearby is untried", min=0.0, max=1.0
    )
    model_every: int = option(
        50, "model learner: transitions between plans while new actions become known (exploration)", min=1
    )
    sarsa_max_dims: int = option(
        6, "learner=auto: continuous observations of at most this many values use Sarsa", min=1
    )
    tiles: int = option(8, "Sarsa: tiles per dimension and tiling", min=1)
    tilings: int = option(8, "Sarsa: offset tilings", min=1)
    memory: int = option(1 << 18, "Sarsa: weights per action; more tiles than this are hashed", min=64)
    alpha: float = option(0.3, "Sarsa step size (shared by the tilings)", min=1e-6, max=1.0)
    lam: float = option(0.9, "Sarsa trace decay lambda", min=0.0, max=1.0)
    sarsa_gamma: float = option(
        0.99, "Sarsa discount (a failure is worth -1 / (1 - gamma), as never arriving)", min=0.5, max=0.9999
    )
    epsilon: float = option(
        0.0, "Sarsa exploration rate (optimistic initial values explore without it)", min=0.0, max=1.0
    )
    embed_every: int = option(5000, "Sarsa: learning steps between embedding sweeps", min=1)
    sarsa_warmup: int = option(
        1000,
        "Sarsa and the planner: random steps first, to measure each value's range (the tiles, the planner's grid) "
        "and, with action_scale=0, how faithfully whole and half moves are carried out (over camera frames: "
        "after the motor map's warm-up, in its coordinates)",
        min=0,
    )
    planner_max_dims: int = option(
        4, "learner=auto: continuous observations of at most this many values with box actions of 2+ dims plan", min=1
    )
    planner_grid: int = option(
        0, "planner: grid nodes per dimension (0: 16, fewer when 16 per value would pass 4096 nodes)", min=0
    )
    planner_every: int = option(250, "planner: transitions between plans (value iteration over the model)", min=1)
    planner_epsilon: float = option(0.05, "planner: random-action rate while learning", min=0.0, max=1.0)
    planner_effort: float = option(
        0.3,
        "planner: cost of the largest action, in steps (of two actions whose cost-to-go differs by less, the "
        "smaller: the plan's interpolated values are that uncertain, and traces become a function of the start)",
        min=0.0,
    )
    motor_warmup: int = option(
        3000,
        "planner over camera frames: random moves whose transitions fit the motor coordinates (the planner's "
        "state: see agent.learners.motor_map)",
        min=10,
    )
    motor_components: int = option(
        32, "planner over camera frames: principal components of the frames the motor map is built on", min=1
    )
    motor_scale: float = option(
        0.0,
        "planner over camera frames: the warm-up's random moves span this fraction of each bound (0: "
        "action_scale, whole moves when that is 0; larger moves change a frame by more pixels, so the map is fitted "
        "on clearer differences)",
        min=0.0,
        max=1.0,
    )
    action_levels: int = option(3, "values per dimension when a box action space is discretised", min=2)
    action_scale: float = option(
        0.0,
        "box actions: the discretised values span this fraction of each bound, about the box's middle "
        "(smaller moves: finer traces, for a body that follows small moves more faithfully); 0: whole "
        "moves, except for the planner when its warm-up (over camera frames: in the motor coordinates) finds half "
        "moves carried out more faithfully (a linear fit of the moves sent leaves over a quarter of a whole move's step "
        "unexplained, and at least a tenth less of a half move's: agent.programs.box_moves)",
        min=0.0,
        max=1.0,
    )
    distance: str = option(
        "auto",
        "box actions: padded sum (Eq 3.1) or dtw between the continuous traces, or net: the distance "
        "between their sums (the net move commanded, for bodies whose moves add up, such as a hand); "
        "auto: net for the planner once a sweep shows the moves add up (where each trace ended less "
        "where it started is linear in its summed moves, explaining 90 % of its variance: "
        "agent.programs.box_moves), else padded",
        choices=("auto", "padded", "dtw", "net"),
    )
    axis_gains: str = option(
        "auto",
        "net moves: auto scales each move axis by the gain the sweep's displacements show, where the "
        "planner plans over the observation itself with one value per move axis and each axis follows "
        "its own moves (agent.programs.box_moves.axis_gains), so the map is in the units the body "
        "senses; off keeps the moves' units",
        choices=("auto", "off"),
    )
    discrete_distance: str = option(
        "auto",
        "discrete actions: edit distance between traces (Algorithm 1), or moves: the distance between how "
        "many times each action occurs in them (turns left out; where moves add up it keeps the places "
        "round walls and holes, agent.embedding.move_counts); auto: moves over a table of states (tabular "
        "and model learners) where each start has one trace (a deterministic world), else edit",
        choices=("auto", "edit", "moves"),
    )
    embedding: str = option(
        "auto",
        "classical MDS of the trace distances, or weighted: metric MDS from it, each pair weighted by "
        "distance^-2 (the near pairs place the points; agent.embedding.weighted_mds); auto: weighted "
        "where the moves distance is used (up to 1,000 starts), else classical",
        choices=("auto", "classical", "weighted"),
    )
    rank: str = option(
        "auto",
        "once the policy is watched, a newer policy is published when it is better by: more goals, "
        "then shorter traces (goals), or a lower end disparity (ends, the planner: its traces end "
        "more nearly where a similarity of their starts puts them, which a net-move map needs); "
        "auto: ends for the planner comparing net moves (distance=net, or auto settled on net) in a "
        "deterministic world, else goals",
        choices=("auto", "goals", "ends"),
    )
    dtw_penalty: float = option(
        1.0, "distance=dtw: cost of each repeated step (keeps trace length in the distance)", min=0.0
    )
    samples: int = option(
        0,
        "traces per start state once the world is seen to be stochastic (every estimator: the goal fraction "
        "that ranks and watches policies is estimated from all of them); 0: for the mean_trace and auto "
        "estimators 768 traces a sweep, 8 to 64 per start (a mean trace's noise falls with its samples), else 8",
        min=0,
        max=100,
    )
    estimator: str = option(
        "auto",
        "stochastic worlds: mode trace or mean pairwise distance (ch. 9.4), mean_trace (the padded sum "
        "between the starts' mean traces, a distance between trace distributions), or plain (the first "
        "sampled trace of each start, as in a deterministic world: the figure the estimators are "
        "compared with); auto, discrete actions: at each sweep, the mode trace where it is at least half of "
        "a start's samples on average (the policy controls the world's chance), else mean_trace (slippery "
        "ice: every sample another trace); box actions: mode",
        choices=("auto", "mode", "mean", "mean_trace", "plain"),
    )
    stochastic_gamma: float = option(
        0.99,
        "tabular learner in a stochastic world: LSPI discount (a long horizon: the safe way round, not the "
        "short risky one)",
        min=0.0,
        max=0.999,
    )
    stochastic_samples: int = option(
        50_000, "tabular learner in a stochastic world: LSPI samples kept (the average of many outcomes)", min=10
    )
    frames: str = option(
        "auto",
        "discrete actions: compare traces in the frame of the start when some actions are rotations "
        "(auto: found from experience, see agent.embedding.rotation_frames), or as they are (off)",
        choices=("auto", "off"),
    )
    watch_after: float = option(
        0.9,
        "a sweep that reaches the goal from this fraction of starts makes the policy accepted (watched); after a "
        "drop in a deterministic world, so does the plan of a complete model (the best the changed body allows)",
        min=0.0,
        max=1.0,
    )
    settle: int = option(
        3,
        "stochastic worlds: a policy still the accepted one after this many newer policies, none better "
        "beyond the noise of the sampled goal fractions, has converged and is watched (where no policy "
        "reaches `watch_after` of the starts: FrozenLake's slippery ice, the best from 3 in 4)",
        min=1,
    )
    learn_lag: int = option(
        75,
        "acts between the start of a background learning job (feature refit + LSPI, MDS) and the act "
        "that uses it (short: the samples taken meanwhile come from the previous policy)",
        min=1,
    )


__all__ = ["LEARNERS", "OWN_LEARNERS", "GenericProgramParams"]
