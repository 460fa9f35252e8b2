"""A world for measuring the loop itself: a fixed-size float32 observation, trivial dynamics."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, WorldSpec
from sensorimotor.protocol.params import option, parse
from sensorimotor.worlds.base import StepResult, World


@dataclass(frozen=True)
class BenchWorldParams:
    """Parameters of the loop-benchmark world."""

    obs_bytes: int = option(16384, "size of the float32 observation, in bytes", min=4)
    episode_steps: int = option(100, "steps per episode", min=1)


class BenchWorld(World):
    """A world for measuring the loop: a constant float32 observation of `obs_bytes` bytes, two actions.

    Parameters
    ----------
    world_id : str, default="bench"
        The world's id on the bus.
    seed : int, default=0
        Seeds the (constant) observation.
    params : BenchWorldParams or None, default=None
        The parameters (default: `BenchWorldParams()`).
    **overrides
        Parameter values applied over `params`.
    """

    kind = "bench"
    Params = BenchWorldParams

    def __init__(
        self, world_id: str = "bench", seed: int = 0, params: BenchWorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(BenchWorldParams, overrides, name=self.kind, base=params)
        obs_bytes, episode_steps = prm.obs_bytes, prm.episode_steps
        self.obs = self.rng.random(obs_bytes // 4, dtype=np.float32)
        self.max_episode_steps = episode_steps
        self.t = 0

    def spec(self) -> WorldSpec:
        """One float32 sensor ``frame`` and two actions, for the ``echo`` program."""
        return WorldSpec(
            self.world_id,
            self.kind,
            (SensorSpec("frame", "float32", self.obs.shape),),
            ActionSpace(n=2),
            program="echo",
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Start an episode (the observation never changes)."""
        self.t = 0
        return StepResult({"frame": self.obs})

    def step(self, action: np.ndarray) -> StepResult:
        """Count a step; the reward is ``action[0]``, the episode ends after `episode_steps`."""
        self.t += 1
        return StepResult({"frame": self.obs}, float(action[0]), self.t >= self.max_episode_steps)
