"""Traces in the frame of the start: for worlds whose actions include rotations (egocentric actions,
such as MiniGrid's turn left / turn right / forward).

Why: with egocentric actions the trace from cell (x, y) facing east is F^a R F^b, and the edit
distance between F^a R F^b and F^b R F^a is 2 whatever a and b (move the turn), so cells mirrored
across the diagonal look alike and the map folds. A turn changes what every later action does; the
edit distance of Algorithm 1 does not know that. Here the agent finds its rotations from its own
experience and relabels each other action by the net rotation made before it, so the trace says
"forward in the start's frame, then forward in the frame turned once" - the allocentric trace, on
which the edit distance is the Manhattan distance again. The turns stay in the trace as symbols.

A *rotation* is an action that, repeated, comes back to the observation it started from (order
k >= 2: R^4 is the identity in a grid) from (almost) every state where the chain is known, and never
sooner. Rotations of the same order that are powers of the first one (L = R^3) share its frame
count. Worlds with no such action (FrozenLake, CliffWalking: a move repeated never comes back; at a
wall it stays, order 1) have no rotations and their traces are left as they are.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass


@dataclass(frozen=True)
class Rotations:
    """The rotations found: their order k (the turns that make a full circle) and each rotation
    action's power of the generator (1 for the generator itself)."""

    order: int
    powers: tuple[tuple[int, int], ...]  # (action, power), sorted by action

    def power(self, action: int) -> int | None:
        """The power of the generator that `action` is, or None when it is not a rotation."""
        return dict(self.powers).get(int(action))


def _chain(nxt: Mapping[tuple[bytes, int], bytes], s: bytes, a: int, n: int) -> list[bytes] | None:
    """The observations after applying `a` 1..n times from `s`, or None where a link is unknown."""
    out = []
    for _ in range(n):
        t = nxt.get((s, a))
        if t is None:
            return None
        out.append(t)
        s = t
    return out


def find_rotations(
    nxt: Mapping[tuple[bytes, int], bytes],
    actions: Sequence[int],
    max_order: int = 8,
    min_evidence: int = 8,
    agreement: float = 0.9,
) -> Rotations | None:
    """Rotations among `actions`, from deterministic transitions `nxt[(observation, action)] ->
    next observation` (observations as bytes keys). An action is a rotation of order k when at
    least `min_evidence` states have a known chain of it, and at least `agreement` of them come back
    to their start after exactly k >= 2 steps. Another rotation of the same order counts as the
    generator's power j when, in `agreement` of the states where both are known, it leads where j
    turns of the generator lead. None when no action is a rotation."""
    starts: dict[int, list[bytes]] = {}
    for s, a in nxt:
        starts.setdefault(int(a), []).append(s)
    orders: dict[int, int] = {}
    for a in actions:
        found: Counter[int | None] = Counter()
        for s in starts.get(int(a), []):
            chain = _chain(nxt, s, int(a), max_order)
            if chain is None:
                continue
            back = next((i + 1 for i, t in enumerate(chain) if t == s), None)
            found[back] += 1
        total = sum(found.values())
        if total < min_evidence:
            continue
        k, c = found.most_common(1)[0]
        if k is not None and k >= 2 and c >= agreement * total:
            orders[int(a)] = k
    if not orders:
        return None
    g = min(orders)
    k = orders[g]
    powers = {g: 1}
    for b, kb in sorted(orders.items()):
        if b == g or kb != k:
            continue
        votes: Counter[int] = Counter()
        for s in starts.get(b, []):
            t = nxt.get((s, b))
            chain = _chain(nxt, s, g, k - 1)
            if t is None or chain is None:
                continue
            votes[next((j + 1 for j, u in enumerate(chain) if u == t), 0)] += 1
        total = sum(votes.values())
        if total >= min_evidence:
            j, c = votes.most_common(1)[0]
            if j > 0 and c >= agreement * total:
                powers[b] = j
    return Rotations(k, tuple(sorted(powers.items())))


def frame_trace(trace: Sequence[int], rotations: Rotations, n_actions: int) -> list[int]:
    """`trace` with every action that is not a rotation relabelled by the net rotation before it
    (symbol ``n_actions * (1 + h) + a`` for action a made h turns from the start's frame, mod the
    order); rotations keep their own index."""
    out = []
    h = 0
    powers = dict(rotations.powers)
    for a in trace:
        p = powers.get(int(a))
        if p is None:
            out.append(n_actions * (1 + h) + int(a))
        else:
            h = (h + p) % rotations.order
            out.append(int(a))
    return out


__all__ = ["Rotations", "find_rotations", "frame_trace"]
