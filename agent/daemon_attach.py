"""Attaching a claimed world (spec, program, lease, truth, checkpoint, link) and pausing a world
that vanished; releasing the links of worlds gone longer than the link ttl (checkpointed first)."""

from __future__ import annotations

import logging
import os
import time
from typing import Any

from sensorimotor.agent.attach import attach, program_name, same_body
from sensorimotor.agent.daemon_leases import Leasing
from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.link import check_truth
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusError
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import EXTERNAL_PROGRAM, EventKind, Truth, WorldSpec, clip

log = logging.getLogger("sme.agent")


class Attaching(Leasing):
    """Attaching, pausing and releasing links (see the module docstring)."""

    def _fetch(self, key: str, cls: type, tries: int = 3) -> Any:
        """The first reply to a query on `key` decoded as `cls` (None: no reply in `tries` tries).
        A reply that does not decode raises at once (asking again gets the same bytes); no reply or
        an error reply (a timeout on one of two routes) is asked again."""
        last: Exception | None = None
        for _ in range(tries):
            try:
                replies = self.bus.get(key, timeout=1.0)
            except BusError as e:
                last = e
            else:
                if replies:
                    return codec.decode(cls, replies[0].payload)
            if self._stop.is_set():
                break
        if last is not None:
            raise last
        return None

    def _attach(self, wid: str) -> None:
        self._gone.pop(wid, None)
        try:
            keys.check_id(wid, "world id")
            spec = self._fetch(keys.world_spec(wid), WorldSpec)
            if spec is None:
                raise BusError("no reply to the spec query")
            if spec.world_id != wid:
                raise SpecMismatch(f"the spec of world {wid!r} is for world {spec.world_id!r}")
        except ProtocolError as e:
            self._attach_failed(wid, "bad_spec", e)
            return
        except (ValueError, BusError) as e:
            if isinstance(e, BusError):
                self._retry_spec[wid] = time.monotonic() + self.SPEC_RETRY
            self._attach_failed(wid, "no_spec", e)
            return
        if spec.program == EXTERNAL_PROGRAM:  # an outside controller answers it (a Gymnasium BusEnv)
            log.info("world %s is driven by an outside controller (program %r): not attached", wid, spec.program)
            self.event(wid, EventKind.ATTACH_FAILED, "the world is driven by an outside controller", "external")
            return
        fresh: Any = None
        known = self.links.get(wid)
        if known is None or not same_body(known.spec, spec):
            # the program first: a world no program fits (a broken or fake one) fails here, before a
            # lease, truth or checkpoint query is sent for it (building one costs < 0.1 s once imported)
            try:
                fresh = make_program(spec, self.seed, **self.program_params.get(program_name(spec), {}))
            except Exception as e:  # noqa: BLE001 - SpecMismatch, KeyError, MemoryError (a huge state space), ...
                self._attach_failed(wid, "no_program", e)
                return
        lease = self._take_lease(wid)
        if lease is None:
            return  # held by another live owner: the claim stays, own() asks again
        epoch = lease.epoch if lease.granted else 0
        granted_at = time.time()
        try:
            truth = self._fetch(keys.world_truth(wid), Truth, tries=1)
        except (BusError, ProtocolError):
            truth = None
        previous = self.links.get(wid)
        if previous is not None:
            previous.set_lease(self.owner_id, epoch)  # before it answers again
        if previous is not None and same_body(previous.spec, spec):
            # resume it, unless another owner answered the world since (its shared state is newer)
            restored = self._load_checkpoint(spec, newer_than=self._stopped_at.get(wid, time.time()))
            if restored is not None:
                previous.stop()
                previous = None
        else:
            restored = self._load_checkpoint(spec)
        if truth is not None:
            try:
                check_truth(truth, wid)
            except ProtocolError as e:
                log.warning("world %s: truth not used: %s", wid, e)
                truth = None
        last = self.store.last_published(wid)
        try:
            att = attach(
                spec,
                self.config,
                self.publish,
                truth=truth,
                previous=previous,
                restored=restored,
                last_published=last,
                program=fresh,
                detector=None if fresh is None else make_detector(self.detector, **fresh.detector_params),
            )
        except Exception as e:  # noqa: BLE001 - no program fits this spec (KeyError, MemoryError, ...); the daemon goes on
            self.leases.release(wid, epoch)
            self._attach_failed(wid, "no_program", e)
            return
        att.link.set_lease(self.owner_id, epoch)
        att.link.outputs_in_background()  # an embedding's scores must not hold up other worlds' answers
        if previous is not None and att.link is not previous:
            previous.stop()
        floor = self._version_floor(wid)
        if att.link.version < floor:
            log.info("world %s: embedding versions go on from v%d (published before a restart)", wid, floor)
            att.link.version = floor
        self.links[wid] = att.link
        self._elsewhere.discard(wid)
        if epoch:
            self._held[wid] = (epoch, granted_at)
        if not self.all_obs and wid not in self._obs_subs:
            # only now: a claimed world that cannot be attached (a fake one) costs no subscriber
            # declarations, which every session on the bus would have to route; the lockstep world
            # resends its observation until it is answered
            self._obs_subs[wid] = [
                self.bus.subscribe(keys.world_obs(wid), self._on_obs),
                self.bus.subscribe(keys.world_truth(wid), self._on_truth),
                self.bus.subscribe(keys.world_event(wid), self._on_world_event),
            ]
        if self.threaded_links:
            att.link.start()
        log.info(
            "world %s %s (%s, program %s, %d steps learned, embedding v%d)",
            wid,
            att.how,
            spec.kind,
            att.link.program.name,
            att.link.learned_steps,
            att.link.version,
        )

    def _attach_failed(self, wid: str, reason: str, e: Exception) -> None:
        if wid in self._retried:  # this appearance of the world was counted and reported already
            log.debug("world %s: still cannot attach: %s", wid, clip(str(e)))
            return
        self.counters["attach_failed"] += 1
        self._warn("world %s: cannot attach: %s", wid, clip(str(e)))
        self.event(wid, EventKind.ATTACH_FAILED, str(e), reason)

    def _detach(self, wid: str) -> None:
        link = self.links.get(wid)
        if link is not None:
            self._gone[wid] = time.monotonic()
        if link is not None and link.state == "attached":
            link.pause()
            log.info("world %s disappeared: link paused at step %d", wid, link.counters.steps)
            link.event(EventKind.PAUSED, "world vanished; waiting for it to return", reason="world_gone")

    def release_expired(self, now: float | None = None) -> list[str]:
        """Release the links of worlds gone longer than `link_ttl`: checkpoint each (with a state
        dir) and drop it from `links`. A link whose checkpoint cannot be written is kept (and tried
        again at the next sweep): releasing it would lose what it learned. Returns the released ids."""
        if self.link_ttl is None:
            return []
        now = time.monotonic() if now is None else now
        released = []
        for wid, since in list(self._gone.items()):
            link = self.links.get(wid)
            if link is None:
                self._gone.pop(wid, None)
                continue
            if now - since < self.link_ttl or link.state == "attached":
                continue
            elsewhere = self._newer_elsewhere(wid)
            if self.state_dir and elsewhere is None and wid not in self.checkpoint(only=wid):
                log.warning("world %s: gone %.0f s but its checkpoint failed; link kept", wid, now - since)
                continue
            if self._gone.pop(wid, None) is None or self.links.get(wid) is not link:
                continue  # it came back meanwhile
            del self.links[wid]
            link.stop()
            self._forget_publishers(wid)
            self.counters["released"] += 1
            self.counters["dropped"] += link.dropped
            released.append(wid)
            held = self._held.pop(wid, None)
            self._other.pop(wid, None)
            if self.state_dir and elsewhere is not None:
                log.info(
                    "world %s gone %.0f s (link ttl %g s): link released, not checkpointed here (%s)",
                    wid,
                    now - since,
                    self.link_ttl,
                    elsewhere,
                )
            elif self.state_dir and os.path.exists(self._checkpoint_path(self.state_dir, wid)):
                log.info(
                    "world %s gone %.0f s (link ttl %g s): checkpointed to %s (%d steps learned; %s) and "
                    "released; it is restored from there if it returns",
                    wid,
                    now - since,
                    self.link_ttl,
                    self._checkpoint_path(self.state_dir, wid),
                    link.learned_steps,
                    f"the newest state: lease epoch {held[0]} was the last seen" if held else "no lease",
                )
            else:
                log.info(
                    "world %s gone %.0f s (link ttl %g s): link released; no --state-dir, so it starts fresh "
                    "if it returns",
                    wid,
                    now - since,
                    self.link_ttl,
                )
        return released
