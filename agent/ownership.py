"""One owner per world: who may answer a world, decided with liveliness tokens on the bus.

Every session that may answer worlds (an agent daemon, or each worker of one) is an *owner* with a
liveliness token `sme/v1/alive/owner/{owner}`. Before it answers world W it declares a claim token
`sme/v1/alive/claim/{W}/{owner}` and waits `settle` seconds; it answers only while it holds the claim
and sees no claim on W by a lower owner id (plain string order). A loser stops answering first, then
withdraws its claim. Claims vanish with their session, so the survivors see a dead owner's worlds
unclaimed and claim them again. Owners share load by count: an owner claims an unclaimed world only
when it owns no more worlds than the least-loaded live owner, and sheds one world (a hand-off) when
it owns two more than that one. See protocol/README.md, "Owners", for the contract.

`OwnerBook` is the view of the bus (filled from liveliness callbacks, thread-safe); `plan` is the
pure decision made from a snapshot of it, once per tick.
"""

from __future__ import annotations

import threading
import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

from sensorimotor.protocol import keys


@dataclass(frozen=True)
class View:
    """A snapshot of the bus: worlds alive, owners alive, and each world's claimants."""

    worlds: frozenset[str]
    owners: frozenset[str]
    claims: dict[str, frozenset[str]]

    def claimants(self, world: str) -> frozenset[str]:
        """The owners claiming `world` (empty when nobody does)."""
        return self.claims.get(world, frozenset())

    def load(self, owner: str) -> int:
        """How many live worlds `owner` claims."""
        return sum(1 for w, c in self.claims.items() if owner in c and w in self.worlds)


class OwnerBook:
    """Liveliness seen on the bus: worlds, owners, claims; `unclaimed_since` per world (monotonic s)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._worlds: set[str] = set()
        self._owners: set[str] = set()
        # immutable per world, so that a view is one shallow copy and lock-free reads see whole sets
        self._claims: dict[str, frozenset[str]] = {}
        self.unclaimed_since: dict[str, float] = {}
        self._touched: dict[str, float] = {}  # token key -> time.monotonic() of its last event (TokenAudit)

    def _touch(self, key: str) -> None:
        self._touched.pop(key, None)  # re-inserted last: the dict stays in the order of the events
        self._touched[key] = time.monotonic()
        if len(self._touched) > self.TOUCHED_MAX:  # bounded: forget the older half, once per half
            self._touched = dict(list(self._touched.items())[len(self._touched) // 2 :])

    TOUCHED_MAX = 16384

    def _world(self, world: str, alive: bool) -> None:
        (self._worlds.add if alive else self._worlds.discard)(world)

    def _owner(self, owner: str, alive: bool) -> None:
        (self._owners.add if alive else self._owners.discard)(owner)

    def _claim(self, key: str, alive: bool) -> None:
        parts = key.split("/")
        if len(parts) < 2:
            return
        world, owner = parts[-2], parts[-1]
        c = self._claims.get(world, frozenset())
        c = c | {owner} if alive else c - {owner}
        if c:
            self._claims[world] = c
        else:
            self._claims.pop(world, None)

    def world(self, world: str, alive: bool) -> None:
        """A world's token appeared or vanished."""
        with self._lock:
            self._world(world, alive)
            self._touch(keys.alive_world(world))

    def owner(self, owner: str, alive: bool) -> None:
        """An owner's token appeared or vanished."""
        with self._lock:
            self._owner(owner, alive)
            self._touch(keys.alive_owner(owner))

    def claim(self, key: str, alive: bool) -> None:
        """A claim token `.../claim/{world}/{owner}` appeared or vanished."""
        with self._lock:
            self._claim(str(key), alive)
            self._touch(str(key))

    def touched(self, key: str) -> float:
        """When the last event about token `key` came (time.monotonic(); -inf: none remembered)."""
        return self._touched.get(key, float("-inf"))

    def mend(self, expr: str, key: str, alive: bool, since: float) -> bool:
        """Book token `key` (of key expression `expr`) as `alive`, as a missed event would have,
        unless an event about it came after `since`: then the events have spoken since the
        disagreement was seen, and nothing is changed (False)."""
        with self._lock:
            if self._touched.get(key, float("-inf")) > since:
                return False
            if expr == keys.ALL_ALIVE_WORLDS:
                self._world(keys.last_chunk(key), alive)
            elif expr == keys.ALL_ALIVE_OWNERS:
                self._owner(keys.last_chunk(key), alive)
            else:
                self._claim(key, alive)
            return True

    def claimed_by_other(self, world: str, me: str) -> bool:
        """Whether an owner other than `me` claims `world` (lock-free read: for the hot path)."""
        c = self._claims.get(world)
        return c is not None and bool(c) and (me not in c or len(c) > 1)

    def claimants(self, world: str) -> frozenset[str]:
        """The owners claiming `world` now (cheaper than a whole `view` per world)."""
        return self._claims.get(world, frozenset())

    def view(self) -> View:
        """A consistent snapshot."""
        with self._lock:
            return View(frozenset(self._worlds), frozenset(self._owners), dict(self._claims))

    def tokens(self) -> dict[str, frozenset[str]]:
        """The token keys the book holds, per liveliness key expression (see `TokenAudit`)."""
        with self._lock:
            return {
                keys.ALL_ALIVE_WORLDS: frozenset(keys.alive_world(w) for w in self._worlds),
                keys.ALL_ALIVE_OWNERS: frozenset(keys.alive_owner(o) for o in self._owners),
                keys.ALL_CLAIMS: frozenset(keys.alive_claim(w, o) for w, c in self._claims.items() for o in c),
            }


class TokenAudit:
    """Finds what a book's liveliness events missed or reported out of order.

    Zenoh reports a token's appearance and disappearance as events; when a router on one of two
    paths to a client dies and the client reconnects through the other, the disappearance (through
    the dead router) can be reported after the appearance (through the new one), and the token is
    then alive but booked as gone: a world nobody claims again. A liveliness query answers from the
    router's own table, so the book is compared with one now and then. A disagreement counts only
    once every query for `patience` seconds has shown it and no event about the token came in that
    time (`touched`), so an event still on its way is never overruled; `OwnerBook.mend` applies it
    only if no event came since either.

    Parameters
    ----------
    patience : float, default 1.5
        Seconds a disagreement must last before it is reported.
    """

    def __init__(self, patience: float = 1.5) -> None:
        if not patience >= 0:
            raise ValueError(f"patience must be >= 0 seconds, not {patience}")
        self.patience = float(patience)
        self._since: dict[str, dict[tuple[str, bool], float]] = {}

    def check(
        self,
        expr: str,
        booked: Iterable[str],
        alive: Iterable[str],
        now: float,
        touched: Callable[[str], float] = lambda key: float("-inf"),
    ) -> list[tuple[str, bool, float]]:
        """The disagreements on key expression `expr` that have lasted `patience` seconds: (key,
        alive as the query says, since when), with `touched(key)` the time of the book's last event
        about the key (a disagreement is timed from the later of the two)."""
        booked, alive = set(booked), set(alive)
        now_seen = [(k, True) for k in alive - booked] + [(k, False) for k in booked - alive]
        before = self._since.get(expr, {})
        since = {d: max(before.get(d, now), touched(d[0])) for d in now_seen}
        self._since[expr] = since
        return sorted((k, a, t) for (k, a), t in since.items() if now - t >= self.patience)


@dataclass(frozen=True)
class Plan:
    """What an owner does this tick: withdraw these claims (why), declare these, hand one off."""

    release: dict[str, str] = field(default_factory=dict)
    claim: tuple[str, ...] = ()
    shed: str | None = None


def plan(
    me: str,
    view: View,
    mine: Iterable[str],
    unclaimed_for: dict[str, float],
    *,
    known: frozenset[str] = frozenset(),
    avoid: frozenset[str] = frozenset(),
    failed: frozenset[str] = frozenset(),
    claim_delay: float = 0.3,
    may_shed: bool = False,
) -> Plan:
    """The decision of owner `me` from `view`.

    Parameters
    ----------
    me : str
        This owner's id.
    view : View
        The bus as seen now (this owner's own claims included once they came back from the bus).
    mine : iterable of str
        The worlds this owner holds a claim token for.
    unclaimed_for : dict
        Seconds each alive world has been seen without any claimant.
    known : frozenset of str
        Worlds this owner has a paused link for: it claims them without waiting `claim_delay` (the
        previous owner of a returning world gets it back first).
    avoid : frozenset of str
        Worlds not to claim now (e.g. an attach just failed).
    failed : frozenset of str
        Worlds this owner claims but could not attach (a fake or broken world). They count as load
        when deciding whether to claim more (so owners take turns with them), but an owner sheds only
        when its *working* worlds exceed the least load by two, and never sheds a failed one: broken
        worlds can never move a healthy one (in another owner's load they can only make it shed less).
    claim_delay : float
        Seconds a world must have been unclaimed before this owner claims it; multiplied by
        1 + this owner's rank among the least-loaded owners, so that ties rarely race.
    may_shed : bool
        Whether a hand-off is allowed this tick (the caller rate-limits them).
    """
    mine = set(mine)
    release: dict[str, str] = {}
    claims, worlds = view.claims, view.worlds
    empty: frozenset[str] = frozenset()
    # set operations and one pass each: a tick must stay cheap with thousands of (fake) worlds
    for w in sorted(mine - worlds):
        release[w] = "world gone"
    contested = [w for w in mine & worlds if len(c := claims.get(w, empty)) > 1 or me not in c]
    for w in sorted(contested):  # (the usual case, alone: nothing to compare)
        lower = min((o for o in claims.get(w, empty) if o < me), default=None)
        if lower is not None:
            release[w] = f"{lower} claims it too (the lower owner id wins)"
    held = mine - set(release)
    owners = set(view.owners) | {me}
    by_set = Counter(map(claims.__getitem__, claims.keys() & worlds))  # few distinct claimant sets
    loads = {o: sum(n for c, n in by_set.items() if o in c) for o in owners}
    loads[me] = len(held & worlds)
    least = min(loads.values())
    healthy = (held - failed) & worlds
    shed = None
    if may_shed and len(healthy) >= least + 2:
        shed = max(healthy)  # deterministic: the last in id order
    claim: tuple[str, ...] = ()
    if loads[me] <= least and shed is None:
        tied = sorted(o for o, n in loads.items() if n == least)
        rank = tied.index(me) if me in tied else len(tied)
        free = worlds - claims.keys() - mine - avoid
        for w in sorted(free, key=lambda w: (w not in known, w)):
            wait = 0.0 if w in known else claim_delay * (1 + rank)
            if unclaimed_for.get(w, 0.0) >= wait:
                claim = (w,)
                break
    return Plan(release, claim, shed)


def claim_key(world: str, owner: str) -> str:
    """The claim token's key (checked ids)."""
    return keys.alive_claim(keys.check_id(world, "world id"), keys.check_id(owner, "owner id"))
