"""Checkpoints shared on the bus: the newest copy of each world, when to share the next one, and
the last embedding version anyone published.

Every owner shares the learned state of the worlds it answers on
`sme/v1/agent/{owner}/checkpoint/{world}`: periodically, on a hand-off or a clean stop, and - so
that a takeover loses little - soon after each new embedding version (at most once per
`min_interval` seconds per world; a checkpoint over `max_bytes` is never put on the bus). Every
owner keeps the newest copy (by `saved_at`) of each world shared by any owner and answers queries
for it, so a new owner resumes from the newest copy any agent holds, not only the ones it heard.

`SharedCheckpoints` (the copies, thread-safe) and `ShareSchedule` (when a world is due) are plain
state: the daemon feeds them from the bus and asks them what to do.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass

from sensorimotor.agent.checkpoint import Checkpoint, CheckpointError, decode_checkpoint

log = logging.getLogger("sme.agent")

#: shared checkpoints larger than this are neither put on the bus nor accepted from it
MAX_SHARED_BYTES = 16 * 1024 * 1024


@dataclass(frozen=True)
class Copy:
    """One shared checkpoint: who shared it, its bytes (as they travel) and what they decode to."""

    owner: str
    data: bytes
    checkpoint: Checkpoint


class SharedCheckpoints:
    """The newest shared checkpoint of each world, and the newest embedding version seen per world.

    Parameters
    ----------
    max_bytes : int, default MAX_SHARED_BYTES
        Copies larger than this are refused before they are decoded.
    """

    def __init__(self, max_bytes: int = MAX_SHARED_BYTES) -> None:
        self.max_bytes = max_bytes
        self._lock = threading.Lock()
        self._copies: dict[str, Copy] = {}
        self._published: dict[str, int] = {}  # world -> highest embedding version published by any agent

    def offer(self, owner: str, world: str, data: bytes, exclude: str = "") -> str | None:
        """Keep `data` (a checkpoint shared by `owner` on world `world`'s key) if it is the newest
        copy of that world; returns why it was refused (None: checked, and kept, or older than the
        one held, or taken by owner `exclude` - this owner's own state, which it has)."""
        if len(data) > self.max_bytes:
            return f"{len(data)} bytes, more than the {self.max_bytes} accepted"
        try:
            ckpt = decode_checkpoint(data)
        except CheckpointError as e:
            return str(e)
        if ckpt.world_id != world:
            return f"it is for world {ckpt.world_id[:64]!r}, not {world[:64]!r}"
        if exclude and ckpt.owner == exclude:
            return None
        with self._lock:
            old = self._copies.get(world)
            if old is None or ckpt.saved_at >= old.checkpoint.saved_at:
                self._copies[world] = Copy(owner, bytes(data), ckpt)
        return None

    def newest(self, world: str) -> Copy | None:
        """The newest copy held of `world` (None: none)."""
        return self._copies.get(world)

    def drop(self, world: str) -> None:
        """Forget the copy of `world` (it could not be restored)."""
        with self._lock:
            self._copies.pop(world, None)

    def published(self, world: str, version: int) -> None:
        """An embedding version of `world` was published (by any agent)."""
        with self._lock:
            if version > self._published.get(world, 0):
                self._published[world] = version

    def last_published(self, world: str) -> int:
        """The highest embedding version of `world` seen published (0: none)."""
        return self._published.get(world, 0)

    def worlds(self) -> list[str]:
        """The worlds a copy is held for."""
        return sorted(self._copies)


class ShareSchedule:
    """When each world's checkpoint is next shared because a new embedding version came out.

    A new version makes the world due; a due world is shared once `min_interval` seconds passed
    since its last share (any share: periodic ones count), so a burst of versions costs one share
    and the last version of a burst is still shared, at most `min_interval` later.

    Parameters
    ----------
    min_interval : float, default 2.0
        Seconds between two shares of one world.

    Examples
    --------
    >>> s = ShareSchedule(2.0)
    >>> s.new_version("g1", now=0.0); s.take(now=0.0)
    ['g1']
    >>> s.shared("g1", now=0.0); s.new_version("g1", now=1.0); s.take(now=1.0)
    []
    >>> s.take(now=2.0)
    ['g1']
    """

    def __init__(self, min_interval: float = 2.0) -> None:
        if min_interval < 0:
            raise ValueError(f"the share interval must be >= 0 seconds, not {min_interval}")
        self.min_interval = min_interval
        self._lock = threading.Lock()
        self._due: set[str] = set()
        self._last: dict[str, float] = {}

    def new_version(self, world: str, now: float) -> None:  # noqa: ARG002 - the time is when take() looks
        """A new embedding version of `world` was published by this owner: share it soon."""
        with self._lock:
            self._due.add(world)

    def shared(self, world: str, now: float) -> None:
        """`world`'s checkpoint was just shared (for whatever reason)."""
        with self._lock:
            self._last[world] = now
            self._due.discard(world)

    def forget(self, world: str) -> None:
        """This owner no longer answers `world`."""
        with self._lock:
            self._due.discard(world)
            self._last.pop(world, None)

    def take(self, now: float) -> list[str]:
        """The due worlds whose interval has passed (sorted); they stay due until `shared`."""
        with self._lock:
            return sorted(w for w in self._due if now - self._last.get(w, float("-inf")) >= self.min_interval)
