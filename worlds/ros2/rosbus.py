"""A session with a ROS 2 robot's `rmw_zenohd` router (or the agent's bus, for the stand-in): the
project's `Bus` plus what rmw_zenoh's wire needs - samples with their attachment, liveliness tokens
of entities, and the graph read from those tokens. zenoh itself stays in `protocol.bus`."""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sensorimotor.protocol.bus import Bus
from sensorimotor.worlds.ros2.attachment import Attachment, AttachmentError, gid_of, parse
from sensorimotor.worlds.ros2.names import Entity, WireNameError, parse_token, token_pattern

log = logging.getLogger("sme.ros2")


@dataclass(frozen=True)
class RosSample:
    """One sample of a topic: its key, CDR payload, parsed attachment and local receive time (ns)."""

    key: str
    payload: bytes
    attachment: Attachment
    received_ns: int


class RosPublisher:
    """Publishes one entity's samples with rmw_zenoh's attachment (sequence numbers from 1)."""

    def __init__(self, bus: RosBus, entity: Entity, block: bool = False) -> None:
        self.entity = entity
        self.gid = gid_of(entity.token())
        self.sequence = 0
        self._put = bus.publisher(entity.key(), express=True, block=block).put
        self._lock = threading.Lock()

    def put(self, payload: bytes) -> int:
        """Send one CDR payload; returns its sequence number."""
        with self._lock:
            self.sequence += 1
            att = Attachment(self.sequence, time.time_ns(), self.gid).encode()
            self._put(payload, attachment=att)
            return self.sequence


class RosBus(Bus):
    """`Bus` with attachments and entity tokens. Samples without rmw_zenoh's attachment are refused
    (counted in `refused`, as rmw_zenoh's subscribers drop them)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.refused = 0
        self._next_id = 0

    def __enter__(self) -> RosBus:
        return self

    @property
    def zid(self) -> str:
        """This session's Zenoh id, as rmw_zenoh writes it in tokens."""
        return str(self._session.info.zid())

    def next_id(self) -> int:
        """A new entity id within this session (rmw_zenoh counts nodes and entities per context)."""
        self._next_id += 1
        return self._next_id

    def declare(self, entity: Entity) -> Any:
        """Declare `entity`'s liveliness token (so `ros2 node list`/`topic list` see it)."""
        return self.token(entity.token())

    def ros_publisher(self, entity: Entity, block: bool = False) -> RosPublisher:
        """Declare the publisher's token and a publisher on its key."""
        self.declare(entity)
        return RosPublisher(self, entity, block)

    def ros_subscribe(self, key: str, callback: Callable[[RosSample], None]) -> Any:
        """Call `callback` with each sample on `key` that carries rmw_zenoh's attachment."""

        def on_sample(sample: Any) -> None:
            raw = sample.attachment
            try:
                att = parse(raw.to_bytes() if raw is not None else None)
            except AttachmentError as e:
                self.refused += 1
                if self.refused == 1:
                    log.warning("refused a sample on %s: %s", sample.key_expr, e)
                return
            try:
                callback(RosSample(str(sample.key_expr), sample.payload.to_bytes(), att, time.time_ns()))
            except Exception:
                log.exception("callback for %s failed", key)

        sub = self._session.declare_subscriber(key, on_sample)
        self._declared.append(sub)
        return sub

    def graph(self, domain: int, timeout: float = 1.0) -> list[Entity]:
        """Every entity of `domain` whose token is alive now (tokens not of rmw_zenoh's format skipped)."""
        out = []
        for key in self.alive(token_pattern(domain), timeout=timeout):
            try:
                out.append(parse_token(key))
            except WireNameError as e:
                log.debug("skipped token %s: %s", key, e)
        return out
