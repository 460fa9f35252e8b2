"""The agent's embeddings offered to ROS tools: every Embedding version the agent publishes for a
ROS 2 world is republished on a ROS 2 topic (default ``/sme/embedding``) as a
``std_msgs/Float64MultiArray`` (RViz, Foxglove, rosbag2 read it).

Layout (docs/ros2.md): ``dim[0]`` = ``points`` (size n, one row per start state, stride n x d),
``dim[1]`` = ``coords`` (size d, the embedding's dimensions, stride d); ``data`` the coordinates row
by row; ``data_offset`` the embedding's version (so a reader can tell versions apart)."""

from __future__ import annotations

import logging
from typing import Any

import numpy as np

from sensorimotor.protocol import codec as sme_codec
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import Bus, BusMessage
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import Embedding
from sensorimotor.worlds.ros2.cdr import Codec
from sensorimotor.worlds.ros2.names import DEFAULT_QOS, Entity
from sensorimotor.worlds.ros2.rosbus import RosBus

log = logging.getLogger("sme.ros2")
EMBEDDING_TYPE = "std_msgs/msg/Float64MultiArray"


def embedding_message(codec: Codec, emb: Embedding) -> Any:
    """The Float64MultiArray of one embedding version (the layout of the module's docstring)."""
    xy = np.asarray(emb.coordinates, dtype=np.float64)
    xy = xy.reshape(len(xy), -1) if xy.size else np.zeros((0, 0))
    n, d = xy.shape
    msg = codec.float64_multi_array(xy.reshape(-1), [("points", n, n * d), ("coords", d, d)])
    msg.layout.data_offset = int(emb.version)
    return msg


class EmbeddingOffer:
    """Republishes `world_id`'s embeddings from the agent's bus onto the robot's bus."""

    def __init__(
        self, agent_bus: Bus, robot_bus: RosBus, codec: Codec, world_id: str, node: Entity, topic: str
    ) -> None:
        self.codec = codec
        self.offered = 0
        ent = Entity(
            node.domain,
            node.zid,
            node.nid,
            robot_bus.next_id(),
            "MP",
            node.node,
            node.namespace,
            node.enclave,
            topic,
            EMBEDDING_TYPE,
            codec.type_hash(EMBEDDING_TYPE),
            DEFAULT_QOS,
        )
        self.pub = robot_bus.ros_publisher(ent)
        agent_bus.subscribe(keys.agent_embedding("*", world_id), self._on_embedding)

    def _on_embedding(self, m: BusMessage) -> None:
        try:
            emb = sme_codec.decode(Embedding, m.payload)
        except ProtocolError as e:
            log.warning("embedding on %s not offered: %s", m.key, e)
            return
        self.pub.put(self.codec.serialize(embedding_message(self.codec, emb), EMBEDDING_TYPE))
        self.offered += 1
