"""The daemon's outputs: the publishers it declares (and forgets with a released link), every
embedding, event and action a link publishes, the events about worlds without a link, and the
embedding-version high-water mark per world in the state dir (written before a version is
published, so a link restored from an older checkpoint after a kill -9 goes on above it)."""

from __future__ import annotations

import logging
import os
import time
from typing import Any

from sensorimotor.agent.checkpoint import MAX_VERSION, write_atomically
from sensorimotor.agent.daemon_state import DaemonState
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.messages import AgentEvent, clip

log = logging.getLogger("sme.agent")


class Publishing(DaemonState):
    """The daemon's outputs (see the module docstring)."""

    def _publisher(self, key: str, schema: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            with self._lock:
                pub = self._pubs.get(key) or self.bus.publisher(key, schema)
                self._pubs[key] = pub
        return pub

    def _forget_publishers(self, wid: str) -> None:
        """Undeclare the publishers declared for world `wid` (its link was released)."""
        for key in (
            keys.world_act(wid),
            keys.agent_embedding(self.agent_id, wid),
            keys.agent_event(self.agent_id, wid),
            keys.agent_checkpoint(self.owner_id, wid),
        ):
            with self._lock:
                pub = self._pubs.pop(key, None)
            if pub is not None:
                self.bus.undeclare(pub)

    def publish(self, channel: str, msg: Any) -> None:
        """Publish a link's message on its channel's key (and pass embeddings and events to `on_output`)."""
        wid = msg.world_id
        if channel == "act":
            key = keys.world_act(wid)
        elif channel == "embedding":
            key = keys.agent_embedding(self.agent_id, wid)
            self._persist_version(wid, msg.version)  # before it is published: never reused after a kill
        else:
            key = keys.agent_event(self.agent_id, wid)
        try:
            self._publisher(key, codec.schema_name(type(msg))).put(codec.encode(msg))
        except Exception:
            if not self.bus.closed:
                log.exception("publishing on %s failed", key)
        if channel == "embedding":
            self.store.published(wid, msg.version)
            if self.schedule is not None:
                self.schedule.new_version(wid, time.monotonic())
        if self.on_output is not None and channel != "act":
            self.on_output(channel, msg)

    # embedding versions: a high-water mark per world in the state dir, written before each version is
    # published, so that a link restored from an older checkpoint (a kill -9 since) goes on above it
    def _version_path(self, wid: str) -> str:
        return os.path.join(str(self.state_dir), f"{wid}.version")

    def _persist_version(self, wid: str, version: int) -> None:
        if not self.state_dir or version <= self._versions.get(wid, -1):
            return
        try:
            write_atomically(self._version_path(wid), f"{version}\n".encode())
            self._versions[wid] = version
        except OSError as e:  # a full disk: the version is still published; a restart may reuse it
            log.error("world %s: embedding version high-water mark not written (%s)", wid, e)

    def _version_floor(self, wid: str) -> int:
        """The highest embedding version this state dir has seen published for `wid` (0: none)."""
        if not self.state_dir:
            return 0
        try:
            with open(self._version_path(wid), "rb") as f:
                text = f.read(32).decode("ascii").strip()
            value = int(text)
        except (OSError, ValueError, UnicodeDecodeError):
            return 0
        if not 0 <= value <= MAX_VERSION:
            log.warning(
                "world %s: embedding version high-water mark %s in %s is beyond the wire's range (0 .. %d); ignored",
                wid,
                clip(text, 40),
                self._version_path(wid),
                MAX_VERSION,
            )
            return 0
        return value

    def event(self, world_id: str, kind: str, detail: str, reason: str = "") -> None:
        """Publish an event about a world that has no link (yet), without declaring a publisher for it
        (a flood of worlds that cannot be attached must not leave one declared publisher each)."""
        msg = AgentEvent(self.agent_id, world_id, kind, detail, 0, time.time(), reason=reason)
        key = keys.agent_event(self.agent_id, world_id)
        try:
            self.bus.put(key, codec.encode(msg), codec.schema_name(AgentEvent))
        except Exception as e:  # noqa: BLE001 - an event is never worth stopping for
            if not getattr(self.bus, "closed", False):
                log.warning("publishing on %s failed: %s", key, e)
        if self.on_output is not None:
            self.on_output("event", msg)
