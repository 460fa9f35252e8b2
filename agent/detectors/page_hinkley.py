"""Page-Hinkley test in "down" mode, on standardised rewards: m_t = sum (xbar - x_i)/sigma - delta,
a drop is declared when m_t - min_{s<=t} m_s > threshold. xbar and sigma come from the reference
regime, which follows the stream `lag` steps late."""

from __future__ import annotations

from agent.detectors.base import DropDetector, RunningMoments


class PageHinkley(DropDetector):
    name = "page_hinkley"

    def __init__(self, delta: float = 0.5, threshold: float = 9.0, warmup: int = 100, rate: float = 0.002) -> None:
        super().__init__()
        if delta < 0 or threshold <= 0:
            raise ValueError("delta must be >= 0 and threshold > 0")
        self.delta, self.threshold = delta, threshold
        self._ref = RunningMoments(warmup, rate)
        self.reset()

    def reset(self) -> None:
        self.n = 0
        self.drift_detected = False
        self._ref.reset()
        self._m = 0.0
        self._min = 0.0

    @property
    def statistic(self) -> float:
        return self._m - self._min

    def _update(self, x: float) -> bool:
        ref = self._ref
        if not ref.ready:
            ref.push(x)
            return False
        self._m += -ref.z(x) - self.delta
        self._min = min(self._min, self._m)
        if self._m - self._min > self.threshold:
            self._m = self._min = 0.0
            ref.reset()
            return True
        ref.push(x)
        return False
