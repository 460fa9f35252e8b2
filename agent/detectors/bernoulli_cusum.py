"""Bernoulli CUSUM (Reynolds & Stoumbos 1999) for a stream of successes and failures: a value at or
below `failure` is a failure; the log-likelihood ratio of a failure rate raised by `shift` over the
reference rate p0 is summed, S = max(0, S + log(p1/p0)) after a failure and S = max(0, S +
log((1-p1)/(1-p0))) after a success (p1 = p0 + shift, at most 1 - floor: a reference that already
fails that often leaves a failure little or nothing to add); a drop when S > h.

Why not the z-score CUSUM on the values themselves: a stream of episode scores with a long tail
(a driver's slow but successful episodes) makes it fire on a cluster of tail values, while what
hurts is episodes that fail. p0 follows the stream `lag` samples late (RunningMoments: exact for
the `warmup`, then exponentially weighted at `p0_rate`) and is kept within [floor, 1 - floor], so
a reference without a single failure still allows one now and then. After a detection the
reference is learned afresh.

`make_detector("cusum", failure=F, ...)` gives this detector: a program whose performance stream
has a failure value (the mountain car's given-up episode, -1) asks for it by its parameters."""

from __future__ import annotations

import math

from sensorimotor.agent.detectors.base import SummedDetector


class BernoulliCUSUM(SummedDetector):
    """One-sided Bernoulli CUSUM for a rise in the failure rate (see the module docstring).

    Parameters
    ----------
    failure : float, default 0.0
        A value at or below this is a failure (0.0: a stream of 1 for a goal, 0 for none).
    shift : float, default 0.3
        The rise of the failure rate the test is tuned to detect.
    h : float, default 8.0
        Decision threshold on the summed log-likelihood ratio.
    floor : float, default 0.02
        Least reference failure rate.
    warmup : int, default 20
        Samples that form the first reference before anything can be detected.
    p0_rate : float, default 0.02
        Rate at which the reference failure rate follows the stream after the warm-up (its own
        name: a program's `rate` is meant for the detectors of values).
    """

    name = "bernoulli_cusum"
    reference_label = "reference failure rate"

    def __init__(
        self,
        failure: float = 0.0,
        shift: float = 0.3,
        h: float = 8.0,
        floor: float = 0.02,
        warmup: int = 20,
        p0_rate: float = 0.02,
    ) -> None:
        super().__init__(warmup, p0_rate)
        if not math.isfinite(failure):
            raise ValueError("failure must be finite")
        if not 0 < shift < 1 or h <= 0 or not 0 < floor < 0.5:
            raise ValueError("shift must be in (0, 1), h > 0 and floor in (0, 0.5)")
        self.failure, self.shift, self.h, self.floor = failure, shift, h, floor
        self.reset()

    def _update(self, x: float) -> bool:
        failed = 1.0 if x <= self.failure else 0.0
        ref = self._ref
        if ref.ready:
            p0 = min(max(ref.mean, self.floor), 1.0 - self.floor)
            p1 = min(p0 + self.shift, 1.0 - self.floor)
            if p1 > p0:  # else the reference fails so often that no rise is left to detect
                step = math.log(p1 / p0) if failed else math.log((1.0 - p1) / (1.0 - p0))
                self._s = max(0.0, self._s + step)
            if self._crossed(self.h):
                return True
        ref.push(failed)
        return False
