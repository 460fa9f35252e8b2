"""Run a World and a Program in one process, no bus: the same lockstep protocol as the world node
and the daemon's link (reset after done or on request), used by tests, `reproduce` and the loop
benchmark's baseline."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from agent.evaluation import score_embedding
from agent.programs.base import EmbeddingOutput, Program
from protocol.messages import Observation
from worlds.base import World


@dataclass
class InProcessRun:
    steps: int = 0
    episodes: int = 0
    seconds: float = 0.0
    outputs: list[Any] = field(default_factory=list)
    errors: list[float | None] = field(default_factory=list)  # Procrustes error per embedding output
    rewards: list[float] = field(default_factory=list)


def run_inprocess(world: World, program: Program, steps: int,
                  on_output: Callable[[Any, float | None], None] | None = None,
                  stop_when: Callable[[InProcessRun], bool] | None = None,
                  controls: dict[int, Any] | None = None, keep_rewards: bool = False) -> InProcessRun:
    run = InProcessRun()
    t0 = time.perf_counter()
    res = world.reset()
    episode, t, start = 0, 0, -1
    for k in range(steps):
        obs = Observation(world.world_id, episode, k, t, res.tensors, float(res.reward), bool(res.done), start)
        if keep_rewards:
            run.rewards.append(float(res.reward))
        dec = program.act(obs)
        for item in program.drain():
            err = None
            if isinstance(item, EmbeddingOutput):
                err = score_embedding(item, world.truth())
                run.errors.append(err)
            run.outputs.append(item)
            if on_output:
                on_output(item, err)
        if controls and k in controls:
            world.perturb(controls[k])
        if res.done or dec.reset:
            start = dec.start if dec.reset else -1
            res = world.reset(start=None if start < 0 else start)
            episode += 1
            t = 0
        else:
            res = world.step(np.asarray(dec.values, dtype=np.float64))
            t += 1
        run.steps += 1
        if stop_when and stop_when(run):
            break
    run.episodes = episode
    run.seconds = time.perf_counter() - t0
    return run
