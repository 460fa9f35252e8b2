"""The mountain-car dynamics of ch. 8 (Eq 8.1-8.6), as pure functions.

v' = clip(v + a p + A cos(w x + phi), -v_max, v_max),  x' = clip(x + v', x_min, x_max),
a in {-1, 0, 1}, p = 0.001, w = pi/4, phi = pi/2, A = 0.0025, x in (-2, 2), v in (-0.07, 0.07);
the goal is x > 1.9. At the left wall the car stops (v = 0).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class MountainCarParams:
    """The constants of Eq 8.1-8.6 (see the module docstring)."""

    p: float = 0.001
    w: float = math.pi / 4
    phi: float = math.pi / 2
    A: float = 0.0025
    x_min: float = -2.0
    x_max: float = 2.0
    v_max: float = 0.07
    goal: float = 1.9


def step(
    x: float, v: float, a: int, prm: MountainCarParams = MountainCarParams(), noise: float = 0.0
) -> tuple[float, float, bool]:
    """One step: (x', v', reached the goal). `noise` is extra thrust in units of the engine's push
    `p` (a noisy world draws it per step, ch. 9.4; 0: the deterministic Eq 8.1-8.6)."""
    if a not in (-1, 0, 1):
        raise ValueError(f"action must be -1, 0 or 1, got {a}")
    v2 = min(max(v + (a + noise) * prm.p + prm.A * math.cos(prm.w * x + prm.phi), -prm.v_max), prm.v_max)
    x2 = x + v2
    if x2 <= prm.x_min:
        x2, v2 = prm.x_min, 0.0
    x2 = min(x2, prm.x_max)
    return x2, v2, x2 > prm.goal


def random_state(rng: np.random.Generator, prm: MountainCarParams = MountainCarParams()) -> tuple[float, float]:
    """A random state before the goal: x uniform in [x_min, goal), v uniform in [-v_max, v_max)."""
    return float(rng.uniform(prm.x_min, prm.goal)), float(rng.uniform(-prm.v_max, prm.v_max))


EVAL_SEED = 8_2026


def evaluation_states(n: int, eval_seed: int = EVAL_SEED, prm: MountainCarParams = MountainCarParams()) -> np.ndarray:
    """[n, 2] fixed random (x, v) states: every world and every agent is evaluated on the same ones."""
    rng = np.random.default_rng(eval_seed)
    return np.array([random_state(rng, prm) for _ in range(n)], dtype=np.float64).reshape(-1, 2)
