"""Every topic a ROS 2 graph publishes over rmw_zenoh, for `sme record --ros2 ENDPOINT`: the
publishers' liveliness tokens say which topics exist, with their types and hashes; each sample is
handed on with its topic, type and the type's message definition (the ``ros2msg`` schema rosbag2
and Foxglove read in MCAP files). Types rosbags does not know are counted, not recorded."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable
from dataclasses import dataclass

from sensorimotor.protocol.bus import BusConfig
from sensorimotor.worlds.ros2.cdr import Codec
from sensorimotor.worlds.ros2.names import WireNameError, parse_token, token_pattern
from sensorimotor.worlds.ros2.rosbus import RosBus, RosSample

log = logging.getLogger("sme.ros2")


@dataclass(frozen=True)
class TappedSample:
    """One sample of a ROS 2 topic: topic name, type, its ``ros2msg`` definition and the CDR bytes."""

    topic: str
    ros_type: str
    msgdef: str
    payload: bytes
    sequence: int


class RosTap:
    """Subscribes to every topic published in `domain` (now and later) on the router at `endpoint`."""

    def __init__(
        self, endpoint: str, on_sample: Callable[[TappedSample], None], domain: int = 0, distro: str = "jazzy"
    ) -> None:
        self.codec = Codec(distro)
        self.on_sample = on_sample
        self.domain = domain
        self.unknown: set[str] = set()
        self.keys: dict[str, tuple[str, str]] = {}  # topic key -> (topic, type)
        self._lock = threading.Lock()
        self.bus = RosBus(BusConfig(mode="client", connect=(endpoint,)))
        try:
            self.bus.watch_alive(token_pattern(domain), self._on_token, history=True)
        except BaseException:
            self.bus.close()
            raise

    def _on_token(self, key: str, alive: bool) -> None:
        if not alive:
            return
        try:
            e = parse_token(key)
        except WireNameError:
            return
        if e.kind != "MP":
            return
        with self._lock:
            if e.key() in self.keys:
                return
            if not self.codec.known(e.ros_type):
                if e.ros_type not in self.unknown:
                    log.warning("ROS 2 topic %s: type %s unknown to rosbags, not recorded", e.topic, e.ros_type)
                self.unknown.add(e.ros_type)
                return
            self.keys[e.key()] = (e.topic, e.ros_type)
        msgdef = self.codec.msgdef(e.ros_type)
        topic, ros_type = e.topic, e.ros_type

        def deliver(s: RosSample) -> None:
            self.on_sample(TappedSample(topic, ros_type, msgdef, s.payload, s.attachment.sequence))

        self.bus.ros_subscribe(e.key(), deliver)

    def close(self) -> None:
        """Close the session with the robot's router."""
        self.bus.close()
