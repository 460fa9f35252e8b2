"""Velocity from a noisy position signal: a constant-velocity Kalman filter, as ch. 8 derives the
car's velocity from its learned (embedded) position. The default process noise (1e-5) is the
square of the largest velocity change per step of the mountain car (p + A).

The filter is filterpy's `KalmanFilter` (predict, then the Joseph-form update) written out for its
two states in plain floats: the mountain car runs it once per car step, and filterpy's general
matrix code cost more than the rest of a car step (a test checks the two agree)."""

from __future__ import annotations

from typing import Any

import numpy as np
from filterpy.common import Q_discrete_white_noise


class VelocityFilter:
    """Constant-velocity Kalman filter over a scalar position: (position, velocity) estimates.

    Parameters
    ----------
    dt : float, default 1.0
        Time between measurements.
    measurement_var : float, default 1e-3
        Variance of a position measurement.
    process_var : float, default 1e-5
        Process-noise variance (white acceleration), see the module docstring.
    """

    def __init__(self, dt: float = 1.0, measurement_var: float = 1e-3, process_var: float = 1e-5) -> None:
        if dt <= 0 or measurement_var <= 0 or process_var <= 0:
            raise ValueError("dt, measurement_var and process_var must be > 0")
        self.dt, self.measurement_var, self.process_var = dt, measurement_var, process_var
        q = Q_discrete_white_noise(2, dt, process_var)
        self._q = (float(q[0, 0]), float(q[0, 1]), float(q[1, 0]), float(q[1, 1]))
        self.reset()

    def reset(self, position: float | None = None) -> None:
        """Start over at `position` (0 when None) with zero velocity and the initial covariance."""
        self._x = [0.0 if position is None else float(position), 0.0]
        self._p = [self.measurement_var, 0.0, 0.0, 1.0]  # row-major 2x2 covariance

    def state(self) -> dict[str, Any]:
        """The filter's estimate and covariance (its matrices follow from the settings)."""
        return {"x": np.array(self._x, dtype=np.float64).reshape(2, 1), "P": np.array(self._p).reshape(2, 2)}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a filter with the same settings."""
        x, P = np.array(state["x"], dtype=np.float64), np.array(state["P"], dtype=np.float64)
        if x.shape != (2, 1) or P.shape != (2, 2):
            raise ValueError(f"velocity filter state needs x (2, 1) and P (2, 2), got {x.shape} and {P.shape}")
        self._x = [float(x[0, 0]), float(x[1, 0])]
        self._p = [float(v) for v in P.reshape(-1)]

    def update(self, position: float) -> tuple[float, float]:
        """Feed one position measurement; returns the filtered (position, velocity)."""
        dt, r = self.dt, self.measurement_var
        q00, q01, q10, q11 = self._q
        x0, x1 = self._x
        p00, p01, p10, p11 = self._p
        # predict: x = F x, P = F P F' + Q with F = [[1, dt], [0, 1]]
        x0 = x0 + dt * x1
        a00, a01 = p00 + dt * p10, p01 + dt * p11  # F P
        p00, p01 = a00 + dt * a01 + q00, a01 + q01
        p10, p11 = p10 + dt * p11 + q10, p11 + q11
        # update with H = [1, 0]: K = P H' / (H P H' + R), Joseph form P = (I - KH) P (I - KH)' + K R K'
        s = p00 + r
        k0, k1 = p00 / s, p10 / s
        y = float(position) - x0
        x0, x1 = x0 + k0 * y, x1 + k1 * y
        i0 = 1.0 - k0
        b00, b01 = i0 * p00, i0 * p01  # (I - KH) P
        b10, b11 = p10 - k1 * p00, p11 - k1 * p01
        self._p = [
            b00 * i0 + k0 * r * k0,
            -b00 * k1 + b01 + k0 * r * k1,
            b10 * i0 + k1 * r * k0,
            -b10 * k1 + b11 + k1 * r * k1,
        ]
        self._x = [x0, x1]
        return x0, x1
