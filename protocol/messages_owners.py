"""The messages of ownership: a lease asked of a world and its answer, and the checkpoint an owner
shares on the bus for the others to resume its worlds from (see protocol/README.md, "Owners")."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class LeaseRequest:
    """An owner asks a world for its lease (or gives it back, `release`), on `.../lease`.

    Attributes
    ----------
    world_id, owner : str
        The world asked and the asking owner.
    epoch : int
        The epoch the asker holds (0: none); with `release`, the epoch given back.
    release : bool
        Give the lease back instead of asking for it.
    request_id : str
        Random per request: a second copy of the same request (a message can arrive twice, once
        through each of two routers) gets the same answer instead of a second grant.
    """

    world_id: str
    owner: str
    epoch: int = 0
    release: bool = False
    request_id: str = ""


@dataclass(frozen=True)
class Lease:
    """A world's answer to a `LeaseRequest`: its lease as it stands after the request.

    Attributes
    ----------
    world_id, session : str
        The world and its process's session (epochs count within one session).
    holder : str
        The owner whose actions are applied ("" while nobody holds the lease).
    epoch : int
        The current epoch; it only grows within a session.
    granted : bool
        Whether the asker holds the lease now.
    reason : str
        ``granted``, ``renewed``, ``held`` (another owner holds it), ``released``, ``not_holder``.
    ttl : float
        Seconds of silence after which a live holder's lease may be granted to another owner.
    timestamp : float
        Seconds since the epoch.
    """

    world_id: str
    session: str
    holder: str
    epoch: int
    granted: bool
    reason: str = ""
    ttl: float = 0.0
    timestamp: float = 0.0


@dataclass(frozen=True)
class SharedCheckpoint:
    """One owner's learned state of one world, shared on the bus (`sme.v1.Checkpoint`).

    Attributes
    ----------
    world_id : str
        The world the state was learned on (it must match the key it arrives on).
    data : bytes
        A checkpoint file (the .npz of `agent.checkpoint`), at most `codec.MAX_TENSOR_BYTES`.
    owner : str
        The owner id that shares it ("" when unknown).
    epoch : int
        The owner's lease epoch on the world; 0 until owners hold leases (protocol/README.md, "Owners").
    format_version : int
        The checkpoint file format version inside `data`.
    embedding_version : int
        The embedding version the state had published.
    saved_at : float
        Seconds since the Unix epoch when the state was taken.
    """

    world_id: str
    data: bytes
    owner: str = ""
    epoch: int = 0
    format_version: int = 0
    embedding_version: int = 0
    saved_at: float = 0.0
