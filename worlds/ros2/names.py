"""rmw_zenoh's names on the wire: topic key expressions, DDS type names, liveliness tokens and the
QoS string inside them (rmw_zenoh `docs/design.md`, `liveliness_utils.cpp`).

A topic ``/arm/joint_states`` of type ``sensor_msgs/msg/JointState`` in domain 0 is published on
``0/arm/joint_states/sensor_msgs::msg::dds_::JointState_/RIHS01_<64 hex>``; Humble writes
``TypeHashNotSupported`` for the hash. Every node, publisher and subscription declares a liveliness
token ``@ros2_lv/<domain>/<zid>/<nid>/<eid>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>`` followed,
for a topic entity, by ``/<topic>/<type>/<hash>/<qos>``; a ``/`` inside a name is written ``%``.
"""

from __future__ import annotations

from dataclasses import dataclass

ADMIN_SPACE = "@ros2_lv"
HASH_NOT_SUPPORTED = "TypeHashNotSupported"  # what Humble (rmw_zenoh 0.1.x) writes for the type hash
KINDS = {"NN": "node", "MP": "publisher", "MS": "subscription", "SS": "service server", "SC": "service client"}
TOPIC_KINDS = ("MP", "MS", "SS", "SC")


class WireNameError(ValueError):
    """A name or token that is not rmw_zenoh's format; the message says which part."""


def mangle(name: str) -> str:
    """A name as one key chunk: every ``/`` written ``%`` (an empty namespace ``/`` becomes ``%``)."""
    return name.replace("/", "%")


def demangle(chunk: str) -> str:
    """The inverse of `mangle`."""
    return chunk.replace("%", "/")


def dds_type_name(ros_type: str) -> str:
    """``pkg/msg/Name`` -> ``pkg::msg::dds_::Name_`` (the DDS name rmw_zenoh puts in keys and tokens)."""
    parts = ros_type.split("/")
    if len(parts) != 3 or not all(parts):
        raise WireNameError(f"type {ros_type!r} is not of the form package/msg/Name")
    pkg, sub, name = parts
    return f"{pkg}::{sub}::dds_::{name}_"


def ros_type_name(dds: str) -> str:
    """``pkg::msg::dds_::Name_`` -> ``pkg/msg/Name``."""
    parts = dds.split("::")
    if len(parts) != 4 or parts[2] != "dds_" or not parts[3].endswith("_"):
        raise WireNameError(f"type {dds!r} is not a DDS type name pkg::msg::dds_::Name_")
    return f"{parts[0]}/{parts[1]}/{parts[3][:-1]}"


def topic_key(domain: int, topic: str, ros_type: str, type_hash: str) -> str:
    """The key expression a topic's samples travel on (leading and trailing ``/`` of the topic dropped)."""
    name = topic.strip("/")
    if not name:
        raise WireNameError(f"topic {topic!r} is empty")
    return f"{domain}/{name}/{dds_type_name(ros_type)}/{type_hash}"


@dataclass(frozen=True)
class Qos:
    """The QoS a token declares. rmw_zenoh writes a field that equals its own default (reliable,
    volatile, keep last 42; `qos.cpp`) as empty; rmw enum values: reliability 1 reliable / 2 best
    effort, durability 1 transient local / 2 volatile, history 1 keep last / 2 keep all."""

    reliability: int = 1
    durability: int = 2
    history: int = 1
    depth: int = 42

    def text(self) -> str:
        """The token's QoS chunk, e.g. ``::,10:,:,:,,`` for rclcpp's default profile (keep last 10),
        ``2::,5:,:,:,,`` for sensor data (best effort, keep last 5)."""
        d = Qos()

        def f(v: int, dv: int) -> str:
            return "" if v == dv else str(v)

        rel, dur = f(self.reliability, d.reliability), f(self.durability, d.durability)
        return f"{rel}:{dur}:{f(self.history, d.history)},{f(self.depth, d.depth)}:,:,:,,"

    @classmethod
    def parse(cls, text: str) -> Qos:
        """The QoS of a token's chunk (deadline, lifespan and liveliness are read but not kept)."""
        parts = text.split(":")
        if len(parts) < 6 or len(parts[2].split(",")) < 2:
            raise WireNameError(f"QoS {text!r} is not rel:dur:hist,depth:deadline:lifespan:liveliness")
        hist, depth = parts[2].split(",")[:2]
        d = cls()
        try:
            return cls(
                int(parts[0]) if parts[0] else d.reliability,
                int(parts[1]) if parts[1] else d.durability,
                int(hist) if hist else d.history,
                int(depth) if depth else d.depth,
            )
        except ValueError:
            raise WireNameError(f"QoS {text!r} has a field that is not a number") from None


DEFAULT_QOS = Qos(depth=10)  # rclcpp's default profile: reliable, volatile, keep last 10
SENSOR_QOS = Qos(reliability=2, depth=5)  # rclcpp's SensorDataQoS


@dataclass(frozen=True)
class Entity:
    """One ROS 2 entity as its liveliness token describes it (`token` writes it, `parse_token` reads it).

    `topic`, `ros_type`, `type_hash` and `qos` are set for publishers, subscriptions and services."""

    domain: int
    zid: str
    nid: int
    eid: int
    kind: str  # NN, MP, MS, SS, SC
    node: str
    namespace: str = "/"
    enclave: str = "/"
    topic: str = ""
    ros_type: str = ""
    type_hash: str = ""
    qos: Qos = DEFAULT_QOS

    def token(self) -> str:
        """The liveliness token key of this entity."""
        if self.kind not in KINDS:
            raise WireNameError(f"entity kind {self.kind!r}; valid: {', '.join(KINDS)}")
        parts = [ADMIN_SPACE, str(self.domain), self.zid, str(self.nid), str(self.eid), self.kind]
        parts += [mangle(self.enclave), mangle(self.namespace), mangle(self.node)]
        if self.kind in TOPIC_KINDS:
            topic = self.topic if self.topic.startswith("/") else "/" + self.topic
            parts += [mangle(topic), dds_type_name(self.ros_type), mangle(self.type_hash), self.qos.text()]
        return "/".join(parts)

    def key(self) -> str:
        """The topic key expression of a publisher's or subscription's samples."""
        return topic_key(self.domain, self.topic, self.ros_type, self.type_hash)


def parse_token(key: str) -> Entity:
    """The entity a liveliness token key describes; a WireNameError says what is wrong with it."""
    parts = key.split("/")
    if len(parts) < 9 or parts[0] != ADMIN_SPACE:
        raise WireNameError(f"{key!r} is not an rmw_zenoh liveliness token ({ADMIN_SPACE}/<domain>/<zid>/...)")
    if any(not p for p in parts):
        raise WireNameError(f"token {key!r} has an empty part")
    kind = parts[5]
    if kind not in KINDS:
        raise WireNameError(f"token {key!r}: entity kind {kind!r}; valid: {', '.join(KINDS)}")
    try:
        domain, nid, eid = int(parts[1]), int(parts[3]), int(parts[4])
    except ValueError:
        raise WireNameError(f"token {key!r}: domain, node id and entity id must be numbers") from None
    enclave, namespace, node = demangle(parts[6]), demangle(parts[7]), demangle(parts[8])
    if kind == "NN":
        return Entity(domain, parts[2], nid, eid, kind, node, namespace, enclave)
    if len(parts) < 13:
        raise WireNameError(f"token {key!r}: a {KINDS[kind]} token needs topic, type, hash and QoS")
    return Entity(
        domain,
        parts[2],
        nid,
        eid,
        kind,
        node,
        namespace,
        enclave,
        topic=demangle(parts[9]),
        ros_type=ros_type_name(parts[10]),
        type_hash=demangle(parts[11]),
        qos=Qos.parse("/".join(parts[12:])),
    )


def token_pattern(domain: int) -> str:
    """The key expression matching every entity token of `domain`."""
    return f"{ADMIN_SPACE}/{domain}/**"
