"""Golden tests of rmw_zenoh's wire as `worlds.ros2` writes and reads it: key expressions, liveliness
tokens (the examples of rmw_zenoh's docs/design.md), the 33-byte attachment (against zenoh's own
serializer), CDR bytes of JointState, Image, Twist and Float64MultiArray (against rosbags and a
second implementation, pycdr2, and hand-written bytes), Humble's TypeHashNotSupported, and a sample
without attachment refused as rmw_zenoh refuses it."""

import struct
import time
from dataclasses import dataclass

import numpy as np
import pytest
import xxhash
from pycdr2 import IdlStruct
from pycdr2.types import float64, int32, sequence, uint8, uint32

from sensorimotor.worlds.ros2 import attachment as att
from sensorimotor.worlds.ros2.cdr import Codec, FieldPathError, image_array, read_path
from sensorimotor.worlds.ros2.names import (
    DEFAULT_QOS,
    SENSOR_QOS,
    Entity,
    Qos,
    WireNameError,
    dds_type_name,
    parse_token,
    ros_type_name,
    topic_key,
)

# verbatim from rmw_zenoh docs/design.md (Jazzy)
STRING_HASH = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
CHATTER_KEY = f"0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"
NODE_TOKEN = "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
PUB_TOKEN = (
    "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/"
    f"%chatter/std_msgs::msg::dds_::String_/{STRING_HASH}/::,7:,:,:,,"
)
JAZZY, HUMBLE = Codec("jazzy"), Codec("humble")


def test_topic_key_and_type_hash_match_design_md():
    assert JAZZY.type_hash("std_msgs/msg/String") == STRING_HASH
    assert topic_key(0, "/chatter", "std_msgs/msg/String", STRING_HASH) == CHATTER_KEY
    assert topic_key(0, "chatter/", "std_msgs/msg/String", STRING_HASH) == CHATTER_KEY
    assert topic_key(7, "/arm/joint_states", "sensor_msgs/msg/JointState", "H") == (
        "7/arm/joint_states/sensor_msgs::msg::dds_::JointState_/H"
    )
    assert dds_type_name("sensor_msgs/msg/Image") == "sensor_msgs::msg::dds_::Image_"
    assert ros_type_name("sensor_msgs::msg::dds_::Image_") == "sensor_msgs/msg/Image"
    with pytest.raises(WireNameError, match="package/msg/Name"):
        dds_type_name("String")


def test_humble_writes_type_hash_not_supported():
    for t in ("std_msgs/msg/String", "sensor_msgs/msg/JointState", "sensor_msgs/msg/Image"):
        assert HUMBLE.type_hash(t) == "TypeHashNotSupported"
        assert JAZZY.type_hash(t).startswith("RIHS01_") and len(JAZZY.type_hash(t)) == 7 + 64
    key = topic_key(0, "/chatter", "std_msgs/msg/String", HUMBLE.type_hash("std_msgs/msg/String"))
    assert key == "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported"


def test_tokens_match_design_md_and_parse_back():
    node = Entity(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, 0, "NN", "listener")
    assert node.token() == NODE_TOKEN
    pub = Entity(
        0, "8b20917502ee955ac4476e0266340d5c", 0, 10, "MP", "talker", "/", "/", "/chatter", "std_msgs/msg/String",
        STRING_HASH, Qos(depth=7),
    )  # fmt: skip
    assert pub.token() == PUB_TOKEN
    assert pub.key() == CHATTER_KEY
    assert parse_token(PUB_TOKEN) == pub and parse_token(NODE_TOKEN) == node
    ns = Entity(0, "z", 1, 3, "MS", "cam", "/robot1", "/", "/robot1/image", "sensor_msgs/msg/Image", "H", SENSOR_QOS)
    assert ns.token() == "@ros2_lv/0/z/1/3/MS/%/%robot1/cam/%robot1%image/sensor_msgs::msg::dds_::Image_/H/2::,5:,:,:,,"
    assert parse_token(ns.token()) == ns


def test_qos_chunk_leaves_rmw_zenoh_defaults_empty():
    assert Qos().text() == "::,:,:,:,,"  # reliable, volatile, keep last 42: rmw_zenoh's own defaults
    assert DEFAULT_QOS.text() == "::,10:,:,:,,"
    assert Qos(reliability=2, durability=1, history=2, depth=1).text() == "2:1:2,1:,:,:,,"
    assert Qos.parse("2::,5:,:,:,,") == SENSOR_QOS
    with pytest.raises(WireNameError, match="rel:dur"):
        Qos.parse("2:1")


@pytest.mark.parametrize(
    "bad, words",
    [
        ("sme/v1/alive/world/x", "not an rmw_zenoh liveliness token"),
        ("@ros2_lv/0/z/0/0/XX/%/%/n", "entity kind 'XX'"),
        ("@ros2_lv/0/z/0/1/MP/%/%/n", "needs topic, type, hash and QoS"),
        ("@ros2_lv/x/z/0/0/NN/%/%/n", "must be numbers"),
    ],
)
def test_malformed_tokens_are_refused_saying_why(bad, words):
    with pytest.raises(WireNameError, match=words):
        parse_token(bad)


def test_attachment_is_zenohs_serialisation_of_two_int64_and_the_gid():
    from zenoh.ext import Int64, z_serialize

    gid = att.gid_of(PUB_TOKEN)
    raw = att.Attachment(42, 1_733_400_000_123_456_789, gid).encode()
    assert len(raw) == att.SIZE == 33
    assert raw == z_serialize((Int64(42), Int64(1_733_400_000_123_456_789), gid)).to_bytes()
    assert raw[16] == 16 and raw[:8] == struct.pack("<q", 42)
    assert att.parse(raw) == att.Attachment(42, 1_733_400_000_123_456_789, gid)
    # GID: XXH3-128 of the token, low 64 bits first, each little-endian (liveliness_utils.cpp)
    h = xxhash.xxh3_128_intdigest(PUB_TOKEN.encode())
    assert gid == struct.pack("<QQ", h & (2**64 - 1), h >> 64)


@pytest.mark.parametrize(
    "raw, words",
    [
        (None, "without attachment"),
        (b"\x00" * 32, "32 bytes"),
        (b"\x00" * 16 + b"\x08" + b"\x00" * 16, "length byte 8"),
    ],
)
def test_malformed_attachments_are_refused(raw, words):
    with pytest.raises(att.AttachmentError, match=words):
        att.parse(raw)


# a second CDR implementation (pycdr2) of the four message types -----------------------------------
@dataclass
class Time(IdlStruct, typename="builtin_interfaces/msg/Time"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs/msg/Header"):
    stamp: Time
    frame_id: str


@dataclass
class JointState(IdlStruct, typename="sensor_msgs/msg/JointState"):
    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


@dataclass
class Image(IdlStruct, typename="sensor_msgs/msg/Image"):
    header: Header
    height: uint32
    width: uint32
    encoding: str
    is_bigendian: uint8
    step: uint32
    data: sequence[uint8]


@dataclass
class Vector3(IdlStruct, typename="geometry_msgs/msg/Vector3"):
    x: float64
    y: float64
    z: float64


@dataclass
class Twist(IdlStruct, typename="geometry_msgs/msg/Twist"):
    linear: Vector3
    angular: Vector3


@dataclass
class Dim(IdlStruct, typename="std_msgs/msg/MultiArrayDimension"):
    label: str
    size: uint32
    stride: uint32


@dataclass
class Layout(IdlStruct, typename="std_msgs/msg/MultiArrayLayout"):
    dim: sequence[Dim]
    data_offset: uint32


@dataclass
class Float64MultiArray(IdlStruct, typename="std_msgs/msg/Float64MultiArray"):
    layout: Layout
    data: sequence[float64]


STAMP = 1_733_400_000_500_000_000


def test_cdr_of_the_four_types_matches_pycdr2_and_rosbags_reads_it_back():
    hdr = Header(Time(1_733_400_000, 500_000_000), "")
    cases = [
        (
            "sensor_msgs/msg/JointState",
            JAZZY.joint_state(["j1", "j2"], [0.25, -1.5], stamp_ns=STAMP),
            JointState(hdr, ["j1", "j2"], [0.25, -1.5], [], []),
        ),
        (
            "sensor_msgs/msg/Image",
            JAZZY.image(np.arange(12, dtype=np.uint8).reshape(2, 2, 3), "rgb8", stamp_ns=STAMP, frame_id=""),
            Image(hdr, 2, 2, "rgb8", 0, 6, list(range(12))),
        ),
        (
            "geometry_msgs/msg/Twist",
            JAZZY.twist([0.5, 0, 0], [0, 0, -0.25]),
            Twist(Vector3(0.5, 0, 0), Vector3(0, 0, -0.25)),
        ),
        (
            "std_msgs/msg/Float64MultiArray",
            JAZZY.float64_multi_array([1.0, 2.0, 3.0], [("points", 3, 3)]),
            Float64MultiArray(Layout([Dim("points", 3, 3)], 0), [1.0, 2.0, 3.0]),
        ),
    ]
    for ros_type, ours, second in cases:
        raw = JAZZY.serialize(ours, ros_type)
        assert raw[:4] == b"\x00\x01\x00\x00", ros_type  # CDR, little endian
        assert raw == second.serialize(), ros_type
        back = JAZZY.deserialize(raw, ros_type)
        assert JAZZY.serialize(back, ros_type) == raw


def test_cdr_bytes_written_out_by_hand():
    twist = JAZZY.serialize(JAZZY.twist([1, 2, 3], [4, 5, 6]), "geometry_msgs/msg/Twist")
    assert twist == b"\x00\x01\x00\x00" + struct.pack("<6d", 1, 2, 3, 4, 5, 6)
    js = JAZZY.serialize(JAZZY.joint_state(["a"], [0.5], stamp_ns=2_000_000_003), "sensor_msgs/msg/JointState")
    # header: sec, nanosec, frame_id "" (length 1: the NUL); name: 1 string "a"; position: 1 double
    # (aligned to 8 from the payload start: offset 32, no padding); velocity, effort: empty
    want = b"\x00\x01\x00\x00" + struct.pack("<iIIB", 2, 3, 1, 0) + b"\x00" * 3
    want += struct.pack("<II", 1, 2) + b"a\x00" + b"\x00" * 2 + struct.pack("<I", 1)
    want += struct.pack("<d", 0.5) + struct.pack("<II", 0, 0)
    assert js == want


def test_field_paths_are_checked_and_read():
    JAZZY.check_path("geometry_msgs/msg/Twist", "angular.z")
    JAZZY.check_path("sensor_msgs/msg/JointState", "position")
    with pytest.raises(FieldPathError, match=r"no numeric field 'angular\.w'; valid: linear\.x, linear\.y"):
        JAZZY.check_path("geometry_msgs/msg/Twist", "angular.w")
    with pytest.raises(
        FieldPathError, match="valid: header.stamp.sec, header.stamp.nanosec, position, velocity, effort"
    ):
        JAZZY.check_path("sensor_msgs/msg/JointState", "name")
    msg = JAZZY.deserialize(
        JAZZY.serialize(JAZZY.twist([1, 2, 3], [4, 5, 6]), "geometry_msgs/msg/Twist"), "geometry_msgs/msg/Twist"
    )
    assert read_path(msg, "angular.y").tolist() == [5.0]


def test_images_are_read_in_every_encoding_with_row_padding():
    rgb = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], dtype=np.uint8)
    img = JAZZY.image(rgb, "rgb8")
    grey = image_array(img)
    assert grey.dtype == np.float32 and grey.shape == (2, 2)
    np.testing.assert_allclose(grey, [[0.2125, 0.7154], [0.0721, 1.0]], atol=1e-6)
    bgr = JAZZY.image(rgb[..., ::-1], "bgr8")
    np.testing.assert_allclose(image_array(bgr), grey)
    mono = JAZZY.image(np.array([[0, 255]], dtype=np.uint8), "mono8")
    mono.step, mono.data = 4, np.array([0, 255, 9, 9], dtype=np.uint8)  # rows padded to 4 bytes
    assert image_array(mono).tolist() == [[0.0, 1.0]]
    f = JAZZY.image(np.array([[0.25, 0.5]], dtype=np.float32), "32FC1")
    assert image_array(
        JAZZY.deserialize(JAZZY.serialize(f, "sensor_msgs/msg/Image"), "sensor_msgs/msg/Image")
    ).tolist() == [[0.25, 0.5]]
    with pytest.raises(ValueError, match="readable: mono8"):
        img.encoding = "yuv422"
        image_array(img)


@pytest.mark.integration
def test_a_sample_without_attachment_is_refused_as_rmw_zenoh_does(endpoint):
    from sensorimotor.protocol.bus import BusConfig
    from sensorimotor.worlds.ros2.rosbus import RosBus

    ent = Entity(0, "z", 0, 1, "MP", "talker", topic="/chatter", ros_type="std_msgs/msg/String", type_hash=STRING_HASH)
    with RosBus(BusConfig(mode="router", listen=(endpoint,), connect=())) as robot:
        with RosBus(BusConfig(mode="client", connect=(endpoint,))) as us:
            got: list = []
            us.ros_subscribe(CHATTER_KEY, got.append)
            pub = robot.ros_publisher(ent)
            payload = JAZZY.serialize(JAZZY.new("std_msgs/msg/String", data="hi"), "std_msgs/msg/String")
            end = time.monotonic() + 5
            while not got and time.monotonic() < end:  # the subscription reaches the router
                robot.put(CHATTER_KEY, payload)  # no attachment: refused
                pub.put(payload)
                time.sleep(0.05)
            assert got
            # the subscription may have reached the router between the two puts: refused once it is up
            end = time.monotonic() + 5
            while us.refused < 1 and time.monotonic() < end:
                robot.put(CHATTER_KEY, payload)
                time.sleep(0.05)
            assert us.refused >= 1
            assert got[0].attachment.gid == att.gid_of(ent.token()) and got[0].attachment.sequence >= 1
            assert JAZZY.deserialize(got[0].payload, "std_msgs/msg/String").data == "hi"
            graph = us.graph(0)
            assert ent in graph  # the publisher's token, parsed back from the router


def test_a_humble_robots_topics_resolve_to_keys_ending_in_type_hash_not_supported():
    """Types and hashes come from the robot's tokens: a Humble robot's keys carry its placeholder."""
    from pathlib import Path

    from sensorimotor.worlds.ros2.robot_file import load
    from sensorimotor.worlds.ros2.world import resolve

    rf = load(str(Path(__file__).parent / "data" / "standin_arm_ros2.toml"))
    offered = [
        ("MP", "/arm/joint_states", "sensor_msgs/msg/JointState"),
        ("MP", "/arm/camera/image_raw", "sensor_msgs/msg/Image"),
        ("MP", "/arm/reward", "std_msgs/msg/Float64"),
        ("MS", "/arm/joint_commands", "sensor_msgs/msg/JointState"),
    ]
    ents = [
        Entity(0, "z", 0, i + 1, k, "arm", "/", "/", t, rt, HUMBLE.type_hash(rt))
        for i, (k, t, rt) in enumerate(offered)
    ]
    topics = resolve(rf, ents, HUMBLE)
    assert (
        topics["/arm/joint_commands"].key
        == "0/arm/joint_commands/sensor_msgs::msg::dds_::JointState_/TypeHashNotSupported"
    )
    assert all(t.type_hash == "TypeHashNotSupported" for t in topics.values())
