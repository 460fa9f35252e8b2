"""Velocity from a noisy position signal: a constant-velocity Kalman filter (filterpy), as ch. 8
derives the car's velocity from its learned (embedded) position. The default process noise
(1e-5) is the square of the largest velocity change per step of the mountain car (p + A)."""

from __future__ import annotations

from typing import Any

import numpy as np
from filterpy.common import Q_discrete_white_noise
from filterpy.kalman import KalmanFilter


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
        self.reset()

    def reset(self, position: float | None = None) -> None:
        """Start over at `position` (0 when None) with zero velocity and the initial covariance."""
        kf = KalmanFilter(dim_x=2, dim_z=1)
        kf.F = np.array([[1.0, self.dt], [0.0, 1.0]])
        kf.H = np.array([[1.0, 0.0]])
        kf.R = np.array([[self.measurement_var]])
        kf.Q = Q_discrete_white_noise(2, self.dt, self.process_var)
        kf.P = np.diag([self.measurement_var, 1.0])
        kf.x = np.array([[0.0 if position is None else float(position)], [0.0]])
        self._kf = kf

    def state(self) -> dict[str, Any]:
        """The filter's estimate and covariance (its matrices follow from the settings)."""
        return {"x": self._kf.x.copy(), "P": self._kf.P.copy()}

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a filter with the same settings."""
        x, P = np.array(state["x"], dtype=np.float64), np.array(state["P"], dtype=np.float64)
        if x.shape != (2, 1) or P.shape != (2, 2):
            raise ValueError(f"velocity filter state needs x (2, 1) and P (2, 2), got {x.shape} and {P.shape}")
        self.reset()
        self._kf.x, self._kf.P = x, P

    def update(self, position: float) -> tuple[float, float]:
        """Feed one position measurement; returns the filtered (position, velocity)."""
        self._kf.predict()
        self._kf.update(np.array([[float(position)]]))
        return float(self._kf.x[0, 0]), float(self._kf.x[1, 0])
