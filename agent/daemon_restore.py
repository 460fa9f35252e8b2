"""Resuming a world's link from a checkpoint: the state dir's file or the newest copy another
owner shared on the bus, whichever is newer; a file that cannot serve this world (unreadable, another
world's, another body's, another program's) is set aside, never overwritten or half-restored."""

from __future__ import annotations

import logging
import os
import time
from typing import Any

from sensorimotor.agent.attach import Restored, program_name
from sensorimotor.agent.checkpoint import (
    Checkpoint,
    CheckpointError,
    check_shapes,
    read_checkpoint,
    set_aside_checkpoint,
)
from sensorimotor.agent.daemon_publish import Publishing
from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol import keys
from sensorimotor.protocol.bus import BusError
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import EventKind, WorldSpec, clip
from sensorimotor.protocol.params import as_strings, parse

log = logging.getLogger("sme.agent")


class _Unrestorable(Exception):
    """A checkpoint whose state this agent's program cannot take (the message says why)."""


class Restoring(Publishing):
    """Loading and restoring checkpoints (see the module docstring)."""

    @staticmethod
    def _checkpoint_path(state_dir: str, wid: str) -> str:
        return os.path.join(state_dir, f"{wid}.ckpt.npz")

    def _load_checkpoint(self, spec: WorldSpec, newer_than: float | None = None) -> Restored | None:
        """The saved link for this world, or None to start fresh: the program rebuilt from its
        class params and restored, its embedding version, and the drop detector restored (None: a
        fresh one). A file that cannot be read or restored is set aside
        as NAME.bad-<UTC time>, one learned on another body (kind, program, sensors, actions) as
        NAME.other-body-<UTC time>: its state cannot serve this world, and left in place it would
        be overwritten by the next checkpoint. Pickles (the old NAME.pkl) are never loaded.

        A checkpoint another owner shared on the bus is used instead when it is newer than the file
        (or there is no file); with `newer_than` (a time.time()), only one saved after it is used."""
        copy = self._newest_copy(spec.world_id, ask=newer_than is None)
        shared = copy.checkpoint if copy is not None else None
        if shared is not None and newer_than is not None and shared.saved_at <= newer_than:
            shared = None
        if shared is not None and not shared.same_body(spec):
            log.warning("world %s: the checkpoint shared on the bus is for another body; not used", spec.world_id)
            shared = None
        local = self._load_file(spec) if newer_than is None else None
        if shared is not None and (local is None or shared.saved_at > local[1]):
            try:
                restored = self._restore(spec, shared, "shared checkpoint")
            except _Unrestorable as e:
                self.counters["bad_checkpoint"] += 1
                log.warning("world %s: the checkpoint shared on the bus %s; set aside", spec.world_id, e)
                self.event(
                    spec.world_id,
                    EventKind.BAD_INPUT,
                    clip(f"checkpoint shared on the bus set aside: it {e}"),
                    "bad_checkpoint",
                )
                self.store.drop(spec.world_id)
            else:
                self.counters["taken_over"] += 1
                log.info(
                    "world %s: resuming from the checkpoint %s shared on the bus (embedding v%d, %d steps, %.1f s old)",
                    spec.world_id,
                    shared.owner or (copy.owner if copy is not None else "?"),
                    shared.version,
                    shared.steps,
                    time.time() - shared.saved_at,
                )
                return restored
        return local[0] if local is not None else None

    def _newest_copy(self, wid: str, ask: bool) -> Any:
        """The newest shared copy of world `wid` this owner holds; with `ask`, first ask every
        other owner for the copy it holds (a takeover resumes from the newest copy any agent holds,
        also one shared before this owner was listening)."""
        if ask and self.book.view().owners - {self.owner_id}:
            try:
                replies = self.bus.get(f"{keys.PREFIX}/agent/*/checkpoint/{wid}", timeout=1.0)
            except (BusError, ValueError) as e:
                log.debug("world %s: asking for checkpoints failed: %s", wid, e)
                replies = []
            except Exception as e:  # noqa: BLE001 - a closing session: use what is held
                log.debug("world %s: asking for checkpoints failed: %s", wid, e)
                replies = []
            for r in replies:
                if r.payload:
                    why = self.store.offer("?", wid, r.payload, exclude=self.owner_id)
                    if why is not None:
                        log.warning("world %s: a checkpoint another owner holds was refused: %s", wid, why)
        return self.store.newest(wid)

    def _restore(self, spec: WorldSpec, saved: Checkpoint, what: str) -> Restored:
        """The program (and detector) rebuilt from checkpoint `saved`; _Unrestorable says why not."""
        if saved.world_id != spec.world_id:
            raise _Unrestorable(f"is for world {saved.world_id!r}, not {spec.world_id!r}")
        try:
            program = make_program(spec, self.seed, **saved.program_params)
            if type(program).__name__ != saved.program_class:
                raise ValueError(f"it holds a {saved.program_class}, this world gets a {type(program).__name__}")
            wanted = as_strings(parse(type(program.params), self.program_params.get(program_name(spec), {})))
            if wanted != saved.program_params:
                log.warning(
                    "%s of world %s was made with program params %s, not %s: keeping its own (the learned "
                    "state belongs to them)",
                    what,
                    spec.world_id,
                    saved.program_params,
                    wanted,
                )
            # the detector the program asks for under the configured name (a program may ask the
            # "cusum" family for its failures: BernoulliCUSUM); a saved state of another kind is left
            fresh = make_detector(self.detector, **program.detector_params)
            same_kind = saved.detector_state is not None and saved.detector_state.get("name") == fresh.name
            detector = fresh if same_kind else None
            # arrays of the shapes this world's program keeps, before anything is restored from them
            program.take_layout(saved.program_state)
            check_shapes(saved.program_state, program.state(), "program_state")
            if detector is not None and saved.detector_state is not None:
                check_shapes(saved.detector_state, detector.state(), "detector_state")
            program.restore(saved.program_state)
            if detector is not None and saved.detector_state is not None:
                detector.restore(saved.detector_state)
        except CheckpointError as e:
            raise _Unrestorable(f"does not fit this world's program: {e}") from None
        except (ValueError, KeyError, TypeError, IndexError, AttributeError, ProtocolError) as e:
            raise _Unrestorable(f"cannot be restored ({type(e).__name__}: {e})") from None
        return Restored(program, saved.version, detector, saved.steps)

    def _load_file(self, spec: WorldSpec) -> tuple[Restored, float] | None:
        """The state dir's checkpoint of this world and when it was saved, or None (see _load_checkpoint)."""
        state_dir = self.state_dir
        if not state_dir:
            return None
        path = self._checkpoint_path(state_dir, spec.world_id)
        if os.path.exists(os.path.join(state_dir, f"{spec.world_id}.pkl")):
            log.warning(
                "world %s: ignoring the old pickle checkpoint %s.pkl (pickles are never loaded)",
                spec.world_id,
                spec.world_id,
            )
        if not os.path.exists(path):
            return None

        def set_aside(why: str, reason: str) -> None:
            self.counters["bad_checkpoint"] += 1
            self.event(
                spec.world_id, EventKind.BAD_INPUT, clip(f"checkpoint {path} set aside: {reason}"), "bad_checkpoint"
            )
            try:
                aside = set_aside_checkpoint(path, why)
            except OSError as e:
                log.warning("checkpoint %s: %s; starting fresh (could not set it aside: %s)", path, reason, e)
            else:
                log.warning("checkpoint %s: %s; set aside as %s, starting fresh", path, reason, aside)

        try:
            saved = read_checkpoint(path)
        except CheckpointError as e:
            set_aside("bad", f"unreadable ({e})")
            return None
        if saved.world_id != spec.world_id:  # a file copied or renamed from another world's
            set_aside(
                "other-world",
                f"saved for world {saved.world_id!r}, not {spec.world_id!r} (a checkpoint is restored only for the "
                "world it names)",
            )
            return None
        if not saved.same_body(spec):
            set_aside(
                "other-body",
                f"learned on a different world body ({saved.kind}, program "
                f"{saved.program or saved.kind!r}) than world {spec.world_id} ({spec.kind})",
            )
            return None
        try:
            restored = self._restore(spec, saved, f"checkpoint {path}")
        except _Unrestorable as e:
            set_aside("bad", str(e))
            return None
        return restored, saved.saved_at
