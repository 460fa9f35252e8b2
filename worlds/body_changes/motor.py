"""Changes on the action channel: what the agent sends becomes what the body does.

Each change is built once from its parsed parameters and the world's action space (refused with
the valid values when they do not fit) and then maps every action: a float64 array (discrete: one
value, the action index; box: one value per dimension) in, the action the world applies out, or
None when the body does nothing this step (a lesioned discrete action, a delay still filling).
"""

from __future__ import annotations

import re
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from sensorimotor.protocol.messages import ActionSpace
from sensorimotor.protocol.params import _scalar, quote
from sensorimotor.worlds.base import PerturbationError
from sensorimotor.worlds.body_changes.kinds import (
    EVERY,
    DelayParams,
    GainParams,
    LesionParams,
    PermuteParams,
    ReverseParams,
)

#: action names that are each other's opposite (lower case), for ``reverse pairs=auto``
ANTONYMS = {
    "up": "down",
    "left": "right",
    "forward": "backward",
    "forwards": "backwards",
    "north": "south",
    "east": "west",
    "in": "out",
    "open": "close",
    "push": "pull",
    "cw": "ccw",
    "increase": "decrease",
    "plus": "minus",
    "pan_left": "pan_right",
    "tilt_up": "tilt_down",
}
ANTONYMS.update({v: k for k, v in list(ANTONYMS.items())})


def _size(space: ActionSpace) -> int:
    return space.n if space.discrete else len(space.low)


def _what(space: ActionSpace) -> str:
    return (
        f"{space.n} discrete actions (0..{space.n - 1})" if space.discrete else f"a box of {len(space.low)} dimensions"
    )


def _indices(index: int, space: ActionSpace, kind: str) -> list[int]:
    n = _size(space)
    if index == EVERY:
        return list(range(n))
    if not 0 <= index < n:
        unit = "action" if space.discrete else "dimension"
        raise PerturbationError(
            f"{kind}: index={index} is out of range: the world has {_what(space)}; valid: -1..{n - 1} (-1: every {unit})"
        )
    return [index]


@dataclass
class ActionChange:
    """One change on the action channel: `apply` maps an action, `reset` begins an episode."""

    kind: str
    detail: str
    world_index: np.ndarray | None = None  # discrete: agent action i -> world action (None: unchanged)
    silent: frozenset[int] = frozenset()  # discrete: actions that do nothing
    scale: np.ndarray | None = None  # box: out = mid + scale * (in - mid), per dimension
    dims: np.ndarray | None = None  # box: out[dims[i]] = rescaled in[i] (a permutation)
    held: np.ndarray | None = None  # box: dimensions held at the middle of their range
    delay: int = 0
    times: float = 1.0  # discrete: how many times the actions in `acting` act per step (gain)
    acting: frozenset[int] = frozenset()
    rng: np.random.Generator | None = None
    low: np.ndarray = field(default_factory=lambda: np.zeros(0))
    high: np.ndarray = field(default_factory=lambda: np.zeros(0))
    _queue: deque = field(default_factory=deque)

    def reset(self) -> None:
        self._queue.clear()

    def repeats(self, a: np.ndarray) -> int:
        """How many times discrete action `a` (the world's) acts this step (1 but for `gain`)."""
        if self.rng is None or int(a[0]) not in self.acting:
            return 1
        whole = int(self.times)
        return whole + int(self.rng.random() < self.times - whole)

    def apply(self, a: np.ndarray) -> np.ndarray | None:
        if self.delay:
            self._queue.append(np.array(a, dtype=np.float64))
            if len(self._queue) <= self.delay:
                return None if self.low.size == 0 else (self.low + self.high) / 2
            return self._queue.popleft()
        if self.low.size == 0:  # discrete
            i = int(a[0])
            if i in self.silent:
                return None
            if self.world_index is not None:
                return np.array([float(self.world_index[i])], dtype=np.float64)
            return a
        mid = (self.low + self.high) / 2
        out = np.array(a, dtype=np.float64)
        if self.dims is not None:
            half = np.where(self.high > self.low, (self.high - self.low) / 2, 1.0)
            unit = (a - mid) / half  # each value in its own dimension's range, as -1..1
            out = out.copy()
            out[self.dims] = mid[self.dims] + unit * half[self.dims]
        if self.scale is not None:
            out = np.clip(mid + self.scale * (out - mid), self.low, self.high)
        if self.held is not None:
            out[self.held] = mid[self.held]
        return out


def _box(kind: str, detail: str, space: ActionSpace, **kw) -> ActionChange:
    return ActionChange(
        kind, detail, low=np.asarray(space.low, dtype=np.float64), high=np.asarray(space.high, dtype=np.float64), **kw
    )


def _pairs(text: str, space: ActionSpace, declared: list[tuple[int, int]] | None = None) -> list[tuple[int, int]]:
    n = space.n
    if text.strip() == "auto":
        if declared:
            return [(i, j) for i, j in declared if 0 <= i < n and 0 <= j < n and i != j]
        names = [x.lower() for x in space.names]
        if len(names) == n:
            found = [(i, names.index(ANTONYMS[x])) for i, x in enumerate(names) if ANTONYMS.get(x) in names]
            pairs = [(i, j) for i, j in found if i < j]
            if pairs:
                return pairs
        return [(i, n - 1 - i) for i in range(n // 2)]
    pairs = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        m = re.fullmatch(r"([0-9]+)\s*:\s*([0-9]+)", part)
        if not m:
            raise PerturbationError(
                f"reverse: pairs={quote(text)}: expected 'auto' or 'a:b,c:d' with actions 0..{n - 1}"
            )
        pairs.append((int(m.group(1)), int(m.group(2))))
    used = [x for p in pairs for x in p]
    if not pairs or any(not 0 <= x < n for x in used) or len(set(used)) != len(used) or any(i == j for i, j in pairs):
        raise PerturbationError(
            f"reverse: pairs={quote(text)}: each pair two different actions of 0..{n - 1}, none used twice (or 'auto')"
        )
    return pairs


def reverse(p: ReverseParams, space: ActionSpace, opposites: list[tuple[int, int]] | None = None) -> ActionChange:
    """A box dimension mirrored about its middle, or discrete actions swapped with their opposites
    (``pairs=auto``: `opposites` as the world declares them, else by the action names, else the
    mirrored index)."""
    if not space.discrete:
        dims = _indices(p.index, space, "reverse")
        scale = np.ones(len(space.low))
        scale[dims] = -1.0
        return _box("reverse", f"reversed action dimension(s) {dims}", space, scale=scale)
    pairs = _pairs(p.pairs, space, opposites)
    if p.index != EVERY:
        _indices(p.index, space, "reverse")
        pairs = [q for q in pairs if p.index in q]
        if not pairs:
            raise PerturbationError(f"reverse: action {p.index} has no opposite here; give one with pairs=a:b")
    m = np.arange(space.n)
    for i, j in pairs:
        m[i], m[j] = j, i
    return ActionChange("reverse", "swapped actions " + ", ".join(f"{i}<->{j}" for i, j in pairs), world_index=m)


def _order(text: str, n: int) -> list[int]:
    t = text.strip()
    if t == "rotate":
        return [(i + 1) % n for i in range(n)]
    m = re.fullmatch(r"([0-9]+)\s*:\s*([0-9]+)", t)
    if m:
        i, j = int(m.group(1)), int(m.group(2))
        if not (0 <= i < n and 0 <= j < n and i != j):
            raise PerturbationError(f"permute: order={quote(text)}: two different indices of 0..{n - 1}")
        out = list(range(n))
        out[i], out[j] = j, i
        return out
    try:
        out = [_scalar(x, int) for x in t.split(",")]  # the strict int of every parameter (no 1_0)
    except ValueError:
        out = []
    if sorted(out) != list(range(n)):
        raise PerturbationError(
            f"permute: order={quote(text)}: expected 'rotate', 'a:b' or a permutation of 0..{n - 1} such as "
            f"{','.join(str((i + 1) % n) for i in range(n))}"
        )
    return out


def permute(p: PermuteParams, space: ActionSpace) -> ActionChange:
    """The agent's action (or dimension) i acts as the world's order[i]."""
    n = _size(space)
    if n < 2:
        raise PerturbationError(f"permute: the world has {_what(space)}: nothing to exchange")
    order = _order(p.order, n)
    detail = "actions" if space.discrete else "action dimensions"
    detail = f"{detail} exchanged: " + ", ".join(f"{i}->{j}" for i, j in enumerate(order) if i != j)
    if space.discrete:
        return ActionChange("permute", detail, world_index=np.asarray(order))
    return _box("permute", detail, space, dims=np.asarray(order))


def gain(p: GainParams, space: ActionSpace) -> ActionChange:
    """A box dimension scaled about the middle of its range; a discrete action repeated."""
    if space.discrete:
        if p.gain < 0:
            raise PerturbationError(
                f"gain: gain={p.gain:g}: a discrete action is repeated 0..10 times; valid: 0.0..10.0"
            )
        which = _indices(p.index, space, "gain")
        return ActionChange(
            "gain",
            f"action(s) {which} act {p.gain:g} times per step",
            times=p.gain,
            acting=frozenset(which),
            rng=np.random.default_rng(p.seed),
        )
    dims = _indices(p.index, space, "gain")
    scale = np.ones(len(space.low))
    scale[dims] = p.gain
    return _box("gain", f"action dimension(s) {dims} scaled by {p.gain:g}", space, scale=scale)


def lesion(p: LesionParams, space: ActionSpace) -> ActionChange:
    """An action dimension held at its middle, or a discrete action that does nothing."""
    which = _indices(p.index, space, "lesion")
    if space.discrete:
        return ActionChange("lesion", f"action(s) {which} no longer act", silent=frozenset(which))
    return _box("lesion", f"action dimension(s) {which} no longer act", space, held=np.asarray(which))


def delay(p: DelayParams, space: ActionSpace) -> ActionChange:
    """Each action applied `steps` steps late."""
    if space.discrete:
        return ActionChange("delay", f"actions applied {p.steps} step(s) late", delay=p.steps)
    return _box("delay", f"actions applied {p.steps} step(s) late", space, delay=p.steps)
