"""Every sme world as a Gymnasium environment, in-process (`SmeEnv`), registered as ``sme/...`` ids.

`GYM_ENVS` maps each id to a world kind and its default parameters; `register_envs` (called on
``import sensorimotor.worlds``) registers them, so that::

    import gymnasium as gym
    import sensorimotor.worlds  # noqa: F401  (or gym.make("sensorimotor.worlds:sme/Gridworld-v0"))

    env = gym.make("sme/Gridworld-v0", params={"size": 7})
    obs, info = env.reset(seed=0, options={"start": 3})

Spaces follow the world's spec: a one-element integer sensor is a Discrete observation (a state
id), any other sensor a Box over its declared range; several sensors make a Dict. Discrete actions
are a Discrete space, a box of actions a Box. ``options={"start": k}`` resets to start state k;
``info["start"]`` says which. An episode that ends without reward at the world's step limit (of
more than one step) is truncated, any other end terminated (a world that knows says so in its
step's info, as `GymWorld` does). For a world served elsewhere over the bus, see `worlds.gym_bus.BusEnv`.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.protocol.messages import ActionSpace, SensorSpec, WorldSpec
from sensorimotor.worlds.base import World

# id -> (world kind, default world parameters); one line per world (small defaults are the caller's)
GYM_ENVS: dict[str, tuple[str, dict[str, Any]]] = {
    "sme/Gridworld-v0": ("gridworld", {}),
    "sme/Retina-v0": ("retina", {}),
    "sme/Vergence-v0": ("vergence", {}),
    "sme/MountainCar-v0": ("mountaincar", {}),
    "sme/RovingEye-v0": ("rovingeye", {}),
    "sme/ObjectPose-v0": ("objectpose", {}),
    "sme/Arm-v0": ("arm", {}),
}


def sensor_space(s: SensorSpec) -> spaces.Space:
    """A sensor as a space: Discrete for a one-element integer sensor, else a Box over its range."""
    dtype = np.dtype(s.dtype)
    if dtype.kind in "iu" and int(np.prod(s.shape)) == 1:
        return spaces.Discrete(int(s.high - s.low) + 1, start=int(s.low))
    return spaces.Box(low=s.low, high=s.high, shape=tuple(s.shape), dtype=dtype)


def observation_space(spec: WorldSpec) -> spaces.Space:
    """The world's observations: one sensor's space, or a Dict of them."""
    if len(spec.sensors) == 1:
        return sensor_space(spec.sensors[0])
    return spaces.Dict({s.name: sensor_space(s) for s in spec.sensors})


def action_space(a: ActionSpace) -> spaces.Space:
    """Discrete actions as Discrete, a box as a float32 Box."""
    if a.discrete:
        return spaces.Discrete(a.n)
    return spaces.Box(np.array(a.low, np.float32), np.array(a.high, np.float32), dtype=np.float32)


def to_gym(spec: WorldSpec, tensors: Mapping[str, np.ndarray]) -> Any:
    """A world's tensors as an element of `observation_space(spec)`."""

    def one(s: SensorSpec) -> Any:
        v = np.asarray(tensors[s.name])
        if np.dtype(s.dtype).kind in "iu" and v.size == 1:
            return np.int64(v.reshape(-1)[0])
        return np.array(v, dtype=s.dtype).reshape(s.shape)  # a copy: worlds may return cached arrays

    if len(spec.sensors) == 1:
        return one(spec.sensors[0])
    return {s.name: one(s) for s in spec.sensors}


def to_world(a: ActionSpace, action: Any) -> np.ndarray:
    """A Gymnasium action as the world's action values (float64, one per dimension)."""
    v = np.asarray(action, dtype=np.float64).reshape(-1)
    return v[:1] if a.discrete else v


class SmeEnv(gym.Env):
    """An sme world, in-process, as a Gymnasium environment.

    Parameters
    ----------
    world : str
        A world kind (`worlds.registry.WORLDS`) or ``gym:ENV_ID``.
    params : mapping or None, default=None
        World parameters (strings or typed values), as for `sme world NAME --param`.
    seed : int, default=0
        Seeds the world (`reset(seed=...)` reseeds it).
    render_mode : {None, "rgb_array"}, default=None
        ``rgb_array``: `render` returns the world's camera frame (worlds that have one).

    Attributes
    ----------
    world : World
        The simulator; ``world.truth()`` is its ground truth, for evaluation only.
    world_spec : WorldSpec
        What the world declares (sensors, actions, start states).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        world: str,
        params: Mapping[str, Any] | None = None,
        seed: int = 0,
        render_mode: str | None = None,
    ) -> None:
        from sensorimotor.worlds.registry import make_world

        self.world = make_world(world, None, seed, params)
        self.world_spec = self.world.spec()
        self.observation_space = observation_space(self.world_spec)
        self.action_space = action_space(self.world_spec.action_space)
        has_frame = type(self.world).frame is not World.frame
        self.metadata = {"render_modes": ["rgb_array"] if has_frame else [], "render_fps": 30}
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            self.world.close()
            raise ValueError(
                f"world {world!r} renders {self.metadata['render_modes'] or 'nothing'}, not {render_mode!r}"
            )
        self.render_mode = render_mode
        self._t = 0
        self._closed = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Begin an episode; ``options={"start": k}`` from start state k (else a random one)."""
        super().reset(seed=seed)
        start = (options or {}).get("start")
        r = self.world.reset(seed=seed, start=None if start is None else int(start))
        self._t = 0
        return to_gym(self.world_spec, r.tensors), {"start": -1 if start is None else int(start)}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """One world step: (observation, reward, terminated, truncated, info)."""
        r = self.world.step(to_world(self.world_spec.action_space, action))
        self._t += 1
        if "truncated" in r.info:
            truncated, terminated = bool(r.info["truncated"]), bool(r.info.get("terminated", False))
        else:
            limit = self.world.max_episode_steps
            truncated = bool(r.done) and limit > 1 and self._t >= limit and r.reward <= 0
            terminated = bool(r.done) and not truncated
        return to_gym(self.world_spec, r.tensors), float(r.reward), terminated, truncated, {}

    def render(self) -> np.ndarray | None:  # type: ignore[override]
        """The world's latest camera frame (``rgb_array``), or None."""
        if self.render_mode != "rgb_array":
            return None
        frame = self.world.frame()
        if frame is not None and frame.ndim == 2:  # a grey camera: rgb_array frames have three channels
            frame = np.repeat(frame[:, :, None], 3, axis=2)
        return frame

    def close(self) -> None:
        """Release the world (twice is fine)."""
        if not self._closed:
            self._closed = True
            self.world.close()


def register_envs(table: Mapping[str, tuple[str, dict[str, Any]]] = GYM_ENVS) -> list[str]:
    """Register the ``sme/...`` ids with Gymnasium (ids already registered are left alone)."""
    done = []
    for env_id, (kind, params) in table.items():
        if env_id not in gym.envs.registry:
            gym.register(
                env_id,
                entry_point="sensorimotor.worlds.gym_env:SmeEnv",
                kwargs={"world": kind, "params": dict(params)},
                disable_env_checker=True,
            )
        done.append(env_id)
    return done


__all__ = ["GYM_ENVS", "SmeEnv", "register_envs", "observation_space", "action_space", "to_gym", "to_world"]
