"""A world running elsewhere, driven over the bus as a Gymnasium environment (`BusEnv`), so that an
outside RL library can train against a live world.

Who answers a world's observations: exactly one controller may publish on a world's ``act`` key,
or two answers would race for every step. A world meant for an outside controller is started with
``sme world NAME --external``: its spec then says ``program: external``, and an agent that sees
it does not attach (it publishes ``attach_failed`` with reason ``external`` instead). `BusEnv`
refuses a world that does not say so (``force=True`` overrides, e.g. for a world written from
protocol/README.md that no agent will ever see).

The lockstep protocol is the agent's: the world publishes observation k (again every 0.5 s until
answered); `step(a)` answers it with action a and waits for observation k + 1; `reset()` answers
it with a reset (``options={"start": k}``: to start state k) and waits for the first observation
of the new episode. A world cannot be reseeded over the bus: ``reset(seed=...)`` seeds only the
environment's own `np_random`. ``terminated`` is the observation's ``done``; ``truncated`` is
always False (the protocol does not tell a time limit from a terminal state).

    env = BusEnv("grid0", connect="tcp/127.0.0.1:7447")
    obs, info = env.reset()
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
"""

from __future__ import annotations

import threading
import time
import weakref
from typing import Any

import gymnasium as gym

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError, BusMessage
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import EXTERNAL_PROGRAM, Action, Observation, WorldSpec
from sensorimotor.worlds.gym_env import action_space, observation_space, to_gym


class BusEnv(gym.Env):
    """A live world over Zenoh as a Gymnasium environment (see the module docstring).

    Parameters
    ----------
    world_id : str
        The world's id on the bus.
    connect : str, default="tcp/127.0.0.1:7447"
        The router to connect to (an agent, or any zenoh router), as a client.
    listen : str or None, default=None
        Be the router instead, listening here (for a world started with ``--connect`` to it and no
        agent on the bus).
    timeout : float, default=10.0
        Seconds to wait for the world's spec and for each observation.
    resend : float, default=0.5
        Seconds after which an unanswered action is published again.
    force : bool, default=False
        Drive a world whose spec does not say ``program: external``.
    bus : BusConfig or None, default=None
        The full session configuration (overrides `connect` and `listen`; e.g. with credentials).

    Raises
    ------
    TimeoutError
        When the world's spec does not come within `timeout`.
    RuntimeError
        When the world was not started for an outside controller (and not `force`).
    """

    metadata = {"render_modes": []}

    def __init__(
        self,
        world_id: str,
        connect: str = keys.DEFAULT_ENDPOINT,
        listen: str | None = None,
        timeout: float = 10.0,
        resend: float = 0.5,
        force: bool = False,
        bus: BusConfig | None = None,
    ) -> None:
        self.world_id = keys.check_id(world_id, "world id")
        self.timeout, self.resend = timeout, resend
        if bus is None:
            bus = (
                BusConfig(mode="router", connect=(), listen=(listen,), credential="agent")
                if listen
                else BusConfig(mode="client", connect=(connect,), retry=True, credential="agent")
            )
        self.bus = Bus(bus, wait_limit=timeout)
        _close_when_the_main_thread_ends(self)
        self._cv = threading.Condition()
        self._obs: Observation | None = None
        self._session = ""
        self._closed = False
        try:
            self.world_spec = self._fetch_spec()
            if self.world_spec.program != EXTERNAL_PROGRAM and not force:
                raise RuntimeError(
                    f"world {world_id!r} asks for program {self.world_spec.program!r}: an agent may be answering "
                    f"its observations too; start it with `sme world ... --external` (or pass force=True)"
                )
            self.observation_space = observation_space(self.world_spec)
            self.action_space = action_space(self.world_spec.action_space)
            self.bus.subscribe(keys.world_obs(self.world_id), self._on_obs)
            self._pub = self.bus.publisher(keys.world_act(self.world_id), codec.schema_name(Action))
        except BaseException:
            self.bus.close()
            raise

    def _fetch_spec(self) -> WorldSpec:
        end = time.monotonic() + self.timeout
        while True:
            try:
                replies = self.bus.get(keys.world_spec(self.world_id), timeout=min(2.0, self.timeout))
            except BusError:
                replies = []
            if replies:
                return codec.decode(WorldSpec, replies[0].payload)
            if time.monotonic() > end:
                raise TimeoutError(f"no spec from world {self.world_id!r} within {self.timeout:g} s")
            time.sleep(0.1)

    def _on_obs(self, msg: BusMessage) -> None:
        try:
            obs = codec.decode(Observation, msg.payload)
        except ProtocolError:
            return
        with self._cv:
            if self._obs is None or obs.step > self._obs.step or obs.session != self._obs.session:
                self._obs = obs
            self._cv.notify_all()

    def _current(self) -> Observation:
        """The observation the world waits on (its latest)."""
        with self._cv:
            if not self._cv.wait_for(lambda: self._obs is not None, self.timeout):
                raise TimeoutError(f"no observation from world {self.world_id!r} within {self.timeout:g} s")
            assert self._obs is not None
            return self._obs

    def _answer(self, action: Action) -> Observation:
        """Publish `action` (again every `resend` s) until the observation after it arrives."""
        data = codec.encode(action)
        end = time.monotonic() + self.timeout
        with self._cv:
            while True:
                self._pub.put(data)
                if self._cv.wait_for(
                    lambda: (
                        self._obs is not None and (self._obs.step > action.step or self._obs.session != self._session)
                    ),
                    self.resend,
                ):
                    assert self._obs is not None
                    return self._obs
                if time.monotonic() > end:
                    raise TimeoutError(
                        f"world {self.world_id!r} did not answer step {action.step} in {self.timeout:g} s"
                    )

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        """Start a new episode (``options={"start": k}``: from start state k)."""
        super().reset(seed=seed)
        cur = self._current()
        self._session = cur.session
        start = int((options or {}).get("start", -1))
        obs = self._answer(Action(self.world_id, cur.step, reset=True, start=start, timestamp=time.time()))
        return to_gym(self.world_spec, obs.tensors), self._info(obs)

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        """Answer the world's observation with `action`; the next observation."""
        cur = self._current()
        self._session = cur.session
        values = tuple(float(v) for v in (action if hasattr(action, "__len__") else [action]))
        obs = self._answer(Action(self.world_id, cur.step, values, timestamp=time.time()))
        return to_gym(self.world_spec, obs.tensors), float(obs.reward), bool(obs.done), False, self._info(obs)

    @staticmethod
    def _info(obs: Observation) -> dict[str, Any]:
        return {"step": obs.step, "episode": obs.episode, "t": obs.t, "start": obs.start}

    def close(self) -> None:
        """Leave the bus (twice is fine); the world waits for its next controller."""
        if not self._closed:
            self._closed = True
            self.bus.close()


def _close_when_the_main_thread_ends(env: BusEnv) -> None:
    """Close `env` when the main thread ends, so a script that forgets `env.close()` still exits.

    A zenoh session with a callback subscriber keeps the interpreter from exiting until it is
    closed, and `atexit` runs too late (after the interpreter waits on zenoh's threads);
    `threading._register_atexit` runs first (concurrent.futures relies on it). A weak reference:
    an env already collected is not kept alive for it."""
    ref = weakref.ref(env)

    def close() -> None:
        e = ref()
        if e is not None:
            e.close()

    try:
        threading._register_atexit(close)  # type: ignore[attr-defined]
    except (AttributeError, RuntimeError):  # no such hook here, or the interpreter is shutting down
        pass


__all__ = ["BusEnv"]
