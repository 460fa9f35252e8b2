"""After a body change, break the relearned policy's ties as the old body's policy broke them.

Why: a sweep's greedy policy breaks near-ties by the previous action, else by a fixed order of the
actions (the lowest index first). Among equally short ways the order picks one - down before right,
say - and the map is embedded from those traces. A body whose actions were exchanged (``reverse``,
``permute``) relearns ways just as short, but the fixed order now names other moves first (right
before down), so the traces take other, equally short, ways round the obstacles and the map differs
(FrozenLake 8x8 reversed: 0.18 from scratch, 0.049 before; the lake's holes favour one staircase).
So on a drop the program keeps where each action led from each observation (the transitions it had
noted) and the order it broke ties by; while relearning, each new action is matched to the old one
that leads to the same places from the same observations (an assignment maximising the agreements),
and ties are broken in the old order of the matched actions. The relearned traces are then the old
ways under the new names, and a body whose actions were only renamed gets its map back as it was.
A change that matches nothing (a new body whose moves are all new) keeps the order it had.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from sensorimotor.agent.programs.generic_base import GenericBase

Transitions = dict[tuple[bytes, int], bytes]


def inherit_order(order: np.ndarray, before: Transitions, after: Transitions, n_actions: int) -> np.ndarray | None:
    """The tie order for the new body: `order` (actions, most preferred first) of the old body, each
    new action taking the place of the old action that led to the same observation from the same
    observation most often (moves that stay put say nothing); None when no move agrees."""
    agree = np.zeros((n_actions, n_actions))  # [new action, old action]
    by_state: dict[bytes, dict[bytes, list[int]]] = {}
    for (key, a), nxt in before.items():
        if nxt != key:
            by_state.setdefault(key, {}).setdefault(nxt, []).append(a)
    for (key, b), nxt in after.items():
        if nxt == key or not 0 <= b < n_actions:
            continue
        for a in by_state.get(key, {}).get(nxt, []):
            if 0 <= a < n_actions:
                agree[b, a] += 1
    if not agree.any():
        return None
    new, old = linear_sum_assignment(-agree)
    rank_old = np.empty(n_actions, dtype=np.int64)
    rank_old[np.asarray(order, dtype=np.int64)] = np.arange(n_actions)
    rank_new = np.empty(n_actions, dtype=np.int64)
    rank_new[new] = rank_old[old]
    return np.argsort(rank_new, kind="stable")


class GenericRelearn(GenericBase):
    """The tie order of the sweeps' greedy choice, and its inheritance across a body change."""

    _tie_order: np.ndarray | None = None  # actions, most preferred first (None: by index)
    _order_before: np.ndarray | None = None  # the order at the last drop
    _before: Transitions | None = None  # where each (observation, action) led before it; None: kept

    def _pick(self, q: np.ndarray, prefer: int | None) -> int:
        """The greedy action for `q`: near-ties broken by `prefer`, else by the tie order."""
        o = self._tie_order
        if o is None:
            return self.lspi.choose(q, prefer)
        p = None if prefer is None else int(np.flatnonzero(o == prefer)[0])
        return int(o[self.lspi.choose(np.asarray(q)[o], p)])

    def _keep_for_relearn(self) -> None:
        """On a drop (before the transitions are forgotten): what the old body did, and its order."""
        if self.model is None and not self.tabular:
            return
        self._order_before = np.arange(self.n_actions) if self._tie_order is None else self._tie_order.copy()
        self._before = {k: first for k, (first, other) in self._transitions.items() if other is None}

    def _inherit_order(self) -> None:
        """Before a sweep while relearning: the tie order matched to the old body's (see the module)."""
        if self._before is None or self._order_before is None:
            return
        after = {k: first for k, (first, other) in self._transitions.items() if other is None}
        order = inherit_order(self._order_before, self._before, after, self.n_actions)
        if order is not None:
            self._tie_order = order

    def _order_kept(self) -> None:
        """The relearned map is published: its order stays (until the next drop)."""
        self._before = None

    def relearn_state(self) -> dict[str, Any]:
        return {
            "tie_order": None if self._tie_order is None else self._tie_order.tolist(),
            "order_before": None if self._order_before is None else self._order_before.tolist(),
            "before": None if self._before is None else [[k.hex(), a, n.hex()] for (k, a), n in self._before.items()],
        }

    def restore_relearn(self, state: dict[str, Any]) -> None:
        to = state.get("tie_order")
        self._tie_order = None if to is None else np.asarray(to, dtype=np.int64)
        ob = state.get("order_before")
        self._order_before = None if ob is None else np.asarray(ob, dtype=np.int64)
        b = state.get("before")
        self._before = None if b is None else {(bytes.fromhex(k), int(a)): bytes.fromhex(n) for k, a, n in b}


__all__ = ["GenericRelearn", "inherit_order"]
