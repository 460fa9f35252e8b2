"""The World interface: what every simulator offers, in-process or served over the bus by `node`."""

from __future__ import annotations

import abc
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from sensorimotor.protocol.messages import Control, Truth, WorldSpec


@dataclass(frozen=True)
class StepResult:
    """What a world returns from `reset` and `step`.

    Attributes
    ----------
    tensors : dict of str to ndarray
        One tensor per sensor of the spec.
    reward : float
        The reward received on entering this state (0 after a reset).
    done : bool
        Whether the episode ended.
    info : dict
        Extra information for the caller (never sent on the bus).
    """

    tensors: dict[str, np.ndarray]
    reward: float = 0.0
    done: bool = False
    info: dict[str, Any] = field(default_factory=dict)


class PerturbationError(ValueError):
    """A Control the world cannot apply; the message says why."""


@dataclass(frozen=True)
class NoParams:
    """The parameters of a world without parameters."""


class World(abc.ABC):
    """A simulator the agent learns from. Worlds own their random generator (`seed=`).

    A world declares its parameters once, as a frozen dataclass (see `protocol.params`) named by the
    class attribute `Params`; its constructor takes `(world_id, seed, params=None, **overrides)` and
    keeps the parsed instance as `self.params`. A subclass implements `spec`, `reset` and `step`,
    and may implement `perturb`, `truth`, `frame` and `close`. `Lockstep` drives it, in-process
    (`tools.inprocess.run_inprocess`) or over the bus (`WorldNode`).

    Parameters
    ----------
    world_id : str, default="w0"
        The world's id on the bus.
    seed : int, default=0
        Seeds `self.rng`, the world's only source of randomness.

    Attributes
    ----------
    kind : str
        The world kind (its registry name).
    max_episode_steps : int
        Steps after which an episode ends.
    Params : type
        The parameter dataclass.
    params : Params instance
        The parsed parameters.
    rng : numpy.random.Generator
        The world's random generator.

    Examples
    --------
    >>> import numpy as np
    >>> from sensorimotor.worlds.gridworld import GridWorld
    >>> with GridWorld("grid0", seed=1, size=5) as w:
    ...     r = w.reset(start=0)
    ...     r = w.step(np.array([1.0]))
    >>> w.spec().world_id
    'grid0'
    """

    kind: str = "world"
    max_episode_steps: int = 1000
    Params: ClassVar[type] = NoParams
    # the parsed instance of `Params`; Any because a subclass may declare other parameters than its
    # base (MountainCarWorld extends VergenceWorld with its own MountainCarWorldParams)
    params: Any

    def __init__(self, world_id: str = "w0", seed: int = 0) -> None:
        self.world_id = world_id
        self.seed = seed
        self.rng = np.random.default_rng(seed)

    @abc.abstractmethod
    def spec(self) -> WorldSpec:
        """What the world is: its sensors, action space, reward range, program and start states.

        Returns
        -------
        WorldSpec
            Constant for the world's lifetime (a perturbation changes the body, not the spec).
        """

    @abc.abstractmethod
    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Begin an episode from start state `start` (0..n_starts-1) or a random one (None).

        Parameters
        ----------
        seed : int or None, default=None
            Reseed `self.rng` first (None: keep the generator).
        start : int or None, default=None
            The start state; None (or negative) draws one at random.

        Returns
        -------
        StepResult
            The first observation of the episode (reward 0).

        Raises
        ------
        ValueError
            If `start` is out of range (`Lockstep` then refuses the reset).
        """

    @abc.abstractmethod
    def step(self, action: np.ndarray) -> StepResult:
        """Apply one action.

        Parameters
        ----------
        action : ndarray
            float64, one value per action dimension (discrete: ``action[0]`` is the index).

        Returns
        -------
        StepResult
            The next observation, the reward received on entering it, and whether the episode ended.

        Raises
        ------
        ValueError
            If the action cannot be applied (`Lockstep` refuses it and starts a new episode).
        """

    def pick_start(self, seed: int | None, start: int | None, n_starts: int) -> int:
        """For `reset`: reseed if asked, draw a random start state when `start` is None or negative,
        refuse one out of range."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if start is None or start < 0:
            return int(self.rng.integers(n_starts))
        if start >= n_starts:
            raise ValueError(f"start {start} out of range 0..{n_starts - 1}")
        return int(start)

    def perturb(self, control: Control) -> str:
        """Apply a perturbation (a body change, a lesion...) between steps.

        Parameters
        ----------
        control : Control
            ``control.kind`` names the perturbation; ``control.params`` are its parameters as
            strings (read them with `param`).

        Returns
        -------
        str
            A one-line description of what changed.

        Raises
        ------
        PerturbationError
            If this world has no such perturbation (the default), or its parameters are invalid.
        """
        raise PerturbationError(f"world kind {self.kind!r} has no perturbation {control.kind!r}")

    def truth(self) -> Truth | None:
        """Ground truth for evaluation only (never fed to learners).

        Returns
        -------
        Truth or None
            ``tensors["positions"]``: the true coordinates of the start states (or points) the
            embeddings are scored against; None for a world without truth (the default). It may
            change after a perturbation.
        """
        return None

    def frame(self) -> np.ndarray | None:
        """The latest camera frame (uint8 [H, W] or [H, W, 3]) for viewers and recordings, if any."""
        return None

    def close(self) -> None:
        """Release what the world holds (a physics server...); the default does nothing."""

    def __enter__(self) -> World:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def param(params: Mapping[str, Any], name: str, default: Any, cast: type = str) -> Any:
    """Read one perturbation (`Control`) parameter with a clear error when it does not parse.

    World parameters are declared in the world's `Params` dataclass instead.

    Parameters
    ----------
    params : mapping of str to str
        ``Control.params``.
    name : str
        The parameter.
    default : object
        Returned when `name` is absent.
    cast : type, default=str
        The type to convert to (``bool`` accepts 1/0, true/false, yes/no, on/off).

    Returns
    -------
    object
        The converted value, or `default`.

    Raises
    ------
    ValueError
        If the value does not convert.
    """
    if name not in params:
        return default
    raw = params[name]
    try:
        if cast is bool and isinstance(raw, str):
            if raw.lower() in ("1", "true", "yes", "on"):
                return True
            if raw.lower() in ("0", "false", "no", "off"):
                return False
            raise ValueError(raw)
        return cast(raw)
    except (TypeError, ValueError):
        raise ValueError(f"parameter {name}={raw!r} is not a valid {cast.__name__}") from None
