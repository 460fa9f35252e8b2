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

A body whose actions act late (``delay``) is no longer a function of the observation: the same
observation and action lead to different observations, depending on the action before. While
relearning after a drop, outcomes that alternate are therefore first taken for a body that remembers:
the state becomes the observation with the action sent last - for a table learner a table of
distinct (observation, last action) pairs, for LSPI (camera frames, long vectors) the fitted RBF
features of the observation, one block per last action - learned afresh, in which a one-step delay
is deterministic again; a trace's last action, sent when the goal was already on its way, never
acts and is dropped.
If outcomes still alternate there, the world is taken as stochastic, as before. Learning from
scratch (no drop) keeps the old rule: alternating outcomes mean a stochastic world.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from sensorimotor.agent.learners.base import TableLearner
from sensorimotor.agent.learners.lspi import TabularBasis
from sensorimotor.agent.learners.lspi_features import basis_state, set_basis
from sensorimotor.agent.programs.base import Decision, EventOutput
from sensorimotor.agent.programs.generic_base import GenericBase
from sensorimotor.protocol.messages import EventKind, Observation

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

    _history = False  # the state is (observation, last action sent): a table's key, LSPI's feature block
    _history_due = False  # outcomes alternated while relearning: history from the next step
    _hist = -1  # the action sent last in this episode (-1: none yet)

    def _init_table(self, table_class: type[TableLearner] | None, ids: bool) -> TabularBasis:  # generic_tables
        raise NotImplementedError

    def _key(self, obs: Observation) -> bytes:
        key = super()._key(obs)
        return key + self._hist.to_bytes(2, "little", signed=True) if self._history else key

    def _become_stochastic(self, step: int) -> None:
        """Outcomes alternated: while relearning a discrete body (a table learner or LSPI), try a
        state that remembers the last action first (see the module); else the world is stochastic."""
        remembers = self.model is not None or self.learner == "lspi"
        if self._history or self.relearn_at is None or not remembers or not self.discrete:
            super()._become_stochastic(step)
            return
        self._history_due = True
        self._transitions.clear()

    def _history_before(self, obs: Observation) -> None:
        """At every step, before acting: enter history mode when due; a new episode has no last action."""
        if self._history_due:
            self._enter_history(obs.step)
        if obs.t == 0:
            self._hist = -1

    def _history_after(self, dec: Decision) -> Decision:
        """The action sent, remembered at every step (so the step that enters history mode knows it):
        in history mode, part of the next step's state (a table's key, LSPI's feature block)."""
        self._hist = -1 if dec.reset or not dec.values or not self.discrete else int(dec.values[0])
        return dec

    def _moves(self, nxt: Transitions) -> Transitions:
        """Where each action led from each observation (the rotations are found in them): in history
        mode the action applied at a step is the one sent before, the last action of the key."""
        if not self._history:
            return nxt
        out: Transitions = {}
        for (key, _), after in nxt.items():
            h = int.from_bytes(key[-2:], "little", signed=True)
            if h >= 0:
                out[(key[:-2], h)] = after[:-2]
        return out

    def _trim(self, trace: list[int], ok: bool) -> None:
        """In history mode a trace that reached the goal ends with an action that never acted (the
        goal came with the one sent before, applied late): it is no move of the way, and dropped."""
        if self._history and ok and trace:
            trace.pop()

    def _enter_history(self, step: int) -> None:
        """A table of (observation, last action), or LSPI features of both, learned afresh,
        relearning from here."""
        assert self.relearn_at is not None
        self._history_due = False
        if self.model is not None:
            self._ids, self._said_table_full = {}, False
        self._remember_last_action()
        keep = self._before, self._order_before
        self.on_drop(self.relearn_at)
        self._before, self._order_before = keep
        what = (
            f"a table of up to {self.n_states} of them"
            if self.model is not None
            else f"LSPI features of the observation, one block per last action ({self._rbf.k} in all)"
        )
        self.emit(
            EventOutput(
                EventKind.POLICY_ITERATION,
                f"outcomes alternate after the body changed: the state is the observation with the last action sent, {what}",
                step,
                reason="history",
            )
        )

    def _remember_last_action(self) -> None:
        """The state becomes the observation with the action sent last: a table of distinct pairs, or
        (LSPI) the same fitted RBFs of the observation, one block per last action."""
        self._history = True
        if self.model is not None:
            self.keyed = True
            self.lspi.basis = self._init_table(type(self.model), False)
        else:
            fitted = basis_state(self._rbf)
            self._rbf = self._new_rbf()
            set_basis(self._rbf, fitted)
            self.lspi.basis = self._rbf
            self.lspi.reset()

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

    def take_layout(self, state: dict[str, Any]) -> None:
        """A saved LSPI that remembered the last action keeps a block of weights per last action."""
        if self.learner == "lspi" and bool(state.get("history", False)) and not self._history:
            self._remember_last_action()

    def relearn_state(self) -> dict[str, Any]:
        return {
            "tie_order": None if self._tie_order is None else self._tie_order.tolist(),
            "order_before": None if self._order_before is None else self._order_before.tolist(),
            "before": None if self._before is None else [[k.hex(), a, n.hex()] for (k, a), n in self._before.items()],
            "history": self._history,
            "history_due": self._history_due,
            "hist": self._hist,
        }

    def restore_relearn(self, state: dict[str, Any]) -> None:
        to = state.get("tie_order")
        self._tie_order = None if to is None else np.asarray(to, dtype=np.int64)
        ob = state.get("order_before")
        self._order_before = None if ob is None else np.asarray(ob, dtype=np.int64)
        b = state.get("before")
        self._before = None if b is None else {(bytes.fromhex(k), int(a)): bytes.fromhex(n) for k, a, n in b}
        self._history_due, self._hist = bool(state.get("history_due", False)), int(state.get("hist", -1))
        if not -1 <= self._hist < self.n_actions:
            raise ValueError(f"saved last action {self._hist} is not one of the {self.n_actions} actions")
        if bool(state.get("history", False)) and not self._history and self.model is not None:
            # the table of (observation, last action) the saved model is of (its rows: the saved
            # ids); LSPI took its layout before its weights were restored (`take_layout`)
            self._remember_last_action()


__all__ = ["GenericRelearn", "inherit_order"]
