"""A world for measuring the loop itself: a fixed-size float32 observation, trivial dynamics."""

from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, WorldSpec
from sensorimotor.worlds.base import StepResult, World, param


class BenchWorld(World):
    kind = "bench"

    def __init__(self, world_id: str = "bench", seed: int = 0, obs_bytes: int = 16384,
                 episode_steps: int = 100) -> None:
        super().__init__(world_id, seed)
        if obs_bytes < 4:
            raise ValueError("obs_bytes must be >= 4")
        self.frame = self.rng.random(obs_bytes // 4, dtype=np.float32)
        self.max_episode_steps = episode_steps
        self.t = 0

    @classmethod
    def from_params(cls, world_id: str, seed: int, params: Mapping[str, Any]) -> "BenchWorld":
        return cls(world_id, seed, param(params, "obs_bytes", 16384, int),
                   param(params, "episode_steps", 100, int))

    def spec(self) -> WorldSpec:
        return WorldSpec(self.world_id, self.kind, (SensorSpec("frame", "float32", self.frame.shape),),
                         ActionSpace(n=2), program="echo")

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        self.t = 0
        return StepResult({"frame": self.frame})

    def step(self, action: np.ndarray) -> StepResult:
        self.t += 1
        return StepResult({"frame": self.frame}, float(action[0]), self.t >= self.max_episode_steps)
