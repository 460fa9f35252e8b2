"""`BodyChanges`: the one layer between the node and any World that applies the generic changes.

It is a World itself, wrapping another: actions pass through the action changes in the order
they were applied (so ``reverse`` twice is the body as it was), observations through the sensor
changes, and everything else goes to the world unchanged. A kind the world declares itself
(`World.own_perturbations`: its `Perturbations`, or a Gymnasium environment's hook) goes to the
world: its own takes precedence. ``restore`` undoes every generic change, and the world's own
``restore`` (or else ``heal``) when it has one. The spec advertises the kinds (see `advertise`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, Control, Truth, WorldSpec
from sensorimotor.worlds.base import PerturbationError, StepResult, World, check_perturbation
from sensorimotor.worlds.body_changes import motor, sensors
from sensorimotor.worlds.body_changes.advertise import KEY, advertisement
from sensorimotor.worlds.body_changes.kinds import GENERIC, LesionParams, kinds_for


class BodyChanges(World):
    """`world` with the generic body changes (reverse, permute, gain, lesion, noise, delay, restore).

    Parameters
    ----------
    world : World
        The world served; it keeps its own perturbations, which take precedence.

    Examples
    --------
    >>> import numpy as np
    >>> from sensorimotor.protocol.messages import Control
    >>> from sensorimotor.worlds.gridworld import GridWorld
    >>> w = BodyChanges(GridWorld("g", size=5))
    >>> w.perturb(Control("g", "permute", {"order": "0:1"}))
    'actions exchanged: 0->1, 1->0'
    """

    def __init__(self, world: World) -> None:
        super().__init__(world.world_id, world.seed)
        self.world = world
        self.kind = world.kind
        self.max_episode_steps = world.max_episode_steps
        self.params = getattr(world, "params", None)
        inner = world.spec()
        self._space, self._sensors = inner.action_space, inner.sensors
        self.own = dict(world.own_perturbations())
        self.generic = {k: v for k, v in kinds_for(self._space).items() if k not in self.own}
        self._advert = advertisement(self.own, self.generic)
        self.actions: list[motor.ActionChange] = []
        self.senses: list[sensors.SensorChange] = []
        self._raw: StepResult | None = None  # the world's last result, before the sensor changes
        self._t = 0

    def perturbations(self) -> dict[str, type]:
        """Every kind this world takes: its own, then the generic ones it has no own kind for."""
        return {**self.own, **self.generic}

    def own_perturbations(self) -> dict[str, type]:
        return self.perturbations()

    # the World interface -----------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """The world's spec, its params with the kinds it takes (``perturbations``)."""
        s = self.world.spec()
        return dataclasses.replace(s, params={**s.params, KEY: self._advert})

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        r = self.world.reset(seed=seed, start=start)
        self._raw, self._t = r, 0
        for ch in self.actions:
            ch.reset()
        return self._sense(r)

    def step(self, action: np.ndarray) -> StepResult:
        if not self.actions:  # the hot path: no change on the action channel
            self._t += 1
            self._raw = self.world.step(action)
            return self._sense(self._raw) if self.senses else self._raw
        given = np.asarray(action, dtype=np.float64).reshape(-1)
        a: np.ndarray | None = given
        times = 1
        if self._fits(given):
            for ch in self.actions:
                if a is None:
                    break
                a = ch.apply(a)
                if a is not None and ch.rng is not None:
                    times *= ch.repeats(a)
        self._t += 1
        if a is None or times == 0:  # the body did nothing: the world is where it was
            prev = self._raw if self._raw is not None else self.world.reset()
            over = self._t >= self.max_episode_steps
            r = StepResult(prev.tensors, 0.0, over, {"body": "did not act"}, truncated=over)
        else:
            r = self.world.step(a)
            reward = r.reward
            for _ in range(times - 1):  # a stronger motor: the same action again, within the step
                if r.done:
                    break
                r = self.world.step(a)
                reward += r.reward
            if times > 1:
                r = dataclasses.replace(r, reward=reward)
        self._raw = r
        return self._sense(r)

    def truth(self) -> Truth | None:
        return self.world.truth()

    def frame(self) -> np.ndarray | None:
        return self.world.frame()

    def close(self) -> None:
        self.world.close()

    # changes -----------------------------------------------------------------------------------
    def perturb(self, control: Control) -> str:
        """Apply a change: the world's own kind by the world, a generic one here; refuse anything
        else (or bad parameters) with a PerturbationError naming the valid kinds or values,
        before anything changes."""
        kind = control.kind
        if kind == "restore":
            return self._restore(control)
        if kind in self.own:
            return self.world.perturb(control)
        if kind not in self.generic:
            check_perturbation(self.kind, self.perturbations(), control)  # raises, naming the valid kinds
        p = check_perturbation(self.kind, self.generic, control)
        try:
            if kind == "noise":
                self.senses.append(sensors.noise(p, self._sensors))
                return self.senses[-1].detail
            if kind == "lesion" and isinstance(p, LesionParams) and p.what == "sensor":
                self.senses.append(sensors.lesion(p, self._sensors))
                return self.senses[-1].detail
            if kind == "reverse":
                change = motor.reverse(p, self._space, self.world.opposite_actions())
            else:
                build: dict[str, Callable[[Any, ActionSpace], motor.ActionChange]] = {
                    "permute": motor.permute,
                    "gain": motor.gain,
                    "lesion": motor.lesion,
                    "delay": motor.delay,
                }
                change = build[kind](p, self._space)
        except PerturbationError as e:
            raise PerturbationError(f"{self.kind} {e}") from None
        self.actions.append(change)
        return change.detail

    def _restore(self, control: Control) -> str:
        n = len(self.actions) + len(self.senses)
        words = [f"{n} generic change(s) undone"]
        if "restore" in self.own:
            words.append(self.world.perturb(control))
        else:
            check_perturbation(self.kind, {"restore": GENERIC["restore"]}, control)
            if "heal" in self.own:
                words.append(self.world.perturb(Control(control.world_id, "heal", {}, control.id, control.timestamp)))
        self.actions, self.senses = [], []
        return "restored: " + "; ".join(words)

    def _fits(self, a: np.ndarray) -> bool:
        """Whether `a` is an action of the space (else it goes to the world as it is, to be refused there)."""
        if self._space.discrete:
            return a.size >= 1 and float(a[0]).is_integer() and 0 <= a[0] < self._space.n
        return a.size == len(self._space.low) and bool(np.all(np.isfinite(a)))

    def _sense(self, r: StepResult) -> StepResult:
        if not self.senses:
            return r
        tensors = r.tensors
        for ch in self.senses:
            tensors = ch.apply(tensors)
        return dataclasses.replace(r, tensors=tensors)


def served(world: World) -> World:
    """`world` with the generic changes (a world already wrapped is returned as it is)."""
    return world if isinstance(world, BodyChanges) else BodyChanges(world)


__all__ = ["BodyChanges", "served"]
