"""The bus's plain types: its error, the message it hands to callbacks, the bounded inbox a
subscriber fills and the declared publisher (no zenoh here: `protocol.bus` builds them)."""

from __future__ import annotations

import collections
import threading
from typing import Any, NamedTuple


class BusError(RuntimeError):
    """The bus could not be opened or used; the message says what to do."""


class BusMessage(NamedTuple):
    """One sample as the bus hands it to callbacks and inboxes.

    Attributes
    ----------
    key : str
        The key expression it was published on.
    payload : bytes
        The raw payload (decode it with `codec.decode`).
    encoding : str
        Zenoh's encoding string, e.g. ``application/protobuf;sme.v1.Observation``.
    kind : str
        ``put``, or ``delete`` (a liveliness token vanished).
    """

    key: str
    payload: bytes
    encoding: str
    kind: str = "put"  # "put" or "delete"


class Inbox:
    """A bounded queue filled by a subscriber: when full, the oldest message is dropped and counted."""

    def __init__(self, maxsize: int) -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be >= 1")
        self.maxsize = maxsize
        self._q: collections.deque[BusMessage] = collections.deque()
        self._cv = threading.Condition()
        self.dropped = 0
        self._closed = False

    def push(self, msg: BusMessage) -> None:
        """Append `msg`, dropping (and counting in `dropped`) the oldest one when full."""
        with self._cv:
            if len(self._q) >= self.maxsize:
                self._q.popleft()
                self.dropped += 1
            self._q.append(msg)
            self._cv.notify()

    def get(self, timeout: float | None = None) -> BusMessage | None:
        """The oldest message, or None after `timeout` seconds (or once closed and empty)."""
        with self._cv:
            if not self._q and not self._closed:
                self._cv.wait(timeout)
            return self._q.popleft() if self._q else None

    def close(self) -> None:
        """Wake every waiting `get`; later gets return what is left, then None."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    def __len__(self) -> int:
        return len(self._q)


class Publisher:
    """A declared publisher; its encoding (schema) was set at declaration."""

    def __init__(self, pub: Any) -> None:
        self._pub = pub
        self.put = pub.put  # bound once: this is the lockstep hot path
