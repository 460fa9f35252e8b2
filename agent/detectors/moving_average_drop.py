"""The dissertation's detector (4.4.2, 8.4): a large negative change in the moving average of the
reward. A short moving average is compared with the long-run reference level; a drop is declared
when the short average falls below the reference by more than `drop` reference standard deviations
of the short average (the reference follows the stream with a lag)."""

from __future__ import annotations

import collections
import math
from typing import Any

from sensorimotor.agent.detectors.base import ReferencedDetector


class MovingAverageDrop(ReferencedDetector):
    """The dissertation's moving-average drop detector (see the module docstring).

    Parameters
    ----------
    window : int, default 20
        Length of the short moving average.
    drop : float, default 5.0
        Threshold, in standard errors of the short average below the reference mean.
    warmup : int, default 200
        Samples that form the first reference.
    rate : float, default 0.002
        Rate at which the reference follows the stream after the warm-up.
    """

    name = "moving_average"

    def __init__(self, window: int = 20, drop: float = 5.0, warmup: int = 200, rate: float = 0.002) -> None:
        super().__init__(warmup, rate)
        if window < 1 or drop <= 0:
            raise ValueError("window must be >= 1 and drop > 0")
        self.window, self.drop = window, drop
        self.reset()

    def _clear(self) -> None:
        self._buf: collections.deque[float] = collections.deque(maxlen=self.window)
        self._stat = 0.0

    @property
    def statistic(self) -> float:
        """How far the short average is below the reference, in its standard errors."""
        return self._stat

    def state(self) -> dict[str, Any]:
        """The referenced detector's snapshot plus the window and statistic."""
        return {**super().state(), "window_values": list(self._buf), "stat": self._stat}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a detector with the same settings."""
        super().restore(state)
        self._buf = collections.deque((float(x) for x in state["window_values"]), maxlen=self.window)
        self._stat = float(state["stat"])

    def _update(self, x: float) -> bool:
        self._buf.append(x)
        if not self._ref.ready:
            self._ref.push(x)
            return False
        short = sum(self._buf) / len(self._buf)
        se = self._ref.sd / math.sqrt(len(self._buf))
        self._stat = (self._ref.mean - short) / se
        if self._stat > self.drop:
            self._ref.reset()
            self._buf.clear()
            self._stat = 0.0
            return True
        self._ref.push(x)
        return False
