"""A stand-in ROS 2 arm: the PyBullet arm world served exactly as a ROS 2 robot on rmw_zenoh would
serve it (keys, liveliness tokens, 33-byte attachments, CDR), for tests and demos where ROS 2 itself
cannot be installed.

It publishes, every control tick (`rate` Hz), the arm's joints as ``sensor_msgs/JointState`` (every
movable joint, the others at rest), the camera as ``sensor_msgs/Image`` (grey ``mono8`` by default,
as the arm world renders it, or ``rgb8``/``32FC1``; `camera` scales it up to e.g. 640x480 for
throughput figures) and the arm world's goal as a ``std_msgs/Float64`` reward (1 on the goal pose),
and subscribes to ``sensor_msgs/JointState`` position commands: each is applied on receipt, as the
arm world applies a move (a target outside the start lattice's range is not made; a locked joint
stays). A ``std_msgs/String`` on ``body_change`` (``lesion joint=lbr_iiwa_joint_2 at=-0.2``) changes
the robot's body the way `sme perturb` changes the arm world's, unannounced to the world process. Run it with ``python -m sensorimotor.worlds.ros2.standin --listen tcp/127.0.0.1:7447``: it
then is the robot's `rmw_zenohd` router as well.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
import time
from dataclasses import asdict, dataclass

import numpy as np

from sensorimotor.protocol.bus import BusConfig, BusError
from sensorimotor.protocol.messages import Control
from sensorimotor.protocol.params import ParamError, assignments
from sensorimotor.worlds.arm import ArmWorld
from sensorimotor.worlds.base import PerturbationError
from sensorimotor.worlds.quiet import pybullet_quiet
from sensorimotor.worlds.ros2.cdr import Codec, check_distro
from sensorimotor.worlds.ros2.names import DEFAULT_QOS, SENSOR_QOS, Entity, Qos
from sensorimotor.worlds.ros2.rosbus import RosBus, RosSample

log = logging.getLogger("sme.ros2.standin")


@dataclass
class StandinStats:
    """What the stand-in did: ticks, late ticks, commands heard, applied, refused and missed."""

    ticks: int = 0
    late_ticks: int = 0  # ticks that began more than one period after they were due
    commands: int = 0
    applied: int = 0
    refused: int = 0  # out of the lattice's range, or naming no moving joint
    dropped: int = 0  # gaps in the commands' sequence numbers: sent, never heard
    late_commands: int = 0  # heard more than one control period after they were sent (source timestamp)
    command_latency_ms_p50: float = 0.0
    command_latency_ms_p99: float = 0.0
    seconds: float = 0.0
    cpu_seconds: float = 0.0


class StandinArm:
    """The arm world behind rmw_zenoh's wire (see the module's docstring)."""

    def __init__(
        self,
        bus: RosBus,
        arm: ArmWorld,
        rate: float = 50.0,
        namespace: str = "/arm",
        domain: int = 0,
        distro: str = "jazzy",
        encoding: str = "mono8",
        camera: tuple[int, int] | None = None,
        node: str = "arm_standin",
    ) -> None:
        if encoding not in ("mono8", "rgb8", "32FC1"):
            raise ValueError(f"stand-in encoding {encoding!r}; valid: mono8, rgb8, 32FC1")
        self.bus, self.arm, self.rate, self.encoding, self.camera = bus, arm, rate, encoding, camera
        self.codec = Codec(check_distro(distro))
        self.stats = StandinStats()
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._last_seq: dict[bytes, int] = {}
        self._latencies: list[float] = []
        c = self.codec
        ns = namespace.rstrip("/") or ""
        self.node = Entity(domain, bus.zid, 0, 0, "NN", node, namespace or "/")
        bus.declare(self.node)

        def ent(kind: str, topic: str, ros_type: str, qos: Qos = DEFAULT_QOS) -> Entity:
            return Entity(
                domain,
                bus.zid,
                0,
                bus.next_id(),
                kind,
                node,
                namespace or "/",
                "/",
                topic,
                ros_type,
                c.type_hash(ros_type),
                qos,
            )

        self.topics = {
            "joints": f"{ns}/joint_states",
            "camera": f"{ns}/camera/image_raw",
            "reward": f"{ns}/reward",
            "command": f"{ns}/joint_commands",
            "body_change": f"{ns}/body_change",
        }
        js, img, f64 = "sensor_msgs/msg/JointState", "sensor_msgs/msg/Image", "std_msgs/msg/Float64"
        self.pub_joints = bus.ros_publisher(ent("MP", self.topics["joints"], js))
        self.pub_camera = bus.ros_publisher(ent("MP", self.topics["camera"], img, SENSOR_QOS))
        self.pub_reward = bus.ros_publisher(ent("MP", self.topics["reward"], f64))
        sub = ent("MS", self.topics["command"], js)
        bus.declare(sub)
        bus.ros_subscribe(sub.key(), self._on_command)
        change = ent("MS", self.topics["body_change"], "std_msgs/msg/String")
        bus.declare(change)
        bus.ros_subscribe(change.key(), self._on_body_change)
        self.changes: list[str] = []
        self.all_joints = [n for n in arm.movable_names]
        self.moving_names = [arm.joint_names[i] for i in arm.moving]
        self.lo, self.hi = arm.poses.min(axis=0) - 1e-9, arm.poses.max(axis=0) + 1e-9
        arm.reset(start=len(arm.poses) // 2)

    # commands ------------------------------------------------------------------------------------
    def _on_command(self, sample: RosSample) -> None:
        att = sample.attachment
        latency = (sample.received_ns - att.timestamp_ns) / 1e6  # same host: one clock
        if latency > 1000.0 / self.rate:
            self.stats.late_commands += 1
        if len(self._latencies) < 100_000:
            self._latencies.append(latency)
        last = self._last_seq.get(att.gid)
        if last is not None and att.sequence > last + 1:
            self.stats.dropped += att.sequence - last - 1
        self._last_seq[att.gid] = max(att.sequence, last or 0)
        msg = self.codec.deserialize(sample.payload, "sensor_msgs/msg/JointState")
        names, pos = list(msg.name), np.asarray(msg.position, dtype=np.float64)
        with self._lock:
            self.stats.commands += 1
            target = self.arm.angles.copy()
            hit = False
            for k, j in enumerate(self.moving_names):
                if j in names and names.index(j) < pos.size:
                    target[k] = pos[names.index(j)]
                    hit = True
            for k, a in self.arm.locked.items():
                target[k] = a
            if hit and np.all(target >= self.lo) and np.all(target <= self.hi) and np.all(np.isfinite(target)):
                self.arm.angles = target
                self.stats.applied += 1
            else:
                self.stats.refused += 1

    def _on_body_change(self, sample: RosSample) -> None:
        """``KIND k=v ...`` on ``{ns}/body_change`` (std_msgs/String): the arm world's own body
        change (morph, lesion, reverse, gain, heal) made to the robot itself, not told to anyone."""
        text = str(self.codec.deserialize(sample.payload, "std_msgs/msg/String").data)
        kind, *rest = text.split() or [""]
        try:
            params = assignments(rest)
            with self._lock:
                said = self.arm.perturb(Control(self.arm.world_id, kind, params))
        except (ParamError, PerturbationError, ValueError) as e:
            log.warning("body change %r refused: %s", text, e)
            self.changes.append(f"refused: {e}")
            return
        log.info("body change: %s", said)
        self.changes.append(said)

    # publishing ----------------------------------------------------------------------------------
    def _image(self, angles: np.ndarray) -> np.ndarray:
        grey = self.arm.observe(angles)  # float32 [S, S] in [0, 1], cached per pose
        if self.camera is not None:
            w, h = self.camera
            rows = (np.arange(h) * grey.shape[0]) // h
            cols = (np.arange(w) * grey.shape[1]) // w
            grey = grey[rows][:, cols]
        if self.encoding == "32FC1":
            return grey
        px = np.round(grey * 255).astype(np.uint8)
        return np.repeat(px[..., None], 3, axis=2) if self.encoding == "rgb8" else px

    def tick(self) -> None:
        """Publish the joints, the camera and the reward once."""
        with self._lock:
            angles = self.arm.angles.copy()
        arm = self.arm
        at = arm.at_goal(angles)
        stamp = time.time_ns()
        pos = [arm.rest[arm.joint_names.index(j)] for j in self.all_joints]
        for k, i in enumerate(arm.moving):
            pos[self.all_joints.index(arm.joint_names[i])] = float(angles[k])
        c = self.codec
        self.pub_joints.put(
            c.serialize(c.joint_state(self.all_joints, pos, stamp_ns=stamp), "sensor_msgs/msg/JointState")
        )
        img = c.image(self._image(angles), self.encoding, stamp_ns=stamp)
        self.pub_camera.put(c.serialize(img, "sensor_msgs/msg/Image"))
        self.pub_reward.put(c.serialize(c.new("std_msgs/msg/Float64", data=1.0 if at else 0.0), "std_msgs/msg/Float64"))
        self.stats.ticks += 1

    def run(self, seconds: float | None = None) -> StandinStats:
        """Tick at `rate` until `stop` (or `seconds` pass)."""
        period = 1.0 / self.rate
        t0, c0 = time.monotonic(), time.process_time()
        due = t0
        while not self._stop.is_set():
            now = time.monotonic()
            if seconds is not None and now - t0 >= seconds:
                break
            if now - due > period:
                self.stats.late_ticks += 1
                due = now  # do not try to catch up: a robot publishes its current state
            self.tick()
            due += period
            self._stop.wait(max(0.0, due - time.monotonic()))
        self.stats.seconds = time.monotonic() - t0
        self.stats.cpu_seconds = time.process_time() - c0
        if self._latencies:
            p50, p99 = np.percentile(self._latencies, [50, 99])
            self.stats.command_latency_ms_p50, self.stats.command_latency_ms_p99 = (
                round(float(p50), 3),
                round(float(p99), 3),
            )
        return self.stats

    def stop(self) -> None:
        self._stop.set()


def main(argv: list[str] | None = None) -> int:
    """``python -m sensorimotor.worlds.ros2.standin``: serve the stand-in arm until Ctrl-C."""
    ap = argparse.ArgumentParser(
        prog="python -m sensorimotor.worlds.ros2.standin", description=__doc__.split("\n\n")[0]
    )
    where = ap.add_mutually_exclusive_group()
    where.add_argument(
        "--listen", default=None, help="be the robot's router too, listening here (default tcp/127.0.0.1:7447)"
    )
    where.add_argument(
        "--connect", default=None, help="join an existing router (rmw_zenohd, or the agent's) as a client"
    )
    ap.add_argument("--rate", type=float, default=50.0, help="control ticks per second (default 50)")
    ap.add_argument("--namespace", default="/arm", help="the robot's namespace (default /arm)")
    ap.add_argument("--domain", type=int, default=0)
    ap.add_argument("--distro", default="jazzy", help="humble, jazzy, kilted or rolling (type hashes; humble has none)")
    ap.add_argument("--encoding", default="mono8", choices=("mono8", "rgb8", "32FC1"))
    ap.add_argument("--camera", default=None, metavar="WxH", help="scale the image up to WxH (e.g. 640x480)")
    ap.add_argument(
        "--param",
        action="append",
        metavar="K=V",
        default=[],
        help="arm world parameter (see `sme world --list-params arm`)",
    )
    ap.add_argument("--seconds", type=float, default=None)
    ap.add_argument("--stats-json", default=None, metavar="FILE")
    ap.add_argument("-q", "--quiet", action="store_true")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.WARNING if args.quiet else logging.INFO, format="%(name)s: %(message)s")
    camera = None
    if args.camera:
        try:
            w, h = (int(x) for x in args.camera.lower().split("x"))
            camera = (w, h)
        except ValueError:
            print(f"standin: --camera {args.camera!r} is not WxH", file=sys.stderr)
            return 2
    try:
        check_distro(args.distro)
        with pybullet_quiet():
            arm = ArmWorld("arm", 0, None, **assignments(args.param))
    except (ParamError, ValueError) as e:
        print(f"standin: {e}", file=sys.stderr)
        return 2
    if args.connect:
        cfg = BusConfig(mode="client", connect=(args.connect,))
    else:
        cfg = BusConfig(mode="router", listen=(args.listen or "tcp/127.0.0.1:7447",), connect=())
    try:
        bus = RosBus(cfg)
    except BusError as e:
        print(f"standin: {e}", file=sys.stderr)
        arm.close()
        return 2
    with bus, arm:
        s = StandinArm(bus, arm, args.rate, args.namespace, args.domain, args.distro, args.encoding, camera)
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: s.stop())
        log.info(
            "stand-in arm %s (%s) on %s at %g Hz", ", ".join(s.moving_names), args.distro, cfg.describe(), args.rate
        )
        stats = s.run(args.seconds)
    log.info("stand-in stopped: %s", asdict(stats))
    if args.stats_json:
        with open(args.stats_json, "w") as f:
            json.dump(asdict(stats), f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
