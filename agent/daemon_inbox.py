"""The daemon's bus callbacks (zenoh threads): observations answered, liveliness of worlds, owners
and claims booked, checkpoints and embedding versions other owners publish kept, truth and world
events passed to their links (lease_lost to the run loop), the checkpoint queryable answered."""

from __future__ import annotations

import logging

from sensorimotor.agent.checkpoint import MAX_VERSION
from sensorimotor.agent.daemon_share import Sharing
from sensorimotor.agent.lease import lost_by
from sensorimotor.agent.link import WorldLink, check_truth
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusMessage
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import Embedding, SharedCheckpoint, Truth, WorldEvent, WorldEventKind, clip

log = logging.getLogger("sme.agent")


class Inbox(Sharing):
    """The bus callbacks (see the module docstring)."""

    # Observations are answered right in the subscriber callback by default: the lockstep world is
    # waiting for exactly this answer, and a queue hop costs ~70 us of a ~400 us round trip. With
    # threaded_links each link runs on its own thread behind a bounded inbox, so one world's slow
    # embedding cannot delay another world's messages.
    def _on_obs(self, msg: BusMessage) -> None:
        wid = keys.world_of(msg.key)
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            if self.threaded_links:
                link.inbox.push(msg)
            else:
                link.handle(msg.payload)
            return
        if wid not in self._claims and self.book.claimed_by_other(wid, self.owner_id):
            self.counters["others"] += 1
        else:
            self.counters["unattached"] += 1

    def _on_alive(self, key: str, alive: bool) -> None:
        wid = keys.last_chunk(key)
        self.book.world(wid, alive)
        self._changes.put((wid, alive))

    def _on_owner(self, key: str, alive: bool) -> None:
        self.book.owner(keys.last_chunk(key), alive)

    def _on_claim(self, key: str, alive: bool) -> None:
        self.book.claim(key, alive)

    def _on_checkpoint(self, msg: BusMessage) -> None:
        """Keep the newest checkpoint another owner shares of each world (decoded: it is checked now)."""
        parts = msg.key.split("/")
        owner, wid = parts[-3], parts[-1]
        if owner == self.owner_id:
            return
        try:
            shared = codec.decode(SharedCheckpoint, msg.payload)
        except ProtocolError as e:
            self.counters["bad_checkpoint"] += 1
            self._warn("checkpoint shared by %s for world %s refused: %s", owner[:64], wid[:64], clip(str(e)))
            return
        if shared.world_id != wid:
            self.counters["bad_checkpoint"] += 1
            self._warn(
                "checkpoint shared by %s on world %s's key is for world %s: refused",
                owner[:64],
                wid[:64],
                clip(shared.world_id),
            )
            return
        why = self.store.offer(owner, wid, shared.data)
        if why is None:
            self._note_lease_elsewhere(wid, owner, shared.epoch, shared.saved_at)
        if why is not None:
            self.counters["bad_checkpoint"] += 1
            self._warn("checkpoint shared by %s for world %s refused: %s", owner[:64], wid[:64], why)

    def _on_embedding(self, msg: BusMessage) -> None:
        """Note the embedding version any agent published (a takeover says when its copy is older)."""
        try:
            emb = codec.decode(Embedding, msg.payload)
        except ProtocolError:
            return  # not ours to judge: watchers report bad embeddings
        if emb.world_id == keys.last_chunk(msg.key) and emb.version <= MAX_VERSION:
            # (a version with no room for the next one on the wire cannot be followed: not taken)
            self.store.published(emb.world_id, emb.version)

    def _answer_checkpoint(self, key: str, payload: bytes | None) -> bytes:
        """The checkpoint queryable: the newest copy this owner holds of the world asked (its own
        last share or another owner's), so a new owner resumes from the newest copy any agent
        holds; empty when it holds none."""
        wid = keys.last_chunk(key)
        copy = self.store.newest(wid)
        own = self._own_shared.get(wid)
        if own is not None and (copy is None or own[0] >= copy.checkpoint.saved_at):
            return own[1]
        return copy.data if copy is not None else b""

    # truth and world events for a world without a link are counted as `unattached`, like its
    # observations (`others` when another owner answers it); a refused one as bad_truth /
    # bad_world_event (the link keeps its truth)
    def _taker(self, wid: str) -> WorldLink | None:
        """The link that takes world `wid`'s truth and events here, or None after counting the message:
        `others` when another owner answers the world (that owner takes and counts it; a paused link
        left here from before a hand-off does not count it a second time), else `unattached`."""
        link = self.links.get(wid)
        elsewhere = wid not in self._claims and self.book.claimed_by_other(wid, self.owner_id)
        if link is not None and (link.state == "attached" or not elsewhere):
            return link
        self.counters["others" if elsewhere else "unattached"] += 1
        return None

    def _on_truth(self, msg: BusMessage) -> None:
        link = self._taker(keys.world_of(msg.key))
        if link is None:
            return
        try:
            truth = codec.decode(Truth, msg.payload)
            check_truth(truth, link.world_id)
        except ProtocolError as e:
            self.counters["bad_truth"] += 1
            self._warn("world %s: bad truth message: %s", link.world_id, e)
            return
        link.truth = truth

    def _on_world_event(self, msg: BusMessage) -> None:
        link = self._taker(keys.world_of(msg.key))
        if link is None:
            return
        try:
            ev = codec.decode(WorldEvent, msg.payload)
            if ev.world_id != link.world_id:
                raise SpecMismatch(f"world event for world {ev.world_id!r} arrived on {link.world_id!r}'s key")
        except ProtocolError as e:
            self.counters["bad_world_event"] += 1
            self._warn("world %s: bad world event: %s", link.world_id, e)
            return
        if ev.kind == WorldEventKind.LEASE_LOST:
            if link.state == "attached" and lost_by(ev, self.owner_id, link.epoch):
                with link.lock:  # stop at once; the run loop withdraws the claim and says so
                    link.pause()
                self._lost.put((link.world_id, ev))
            return  # addressed to another owner (or an old epoch of ours): nothing to do here
        link.world_event(ev)
