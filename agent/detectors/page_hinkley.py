"""Page-Hinkley test (Page 1954; Hinkley 1971) in "down" mode: m_t = sum_i (xbar_i - x_i)/sigma - delta
with xbar_i the mean of all samples since the last detection (the classic form; against a known
reference mean it would coincide with CUSUM), and a drop when m_t - min_s m_s > threshold.
sigma is the standard deviation over the warm-up samples."""

from __future__ import annotations

import math
from typing import Any

from sensorimotor.agent.detectors.base import DropDetector


class PageHinkley(DropDetector):
    """Page-Hinkley test for drops (see the module docstring).

    Parameters
    ----------
    delta : float, default 0.25
        Magnitude allowance per step, in warm-up standard deviations.
    threshold : float, default 16.0
        Decision threshold on m_t - min m.
    warmup : int, default 100
        Samples used to estimate sigma before anything can be detected.
    """

    name = "page_hinkley"

    def __init__(self, delta: float = 0.25, threshold: float = 16.0, warmup: int = 100) -> None:
        super().__init__()
        if delta < 0 or threshold <= 0 or warmup < 2:
            raise ValueError("delta must be >= 0, threshold > 0 and warmup >= 2")
        self.delta, self.threshold, self.warmup = delta, threshold, warmup
        self.reset()

    def reset(self) -> None:
        """Forget everything: the next sample starts a new warm-up."""
        self.n = 0
        self.drift_detected = False
        self._count = 0
        self._mean = 0.0
        self._m2 = 0.0
        self._sd = 1.0
        self._m = 0.0
        self._min = 0.0

    @property
    def statistic(self) -> float:
        """m_t - min_s m_s (a drop when it exceeds `threshold`)."""
        return self._m - self._min

    def state(self) -> dict[str, Any]:
        """The base snapshot plus the running sums."""
        return {
            **super().state(),
            "count": self._count,
            "mean": self._mean,
            "m2": self._m2,
            "sd": self._sd,
            "m": self._m,
            "min": self._min,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a detector with the same settings."""
        super().restore(state)
        self._count = int(state["count"])
        self._mean, self._m2, self._sd = float(state["mean"]), float(state["m2"]), float(state["sd"])
        self._m, self._min = float(state["m"]), float(state["min"])

    @property
    def reference(self) -> float:
        """Mean of the samples since the last detection or reset (NaN when there are none)."""
        return self._mean if self._count else float("nan")

    def _update(self, x: float) -> bool:
        self._count += 1
        d = x - self._mean
        self._mean += d / self._count
        self._m2 += d * (x - self._mean)
        if self._count <= self.warmup:
            self._sd = math.sqrt(max(self._m2 / max(self._count - 1, 1), 1e-12))
            return False
        self._m += (self._mean - x) / self._sd - self.delta
        self._min = min(self._min, self._m)
        if self._m - self._min > self.threshold:
            self.reset()
            return True
        return False
