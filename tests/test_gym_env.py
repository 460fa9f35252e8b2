"""Every sme world as a Gymnasium environment: registered on `import sensorimotor.worlds`,
passing Gymnasium's own environment checker in-process, and behaving as the world does."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import sensorimotor.worlds  # noqa: F401 - registers the sme/... ids
from sensorimotor.worlds.gym_env import GYM_ENVS, SmeEnv

# small, fast worlds for the checker (an id without an entry here runs with its registered defaults)
SMALL = {
    "sme/Gridworld-v0": {"size": 5},
    "sme/Retina-v0": {"layers": 2, "fields": 8, "supersample": 1},
    "sme/Vergence-v0": {"n_starts": 3, "fovea": 8},
    "sme/MountainCar-v0": {"n_positions": 3, "n_eval": 0, "fovea": 8, "cache_size": 100},
    "sme/ObjectPose-v0": {"half_range": 1, "image": 32, "goal": "0,0"},
    "sme/Arm-v0": {"lattice": 3, "image": 24, "goal_image": 48},
}


def test_every_sme_world_is_registered_on_import():
    assert {"sme/Gridworld-v0", "sme/Retina-v0", "sme/Vergence-v0", "sme/MountainCar-v0", "sme/RovingEye-v0"} <= set(
        GYM_ENVS
    )
    for env_id in GYM_ENVS:
        assert env_id in gym.envs.registry


@pytest.mark.parametrize("env_id", sorted(GYM_ENVS))
def test_check_env_passes(env_id):
    env = gym.make(env_id, **({"params": SMALL[env_id]} if env_id in SMALL else {}))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # advice (e.g. normalise Box actions), not failures
            check_env(env.unwrapped)
    finally:
        env.close()


def test_gridworld_env_starts_where_asked_and_terminates_at_the_goal():
    env = gym.make("sensorimotor.worlds:sme/Gridworld-v0", params={"size": 3})
    u = env.unwrapped
    assert isinstance(u, SmeEnv) and env.observation_space == gym.spaces.Discrete(9)
    cells = u.world.truth().tensors["positions"].tolist()
    start = cells.index([1.0, 0.0])  # below the goal (1, 1)
    obs, info = env.reset(seed=0, options={"start": start})
    assert info["start"] == start and obs == u.world.state_id[start]
    obs, reward, terminated, truncated, _ = env.step(0)  # up
    assert (reward, terminated, truncated) == (1.0, True, False) and obs == u.world.state_id[cells.index([1.0, 1.0])]
    env.close()


def test_a_long_walk_without_the_goal_is_truncated():
    env = gym.make("sme/Gridworld-v0", params={"size": 5, "max_episode_steps": 3})
    cells = env.unwrapped.world.truth().tensors["positions"].tolist()
    env.reset(seed=1, options={"start": cells.index([0.0, 0.0])})
    ends = [env.step(1)[2:4] for _ in range(3)]  # down into the wall: stays put
    assert ends == [(False, False), (False, False), (False, True)]
    env.close()


def test_a_gym_world_round_trips():
    env = SmeEnv("gym:MountainCar-v0", params={"start_grid": 3})  # a Gymnasium env served as a world, and back
    obs, _ = env.reset(seed=0, options={"start": 0})
    assert env.observation_space.shape == (2,) and obs == pytest.approx(np.array([-1.2, -0.07], np.float32))
    env.close()


def test_a_world_with_a_camera_renders_rgb_frames():
    env = gym.make("sme/Retina-v0", params=SMALL["sme/Retina-v0"], render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.ndim == 3 and frame.shape[2] == 3 and frame.dtype == np.uint8
    env.close()
    with pytest.raises(ValueError, match="renders nothing"):
        gym.make("sme/Gridworld-v0", render_mode="rgb_array")
