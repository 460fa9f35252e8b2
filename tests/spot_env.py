"""A world seen only through a camera, small enough for tests: `gym:tests.spot_env:zoo-test/Spot-v0`
(importing this module registers it, as a user's own package would; the repository root must be
on the path, e.g. PYTHONPATH=.). The panda-gym pixels case in miniature: box moves of a spot, 16 x 16
grey frames, start states and truth declared by the `EmbeddableEnv` hook."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from sensorimotor.worlds.gym_world import EmbeddableEnv

SPOT_STARTS = np.array(
    [(x, y) for x in np.linspace(0.2, 0.8, 5) for y in np.linspace(0.2, 0.8, 5) if (x, y) != (0.5, 0.5)]
)


class Spot(gym.Env):
    """A camera that sees a spot (16 x 16 grey frames, never the position): the agent sends moves
    of the spot (a 2-value box, 0.05 per unit) and succeeds within 0.06 of the centre."""

    def __init__(self, camera: bool = True, lag: bool = False) -> None:
        self.camera = camera  # False: the spot's position is observed instead (zoo-test/SpotState-v0)
        # True: a move shifts the spot's target and the spot follows at most 0.025 per axis and step,
        # as panda-gym's hand does: a whole move spills into the next steps (zoo-test/SpotLag-v0)
        self.lag = lag
        self.observation_space = (
            gym.spaces.Box(0, 255, (16, 16), np.uint8) if camera else gym.spaces.Box(0.0, 1.0, (2,), np.float32)
        )
        self.action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.p = np.full(2, 0.2)
        self.target = self.p.copy()

    @staticmethod
    def frame_at(p: np.ndarray) -> np.ndarray:
        g = (np.arange(16) + 0.5) / 16
        yy, xx = np.meshgrid(g, g, indexing="ij")
        return (255 * np.exp(-((xx - p[0]) ** 2 + (yy - p[1]) ** 2) / (2 * 0.12**2))).astype(np.uint8)

    def frame(self) -> np.ndarray:
        return self.frame_at(self.p) if self.camera else self.p.astype(np.float32)

    def reset(self, seed: int | None = None, options: dict | None = None) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self.p = np.full(2, 0.2)
        self.target = self.p.copy()
        return self.frame(), {"is_success": False}

    def step(self, a: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        if self.lag:
            self.target = np.clip(self.target + 0.05 * np.clip(np.asarray(a, float), -1, 1), 0.05, 0.95)
            self.p = self.p + np.clip(self.target - self.p, -0.025, 0.025)
        else:
            self.p = np.clip(self.p + 0.05 * np.clip(np.asarray(a, float), -1, 1), 0.05, 0.95)
        ok = bool(np.linalg.norm(self.p - 0.5) < 0.06)
        return self.frame(), 0.0, ok, False, {"is_success": ok}


def _put(env: gym.Env, p: np.ndarray) -> np.ndarray:
    spot: Any = env.unwrapped
    spot.p = np.array(p, dtype=float)
    spot.target = spot.p.copy()
    return spot.frame()


for _id, _camera, _lag in (
    ("zoo-test/Spot-v0", True, False),
    ("zoo-test/SpotState-v0", False, False),
    ("zoo-test/SpotLag-v0", True, True),
):
    if _id not in gym.registry:
        gym.register(
            _id,
            entry_point=lambda camera=_camera, lag=_lag: EmbeddableEnv(
                Spot(camera, lag), SPOT_STARTS, _put, SPOT_STARTS
            ),
            max_episode_steps=60,
        )
