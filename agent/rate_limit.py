"""A token bucket: at most `rate` reports per second (bursts of `rate`), the rest counted.

Hostile or broken input can arrive at bus speed; every item is counted where it lands, but the log
lines and events that describe it must not cost the process more than a few per second (a log
line per message is I/O and GIL time taken from the lockstep path)."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable


class TokenBucket:
    """`take()` is True at most `rate` times per second on average (a burst of up to `rate`);
    `suppressed()` returns, and resets, how many `take()`s were refused since the last call."""

    def __init__(self, rate: float, clock: Callable[[], float] = time.monotonic) -> None:
        if not rate > 0:
            raise ValueError(f"rate must be > 0 per second, not {rate}")
        self.rate = float(rate)
        self._clock = clock
        self._budget = self.rate
        self._last = clock()
        self._refused = 0
        self._lock = threading.Lock()

    def take(self) -> bool:
        """One report allowed now? (False: counted as suppressed)."""
        with self._lock:
            now = self._clock()
            self._budget = min(self.rate, self._budget + (now - self._last) * self.rate)
            self._last = now
            if self._budget >= 1.0:
                self._budget -= 1.0
                return True
            self._refused += 1
            return False

    def suppressed(self) -> int:
        """How many reports were refused since the last call (and reset the count)."""
        with self._lock:
            n, self._refused = self._refused, 0
            return n
