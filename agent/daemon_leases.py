"""Claims and leases of the worlds one owner answers (see `agent.ownership`, `agent.lease`): a
claim declared and withdrawn, a lease asked for, waited on and given back, and the worlds whose lease
was lost to another owner: stopped at once, said so, and not claimed again for a while."""

from __future__ import annotations

import logging
import queue
import time

from sensorimotor.agent.daemon_status import Reporting
from sensorimotor.agent.lease import Outcome
from sensorimotor.agent.ownership import claim_key
from sensorimotor.protocol.messages import EventKind

log = logging.getLogger("sme.agent")


class Leasing(Reporting):
    """Claims and leases (see the module docstring)."""

    # claims ------------------------------------------------------------------------------------
    def _claim(self, wid: str) -> None:
        tok = self.bus.token(claim_key(wid, self.owner_id))
        self._claims[wid] = (tok, time.monotonic())
        self.counters["claimed"] += 1
        log.info("owner %s claims world %s", self.owner_id, wid)

    def _stop_answering(self, wid: str, why: str) -> None:
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            with link.lock:  # an answer in flight goes out before the claim is withdrawn
                link.pause()
            link.event(EventKind.PAUSED, f"no longer answered by {self.owner_id}: {why}", reason="released")
        self._stopped_at[wid] = time.time()

    def _release(self, wid: str, why: str) -> None:
        """Stop answering world `wid` (first), give its lease back (if it is still there), then
        withdraw the claim."""
        self._stop_answering(wid, why)
        link = self.links.get(wid)
        if link is not None and link.epoch > 0:
            if wid in self.book.view().worlds and self.leases.release(wid, link.epoch):
                log.info("owner %s gave world %s's lease (epoch %d) back", self.owner_id, wid, link.epoch)
            link.set_lease(self.owner_id, 0)
        self._waiting.pop(wid, None)
        if self.schedule is not None:
            self.schedule.forget(wid)
        held = self._claims.pop(wid, None)
        self._failed.discard(wid)
        self._retry_spec.pop(wid, None)
        self._retried.discard(wid)
        for sub in self._obs_subs.pop(wid, ()):
            self.bus.undeclare(sub)
        if held is not None:
            self.bus.undeclare(held[0])
            log.info("owner %s releases world %s: %s", self.owner_id, wid, why)

    # leases (see agent.lease) ---------------------------------------------------------------------
    LEASE_RETRY = 0.5  # seconds between two lease requests to a world whose lease another owner holds
    SPEC_RETRY = 5.0  # seconds after which a claimed world whose spec query went unanswered is tried again

    def _take_lease(self, wid: str) -> Outcome | None:
        """Ask world `wid` for its lease: the outcome when granted, or for a world without leases
        (answered unfenced, epoch 0); None when another owner holds it (this owner waits, reports it
        once, and asks again every LEASE_RETRY seconds)."""
        out = self.leases.acquire(wid)
        if out.granted:
            self.counters["lease_granted"] += 1
            if self._waiting.pop(wid, None) is not None:
                log.info("world %s: lease granted to %s (epoch %d) after waiting", wid, self.owner_id, out.epoch)
            return out
        if out.unfenced:
            self.counters["unfenced"] += 1
            self._warn(
                "world %s answers no lease request (a world written before leases): answered unfenced, "
                "only the claim protocol keeps a second owner away",
                wid,
            )
            return out
        self.counters["lease_refused"] += 1
        self._note_lease_elsewhere(wid, out.holder, out.epoch, time.time())
        first = wid not in self._waiting
        self._waiting[wid] = time.monotonic()
        if first:
            what = f"held by {out.holder} (epoch {out.epoch})" if out.holder else f"not granted ({out.reason})"
            log.info("world %s: lease %s; %s waits and asks again", wid, what, self.owner_id)
            self.event(
                wid,
                EventKind.LEASE_REFUSED,
                f"the world's lease is {what}; {self.owner_id} does not answer it and asks again",
                out.reason or "held",
            )
        return None

    def _handle_lost(self) -> None:
        """The worlds whose lease this owner lost (their lease_lost events, seen on a bus thread,
        paused the link at once): say so, and withdraw the claim; a world whose lease went to
        another owner is not claimed again for a while, one whose lease is free (the world restarted
        or nobody holds it) is claimed again at once."""
        while True:
            try:
                wid, ev = self._lost.get_nowait()
            except queue.Empty:
                return
            link = self.links.get(wid)
            if link is None or link.epoch != ev.epoch:
                continue  # already handled, or a newer lease since
            self.counters["lease_lost"] += 1
            if ev.holder:
                detail = (
                    f"world {wid} applies the actions of owner {ev.holder} (lease epoch {ev.holder_epoch}), not "
                    f"those of {self.owner_id} (epoch {ev.epoch}): {self.owner_id} stopped answering it"
                )
            else:
                detail = f"world {wid} has no lease holder now (it restarted or the lease was freed): asking again"
            log.warning("%s", detail)
            link.event(
                EventKind.LEASE_LOST,
                detail,
                ev.step,
                {"epoch": float(ev.epoch), "holder_epoch": float(ev.holder_epoch)},
                reason="held" if ev.holder else "free",
            )
            link.set_lease(self.owner_id, 0)  # nothing to give back
            self._note_lease_elsewhere(wid, ev.holder, ev.holder_epoch, time.time())
            self._release(wid, f"lease lost to {ev.holder or 'nobody'}")
            if ev.holder:
                self._elsewhere.add(wid)
                self._avoid[wid] = time.monotonic() + 5.0
