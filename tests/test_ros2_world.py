"""`sme world ros2` with the stand-in ROS 2 arm (rmw_zenoh's wire, no ROS install): the robot file
checked against what the robot's tokens offer (exit 2 naming the choices), the robot's moves the
same as the arm world's, and one bounded end-to-end run - stand-in -> rmw_zenoh-format bus ->
`sme world ros2` -> stock `sme agent` -> embedding, offered back on a ROS 2 topic."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sensorimotor.protocol.params import ParamError
from sensorimotor.tools.common import free_port

ROOT = Path(__file__).resolve().parents[1]
BASE = (ROOT / "tests" / "data" / "standin_arm_ros2.toml").read_text()
GRID = "grid = [[-0.2, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0], [-0.2, 0.0, 0.2, 0.4, 0.6, 0.8, 1.0]]"
RATE = 100.0


def small_file(folder: Path, ep: str, *edits: tuple[str, str], name: str = "robot.toml") -> str:
    """The stand-in's robot file for a lattice of 3 (9 starts), at RATE Hz, on `ep`, with `edits`."""
    text = BASE.replace('connect = "tcp/127.0.0.1:7447"', f'connect = "{ep}"').replace("rate = 50.0", f"rate = {RATE}")
    text = text.replace(GRID, "grid = [[0.2, 0.4, 0.6], [0.2, 0.4, 0.6]]").replace(
        "max_episode_steps = 48", "max_episode_steps = 16"
    )
    text = text.replace("[robot]\n", "[robot]\ndiscovery_timeout = 0.5\n")
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new, 1)  # the first: the sensors come before the action
    path = folder / name
    path.write_text(text)
    return str(path)


@pytest.fixture(scope="module")
def standin():
    """The stand-in arm (lattice 3) as its own rmw_zenohd router on a free port; stopped at the end."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    cmd = [sys.executable, "-m", "sensorimotor.worlds.ros2.standin", "--listen", ep, "--rate", str(RATE), "-q"]
    p = subprocess.Popen(
        [*cmd, "--param", "lattice=3"], cwd=ROOT, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True
    )
    from sensorimotor.protocol.bus import BusConfig
    from sensorimotor.worlds.ros2.rosbus import RosBus
    from tests.conftest import wait_for

    def up() -> bool:
        try:
            with RosBus(BusConfig(mode="client", connect=(ep,))) as b:
                return any(e.kind == "MS" for e in b.graph(0))
        except Exception:
            return False

    try:
        assert wait_for(up, 30, every=0.3), "the stand-in did not come up"
        yield ep
    finally:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
        if p.stderr:
            p.stderr.close()


@pytest.mark.integration
@pytest.mark.parametrize(
    "edit, words",
    [
        (
            ('type = "sensor_msgs/msg/JointState"\nfield', 'type = "sensor_msgs/msg/Imu"\nfield'),
            "sensor 'joints': the robot's /arm/joint_states is sensor_msgs/msg/JointState, not sensor_msgs/msg/Imu",
        ),
        (
            ('topic = "/arm/joint_states"', 'topic = "/arm/joints"'),
            "the robot publishes no topic /arm/joints (sensor 'joints'); it publishes: /arm/camera/image_raw "
            "(sensor_msgs/msg/Image), /arm/joint_states (sensor_msgs/msg/JointState), /arm/reward (std_msgs/msg/Float64)",
        ),
        (
            ('field = "position"\njoints', 'field = "positions"\njoints'),
            "no numeric field 'positions'; valid: header.stamp.sec",
        ),
        (('topic = "/arm/joint_commands"', 'topic = "/arm/cmd"'), "the robot subscribes to no topic /arm/cmd"),
    ],
)
def test_what_the_robot_does_not_offer_is_refused_naming_what_it_does(standin, tmp_path, edit, words):
    from sensorimotor.worlds.ros2.world import Ros2World

    with pytest.raises(ParamError) as e:
        Ros2World("ros2", 0, robot=small_file(tmp_path, standin, edit))
    assert words in str(e.value)


@pytest.mark.integration
def test_sme_world_ros2_exits_2_naming_the_robots_topics(standin, tmp_path):
    bad = small_file(tmp_path, standin, ('topic = "/arm/reward"', 'topic = "/arm/score"'))
    p = subprocess.run(
        [
            sys.executable,
            "-m",
            "sensorimotor.tools.cli",
            "world",
            "ros2",
            "--robot",
            bad,
            "--connect",
            f"tcp/127.0.0.1:{free_port()}",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2
    assert (
        "publishes no topic /arm/score (goal reward)" in p.stderr and "/arm/reward (std_msgs/msg/Float64)" in p.stderr
    )


@pytest.mark.integration
def test_the_stand_in_moves_as_the_arm_world_does(standin, tmp_path):
    """Seeded actions through rmw_zenoh's wire give the arm world's joints, rewards and images."""
    from sensorimotor.worlds.arm import ArmWorld
    from sensorimotor.worlds.ros2.world import Ros2World

    with Ros2World("ros2", 0, robot=small_file(tmp_path, standin)) as w, ArmWorld("arm", 0, lattice=3) as arm:
        assert w.spec().n_starts == arm.spec().n_starts == 9
        np.testing.assert_allclose(w.truth().tensors["positions"], arm.truth().tensors["positions"], atol=1e-9)
        rng = np.random.default_rng(3)
        k = 0
        a, b = w.reset(start=k), arm.reset(start=k)
        for _ in range(40):
            assert a.reward == b.reward and a.done == b.done
            np.testing.assert_allclose(a.tensors["camera"], b.tensors["camera"], atol=1 / 255)
            if a.done:
                k = int(rng.integers(9))
                a, b = w.reset(start=k), arm.reset(start=k)
                continue
            act = np.array([rng.integers(4)])
            a, b = w.step(act), arm.step(act)
        assert w.stale == 0


@pytest.mark.integration
def test_the_stand_in_through_sme_world_ros2_is_embedded_and_offered_on_a_ros2_topic(
    procs, endpoint, standin, tmp_path
):
    """stand-in -> `sme world ros2` -> stock `sme agent` -> an embedding within 0.1 of the joint
    lattice; the world is a node of the ROS graph and republishes it as a Float64MultiArray."""
    from sensorimotor.protocol.bus import BusConfig
    from sensorimotor.worlds.ros2.cdr import Codec
    from sensorimotor.worlds.ros2.names import topic_key
    from sensorimotor.worlds.ros2.rosbus import RosBus
    from tests.conftest import agent_status, wait_for, world_link

    robot = small_file(tmp_path, standin)
    # a stock agent; its first policy iteration sooner than by default (this checks the path, not the figure:
    # `sme bench ros2 learn` compares the default agent's figure with `sme world arm`'s)
    procs.start("agent", "--listen", endpoint, "-q", "--program-param", "generic.samples_per_iteration=150")
    procs.start("world", "ros2", "--robot", robot, "--connect", endpoint, "--steps", "2000", "-q")
    codec = Codec("jazzy")
    t = "std_msgs/msg/Float64MultiArray"
    with RosBus(BusConfig(mode="client", connect=(standin,))) as ros:
        got: list = []
        ros.ros_subscribe(topic_key(0, "/sme/embedding", t, codec.type_hash(t)), got.append)

        def learned() -> bool:
            link = world_link(agent_status(endpoint), "ros2")
            return link is not None and link.embedding_version > 0 and link.last_procrustes_error < 0.1

        assert wait_for(learned, 120, every=0.5)
        graph = ros.graph(0)
        ours = {(e.kind, e.topic) for e in graph if e.node == "sme_world"}
        assert {
            ("NN", ""),
            ("MP", "/arm/joint_commands"),
            ("MS", "/arm/camera/image_raw"),
            ("MP", "/sme/embedding"),
        } <= ours
        assert wait_for(lambda: got, 20)
        msg = codec.deserialize(got[-1].payload, t)
        dims = [(d.label, d.size, d.stride) for d in msg.layout.dim]
        assert dims == [("points", 9, 18), ("coords", 2, 2)] and msg.data.shape == (18,)
        assert msg.layout.data_offset >= 1  # the embedding's version


@pytest.mark.integration
def test_sme_record_keeps_ros2_topics_with_ros2msg_schemas(standin, tmp_path):
    """`sme record --ros2`: every ROS 2 channel is CDR with its ros2msg schema (mcap's reader),
    and rosbags reads its messages back; `sme replay`'s reader leaves them out."""
    from mcap.reader import make_reader

    from sensorimotor.protocol.bus import BusConfig
    from sensorimotor.tools.commands.record import Recorder
    from sensorimotor.tools.mcap_io import read
    from sensorimotor.worlds.ros2.cdr import Codec
    from sensorimotor.worlds.ros2.rosbus import RosBus
    from sensorimotor.worlds.ros2.tap import RosTap
    from tests.conftest import wait_for

    path = str(tmp_path / "ros2.mcap")
    topics = {"/arm/joint_states", "/arm/camera/image_raw", "/arm/reward"}
    with RosBus(BusConfig(mode="client", connect=(standin,))) as bus:
        rec = Recorder(bus, path).start()
        tap = RosTap(standin, rec.add_ros2)
        try:
            assert wait_for(lambda: topics <= {t for t, _ in tap.keys.values()} and rec.received >= 30, 20)
        finally:
            tap.close()
            rec.stop()
    codec = Codec("jazzy")
    seen: dict[str, int] = {}
    with open(path, "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if channel.message_encoding != "cdr":
                continue
            assert schema is not None and schema.encoding == "ros2msg"
            assert schema.data.decode() == codec.msgdef(schema.name)
            msg = codec.deserialize(message.data, schema.name)
            if channel.topic == "/arm/joint_states":
                assert "lbr_iiwa_joint_2" in list(msg.name) and len(msg.position) == len(msg.name)
            seen[channel.topic] = seen.get(channel.topic, 0) + 1
    assert topics <= set(seen) and min(seen[t] for t in topics) >= 2
    assert not any(r.topic.startswith("/") for r in read(path))


@pytest.mark.integration
def test_a_body_change_on_the_robot_itself_is_seen_only_in_what_it_does(standin, tmp_path):
    """A lesion made on the stand-in (its body_change topic, as a ROS 2 node would send it): the
    world is not told; the joint no longer moves, and a start pose it cannot reach starts where the
    robot stopped. `heal` gives the joint back (the module's stand-in is shared)."""
    import time

    from sensorimotor.worlds.ros2.cdr import Codec
    from sensorimotor.worlds.ros2.names import Entity
    from sensorimotor.worlds.ros2.world import Ros2World
    from tests.conftest import wait_for

    c, t = Codec(), "std_msgs/msg/String"
    with Ros2World("ros2", 0, robot=small_file(tmp_path, standin)) as w:
        pub = w.bus.ros_publisher(
            Entity(0, w.bus.zid, 0, 99, "MP", "tester", "/", "/", "/arm/body_change", t, c.type_hash(t))
        )
        w.reset(start=4)  # (0.4, 0.4)

        time.sleep(0.5)  # the stand-in's subscription reaches the new publisher (a second lesion would free the joint)
        pub.put(c.serialize(c.new(t, data="lesion joint=lbr_iiwa_joint_2 at=0.6"), t))
        try:
            assert wait_for(lambda: abs(w._fresh(0)["readings"]["joints"][0] - 0.6) < 1e-9, 10, every=0.05)
            w.step(np.array([0]))  # joint 2 + : locked, stays
            w.step(np.array([2]))  # joint 4 + : moves
            np.testing.assert_allclose(w._obs["readings"]["joints"], [0.6, 0.6], atol=1e-9)
            w.reset(start=0)  # (0.2, 0.2): joint 2 cannot get there
            np.testing.assert_allclose(w._obs["readings"]["joints"], [0.6, 0.2], atol=1e-9)
            assert w.starts_short == 1
        finally:
            pub.put(c.serialize(c.new(t, data="heal"), t))
        w.reset(start=0)
        np.testing.assert_allclose(w._obs["readings"]["joints"], [0.2, 0.2], atol=1e-9)
