"""The world's side of ownership: one lease, an epoch that only grows, and the check of every action.

Liveliness tells owners who is alive; it is not consensus, and in a partition two owners can each
believe they own a world. The world sees every action meant for it, so this is where ownership is
checked: an owner asks the world for its lease (a `LeaseRequest` on `sme/v1/world/{id}/lease`), the
world grants it with a new epoch, and from then on applies only the actions that carry the holder's
owner id and that epoch. An action from anyone else is not applied; its owner is told with a
`WorldEvent` of kind ``lease_lost``. See protocol/README.md, "Leases", for the contract.

Granting rules (request from owner O carrying epoch e):
- a second copy of the request that made the current lease (same `request_id`: a message can
  arrive twice, once through each of two routers): the same answer again;
- O holds the lease at epoch e: renewed, same epoch;
- nobody holds it, its holder was silent for `ttl` seconds, its holder's owner token vanished and it
  was silent for `gone_grace` seconds (liveliness alone is not trusted: in a partition a token can
  vanish on one path while its owner still answers on another), or O holds it under another epoch
  (O restarted): granted to O with epoch + 1;
- otherwise refused (``held``): the holder is alive and answering.
A release from the holder of the current epoch frees the lease (the epoch stays: it never goes
back). Actions with epoch 0 (agents that predate leases) are applied only while nobody holds it.

`LeaseKeeper` is plain state and decisions with the clock passed in: the node calls it under its
lock, and the tests call it directly.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from sensorimotor.protocol.messages import Action, Lease, LeaseRequest, WorldEvent, WorldEventKind


@dataclass
class LeaseCounts:
    """What the keeper decided: grants, refusals, fenced actions, and who was applied under which epoch."""

    granted: int = 0  # leases granted (each with a new epoch)
    refused: int = 0  # requests refused because another live owner holds the lease
    released: int = 0
    fenced: int = 0  # actions not applied: not from the current lease
    unleased: int = 0  # actions with epoch 0 applied while nobody held the lease
    lost_sent: int = 0  # lease_lost events sent (rate-limited)
    owners: dict[int, set[str]] = field(default_factory=dict)  # epoch -> owners whose actions were applied

    def summary(self) -> dict:
        """JSON-ready counts; `owners` as {epoch: [owner, ...]} and the most owners seen under one epoch."""
        return {
            "leases_granted": self.granted,
            "leases_refused": self.refused,
            "leases_released": self.released,
            "actions_fenced": self.fenced,
            "actions_unleased": self.unleased,
            "lease_lost_sent": self.lost_sent,
            "lease_owners": {str(e): sorted(o) for e, o in sorted(self.owners.items())},
            "max_owners_per_lease": max((len(o) for o in self.owners.values()), default=0),
        }


class LeaseKeeper:
    """The lease of one world session.

    Parameters
    ----------
    world_id : str
        The world's id (requests for another world are answered ``not_holder``).
    session : str
        The world process's session; epochs count within it.
    ttl : float, default 1.5
        Seconds without an applied action from the holder after which the lease may be granted to
        another owner (inf: only on release or when the holder's owner token vanishes).
    lost_every : float, default 0.5
        Seconds between two ``lease_lost`` events to the same (owner, epoch).
    gone_grace : float, default 0.25
        Seconds of silence after which a holder whose owner token vanished loses the lease.

    Examples
    --------
    >>> k = LeaseKeeper("g1", "s")
    >>> k.request(LeaseRequest("g1", "a"), now=0.0).epoch
    1
    >>> k.request(LeaseRequest("g1", "b"), now=0.1).granted  # a is alive and recent
    False
    >>> k.admit(Action("g1", 0, (0.0,), owner="a", epoch=1), now=0.2)
    True
    """

    def __init__(
        self, world_id: str, session: str, ttl: float = 1.5, lost_every: float = 0.5, gone_grace: float = 0.25
    ) -> None:
        if not ttl > 0:
            raise ValueError(f"lease ttl must be > 0 seconds, not {ttl}")
        self.world_id = world_id
        self.session = session
        self.ttl = float(ttl)
        self.lost_every = lost_every
        self.gone_grace = gone_grace
        self._granted_by = ""  # request_id of the request that made the current lease
        self.holder = ""
        self.epoch = 0
        self.heard = 0.0  # monotonic time of the holder's last grant or applied action
        self.counts = LeaseCounts()
        self._gone: set[str] = set()  # owners whose liveliness token the world saw vanish
        self._lost_at: dict[tuple[str, int], float] = {}

    def owner_alive(self, owner: str, alive: bool) -> None:
        """An owner's liveliness token appeared or vanished (a vanished holder's lease is free to grant)."""
        (self._gone.discard if alive else self._gone.add)(owner)
        if len(self._gone) > 4096:  # bounded: forget the oldest-looking half (ids of long-dead owners)
            for o in sorted(self._gone)[:2048]:
                self._gone.discard(o)

    def free(self, now: float) -> bool:
        """Whether the lease may go to a new owner now."""
        silent = now - self.heard
        return not self.holder or silent >= self.ttl or (self.holder in self._gone and silent >= self.gone_grace)

    def _lease(self, granted: bool, reason: str) -> Lease:
        return Lease(self.world_id, self.session, self.holder, self.epoch, granted, reason, self.ttl, time.time())

    def request(self, req: LeaseRequest, now: float) -> Lease:
        """Answer a lease request (see the module docstring for the rules)."""
        if req.world_id != self.world_id:
            return self._lease(False, "not_holder")
        if req.request_id and req.request_id == self._granted_by and req.owner == self.holder:
            return self._lease(True, "granted")  # a copy of the request that made this lease
        if req.release:
            if req.owner == self.holder and req.epoch == self.epoch:
                self.holder = ""
                self.counts.released += 1
                return self._lease(False, "released")
            return self._lease(False, "not_holder")
        if req.owner == self.holder and req.epoch == self.epoch and self.epoch > 0:
            self.heard = now
            return self._lease(True, "renewed")
        if req.owner == self.holder or self.free(now):
            self.epoch += 1
            self.holder = req.owner
            self._granted_by = req.request_id
            self.heard = now
            self.counts.granted += 1
            self._gone.discard(req.owner)
            return self._lease(True, "granted")
        self.counts.refused += 1
        return self._lease(False, "held")

    def admit(self, act: Action, now: float) -> bool:
        """Whether `act` may be applied: it carries the current lease, or (epoch 0) nobody holds one.
        Counts it either way; an applied leased action renews the holder's silence clock."""
        if act.epoch and act.epoch == self.epoch and act.owner == self.holder:
            self.heard = now
            owners = self.counts.owners.get(act.epoch)
            if owners is None:
                owners = self.counts.owners[act.epoch] = set()
            if act.owner not in owners:
                owners.add(act.owner)
            return True
        if act.epoch == 0 and not self.holder:
            self.counts.unleased += 1
            return True
        self.counts.fenced += 1
        return False

    def lost_event(self, act: Action, now: float) -> WorldEvent | None:
        """The ``lease_lost`` event for a fenced action's owner, at most once per `lost_every` per
        (owner, epoch); None when one went out recently or the action names no owner."""
        if not act.owner:
            return None
        key = (act.owner, act.epoch)
        last = self._lost_at.get(key)
        if last is not None and now - last < self.lost_every:
            return None
        if len(self._lost_at) > 1024:
            self._lost_at.clear()
        self._lost_at[key] = now
        self.counts.lost_sent += 1
        who = f"owner {self.holder} (epoch {self.epoch})" if self.holder else "nobody (the lease is free: ask for it)"
        return WorldEvent(
            self.world_id,
            WorldEventKind.LEASE_LOST,
            "not_holder",
            f"action of owner {act.owner[:64]} epoch {act.epoch} not applied: the lease is held by {who}",
            act.step,
            self.session,
            time.time(),
            owner=act.owner[:64],
            epoch=act.epoch,
            holder=self.holder,
            holder_epoch=self.epoch,
        )
