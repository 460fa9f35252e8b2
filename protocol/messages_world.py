"""The messages of a world: what it offers (`WorldSpec`: sensors, action space, goal), what it
observes, the actions and controls it is sent, its ground truth and the events it reports."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sensorimotor.protocol.messages_kinds import GoalRule


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
