"""The messages of an agent: the embedding versions it publishes, its events (with how a link was
attached), and its status (`sme status`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


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
