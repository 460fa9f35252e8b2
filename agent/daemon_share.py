"""Writing and sharing checkpoints: each link's learned state to the state dir (atomically) and on
the bus for the other owners, and which owner holds the newest state of a world (by lease epoch,
not by who claimed last), so a link released here never overwrites a newer state written elsewhere."""

from __future__ import annotations

import logging
import os
import time

from sensorimotor.agent.checkpoint import (
    FORMAT_VERSION,
    Checkpoint,
    CheckpointError,
    encode_checkpoint,
    read_checkpoint,
    write_atomically,
)
from sensorimotor.agent.daemon_restore import Restoring
from sensorimotor.agent.link import WorldLink
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.messages import SharedCheckpoint
from sensorimotor.protocol.params import as_strings

log = logging.getLogger("sme.agent")


class Sharing(Restoring):
    """Writing and sharing checkpoints (see the module docstring)."""

    # whose state is newest: by lease epoch, not by who claimed last ----------------------------------
    def _note_lease_elsewhere(self, wid: str, owner: str, epoch: int, when: float) -> None:
        """Another owner held world `wid`'s lease at `epoch` at time `when` (a lease refusal or
        lease_lost naming it, a checkpoint it shared)."""
        if not owner or owner == self.owner_id or epoch <= 0 or wid not in self.links:
            return  # (only worlds with a link here: the others' worlds would pile up in memory)
        old = self._other.get(wid)
        if old is None or when > old[2]:
            self._other[wid] = (owner, epoch, when)

    def _newer_elsewhere(self, wid: str) -> str | None:
        """Why another owner holds a newer learned state of world `wid` than this owner's link
        (None: this owner's is the newest it knows of, so a release checkpoints it).

        Leases decide, not claims: a claim can be withdrawn before its owner answers a single step
        (the world vanished, a lower owner won), so a world claimed elsewhere after this owner
        answered it still has its newest state here unless another owner is seen holding its lease
        after this owner's grant, or wrote the state dir's checkpoint after this owner stopped. A
        world without leases (epoch 0) falls back to the claims (`_elsewhere`)."""
        held = self._held.get(wid)
        other = self._other.get(wid)
        if other is not None and (held is None or other[2] > held[1]):
            mine = f"this owner's epoch {held[0]}" if held is not None else "this owner held none"
            return f"owner {other[0][:64]} held its lease (epoch {other[1]}) after this owner did ({mine})"
        if held is None and wid in self._elsewhere:
            return "another owner answered it since (the world grants no leases: its state is that owner's)"
        if self.state_dir and wid in self._elsewhere:
            path = self._checkpoint_path(self.state_dir, wid)
            try:
                on_disk = read_checkpoint(path) if os.path.exists(path) else None
            except CheckpointError:
                on_disk = None
            stopped = self._stopped_at.get(wid, float("inf"))
            if on_disk is not None and on_disk.owner not in ("", self.owner_id) and on_disk.saved_at > stopped:
                return f"owner {on_disk.owner[:64]} wrote {path} after this owner stopped answering it"
        return None

    def checkpoint(self, only: str | None = None) -> set[str]:
        """Write every link's learned state (or only world `only`'s) to STATE_DIR/<world>.ckpt.npz
        (atomically, no pickle). A write that fails (e.g. a full disk) is logged and leaves the
        previous checkpoint in place. Returns the ids of the worlds written."""
        written: set[str] = set()
        state_dir = self.state_dir
        if not state_dir:
            return written
        with self._ckpt_lock:  # one writer at a time (a worker's exit deadline may write beside close())
            self._checkpoint_links(state_dir, only, written)
        return written

    def _checkpoint_links(self, state_dir: str, only: str | None, written: set[str]) -> None:
        for wid, link in list(self.links.items()):
            if only is not None and wid != only:
                continue
            if link.state != "attached" and self._newer_elsewhere(wid) is not None:
                continue  # another owner holds a newer state of it: its file is theirs to write
            path = self._checkpoint_path(state_dir, wid)
            data = self._encoded_state(wid, link)
            if data is None:
                continue
            try:
                write_atomically(path, data)
                written.add(wid)
            except OSError as e:  # e.g. a full disk: the previous checkpoint stays, learning goes on
                log.error("world %s: checkpoint not written (%s); the previous one is kept", wid, e)

    def _encoded_state(self, wid: str, link: WorldLink) -> bytes | None:
        """Link `link`'s learned state as checkpoint bytes (None, logged, if it cannot be encoded)."""
        encoded = self._encoded_snapshot(wid, link)
        return None if encoded is None else encoded[1]

    def _encoded_snapshot(self, wid: str, link: WorldLink) -> tuple[float, bytes] | None:
        """Link `link`'s learned state as (saved_at, checkpoint bytes); None, logged, if it cannot be encoded."""
        with link.lock:  # a consistent snapshot (copies): it is written while the link runs on
            program, spec = link.program, link.spec
            ckpt = Checkpoint(
                world_id=wid,
                kind=spec.kind,
                program=spec.program,
                sensors=tuple(spec.sensors),
                action_space=spec.action_space,
                version=link.version,
                program_class=type(program).__name__,
                program_params=as_strings(program.params),
                program_state=program.state(),
                detector_state=link.detector.state() if link.detector is not None else None,
                saved_at=time.time(),
                steps=link.learned_steps,
                owner=self.owner_id,
                # the lease the state was learned under (a released link holds none any more)
                epoch=link.epoch or self._held.get(wid, (0, 0.0))[0],
            )
        try:
            return ckpt.saved_at, encode_checkpoint(ckpt)
        except ValueError:  # a program whose state is not arrays and plain values: a bug, not fatal
            log.exception("world %s: checkpoint not written", wid)
            return None

    def share(self, only: str | None = None, worlds: list[str] | None = None) -> int:
        """Put the learned state of every world this daemon answers (or only `only`, or only those
        in `worlds` that are attached) on the bus, for the other owners to resume from if this one
        dies; nothing while no other owner is alive. A checkpoint over `share_max_bytes` is not
        shared (counted `share_oversize`, logged). Returns how many were shared."""
        if not (self.book.view().owners - {self.owner_id}):
            return 0
        n = 0
        for wid, link in list(self.links.items()):
            if (only is not None and wid != only) or (worlds is not None and wid not in worlds):
                continue
            if wid not in self._claims or (only is None and link.state != "attached"):
                continue
            encoded = self._encoded_snapshot(wid, link)
            if encoded is None:
                continue
            if self.schedule is not None:
                self.schedule.shared(wid, time.monotonic())
            if len(encoded[1]) > self.store.max_bytes:
                if wid not in self._oversize_told:
                    self._oversize_told.add(wid)
                    log.warning(
                        "world %s: checkpoint of %d bytes is over the %d shared on the bus: not shared "
                        "(a takeover would start from an older copy or fresh)",
                        wid,
                        len(encoded[1]),
                        self.store.max_bytes,
                    )
                self.counters["share_oversize"] += 1
                continue
            shared = SharedCheckpoint(
                wid,
                encoded[1],
                owner=self.owner_id,
                epoch=link.epoch,
                format_version=FORMAT_VERSION,
                embedding_version=link.version,
                saved_at=encoded[0],
            )
            try:
                self.bus.put(
                    keys.agent_checkpoint(self.owner_id, wid),
                    codec.encode(shared),
                    codec.schema_name(SharedCheckpoint),
                )
                self._own_shared[wid] = encoded
                n += 1
            except Exception as e:  # noqa: BLE001 - a closing bus: the next share will do
                log.warning("world %s: checkpoint not shared: %s", wid, e)
        self.counters["shared"] += n
        return n

    def share_new_versions(self, now: float | None = None) -> int:
        """Share the worlds that published a new embedding version since their last share, each at
        most once per `share_on_embedding` seconds (see `ShareSchedule`). Returns how many were shared."""
        if self.schedule is None:
            return 0
        due = self.schedule.take(time.monotonic() if now is None else now)
        if not due:
            return 0
        n = self.share(worlds=due)
        for w in due:  # not answered here any more, or no other owner to share with: not due again
            self.schedule.shared(w, time.monotonic() if now is None else now)
        self.counters["shared_on_embedding"] += n
        return n
