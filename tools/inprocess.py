"""Run a World and a Program in one process, no bus, through the daemon's own WorldLink (the
same lockstep protocol, scoring, drop detection and events). Used by tests, `reproduce` and the
loop benchmark's baseline."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from sensorimotor.agent.attach import AgentConfig, attach
from sensorimotor.agent.detectors import DropDetector
from sensorimotor.agent.programs.base import Program
from sensorimotor.protocol.messages import AgentEvent, Control, Embedding, Observation
from sensorimotor.worlds.base import World
from sensorimotor.worlds.lockstep import Lockstep


@dataclass
class InProcessRun:
    """What `run_inprocess` did: steps, episodes, seconds, and every message the agent published.

    Attributes
    ----------
    steps, episodes : int
        Answered steps and episodes begun.
    seconds : float
        Wall time of the loop.
    outputs : list
        Embedding, AgentEvent and WorldEvent messages, in order.
    """

    steps: int = 0
    episodes: int = 0
    seconds: float = 0.0
    outputs: list[Any] = field(default_factory=list)  # Embedding and AgentEvent messages, in order

    @property
    def embeddings(self) -> list[Embedding]:
        """The Embedding messages, in order."""
        return [o for o in self.outputs if isinstance(o, Embedding)]

    @property
    def errors(self) -> list[float | None]:
        """The Procrustes error of each embedding (None where the world gave no truth)."""
        return [e.procrustes_error for e in self.embeddings]

    def events(self, kind: str | None = None) -> list[AgentEvent]:
        """The AgentEvents, all or those of `kind`."""
        return [o for o in self.outputs if isinstance(o, AgentEvent) and (kind is None or o.kind == kind)]


def run_inprocess(
    world: World,
    program: Program,
    steps: int,
    detector: DropDetector | None = None,
    on_output: Callable[[Any], None] | None = None,
    stop_when: Callable[[InProcessRun], bool] | None = None,
    perturb: Callable[[int], Control | None] | None = None,
    on_step: Callable[[int, Observation], None] | None = None,
) -> InProcessRun:
    """Run `program` on `world` for `steps` steps through the same attach path and lockstep driver
    as the daemon and the world node, without a bus.

    The run ends early when the link pauses (a program that keeps failing) or `stop_when` says so.

    Parameters
    ----------
    world : World
        The simulator (not closed here).
    program : Program
        The developmental program, built for ``world.spec()``.
    steps : int
        The most steps to run.
    detector : DropDetector or None, default=None
        The reward-drop detector (None: no drop detection).
    on_output : callable or None, default=None
        ``on_output(msg)`` for every Embedding, AgentEvent and WorldEvent, as it is published.
    stop_when : callable or None, default=None
        ``stop_when(run)`` after every step; True ends the run.
    perturb : callable or None, default=None
        ``perturb(k)`` may return a Control, applied to the world after step k is answered (as a
        live perturbation arrives between steps).
    on_step : callable or None, default=None
        ``on_step(k, obs)`` sees every observation before the program does.

    Returns
    -------
    InProcessRun
        The counts and every message published (WorldEvents, e.g. a refused action, included).

    Examples
    --------
    >>> from sensorimotor.agent.programs.gridworld import GridworldProgram
    >>> from sensorimotor.worlds.gridworld import GridWorld
    >>> w = GridWorld(seed=0)
    >>> run = run_inprocess(w, GridworldProgram(w.spec(), seed=0), 8000)
    >>> len(run.embeddings), round(run.errors[0], 2), run.errors[-1] < 0.02  # the map, LSPI iteration by iteration
    (8, 0.8, True)
    """
    run = InProcessRun()
    answers: list[Any] = []

    def publish(channel: str, msg: Any) -> None:
        if channel == "act":
            answers.append(msg)
        else:
            run.outputs.append(msg)
            if on_output:
                on_output(msg)

    lock = Lockstep(world, world.world_id)
    link = attach(
        world.spec(), AgentConfig("inproc"), publish, truth=world.truth(), program=program, detector=detector
    ).link
    t0 = time.perf_counter()
    for k in range(steps):
        obs = lock.observation()
        if on_step:
            on_step(k, obs)
        answers.clear()
        link.answer(obs)
        if not answers:
            break  # the link paused
        ctl = perturb(k) if perturb is not None else None
        if ctl is not None:
            world.perturb(ctl)
            link.truth = world.truth()
        refused = lock.advance(answers[-1])
        if refused is not None:
            publish("world_event", refused)
            link.world_event(refused)
        run.steps += 1
        if stop_when and stop_when(run):
            break
    run.episodes = lock.episode
    run.seconds = time.perf_counter() - t0
    return run
