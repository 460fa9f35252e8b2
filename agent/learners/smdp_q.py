"""Tabular SMDP Q-learning over primitive actions plus options (ch. 9.6's option agents).

Choices 0..n_actions-1 are the primitive actions; choice n_actions + j runs option j, a fixed
action sequence executed open loop (it stops early when the episode ends). After a choice that
took k primitive steps and collected the discounted reward R = sum_i gamma^i r_i:
Q(s, o) += alpha (R + gamma^k max_o' Q(s', o') - Q(s, o)) (0 for the next state when terminal).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


class OptionQLearner:
    """Epsilon-greedy SMDP Q-learning over a table of discrete states.

    Parameters
    ----------
    n_states : int
        Number of (discrete) states.
    n_actions : int
        Number of primitive actions.
    options : sequence of sequences of int
        Each option is a fixed sequence of primitive actions (may be empty: no options).
    alpha, gamma, epsilon : float
        Step size, discount and exploration probability.
    seed : int, default 0
        Seeds the learner's generator (exploration and ties).
    """

    def __init__(
        self,
        n_states: int,
        n_actions: int,
        options: Sequence[Sequence[int]] = (),
        alpha: float = 0.5,
        gamma: float = 0.95,
        epsilon: float = 0.1,
        seed: int = 0,
    ) -> None:
        if n_states < 1 or n_actions < 1 or not 0 < alpha <= 1 or not 0 <= gamma <= 1 or not 0 <= epsilon <= 1:
            raise ValueError("need n_states, n_actions >= 1, 0 < alpha <= 1 and gamma, epsilon in [0, 1]")
        opts = [tuple(int(a) for a in o) for o in options]
        if any(not o or min(o) < 0 or max(o) >= n_actions for o in opts):
            raise ValueError(f"every option must be a non-empty sequence of actions in 0..{n_actions - 1}")
        self.n_actions, self.options = n_actions, opts
        self.alpha, self.gamma, self.epsilon = alpha, gamma, epsilon
        self.rng = np.random.default_rng(seed)
        self.q = np.zeros((n_states, n_actions + len(opts)))

    @property
    def n_choices(self) -> int:
        """Primitive actions plus options."""
        return self.q.shape[1]

    def actions_of(self, choice: int) -> tuple[int, ...]:
        """The primitive actions a choice runs: one for a primitive, the sequence for an option."""
        return (choice,) if choice < self.n_actions else self.options[choice - self.n_actions]

    def choose(self, s: int) -> int:
        """Epsilon-greedy choice in state `s`, ties broken at random (for learning)."""
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.n_choices))
        q = self.q[s]
        best = np.flatnonzero(q == q.max())
        return int(best[self.rng.integers(best.size)])

    def greedy(self, s: int) -> int:
        """The best choice in `s`, ties to the lowest index (deterministic, for evaluation)."""
        return int(np.argmax(self.q[s]))

    def update(self, s: int, choice: int, reward: float, k: int, s2: int, done: bool) -> None:
        """SMDP update after `choice` from `s` took `k` steps, collected discounted `reward`, ended in `s2`."""
        target = reward + (0.0 if done else self.gamma**k * float(self.q[s2].max()))
        self.q[s, choice] += self.alpha * (target - self.q[s, choice])
