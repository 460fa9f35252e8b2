"""Changes on the observation channel: what the world senses becomes what the agent receives.

Each change is built from its parsed parameters and the world's sensors (a sensor name that is not
one of them is refused with the valid names) and maps the tensors of every observation to new
arrays of the same dtype and shape, within the sensors' finite declared bounds.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sensorimotor.protocol.messages import SensorSpec
from sensorimotor.worlds.base import PerturbationError
from sensorimotor.worlds.body_changes.kinds import LesionParams, NoiseParams


def _chosen(name: str, sensors: tuple[SensorSpec, ...], kind: str) -> tuple[SensorSpec, ...]:
    if not name:
        return sensors
    found = tuple(s for s in sensors if s.name == name)
    if not found:
        raise PerturbationError(
            f"{kind}: sensor={name!r} is not a sensor of this world; valid: {', '.join(s.name for s in sensors)}"
        )
    return found


def _bounded(x: np.ndarray, s: SensorSpec) -> np.ndarray:
    lo = s.low if math.isfinite(s.low) else None
    hi = s.high if math.isfinite(s.high) else None
    if np.issubdtype(np.dtype(s.dtype), np.integer):
        x = np.rint(x)
        info = np.iinfo(np.dtype(s.dtype))
        lo = info.min if lo is None else max(lo, info.min)
        hi = info.max if hi is None else min(hi, info.max)
    if lo is not None or hi is not None:
        x = np.clip(x, lo, hi)
    return x.astype(s.dtype)


@dataclass
class SensorChange:
    """One change on the observation channel."""

    kind: str
    detail: str
    sensors: tuple[SensorSpec, ...]
    sd: float = 0.0
    rng: np.random.Generator | None = None
    region: tuple[float, float] = (0.0, 0.0)

    def apply(self, tensors: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
        out = dict(tensors)
        for s in self.sensors:
            x = np.asarray(tensors[s.name])
            if self.rng is not None:
                out[s.name] = _bounded(x + self.rng.normal(0.0, self.sd, x.shape), s)
            else:
                flat = np.array(x).reshape(-1)
                a = int(math.floor(self.region[0] * flat.size))
                b = max(int(math.ceil(self.region[1] * flat.size)), a + 1)
                flat[a:b] = _bounded(np.zeros(1), s)[0]
                out[s.name] = flat.reshape(x.shape)
        return out


def noise(p: NoiseParams, sensors: tuple[SensorSpec, ...]) -> SensorChange:
    """Gaussian noise of sd `p.sd` on one sensor or all, seeded by `p.seed`."""
    chosen = _chosen(p.sensor, sensors, "noise")
    names = ", ".join(s.name for s in chosen)
    return SensorChange(
        "noise", f"sensor noise sd {p.sd:g} on {names} (seed {p.seed})", chosen, p.sd, np.random.default_rng(p.seed)
    )


def lesion(p: LesionParams, sensors: tuple[SensorSpec, ...]) -> SensorChange:
    """A region of one sensor (or every sensor) that reads 0: the fraction start..stop of its flattened values."""
    if not p.stop > p.start:
        raise PerturbationError(f"lesion: stop={p.stop:g} must be above start={p.start:g} (both fractions in 0..1)")
    chosen = _chosen(p.sensor, sensors, "lesion")
    names = ", ".join(s.name for s in chosen)
    return SensorChange(
        "lesion", f"sensor region {p.start:g}..{p.stop:g} of {names} reads 0", chosen, region=(p.start, p.stop)
    )
