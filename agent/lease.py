"""The owner's side of a world's lease: ask for it, give it back, and tell whether a world's
``lease_lost`` event means this owner must stop.

A world applies only the actions of its lease holder (see `worlds.lease` and protocol/README.md,
"Leases"). Before an owner answers a world it asks for the lease on `sme/v1/world/{id}/lease`:
granted, its actions carry (owner, epoch); held by another live owner, it waits and asks again; no
answer at all (a world written before leases existed), it answers unfenced with epoch 0, which
such a world ignores and a leasing world applies only while nobody holds its lease.

`ask` is the pure reading of a reply; `LeaseClient` adds the bus round trip.
"""

from __future__ import annotations

import logging
import secrets
from collections.abc import Callable
from dataclasses import dataclass

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import Lease, LeaseRequest, WorldEvent, WorldEventKind

log = logging.getLogger("sme.agent")

#: `(key, payload, timeout) -> reply payloads`; raises on an error reply (`Bus.get` does)
Get = Callable[[str, bytes, float], list[bytes]]


@dataclass(frozen=True)
class Outcome:
    """What a lease request came to.

    Attributes
    ----------
    granted : bool
        The asker holds the lease (answer with `epoch`).
    epoch : int
        The asker's epoch when granted; the current epoch otherwise (0 unknown).
    holder : str
        Who holds the lease ("" nobody or unknown).
    reason : str
        The world's reason token, or ``no_lease`` (no answer: a world without leases, answered
        unfenced) or ``bad_reply``.
    session : str
        The world session the epoch belongs to.
    """

    granted: bool
    epoch: int = 0
    holder: str = ""
    reason: str = ""
    session: str = ""

    @property
    def unfenced(self) -> bool:
        """The world has no lease: answer it with epoch 0 (the claim protocol alone decides)."""
        return self.reason == "no_lease"


def read_reply(world_id: str, owner: str, replies: list[bytes]) -> Outcome:
    """The outcome of a lease request from its replies (pure: what `LeaseClient.acquire` decides).

    No reply: a world without leases (``no_lease``, answered unfenced). A reply that does not
    decode, or is for another world: ``bad_reply`` (not granted: ask again later)."""
    if not replies:
        return Outcome(False, reason="no_lease")
    try:
        lease = codec.decode(Lease, replies[0])
    except ProtocolError as e:
        log.warning("world %s: bad lease reply: %s", world_id, e)
        return Outcome(False, reason="bad_reply")
    if lease.world_id != world_id:
        return Outcome(False, reason="bad_reply")
    granted = lease.granted and lease.holder == owner and lease.epoch > 0
    return Outcome(granted, lease.epoch, lease.holder, lease.reason, lease.session)


def lost_by(ev: WorldEvent, owner: str, epoch: int) -> bool:
    """Whether world event `ev` says that `owner`, answering with `epoch`, lost the world: a
    ``lease_lost`` addressed to this owner and this epoch, the lease now elsewhere or free. An
    event about an epoch this owner no longer uses (it got a newer lease since) is not."""
    return (
        ev.kind == WorldEventKind.LEASE_LOST
        and ev.owner == owner
        and ev.epoch == epoch
        and not (ev.holder == owner and ev.holder_epoch == epoch)
    )


class LeaseClient:
    """Ask worlds for their lease and give it back, as owner `owner`.

    Parameters
    ----------
    get : callable
        ``get(key, payload, timeout) -> [reply payload, ...]`` (the bus's query).
    owner : str
        This owner's id.
    timeout : float, default 1.0
        Seconds to wait for the world's answer.
    """

    def __init__(self, get: Get, owner: str, timeout: float = 1.0) -> None:
        self._get = get
        self.owner = owner
        self.timeout = timeout

    def acquire(self, world_id: str, epoch: int = 0, tries: int = 2) -> Outcome:
        """Ask world `world_id` for its lease (`epoch`: the one held, to renew it). A world that
        does not answer after `tries` queries is taken for one without leases (``no_lease``)."""
        # one id for every try: a copy that arrives twice (two routers) or a retry after a lost reply
        # gets the same lease, not a second grant that would fence the first
        payload = codec.encode(LeaseRequest(world_id, self.owner, epoch, request_id=secrets.token_hex(8)))
        out = Outcome(False, reason="no_lease")
        for _ in range(tries):
            try:
                out = read_reply(world_id, self.owner, self._get(keys.world_lease(world_id), payload, self.timeout))
            except Exception as e:  # noqa: BLE001 - an error reply or a closing bus: not granted, ask again
                log.warning("world %s: lease request failed: %s", world_id, e)
                return Outcome(False, reason="bad_reply")
            if not out.unfenced:
                return out
        return out

    def release(self, world_id: str, epoch: int, timeout: float = 0.5) -> bool:
        """Give the lease of `epoch` back (best effort); True when the world confirmed it."""
        if epoch <= 0:
            return False
        payload = codec.encode(LeaseRequest(world_id, self.owner, epoch, release=True))
        try:
            replies = self._get(keys.world_lease(world_id), payload, timeout)
        except Exception as e:  # noqa: BLE001 - the world is gone or the bus closing: its ttl frees it
            log.debug("world %s: lease release failed: %s", world_id, e)
            return False
        return read_reply(world_id, self.owner, replies).reason == "released"
