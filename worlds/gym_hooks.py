"""The hooks a Gymnasium environment offers a world (`EmbeddableEnv` and the ``sme_*`` methods on
any wrapper layer): its start states, how to reset to one, its truth and its own body changes."""

from collections.abc import Callable, Mapping
from typing import Any

import gymnasium as gym
import numpy as np

from sensorimotor.protocol.messages import GoalRule


class EmbeddableEnv(gym.Wrapper):
    """The hook that makes any environment embeddable, as a wrapper: its start states, how to reset
    to one, and their truth (and, optionally, how its goal is recognised).

    An environment can offer the same by itself, with methods ``sme_start_states()``,
    ``sme_reset_to(start)``, ``sme_truth()``, ``sme_perturb(kind, params)`` and attributes
    ``sme_goal`` and ``sme_perturbations``, on any wrapper layer.

    Parameters
    ----------
    env : gymnasium.Env
        The environment.
    starts : sequence
        The start states, as whatever `reset_to` takes.
    reset_to : callable
        ``reset_to(env, start) -> observation``: after ``env.reset()``, put the environment into
        `start` and return its observation.
    truth : array-like
        ``[len(starts), d]`` true coordinates of the start states.
    goal : str or None, default=None
        A `GoalRule` token, when the family default does not fit.
    perturb : callable or None, default=None
        ``perturb(env, kind, params) -> str``: apply a body change of the environment's own and
        say what changed (see `worlds.body_changes.hook`); raise ValueError to refuse it.
    perturbations : mapping or None, default=None
        The kinds `perturb` offers: kind -> parameter dataclass (`params` is then its parsed
        instance) or a one-line description (`params` is then a dict of strings).

    Examples
    --------
    ::

        env = EmbeddableEnv(MyEnv(), starts=cells, reset_to=lambda e, c: e.unwrapped.place(c), truth=cells)
        gymnasium.register("my/Env-v0", entry_point=lambda **kw: EmbeddableEnv(MyEnv(**kw), ...))
        # sme world gym:my_package:my/Env-v0
    """

    def __init__(
        self,
        env: gym.Env,
        starts: Any,
        reset_to: Callable[[gym.Env, Any], Any],
        truth: Any,
        goal: str | None = None,
        perturb: Callable[[gym.Env, str, Any], str] | None = None,
        perturbations: Mapping[str, Any] | None = None,
    ) -> None:
        super().__init__(env)
        self._starts, self._reset_to = list(starts), reset_to
        self._truth = np.asarray(truth, dtype=np.float64)
        if self._truth.ndim != 2 or self._truth.shape[0] != len(self._starts):
            raise ValueError(f"truth must be [len(starts), d]; got {self._truth.shape} for {len(self._starts)} starts")
        if goal is not None:
            self.sme_goal = GoalRule(goal)
        if (perturb is None) != (perturbations is None):
            raise ValueError("perturb and perturbations go together: the hook and the kinds it offers")
        if perturb is not None:
            self.sme_perturbations = dict(perturbations or {})
            self._perturb = perturb

    def sme_perturb(self, kind: str, params: Any) -> str:
        """Apply the environment's own body change `kind` (the `perturb` given)."""
        if getattr(self, "_perturb", None) is None:
            raise ValueError("this EmbeddableEnv was given no perturb hook")
        return self._perturb(self.env, kind, params)

    def sme_start_states(self) -> list[Any]:
        return list(self._starts)

    def sme_reset_to(self, start: Any) -> Any:
        return self._reset_to(self.env, start)

    def sme_truth(self) -> np.ndarray:
        return self._truth


def _layers(env: gym.Env) -> list[Any]:
    """The wrapper layers of `env`, outermost first, down to the unwrapped environment."""
    out: list[Any] = []
    e: Any = env
    while e is not None and e not in out:
        out.append(e)
        e = getattr(e, "env", None) if isinstance(e, gym.Wrapper) else None
    return out


def _hooked(env: gym.Env, name: str) -> Any:
    """Attribute `name` of the first wrapper layer (or the unwrapped environment) that has it."""
    for layer in _layers(env):
        try:
            return getattr(layer, name)
        except AttributeError:
            continue
    return None
