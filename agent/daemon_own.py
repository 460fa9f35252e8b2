"""The ownership tick (which worlds this owner claims, withdraws, hands off and attaches, by
`agent.ownership.plan`) and the liveliness audit that books what zenoh's liveliness events missed."""

from __future__ import annotations

import logging
import time

from sensorimotor.agent.daemon_attach import Attaching
from sensorimotor.agent.ownership import TokenAudit, plan
from sensorimotor.protocol import keys

log = logging.getLogger("sme.agent")


class Owning(Attaching):
    """The ownership tick and the liveliness audit (see the module docstring)."""

    def own(self) -> None:
        """One ownership tick: withdraw lost claims, hand one world off if overloaded, claim a free
        world if least loaded, and attach the worlds whose claim has settled."""
        now = time.monotonic()
        view = self.book.view()
        me = self.owner_id
        for w in view.worlds:
            c = view.claims.get(w)
            if w in self._claims or (c is not None and (len(c) > 1 or me not in c)):  # claimed by another
                self.book.unclaimed_since.pop(w, None)
            else:
                self.book.unclaimed_since.setdefault(w, now)
        for w in list(self.book.unclaimed_since):
            if w not in view.worlds:
                del self.book.unclaimed_since[w]
        for w, until in list(self._avoid.items()):
            if until <= now:
                del self._avoid[w]
        known = frozenset(w for w, ln in self.links.items() if ln.state != "attached")
        p = plan(
            self.owner_id,
            view,
            self._claims,
            {w: now - t for w, t in self.book.unclaimed_since.items()},
            known=known,
            avoid=frozenset(self._avoid) | frozenset(self._bad_ids),
            failed=frozenset(self._failed),
            claim_delay=self.claim_delay,
            may_shed=now - self._last_shed >= 2.0 and now - self._started_mono >= 2.0,
        )
        for w in self.links:
            if view.claimants(w) and self.owner_id not in view.claimants(w):
                self._elsewhere.add(w)  # another owner answers it now
        for w, why in p.release.items():
            if "wins" in why:
                self.counters["lost"] += 1
                self._elsewhere.add(w)
                link = self.links.get(w)
                if link is not None and link.state == "attached":  # the winner resumes from here
                    self._stop_answering(w, why)
                    self.share(only=w)
            self._release(w, why)
        if p.shed is not None:
            self._last_shed = now
            self._stop_answering(p.shed, "handed off to balance the load")
            self.share(only=p.shed)
            self._release(p.shed, "handed off to balance the load")
            self._elsewhere.add(p.shed)
            self._avoid[p.shed] = now + 5.0
            self.counters["shed"] += 1
        for w in p.claim:
            try:
                keys.check_id(w, "world id")
            except ValueError as e:  # a token no world id can have: never claimed, reported once (lowest owner)
                self._bad_ids.add(w)
                if self.owner_id == min(view.owners | {self.owner_id}):
                    self._attach_failed(w, "no_spec", e)
                continue
            self._claim(w)
        for w, (_, since) in list(self._claims.items()):
            if now - since < self.claim_settle:
                continue
            link = self.links.get(w)
            if link is not None and link.state == "attached":
                continue
            if w in self._failed and now >= self._retry_spec.get(w, float("inf")):
                self._failed.discard(w)  # no spec reply last time (a route being rebuilt?): once more
                self._retry_spec.pop(w, None)
                self._retried.add(w)  # a second failure is not counted or reported again
            if w in self._failed or any(o < self.owner_id for o in self.book.claimants(w)):
                continue  # tried once this appearance / withdrawn at the next tick
            if now - self._waiting.get(w, float("-inf")) < self.LEASE_RETRY:
                continue  # its lease is held by another owner: ask again in a moment
            self._attach(w)
            link = self.links.get(w)
            if w in self._waiting:
                continue  # the world's lease is held elsewhere: keep the claim and ask again
            if link is None or link.state != "attached":
                # keep the claim: the world is reported once (attach_failed), not by every owner in turn;
                # it is tried again when it reappears
                self._failed.add(w)

    AUDIT_EVERY = 0.5  # seconds between two comparisons of the owner book with a liveliness query

    def _audit_liveliness(self) -> None:
        """Compare the owner book with liveliness queries every AUDIT_EVERY seconds and book what the
        events missed (`TokenAudit`: a world that reconnected through another router can stay booked
        as gone); a world's missed event also goes to the main loop, as zenoh's would have."""
        audit = TokenAudit()
        exprs = (keys.ALL_ALIVE_WORLDS, keys.ALL_ALIVE_OWNERS, keys.ALL_CLAIMS)
        steps: dict[str, int] = {}
        # a router answers from its own tables; a client (a worker) through its link to one, whose
        # answers go empty while the link is re-made under load: a client books only what the audit
        # finds alive (a missed appearance leaves a world nobody claims; a false disappearance
        # would pause a live world and hand it off; a missed disappearance only keeps a claim)
        router = getattr(getattr(self.bus, "config", None), "mode", "router") == "router"
        while not self._stop.wait(self.AUDIT_EVERY):
            held = self.book.tokens()  # before the queries: an event meanwhile shows as touched
            sure = self._surely_alive(steps)
            for expr in exprs:
                booked = held[expr]
                try:
                    alive = self.bus.alive(expr, timeout=1.0, complete=True)
                except Exception as e:  # noqa: BLE001 - a closing session or a route's error: next time
                    log.debug("liveliness audit of %s skipped: %s", expr, e)
                    continue
                if booked and not alive:
                    # no evidence: zenoh 1.x sometimes answers a liveliness query with nothing at all on a
                    # session that watches the same tokens (~1 query in 5 here, whatever the reply handler);
                    # taken as evidence, a few such answers in a row unbooked every world at once
                    continue
                # under load an answer can lack replies (issue 41: hundreds of fake worlds mended as gone
                # and back, a healthy world paused): one that lacks a token surely alive is not used
                lacking = sure[expr] - set(alive)
                if expr == keys.ALL_CLAIMS:
                    lacking &= self._own_claims()  # not withdrawn while the query ran
                if lacking:
                    log.debug("liveliness audit of %s skipped: the answer lacks %d live tokens", expr, len(lacking))
                    continue
                for key, is_alive, since in audit.check(expr, booked, alive, time.monotonic(), self.book.touched):
                    if not is_alive and (not router or self._answers_alive(key)):
                        continue  # a client (see `router`), or absent from the list but present when asked alone
                    if not self.book.mend(expr, key, is_alive, since):
                        continue
                    self.counters["liveliness_mended"] += 1
                    log.info("liveliness token %s is %s, but zenoh never said so", key, "alive" if is_alive else "gone")
                    if expr == keys.ALL_ALIVE_WORLDS:
                        self._changes.put((keys.last_chunk(key), is_alive))

    def _surely_alive(self, steps: dict[str, int]) -> dict[str, set[str]]:
        """Tokens a complete liveliness answer lists, per audited expression: this owner's own token
        and claims, and the worlds whose links here answered an observation since the last call
        (`steps`: each link's steps then, updated)."""
        worlds = set()
        for wid, link in list(self.links.items()):
            n = link.counters.steps
            if link.state == "attached" and steps.get(wid, n) != n:
                worlds.add(keys.alive_world(wid))
            steps[wid] = n
        return {
            keys.ALL_ALIVE_WORLDS: worlds,
            keys.ALL_ALIVE_OWNERS: {keys.alive_owner(self.owner_id)},
            keys.ALL_CLAIMS: self._own_claims(),
        }

    def _own_claims(self) -> set[str]:
        """This owner's claim tokens declared at least a second ago (the bus has them all by then)."""
        now = time.monotonic()
        return {keys.alive_claim(w, self.owner_id) for w, (_, t) in list(self._claims.items()) if now - t >= 1.0}

    def _answers_alive(self, key: str) -> bool:
        """Whether a liveliness query for token `key` alone finds it (True when in doubt)."""
        try:
            return bool(self.bus.alive(key, timeout=1.0, complete=True))
        except Exception:  # noqa: BLE001 - a closing session or a route's error
            return True
