"""Standardised one-sided (downward) CUSUM (Page 1954): S = max(0, S + (mu - x)/sigma - k);
a drop is declared when S > h. mu and sigma describe the reference regime (see RunningMoments) and
follow the stream `lag` steps late, so a drop in progress does not pull the reference down. After a
detection the reference is learned afresh. With k = 0.5 and h = 9 the in-control run length of
N(0,1) data is about 5e4 steps and a 2-sigma drop is detected in about 7 steps."""

from __future__ import annotations

from sensorimotor.agent.detectors.base import SummedDetector


class CUSUM(SummedDetector):
    """One-sided standardised CUSUM for drops (see the module docstring).

    Parameters
    ----------
    k : float, default 0.5
        Allowance, in reference standard deviations, subtracted at every step.
    h : float, default 9.0
        Decision threshold on the cumulative sum.
    warmup : int, default 100
        Samples that form the first reference before anything can be detected.
    rate : float, default 0.002
        Rate at which the reference follows the stream after the warm-up.
    """

    name = "cusum"

    def __init__(self, k: float = 0.5, h: float = 9.0, warmup: int = 100, rate: float = 0.002) -> None:
        super().__init__(warmup, rate)
        if k < 0 or h <= 0:
            raise ValueError("k must be >= 0 and h > 0")
        self.k, self.h = k, h
        self.reset()

    def _update(self, x: float) -> bool:
        ref = self._ref
        if not ref.ready:
            ref.push(x)
            return False
        self._s = max(0.0, self._s - ref.z(x) - self.k)
        if self._crossed(self.h):
            return True
        ref.push(x)
        return False
