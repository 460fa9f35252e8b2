"""The World interface: what every simulator offers, in-process or served over the bus by `node`."""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from sensorimotor.protocol.messages import Control, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, describe, format_value, parse, quote, suggest


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
    truncated : bool
        `done` because of a time limit, not a terminal state (sent as `Observation.truncated`).
    success : bool
        The world's own success flag (sent as `Observation.success`; goal rule ``success``).
    """

    tensors: dict[str, np.ndarray]
    reward: float = 0.0
    done: bool = False
    info: dict[str, Any] = field(default_factory=dict)
    truncated: bool = False
    success: bool = False


class PerturbationError(ValueError):
    """A Control the world cannot apply; the message says why."""


def check_perturbation(kind: str, perturbations: Mapping[str, type], control: Control) -> Any:
    """`control.params` parsed with the declaration of its kind in `perturbations` (a world kind's
    `World.Perturbations`), or a PerturbationError naming the parameter and every valid range.

    The world calls it before it changes anything; `sme perturb` calls it too, with the declaration
    of the running world's kind, so that it refuses at once what the world would refuse."""
    cls = perturbations.get(control.kind)
    if cls is None:
        best = suggest(control.kind, perturbations)
        hint = f" (did you mean {best!r}?)" if best else ""
        valid = ", ".join(perturbations) or "(none)"
        raise PerturbationError(f"{kind} has no perturbation {quote(control.kind)}{hint}; valid: {valid}")
    name = f"{kind} {control.kind}"
    try:
        return parse(cls, dict(control.params), name=name)
    except ParamError as e:
        raise PerturbationError(f"{e}; {name} takes {param_ranges(cls)}") from None


@dataclass(frozen=True)
class NoParams:
    """The parameters of a world without parameters."""


@dataclass(frozen=True)
class HealParams:
    """Undo every perturbation: the body and sensors the world started with."""


def param_ranges(cls: type) -> str:
    """One line naming every declared parameter of `cls` with its type, range and default, e.g.
    ``"radius: float in 0.0..512.0 (default 6.0)"``; for refusal messages."""
    fields = {f.name: f for f in dataclasses.fields(cls)}
    parts = []
    for info in describe(cls):
        meta = fields[info.name].metadata
        lo, hi, choices = meta.get("min"), meta.get("max"), meta.get("choices")
        if choices is not None:
            rng = " one of " + "|".join(format_value(c) for c in choices)
        elif lo is not None and hi is not None:
            rng = f" in {format_value(lo)}..{format_value(hi)}"
        elif lo is not None:
            rng = f" >= {format_value(lo)}"
        elif hi is not None:
            rng = f" <= {format_value(hi)}"
        else:
            rng = ""
        parts.append(f"{info.name}: {info.type}{rng} (default {info.default})")
    return ", ".join(parts) if parts else "no parameters"


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
    #: perturbation kind -> its parameter dataclass (declared once; `perturbation_params` parses)
    Perturbations: ClassVar[Mapping[str, type]] = {}
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

    def perturbation_params(self, control: Control) -> Any:
        """`control.params` parsed with the declaration of its kind in `Perturbations`.

        Call it before changing anything: an unknown kind, an unknown key, a value that is not of
        the declared type (NaN and inf are not floats here) or out of range raises a
        PerturbationError naming the parameter and every valid range, and the world stays as it was.
        """
        return check_perturbation(self.kind, self.Perturbations, control)

    def own_perturbations(self) -> Mapping[str, type]:
        """The kinds this world applies itself (default: `Perturbations`); served by our node, it
        also takes the generic kinds of `worlds.body_changes`, and its own take precedence."""
        return self.Perturbations

    def opposite_actions(self) -> list[tuple[int, int]] | None:
        """Pairs of discrete actions that undo each other (up/down...), for the generic ``reverse``;
        None (the default): found from the spec's action names, else the mirrored index."""
        return None

    def perturb(self, control: Control) -> str:
        """Apply a perturbation; return a one-line description of what changed. Refuse a bad one
        with a PerturbationError before changing anything (see `perturbation_params`)."""
        self.perturbation_params(control)
        raise PerturbationError(f"world kind {self.kind!r} has no perturbation {quote(control.kind)}")

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
