"""`sme world ros2 --robot FILE.toml`: a ROS 2 robot reached through its `rmw_zenohd` router,
served to the agent as an ordinary world (docs/ros2.md).

At start-up the robot's liveliness tokens say which topics it publishes and subscribes to, with
their types and hashes; the robot file's topics, types and field paths are checked against them (a
`RobotFileError` names what the robot offers). The robot runs free: each `step` publishes one
command (the robot holds the latest between its own ticks) and reads, as the observation, the first
samples of every sensor and goal topic received `settle` control periods after it. `reset` drives
the robot to a start pose with an absolute position command and waits until it reads within
tolerance of it. Our node and its publishers and subscriptions declare rmw_zenoh tokens, so the
world shows in `ros2 node list` and `ros2 topic list`; embeddings are offered on a ROS 2 topic
(`presence.EmbeddingOffer`)."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.messages import ActionSpace, SensorSpec, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, option, parse
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.ros2.cdr import Codec, FieldPathError, image_array, read_path
from sensorimotor.worlds.ros2.names import DEFAULT_QOS, SENSOR_QOS, Entity
from sensorimotor.worlds.ros2.presence import EmbeddingOffer
from sensorimotor.worlds.ros2.robot_file import (
    IMAGE,
    JOINT_STATE,
    MULTI_ARRAY,
    RobotFile,
    RobotFileError,
    SensorMap,
    load,
)
from sensorimotor.worlds.ros2.rosbus import RosBus, RosPublisher, RosSample

log = logging.getLogger("sme.ros2")
STILL_READINGS = 2  # fresh readings without a move after which a start pose counts as out of reach


@dataclass(frozen=True)
class Ros2WorldParams:
    """Parameters of the ROS 2 world (the robot itself is described by its robot file)."""

    robot: str = option("", "the robot file (TOML; docs/ros2.md)")
    connect: str = option("", "the robot's rmw_zenohd endpoint (empty: the robot file's `connect`)")


@dataclass(frozen=True)
class Topic:
    """A topic as the robot declares it: type, hash and the key its samples travel on."""

    name: str
    ros_type: str
    type_hash: str
    key: str


class Latest:
    """The newest sample of each subscribed topic, and a way to wait for fresh ones."""

    def __init__(self) -> None:
        self._samples: dict[str, RosSample] = {}
        self._cv = threading.Condition()
        self.received = 0

    def push(self, topic: str, sample: RosSample) -> None:
        with self._cv:
            self._samples[topic] = sample
            self.received += 1
            self._cv.notify_all()

    def wait(self, topics: list[str], after_ns: int, timeout: float) -> dict[str, RosSample] | None:
        """The newest sample of every topic once each was received at or after `after_ns`; None
        when `timeout` seconds pass first."""
        end = time.monotonic() + timeout
        with self._cv:
            while True:
                got = {t: self._samples.get(t) for t in topics}
                if all(s is not None and s.received_ns >= after_ns for s in got.values()):
                    return got  # type: ignore[return-value]
                left = end - time.monotonic()
                if left <= 0:
                    return None
                self._cv.wait(left)

    def get(self, topic: str) -> RosSample | None:
        with self._cv:
            return self._samples.get(topic)


def offered(entities: list[Entity], kind: str) -> dict[str, Entity]:
    """Topic name -> entity of the tokens of `kind` (MP: what the robot publishes, MS: what it takes)."""
    return {e.topic: e for e in entities if e.kind == kind}


def _listing(found: dict[str, Entity]) -> str:
    return ", ".join(f"{t} ({e.ros_type})" for t, e in sorted(found.items())) or "(nothing)"


def resolve(rf: RobotFile, entities: list[Entity], codec: Codec) -> dict[str, Topic]:
    """Each topic of the robot file as the robot declares it; a RobotFileError naming what the
    robot does offer for a missing topic, a wrong type or a field path the type does not have."""
    pubs, subs = offered(entities, "MP"), offered(entities, "MS")
    out: dict[str, Topic] = {}

    def one(topic: str, want: str, found: dict[str, Entity], what: str) -> Topic:
        e = found.get(topic)
        if e is None:
            verb = "publishes" if found is pubs else "subscribes to"
            raise RobotFileError(f"the robot {verb} no topic {topic} ({what}); it {verb}: {_listing(found)}")
        if want and e.ros_type != want:
            same = sorted(t for t, x in found.items() if x.ros_type == want)
            hint = f"; topics of type {want}: {', '.join(same)}" if same else ""
            raise RobotFileError(f"{what}: the robot's {topic} is {e.ros_type}, not {want}{hint}")
        if not codec.known(e.ros_type):
            raise RobotFileError(f"{what}: type {e.ros_type} of {topic} is not in rosbags' {codec.distro} types")
        return Topic(topic, e.ros_type, e.type_hash, e.key())

    for s in rf.sensors:
        t = out[s.topic] = one(s.topic, s.type, pubs, f"sensor {s.name!r}")
        if t.ros_type != IMAGE:
            try:
                codec.check_path(t.ros_type, s.field)
            except FieldPathError as e:
                raise RobotFileError(f"sensor {s.name!r}: {e}") from None
        elif s.field:
            raise RobotFileError(f"sensor {s.name!r}: an Image takes no `field` (served as a grey image)")
    g = rf.goal
    t = out[g.topic] = one(g.topic, "", pubs, f"goal {g.kind}")
    try:
        codec.check_path(t.ros_type, g.field)
    except FieldPathError as e:
        raise RobotFileError(f"goal {g.kind}: {e}") from None
    out[rf.action.topic] = one(rf.action.topic, rf.action.type, subs, "the action's command topic")
    return out


class Ros2World(World):
    """A ROS 2 robot over rmw_zenoh, served as a world (see the module's docstring).

    Parameters
    ----------
    world_id : str, default="ros2"
    seed : int, default=0
        Seeds the choice of random start poses.
    params : Ros2WorldParams or None
    **overrides
        Parameter values over `params`.

    Raises
    ------
    ParamError
        A robot file that cannot be read, a robot that cannot be reached, or one that does not
        offer what the file names (the message names what it does offer).
    """

    kind = "ros2"
    Params: ClassVar[type] = Ros2WorldParams

    def __init__(
        self, world_id: str = "ros2", seed: int = 0, params: Ros2WorldParams | None = None, **overrides: Any
    ) -> None:
        super().__init__(world_id, seed)
        self.params = prm = parse(Ros2WorldParams, overrides, name=self.kind, base=params)
        if not prm.robot:
            raise ParamError("ros2: a robot file is required (--robot FILE.toml; docs/ros2.md)")
        try:
            self.rf = rf = load(prm.robot)
        except RobotFileError as e:
            raise ParamError(f"ros2: {e}") from None
        self.codec = Codec(rf.distro)
        self.max_episode_steps = rf.max_episode_steps
        endpoint = prm.connect or rf.connect
        self.bus = self._connect(endpoint, rf.discovery_timeout)
        self.latest = Latest()
        self.starts_short = 0  # resets that ended where the robot stopped short of the start pose
        self.stale = 0  # observations taken without fresh samples of every topic (the robot fell behind)
        self.commands = 0
        try:
            self._attach()
        except BaseException:
            self.bus.close()
            raise

    # start-up ------------------------------------------------------------------------------------
    @staticmethod
    def _connect(endpoint: str, timeout: float) -> RosBus:
        """A client session with the robot's router, tried again for `timeout` seconds."""
        end = time.monotonic() + timeout
        while True:
            try:
                return RosBus(BusConfig(mode="client", connect=(endpoint,)))
            except BusError:
                if time.monotonic() >= end:
                    raise ParamError(
                        f"ros2: nothing answered at {endpoint} within {timeout:g} s: is the robot's router "
                        "(`ros2 run rmw_zenoh_cpp rmw_zenohd`) running there? Set `connect` in [robot] or --param connect=..."
                    ) from None
                time.sleep(0.2)

    def _discover(self) -> dict[str, Topic]:
        rf = self.rf
        end = time.monotonic() + rf.discovery_timeout
        while True:
            entities = self.bus.graph(rf.domain, timeout=min(1.0, rf.discovery_timeout))
            try:
                return resolve(rf, entities, self.codec)
            except RobotFileError as e:
                if time.monotonic() >= end:
                    raise ParamError(f"ros2: {rf.source}: {e}") from None
            time.sleep(0.1)

    def _attach(self) -> None:
        rf, bus = self.rf, self.bus
        self.topics = self._discover()
        node = Entity(rf.domain, bus.zid, 0, 0, "NN", rf.node, rf.namespace)
        bus.declare(node)
        read = [s.topic for s in rf.sensors] + [rf.goal.topic]
        self.read_topics = list(dict.fromkeys(read))
        for name in self.read_topics:
            t = self.topics[name]
            sub = Entity(
                rf.domain,
                bus.zid,
                0,
                bus.next_id(),
                "MS",
                rf.node,
                rf.namespace,
                "/",
                name,
                t.ros_type,
                t.type_hash,
                SENSOR_QOS,
            )
            bus.declare(sub)
            bus.ros_subscribe(t.key, self._pusher(name))
        cmd = self.topics[rf.action.topic]
        ent = Entity(
            rf.domain,
            bus.zid,
            0,
            bus.next_id(),
            "MP",
            rf.node,
            rf.namespace,
            "/",
            cmd.name,
            cmd.ros_type,
            cmd.type_hash,
            DEFAULT_QOS,
        )
        self.command: RosPublisher = bus.ros_publisher(ent, block=True)
        self.node = node
        first = self.latest.wait(self.read_topics, 0, rf.discovery_timeout)
        if first is None:
            silent = [t for t in self.read_topics if self.latest.get(t) is None]
            raise ParamError(f"ros2: no sample within {rf.discovery_timeout} s on {', '.join(silent)}")
        self._obs = self._observe(first)
        self.t = 0

    def _pusher(self, topic: str) -> Callable[[RosSample], None]:
        return lambda sample: self.latest.push(topic, sample)

    # reading -------------------------------------------------------------------------------------
    def _decode(self, topic: str, sample: RosSample) -> Any:
        return self.codec.deserialize(sample.payload, self.topics[topic].ros_type)

    def _sensor(self, s: SensorMap, msg: Any) -> np.ndarray:
        if self.topics[s.topic].ros_type == IMAGE:
            return image_array(msg)
        values = read_path(msg, s.field)
        if s.joints:
            names = list(msg.name)
            missing = [j for j in s.joints if j not in names]
            if missing:
                raise ValueError(f"sensor {s.name!r}: joint {missing[0]} not in the JointState ({', '.join(names)})")
            values = values[[names.index(j) for j in s.joints]]
        return values  # float64: relative commands add to it exactly; served as float32

    def _observe(self, samples: dict[str, RosSample]) -> dict[str, Any]:
        msgs = {t: self._decode(t, samples[t]) for t in self.read_topics}
        readings = {s.name: self._sensor(s, msgs[s.topic]) for s in self.rf.sensors}
        goal = read_path(msgs[self.rf.goal.topic], self.rf.goal.field)
        return {"readings": readings, "goal": float(goal[0]) if goal.size else 0.0}

    def _fresh(self, after_ns: int) -> dict[str, Any]:
        period = 1.0 / self.rf.rate
        after = after_ns + int(self.rf.settle * period * 1e9)
        got = self.latest.wait(self.read_topics, after, timeout=20 * period + 2.0)
        if got is None:
            self.stale += 1
            if self.stale == 1 or self.stale % 100 == 0:
                silent = [t for t in self.read_topics if (s := self.latest.get(t)) is None or s.received_ns < after]
                log.warning(
                    "no fresh sample on %s (%d observations so far went stale): is the robot up?",
                    ", ".join(silent),
                    self.stale,
                )
            got = {t: self.latest.get(t) for t in self.read_topics}  # type: ignore[misc]
        return self._observe(got)  # type: ignore[arg-type]

    def _result(self, obs: dict[str, Any], first: bool = False) -> StepResult:
        self._obs = obs
        g = self.rf.goal
        if g.kind == "success":
            reached = obs["goal"] != 0.0
            reward = 1.0 if reached else 0.0
        else:
            reward = obs["goal"]
            reached = g.end_at is not None and reward >= g.end_at
        if first:
            reward = reward if reached else 0.0
        tensors = {s.name: obs["readings"][s.name].astype(np.float32) for s in self.rf.sensors if s.serve}
        out = not reached and self.t >= self.max_episode_steps
        return StepResult(tensors, float(reward), reached or out, truncated=out, success=reached)

    # commanding ----------------------------------------------------------------------------------
    def _send(self, values: np.ndarray) -> int:
        a = self.rf.action
        c = self.codec
        if a.type == JOINT_STATE:
            if a.field == "position":
                msg = c.joint_state(a.joints, position=values)
            else:
                msg = c.joint_state(a.joints, velocity=values)
        elif a.type == MULTI_ARRAY:
            msg = c.float64_multi_array(values)
        else:
            lin, ang = np.zeros(3), np.zeros(3)
            for f, v in zip(a.fields, values, strict=True):
                part, axis = f.split(".")
                (lin if part == "linear" else ang)["xyz".index(axis)] = v
            msg = c.twist(lin, ang)
        now = time.time_ns()
        self.command.put(c.serialize(msg, a.type))
        self.commands += 1
        return now

    def command_values(self, action: np.ndarray) -> np.ndarray:
        """What action `action` sends (relative position commands: added to the latest reading)."""
        a = self.rf.action
        act = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.discrete:
            k = int(act[0]) if act.size else -1
            if not 0 <= k < len(a.discrete) or act[0] != k:
                raise ValueError(f"action {act[0] if act.size else None} out of range 0..{len(a.discrete) - 1}")
            values = np.array(a.discrete[k])
        else:
            if act.size != a.width or not np.all(np.isfinite(act)):
                raise ValueError(f"action must be {a.width} finite values, got {act.size}")
            values = np.clip(act, a.low, a.high)
        if a.relative_to:
            base = self._obs["readings"][a.relative_to].astype(np.float64)
            if base.size != values.size:
                raise ValueError(f"sensor {a.relative_to!r} reads {base.size} values, the action sends {values.size}")
            values = base + values
        return values

    # World interface -----------------------------------------------------------------------------
    def spec(self) -> WorldSpec:
        """The served sensors, the action space and the start poses of the robot file."""
        rf = self.rf
        sensors = []
        for s in rf.sensors:
            if not s.serve:
                continue
            v = self._obs["readings"][s.name]
            if self.topics[s.topic].ros_type == IMAGE:
                sensors.append(SensorSpec(s.name, "float32", tuple(v.shape), 0.0, 1.0, f"grey image of {s.topic}"))
            else:
                what = f"{s.topic} {s.field}" + (f" of {', '.join(s.joints)}" if s.joints else "")
                sensors.append(SensorSpec(s.name, "float32", tuple(v.shape), -1e6, 1e6, what))
        a = rf.action
        if a.discrete:
            names = a.names or tuple(f"a{i}" for i in range(len(a.discrete)))
            space = ActionSpace(n=len(a.discrete), names=names)
        else:
            names = a.names or a.joints or a.fields or tuple(f"u{i}" for i in range(a.width))
            space = ActionSpace(low=a.low, high=a.high, names=names)
        n_starts = len(rf.start.poses) if rf.start else 0
        return WorldSpec(
            world_id=self.world_id,
            kind=self.kind,
            sensors=tuple(sensors),
            action_space=space,
            reward_min=0.0,
            reward_max=1.0 if rf.goal.kind == "success" else float(rf.goal.end_at or 1.0),
            program="generic",
            n_starts=n_starts,
            params={
                "robot": rf.source,
                "distro": rf.distro,
                "rate_hz": repr(rf.rate),
                "command": f"{a.topic} ({a.type})",
                "max_episode_steps": str(self.max_episode_steps),
                **({"truth_dims": str(a.width)} if rf.start else {}),
            },
            goal="reward",
        )

    def reset(self, seed: int | None = None, start: int | None = None) -> StepResult:
        """Drive the robot to start pose `start` (random when None); without start poses, go on
        from where the robot is."""
        self.t = 0
        st = self.rf.start
        if st is None:
            if seed is not None:
                self.rng = np.random.default_rng(seed)
            return self._result(self._fresh(time.time_ns()), first=True)
        k = self.pick_start(seed, start, len(st.poses))
        obs, reached = self._drive(np.array(st.poses[k]), st.sensor, st.tolerance, st.timeout)
        if not reached:
            self.starts_short += 1
            if self.starts_short == 1:
                log.info("start pose %s not reached; starting from where the robot stopped", st.names[k])
        return self._result(obs, first=True)

    def _drive(self, target: np.ndarray, sensor: str, tol: float, timeout: float) -> tuple[dict[str, Any], bool]:
        """Send the position command `target` until `sensor` reads within `tol` of it (True), or
        the robot stops short - `STILL_READINGS` fresh readings without a move: a locked joint, a
        limit, a refused target - or `timeout` seconds pass (False). Reading until the target is
        seen also keeps a command that reached the robot late from being read as not made."""
        deadline = time.monotonic() + timeout
        last, still = None, 0
        while True:
            obs = self._fresh(self._send(target))
            now = obs["readings"][sensor]
            if np.all(np.abs(now - target) <= tol):
                return obs, True
            still = still + 1 if last is not None and np.all(np.abs(now - last) <= tol / 2) else 0
            if still >= STILL_READINGS or time.monotonic() > deadline:
                return obs, False
            last = now

    def step(self, action: np.ndarray) -> StepResult:
        """Send one command and read the robot `settle` control periods later; a position command
        relative to a sensor is sent until the robot is there or stops short (see `_drive`)."""
        values = self.command_values(action)
        self.t += 1
        a = self.rf.action
        if a.relative_to:
            tol = self.rf.start.tolerance if self.rf.start else 1e-3
            obs, _ = self._drive(values, a.relative_to, tol, 20 / self.rf.rate + 2.0)
            return self._result(obs)
        return self._result(self._fresh(self._send(values)))

    def truth(self) -> Truth | None:
        """The start poses (``positions``, the commanded joint values), row i for start state i."""
        if self.rf.start is None:
            return None
        return Truth(self.world_id, "start_states", {"positions": np.array(self.rf.start.poses, dtype=np.float64)})

    def frame(self) -> np.ndarray | None:
        """The first served image, as uint8 grey."""
        for s in self.rf.sensors:
            if self.topics[s.topic].ros_type == IMAGE:
                return (np.clip(self._obs["readings"][s.name], 0, 1) * 255).astype(np.uint8)
        return None

    def offer_embeddings(self, agent_bus: Bus, world_id: str) -> EmbeddingOffer:
        """Republish this world's embeddings on the robot file's `embedding_topic` (see `presence`)."""
        self.offer = EmbeddingOffer(agent_bus, self.bus, self.codec, world_id, self.node, self.rf.embedding_topic)
        return self.offer

    def close(self) -> None:
        """Close the session with the robot (its tokens vanish with it)."""
        bus = getattr(self, "bus", None)
        if bus is not None:
            bus.close()
