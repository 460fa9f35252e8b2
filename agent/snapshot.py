"""Helpers for the `state()` / `restore()` convention (see `sensorimotor.agent.programs.base`):
random generator state as a plain dict, and the conversions snapshots need (tuples and non-str
dict keys do not survive JSON, so they are stored as lists and rebuilt here)."""

from __future__ import annotations

import copy
from typing import Any

import numpy as np


def rng_state(rng: np.random.Generator) -> dict[str, Any]:
    """The generator's full state as a plain dict (a copy)."""
    return dict(copy.deepcopy(rng.bit_generator.state))


def set_rng_state(rng: np.random.Generator, state: dict[str, Any]) -> None:
    """Put an `rng_state` snapshot back in place, so every holder of `rng` continues from it."""
    kind = type(rng.bit_generator).__name__
    if state.get("bit_generator") != kind:
        raise ValueError(f"generator state is for {state.get('bit_generator')!r}, not {kind}")
    rng.bit_generator.state = copy.deepcopy(state)


def array_or_none(x: Any) -> np.ndarray | None:
    """A copy of an optional array (snapshots must not share memory with the running component)."""
    return None if x is None else np.array(x, copy=True)


def tuple_or_none(x: Any) -> tuple | None:
    """A list stored for a tuple, back as the tuple (None stays None)."""
    return None if x is None else tuple(x)
