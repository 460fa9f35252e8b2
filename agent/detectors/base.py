"""The detector interface: `update(x)` one reward at a time, returning True on the step a drop is
detected; `statistic` is the current test statistic (for plots); `reset()` forgets everything;
`state()` / `restore(state)` save and resume it (the convention of `agent.programs.base`)."""

from __future__ import annotations

import abc
import collections
import math
from typing import Any


class DropDetector(abc.ABC):
    """Base of the reward-drop detectors: a sequential test fed one performance value at a time.

    Subclasses implement `_update`, `statistic` and `reset`; `name` identifies them in events and
    saved state. A detection is reported once, on the step it happens, after which the detector
    learns its reference afresh.
    """

    name = "detector"
    #: what `reference` is, in the drop event's text
    reference_label = "reference"

    def __init__(self) -> None:
        self.drift_detected = False
        self.n = 0

    @abc.abstractmethod
    def _update(self, x: float) -> bool: ...

    def update(self, x: float) -> bool:
        """Feed one value of the watched stream (e.g. a reward).

        Parameters
        ----------
        x : float
            The next value; must be finite.

        Returns
        -------
        bool
            True on the step a drop is detected (also kept in `drift_detected`).

        Raises
        ------
        ValueError
            If `x` is NaN or infinite.

        Examples
        --------
        Watch a stream and relearn when it drops::

            det = make_detector("cusum")
            for r in rewards:
                if det.update(r):
                    relearn()
        """
        x = float(x)
        if not math.isfinite(x):
            raise ValueError(f"{self.name}: reward must be finite, got {x!r}")
        self.n += 1
        self.drift_detected = self._update(x)
        return self.drift_detected

    @property
    @abc.abstractmethod
    def statistic(self) -> float:
        """The current test statistic (for plots and status), on the detector's own scale."""

    @property
    def reference(self) -> float:
        """The reference (pre-drop) mean the detector compares with; NaN before it has one."""
        ref = getattr(self, "_ref", None)
        return ref.mean if ref is not None and ref.count else float("nan")

    @abc.abstractmethod
    def reset(self) -> None:
        """Forget everything: the next sample starts a new warm-up."""

    def state(self) -> dict[str, Any]:
        """A snapshot of the running statistics; `name` says which detector it belongs to."""
        return {"name": self.name, "n": self.n, "drift_detected": self.drift_detected}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a detector of the same kind and settings."""
        if state["name"] != self.name:
            raise ValueError(f"detector state is for {state['name']!r}, not {self.name!r}")
        self.n, self.drift_detected = int(state["n"]), bool(state["drift_detected"])


class RunningMoments:
    """Mean and variance of the reference (pre-drop) regime: exact (Welford) for the first `warmup`
    samples, then exponentially weighted with rate `rate` so slow improvements are followed.

    Samples join the reference `lag` steps late (default: half the warmup, at most 50) (`push`): a drop is detected long before its
    samples would enter, and, unlike updating only while no drop is suspected, no selection bias
    creeps into the mean and variance."""

    def __init__(self, warmup: int = 100, rate: float = 0.002, lag: int | None = None) -> None:
        if warmup < 2:
            raise ValueError("warmup must be >= 2")
        if not 0 < rate < 1:
            raise ValueError("rate must be in (0, 1)")
        lag = min(50, warmup // 2) if lag is None else lag
        if lag < 0:
            raise ValueError("lag must be >= 0")
        self.warmup = warmup
        self.rate = rate
        self.lag = lag
        self.reset()

    def push(self, x: float) -> None:
        """Queue `x`; the sample `lag` steps back joins the moments."""
        self._pending.append(x)
        if len(self._pending) > self.lag:
            self.add(self._pending.popleft())

    def reset(self) -> None:
        """Forget all samples, queued ones included."""
        self._pending: collections.deque[float] = collections.deque()
        self.count = 0
        self.mean = 0.0
        self._m2 = 0.0
        self.var = 0.0

    @property
    def ready(self) -> bool:
        """Whether the warm-up is over (the moments describe a reference)."""
        return self.count >= self.warmup

    @property
    def sd(self) -> float:
        """Standard deviation of the reference (floored at 1e-6, so z-scores stay finite)."""
        return math.sqrt(max(self.var, 1e-12))

    def add(self, x: float) -> None:
        """Let `x` join the moments now (exact during warm-up, exponentially weighted after)."""
        self.count += 1
        if self.count <= self.warmup:
            d = x - self.mean
            self.mean += d / self.count
            self._m2 += d * (x - self.mean)
            self.var = self._m2 / max(self.count - 1, 1)
        else:
            d = x - self.mean
            self.mean += self.rate * d
            self.var = (1 - self.rate) * (self.var + self.rate * d * d)

    def z(self, x: float) -> float:
        """`x` standardised against the reference: (x - mean) / sd."""
        return (x - self.mean) / self.sd

    def state(self) -> dict[str, Any]:
        """The moments and the samples still waiting to join (warmup, rate, lag are configuration)."""
        return {"pending": list(self._pending), "count": self.count, "mean": self.mean, "m2": self._m2, "var": self.var}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of moments with the same settings."""
        self._pending = collections.deque(float(x) for x in state["pending"])
        self.count = int(state["count"])
        self.mean, self._m2, self.var = float(state["mean"]), float(state["m2"]), float(state["var"])


class ReferencedDetector(DropDetector):
    """A detector that compares the stream with a lagged reference regime (RunningMoments)."""

    def __init__(self, warmup: int, rate: float) -> None:
        super().__init__()
        self._ref = RunningMoments(warmup, rate)

    def reset(self) -> None:
        """Forget the reference and the statistic; the next sample starts a new warm-up."""
        self.n = 0
        self.drift_detected = False
        self._ref.reset()
        self._clear()

    @abc.abstractmethod
    def _clear(self) -> None:
        """Forget the detector's own statistic."""

    def state(self) -> dict[str, Any]:
        """The base snapshot plus the reference moments."""
        return {**super().state(), "reference": self._ref.state()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot (reference moments included)."""
        super().restore(state)
        self._ref.restore(state["reference"])


class SummedDetector(ReferencedDetector):
    """A referenced detector whose statistic is a one-sided sum S, saved with it (the CUSUMs)."""

    def _clear(self) -> None:
        self._s = 0.0

    @property
    def statistic(self) -> float:
        """The sum S (a drop when it exceeds the detector's threshold `h`)."""
        return self._s

    def _crossed(self, h: float) -> bool:
        """Whether S exceeds `h`: then a drop, and S and the reference start afresh."""
        if self._s <= h:
            return False
        self._s = 0.0
        self._ref.reset()
        return True

    def state(self) -> dict[str, Any]:
        """The referenced detector's snapshot plus the sum S."""
        return {**super().state(), "s": self._s}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of the same detector with the same settings."""
        super().restore(state)
        self._s = float(state["s"])
