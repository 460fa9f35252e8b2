"""The messages as plain frozen dataclasses: what agent and worlds work with (never protobuf)."""

from __future__ import annotations

from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np

SCHEMA_VERSION = 1
MAX_ECHO = 1000  # characters of its input an event's detail or a log line copies at most (see `clip`)


def clip(text: str, limit: int = MAX_ECHO) -> str:
    """`text` cut to `limit` characters with a note of how much was left out: events and log lines
    say what input they refused without copying all of it (1 MB in must not make a 1 MB event)."""
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... [{len(text) - limit} more characters not shown]"


#: `WorldSpec.program` of a world driven by an outside controller (`sme world --external`, a
#: Gymnasium `BusEnv`): agents do not attach to it
EXTERNAL_PROGRAM = "external"


class EventKind(StrEnum):
    """The `kind` of an AgentEvent (one token on the wire; see protocol/README.md)."""

    ATTACHED = "attached"  # a link to a world was made; `config` says how
    ATTACH_FAILED = "attach_failed"  # `reason`: no_spec, bad_spec, no_program, bad_checkpoint, ...
    PAUSED = "paused"  # `reason`: world_gone, program_errors
    RESUMED = "resumed"
    BAD_INPUT = "bad_input"  # `reason`: the rejection kind (malformed, non_finite, ...)
    DROP_DETECTED = "drop_detected"  # `reason`: the detector's name
    RELEARNING = "relearning"
    RELEARNED = "relearned"
    PROGRAM_ERROR = "program_error"  # `reason`: the exception's type name
    PROGRAM_FALLBACK = "program_fallback"  # the world asked for a program the agent lacks (`reason`)
    POLICY_ITERATION = "policy_iteration"
    EVALUATION = "evaluation"
    WORLD_EVENT = "world_event"  # a WorldEvent the agent saw, `reason` = its kind
    LEASE_LOST = "lease_lost"  # the world applies another owner's actions now: this agent stopped answering it
    LEASE_REFUSED = "lease_refused"  # the world's lease is held by another owner; this agent waits (`reason`: held)


class Trigger(StrEnum):
    """Why an Embedding version was made (its `trigger`)."""

    RANDOM_POLICY = "random_policy"
    POLICY_ITERATION = "policy_iteration"  # `iteration` says which
    PERIODIC = "periodic"
    RELEARNED = "relearned"  # after a detected drop, at `drop_step`
    POLICY_MAP = "policy_map"  # clustered traces of a trained policy (ch. 9.6), `labels` per row


class GoalRule(StrEnum):
    """How a world's goal is recognised (`WorldSpec.goal`): what ends a trace as a success."""

    REWARD = "reward"  # a positive reward (the dissertation's worlds)
    TERMINATED = "terminated"  # the episode ended on a terminal state, not by a time limit (Gymnasium)
    SUCCESS = "success"  # the observation's success flag (panda-gym's, Gymnasium-Robotics' is_success)
    NONE = "none"  # no goal state (CartPole, Pendulum: their terminations are failures or never come)


class WorldEventKind(StrEnum):
    """The `kind` of a WorldEvent."""

    ACTION_REFUSED = "action_refused"  # the world could not apply an action; it reset the episode instead
    CONTROL_APPLIED = "control_applied"
    CONTROL_REFUSED = "control_refused"
    LEASE_LOST = "lease_lost"  # an action whose owner/epoch is not the current lease was not applied


@dataclass(frozen=True)
class SensorSpec:
    """One sensor a world publishes: every Observation carries a tensor of exactly this dtype and shape.

    Attributes
    ----------
    name : str
        The tensor's name in `Observation.tensors`.
    dtype : str
        A numpy dtype name (``uint8``, ``float32``, ...; see `codec.DTYPES`).
    shape : tuple of int
        The tensor's shape.
    low, high : float
        The range of the values (documentation for programs and viewers).
    description : str
        What the sensor measures, for people.
    """

    name: str
    dtype: str
    shape: tuple[int, ...]
    low: float = 0.0
    high: float = 1.0
    description: str = ""


@dataclass(frozen=True)
class ActionSpace:
    """The actions a world accepts: discrete (``n > 0``) or a box (`low`/`high` per dimension).

    Attributes
    ----------
    n : int
        The number of discrete actions (0 for a box).
    low, high : tuple of float
        Per-dimension bounds of a box.
    names : tuple of str
        Optional names of the discrete actions or box dimensions.
    """

    n: int = 0
    low: tuple[float, ...] = ()
    high: tuple[float, ...] = ()
    names: tuple[str, ...] = ()

    @property
    def discrete(self) -> bool:
        """Whether actions are indices (``values[0]`` in ``0..n-1``)."""
        return self.n > 0

    @property
    def dims(self) -> int:
        """The number of values an Action carries (1 for a discrete space)."""
        return 1 if self.discrete else len(self.low)


@dataclass(frozen=True)
class WorldSpec:
    """What a world is, answered on its spec queryable: what the agent needs before the first step.

    Attributes
    ----------
    world_id : str
        The world's id (a key chunk, see `keys.check_id`).
    kind : str
        The world kind (``gridworld``, ``retina``, ...).
    sensors : tuple of SensorSpec
        Every tensor an Observation carries.
    action_space : ActionSpace
        The actions the world accepts.
    reward_min, reward_max : float
        The reward range.
    program : str
        The developmental program the agent should run on this world.
    n_starts : int
        The number of start states the world can reset to.
    params : dict of str to str
        The world's parameters as exact ``k=v`` strings.
    session : str
        A random string per world process start (a new one means the world restarted).
    goal : str
        How the goal is recognised, a `GoalRule` token: ``reward`` (a positive reward),
        ``terminated`` (done and not truncated) or ``success`` (the observation's success flag).
    """

    world_id: str
    kind: str
    sensors: tuple[SensorSpec, ...]
    action_space: ActionSpace
    reward_min: float = 0.0
    reward_max: float = 1.0
    program: str = ""
    n_starts: int = 0
    params: dict[str, str] = field(default_factory=dict)
    session: str = ""
    goal: str = GoalRule.REWARD

    def sensor(self, name: str) -> SensorSpec:
        """The sensor called `name` (KeyError naming the world if there is none)."""
        for s in self.sensors:
            if s.name == name:
                return s
        raise KeyError(f"world {self.world_id!r} has no sensor {name!r}")


@dataclass(frozen=True)
class Observation:
    """What a world publishes at each lockstep step; the agent answers it with an Action.

    Attributes
    ----------
    world_id : str
        The world's id.
    episode : int
        The episode counter.
    step : int
        The per-world step counter, strictly increasing; the answering Action carries it.
    t : int
        The step within the episode (0 after a reset).
    tensors : dict of str to ndarray
        One tensor per sensor of the spec.
    reward : float
        The reward received on entering this state (0 at ``t = 0``).
    done : bool
        Whether the episode ended here (the answer resets the world).
    start : int
        The start state of this episode (-1 if random).
    timestamp : float
        Seconds since the epoch.
    session : str
        The world process's session (see `WorldSpec.session`).
    truncated : bool
        ``done`` because of a time limit, not a terminal state.
    success : bool
        The world's own success flag (goal rule ``success``).
    """

    world_id: str
    episode: int
    step: int
    t: int
    tensors: dict[str, np.ndarray]
    reward: float = 0.0
    done: bool = False
    start: int = -1
    timestamp: float = 0.0
    session: str = ""
    truncated: bool = False
    success: bool = False


@dataclass(frozen=True)
class Action:
    """The agent's answer to the observation of step `step`.

    Attributes
    ----------
    world_id : str
        The world's id.
    step : int
        The step of the observation this answers.
    values : tuple of float
        Discrete: ``values[0]`` is the action index; box: one value per dimension.
    reset : bool
        Start a new episode instead of stepping.
    start : int
        The start state of that episode (-1 for a random one).
    timestamp : float
        Seconds since the epoch.
    owner : str
        The owner id answering ("" from agents that predate leases).
    epoch : int
        The lease epoch that owner holds on the world (0: no lease).
    """

    world_id: str
    step: int
    values: tuple[float, ...] = ()
    reset: bool = False
    start: int = -1
    timestamp: float = 0.0
    owner: str = ""
    epoch: int = 0


@dataclass(frozen=True)
class Control:
    """A perturbation of a world (a body change, a lesion...), applied between steps.

    Attributes
    ----------
    world_id : str
        The world's id.
    kind : str
        The perturbation, as the world names it (see each world's `perturb`).
    params : dict of str to str
        The perturbation's parameters as strings.
    id : int
        An id the sender chooses, to match the world's report.
    timestamp : float
        Seconds since the epoch.
    """

    world_id: str
    kind: str
    params: dict[str, str] = field(default_factory=dict)
    id: int = 0
    timestamp: float = 0.0


@dataclass(frozen=True)
class Truth:
    """A world's ground truth, used to score embeddings and never to learn.

    Attributes
    ----------
    world_id : str
        The world's id.
    kind : str
        The world kind.
    tensors : dict of str to ndarray
        ``positions``: float64 ``[n, d]``, row *i* the true coordinates of start state or point *i*;
        worlds may add others.
    step : int
        The step at which the truth was taken.
    timestamp : float
        Seconds since the epoch.
    """

    world_id: str
    kind: str
    tensors: dict[str, np.ndarray]
    step: int = 0
    timestamp: float = 0.0


@dataclass(frozen=True)
class Embedding:
    """One version of what an agent learned about a world: coordinates of its states.

    Attributes
    ----------
    agent_id, world_id : str
        Who learned it, from which world.
    version : int
        Increases with every embedding of the link.
    trigger : str
        Why this version was made (a `Trigger` token; readers accept unknown tokens).
    ids : tuple of int
        The state (start) ids, one per row of `coordinates`.
    coordinates : ndarray
        ``[len(ids), d]`` embedded coordinates.
    eigenvalues : tuple of float
        The eigenvalues of the embedding's dimensions.
    procrustes_error : float or None
        The error against the world's truth after Procrustes alignment (None without truth).
    step : int
        The world step at which it was made.
    timestamp : float
        Seconds since the epoch.
    metrics : dict of str to float
        Program-specific scores (e.g. ``policy_success``).
    iteration : int
        The number of policy iterations the traces come from (trigger ``policy_iteration``).
    drop_step : int or None
        The step at which a reward drop was detected (trigger ``relearned``).
    labels : tuple of int
        Cluster of each row (trigger ``policy_map``); empty otherwise.
    scores : EmbeddingScores or None
        Trustworthiness, continuity and the two dissimilarities against truth (None without truth).
    """

    agent_id: str
    world_id: str
    version: int
    trigger: str
    ids: tuple[int, ...]
    coordinates: np.ndarray
    eigenvalues: tuple[float, ...]
    procrustes_error: float | None = None
    step: int = 0
    timestamp: float = 0.0
    metrics: dict[str, float] = field(default_factory=dict)
    iteration: int = 0
    drop_step: int | None = None
    labels: tuple[int, ...] = ()
    scores: EmbeddingScores | None = None


@dataclass(frozen=True)
class EmbeddingScores:
    """The field's scores of an embedding against ground truth (wire: `Embedding.scores`).

    Attributes
    ----------
    trustworthiness, continuity : float
        In [0, 1] (``sklearn.manifold.trustworthiness``; continuity swaps the spaces), over
        `n_neighbors` nearest neighbours.
    metric_dissimilarity, topological_dissimilarity : float
        Laflaquière et al. 2019: pairwise-distance dissimilarity after an affine fit of the truth,
        unweighted and weighted toward near pairs; 0 = an affine image of the truth.
    n_neighbors : int
        The k of trustworthiness and continuity.
    n_points : int
        Rows scored: fewer than the embedding's when it was subsampled (a fixed subset).
    """

    trustworthiness: float
    continuity: float
    metric_dissimilarity: float
    topological_dissimilarity: float
    n_neighbors: int
    n_points: int


@dataclass(frozen=True)
class AttachConfig:
    """What decides an agent's behaviour on one world besides its observations."""

    seed: int = 0
    detector: str = ""
    program: str = ""
    program_params: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class AgentEvent:
    """Something an agent reports about a link (attached, paused, drop detected...).

    Attributes
    ----------
    agent_id, world_id : str
        The agent and the world the link joins.
    kind : str
        An `EventKind` token.
    detail : str
        For people; never parsed.
    step : int
        The world step it refers to.
    timestamp : float
        Seconds since the epoch.
    values : dict of str to float
        Numbers that go with the event (e.g. ``reward`` and ``reference`` of a drop).
    reason : str
        A machine-readable sub-kind (see protocol/README.md).
    config : AttachConfig or None
        How the link was attached (kind ``attached`` only).
    """

    agent_id: str
    world_id: str
    kind: str
    detail: str = ""
    step: int = 0
    timestamp: float = 0.0
    values: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    config: AttachConfig | None = None


@dataclass(frozen=True)
class WorldEvent:
    """Something a world reports about itself (e.g. an action it could not apply, a control it
    applied or refused).

    Attributes
    ----------
    world_id, kind : str
        The world and what happened (`WorldEventKind`).
    reason, detail : str
        The machine-readable sub-kind (for controls: the control's kind) and words for people.
    step : int
        The observation step concerned.
    session, timestamp
        The world process's session and the time (seconds since the epoch).
    control_id : int
        For ``control_applied`` / ``control_refused``: the `Control.id` answered (0: none), so the
        sender (`sme perturb`) knows which of its requests this is.
    owner, epoch : str, int
        Kind ``lease_lost``: the owner whose action was not applied and the epoch it carried.
    holder, holder_epoch : str, int
        Kind ``lease_lost``: the lease as it stands.
    """

    world_id: str
    kind: str
    reason: str = ""
    detail: str = ""
    step: int = 0
    session: str = ""
    timestamp: float = 0.0
    owner: str = ""
    epoch: int = 0
    holder: str = ""
    holder_epoch: int = 0
    control_id: int = 0


@dataclass(frozen=True)
class LeaseRequest:
    """An owner asks a world for its lease (or gives it back, `release`), on `.../lease`.

    Attributes
    ----------
    world_id, owner : str
        The world asked and the asking owner.
    epoch : int
        The epoch the asker holds (0: none); with `release`, the epoch given back.
    release : bool
        Give the lease back instead of asking for it.
    request_id : str
        Random per request: a second copy of the same request (a message can arrive twice, once
        through each of two routers) gets the same answer instead of a second grant.
    """

    world_id: str
    owner: str
    epoch: int = 0
    release: bool = False
    request_id: str = ""


@dataclass(frozen=True)
class Lease:
    """A world's answer to a `LeaseRequest`: its lease as it stands after the request.

    Attributes
    ----------
    world_id, session : str
        The world and its process's session (epochs count within one session).
    holder : str
        The owner whose actions are applied ("" while nobody holds the lease).
    epoch : int
        The current epoch; it only grows within a session.
    granted : bool
        Whether the asker holds the lease now.
    reason : str
        ``granted``, ``renewed``, ``held`` (another owner holds it), ``released``, ``not_holder``.
    ttl : float
        Seconds of silence after which a live holder's lease may be granted to another owner.
    timestamp : float
        Seconds since the epoch.
    """

    world_id: str
    session: str
    holder: str
    epoch: int
    granted: bool
    reason: str = ""
    ttl: float = 0.0
    timestamp: float = 0.0


@dataclass(frozen=True)
class SharedCheckpoint:
    """One owner's learned state of one world, shared on the bus (`sme.v1.Checkpoint`).

    Attributes
    ----------
    world_id : str
        The world the state was learned on (it must match the key it arrives on).
    data : bytes
        A checkpoint file (the .npz of `agent.checkpoint`), at most `codec.MAX_TENSOR_BYTES`.
    owner : str
        The owner id that shares it ("" when unknown).
    epoch : int
        The owner's lease epoch on the world; 0 until owners hold leases (protocol/README.md, "Owners").
    format_version : int
        The checkpoint file format version inside `data`.
    embedding_version : int
        The embedding version the state had published.
    saved_at : float
        Seconds since the Unix epoch when the state was taken.
    """

    world_id: str
    data: bytes
    owner: str = ""
    epoch: int = 0
    format_version: int = 0
    embedding_version: int = 0
    saved_at: float = 0.0


@dataclass(frozen=True)
class LinkStatus:
    """The state of one agent-world link, as `sme status` shows it.

    Attributes
    ----------
    world_id, kind, program : str
        The world, its kind and the program running on it.
    state : str
        ``attached`` or ``paused``.
    steps, episodes : int
        Counted since the link was made.
    embedding_version : int
        The latest Embedding version.
    reward_mean : float
        The recent mean reward.
    rejected : dict of str to int
        Refused observations by error kind.
    last_procrustes_error : float
        The latest embedding's error (NaN when unknown).
    detector_statistic : float
        The drop detector's current statistic.
    drops : int
        Detected reward drops.
    """

    world_id: str
    kind: str
    program: str
    state: str
    steps: int = 0
    episodes: int = 0
    embedding_version: int = 0
    reward_mean: float = 0.0
    rejected: dict[str, int] = field(default_factory=dict)
    last_procrustes_error: float = float("nan")
    detector_statistic: float = 0.0
    drops: int = 0
    dropped: int = 0


@dataclass(frozen=True)
class AgentStatus:
    """An agent daemon's status, answered on its status queryable.

    Attributes
    ----------
    agent_id : str
        The agent's id.
    uptime : float
        Seconds since the daemon started.
    links : tuple of LinkStatus
        One per attached world.
    counters : dict of str to int
        Daemon-wide counters (``unattached``, ``attach_failed``, ...).
    timestamp : float
        Seconds since the epoch.
    """

    agent_id: str
    uptime: float
    links: tuple[LinkStatus, ...] = ()
    counters: dict[str, int] = field(default_factory=dict)
    timestamp: float = 0.0
