"""Velocity as the change of a position over several steps: the least-squares slope of the last
`window` + 1 positions (ch. 8: the car's velocity is "the change of that internal position over
time"). On a position quantised to whole vergence steps it follows a turn of the car with a lag of
about window / 2 steps and no tuning of noise variances, unlike the constant-velocity Kalman
filter (`kalman_velocity`), whose process noise sets a lag that is hard to choose for a reading
whose scale varies along the track."""

from __future__ import annotations

from collections import deque
from typing import Any

import numpy as np


class WindowVelocity:
    """Least-squares slope of the last `window` + 1 positions, per step; (position, velocity).

    The position returned is the latest reading itself; after `reset` the slope uses the readings
    seen so far (velocity 0 from one reading).
    """

    def __init__(self, window: int = 8) -> None:
        if window < 1:
            raise ValueError(f"window must be >= 1, got {window}")
        self.window = window
        self._h: deque[float] = deque(maxlen=window + 1)

    def reset(self, position: float | None = None) -> None:
        """Start over, with `position` as the only reading (none when None)."""
        self._h.clear()
        if position is not None:
            self._h.append(float(position))

    def update(self, position: float) -> tuple[float, float]:
        """Feed one position reading; returns (the reading, the slope of the window's readings)."""
        self._h.append(float(position))
        n = len(self._h)
        if n < 2:
            return float(position), 0.0
        t = np.arange(n) - (n - 1) / 2
        return float(position), float(t @ np.fromiter(self._h, float, n) / (t @ t))

    def state(self) -> dict[str, Any]:
        """The readings in the window."""
        return {"history": list(self._h)}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of an estimator with the same window."""
        self._h = deque((float(p) for p in state["history"]), maxlen=self.window + 1)
