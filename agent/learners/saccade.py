"""The factored saccade learner of ch. 4 (Eq 4.2-4.7).

Each receptive field k keeps a preferred saccade pi_k and a reward estimate R_k. The retina's
saccade is the activation-weighted mean pi*(s) = sum_k d_k pi_k / sum_k d_k (Eq 4.3) plus
exploration. After the saccade, with pre-saccade activations d_k and reward R:
  basic rule  (Eq 4.4-4.5): if R > R_k:  R_k += d_k a (R - R_k);  pi_k += d_k a (a_taken - pi_k)
  robust rule (Eq 4.7):     R_k += d_k a (R - R_k) always;  pi_k moves as above when R > R_k.
Exploration (4.4.2): gamma = r_a / r_ref, where r_a = sum_k d_k R_k / sum_k d_k is the reward the
active fields expect and r_ref the retina's moving average of observed rewards; the saccade is
gamma pi* + (1 - gamma) a_random, plus Gaussian noise of sd `noise_sd`. (The dissertation divides
by the maximum reward seen; with the robust rule R_k are averages, so that ratio never reaches 1
and random saccades would be mixed in for ever. Against the moving average, gamma is ~1 once the
estimates are learned and 0 right after `reset_estimates()`, which a detected drop triggers.)
Exploration modes: "gaussian" (4.4.1: noise only), "gamma" (mixing always), and "relearn" (the
default: noise only, and gamma mixing from `reset_estimates()` until `end_relearning()`). Mixing
all the time costs accuracy - a lucky random saccade pulls every active field's preference a long
way - so it is kept for what 4.4.2 introduced it for: large changes.
The learned geometry is -pi_k: the position of field k in motor units.

Credit (`credit`): "activation" is Eq 4.5 as written, step d_k a. "share" shares one saccade's
credit among the fields it lit: step d_k a min(1, A / sum_j d_j), A the moving average of the
pre-saccade total activation, so no saccade teaches more than a typical one (sum_k step_k <= a A).
Eq 4.5 assumes a small spot, where a lit field says where the target is; on a natural scene a
large blob lights hundreds of fields at once, each is pulled fully to the one saccade that centred
the blob, and the preferences of the fovea learn a common offset (about 6 px on 'astronaut') that
repeated saccades integrate into a drift off the blob. A target no larger than usual (total
activation <= A) still learns as Eq 4.5. `experience` counts the activation credited (d_k times
that factor), so fields lit only under large blobs are not embedded before they have learned.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.agent.snapshot import rng_state, set_rng_state

RULES = ("basic", "robust")
CREDIT = ("activation", "share")
EXPLORATION = ("relearn", "gamma", "gaussian")


def share_factor(total: float, typical_total: float) -> float:
    """min(1, A / total): the credit factor of a saccade whose pre-saccade activation sums to
    `total`, when a typical one sums to A (1 when nothing is lit)."""
    return 1.0 if total <= 1e-12 else min(1.0, typical_total / total)


class SaccadeLearner:
    """The factored saccade learner of ch. 4: per receptive field a preferred saccade and a reward
    estimate (see the module docstring for the rules and exploration).

    Parameters
    ----------
    n_fields : int
        Number of receptive fields.
    low, high : np.ndarray
        Bounds of the saccade (action) box, 1-D, high > low.
    alpha : float, default 0.5
        Learning rate, in (0, 1].
    noise_sd : float, optional
        Exploration noise sd in action units (default: 0.075 x the mean action range).
    rule : {"robust", "basic"}, default "robust"
        Update rule (Eq 4.7 or Eq 4.4-4.5).
    exploration : {"relearn", "gamma", "gaussian"}, default "relearn"
        Exploration mode.
    credit : {"activation", "share"}, default "activation"
        Step of a field's preference update: Eq 4.5 (d_k alpha), or one saccade's credit shared
        among the fields it lit (see the module docstring).
    init_spread : float, default 1.0
        Initial preferences are uniform over the box scaled by this, in [0, 1].
    seed : int, default 0
        Seed of the learner's generator.
    """

    def __init__(
        self,
        n_fields: int,
        low: np.ndarray,
        high: np.ndarray,
        alpha: float = 0.5,
        noise_sd: float | None = None,
        rule: str = "robust",
        exploration: str = "relearn",
        init_spread: float = 1.0,
        seed: int = 0,
        credit: str = "activation",
    ) -> None:
        low, high = np.asarray(low, dtype=np.float64), np.asarray(high, dtype=np.float64)
        if n_fields < 1:
            raise ValueError("n_fields must be >= 1")
        if low.shape != high.shape or low.ndim != 1 or not (high > low).all():
            raise ValueError("low/high must be 1-D bounds with high > low")
        if not 0 < alpha <= 1:
            raise ValueError("alpha must be in (0, 1]")
        if rule not in RULES:
            raise ValueError(f"rule must be one of {RULES}")
        if exploration not in EXPLORATION:
            raise ValueError(f"exploration must be one of {EXPLORATION}")
        if credit not in CREDIT:
            raise ValueError(f"credit must be one of {CREDIT}")
        if not 0 <= init_spread <= 1:
            raise ValueError("init_spread must be in [0, 1]")
        self.init_spread = init_spread
        self.n_fields = n_fields
        self.low, self.high = low, high
        self.alpha = alpha
        # default: the dissertation's 10 px, as the fraction of the action range it is on our retina
        self.noise_sd = float(noise_sd) if noise_sd is not None else float(0.075 * (high - low).mean())
        self.rule = rule
        self.exploration = exploration
        self.credit = credit
        self.seed = seed
        self.reset()

    REF_RATE = 0.02

    def reset(self) -> None:
        """Back to the initial (seeded, random) preferences and zero reward estimates."""
        self.rng = np.random.default_rng(self.seed)
        self.pi = self.rng.uniform(self.low, self.high, (self.n_fields, self.low.size)) * self.init_spread
        self.R = np.zeros(self.n_fields)
        # summed (credited) pre-saccade activation: how much each field has learned from
        self.experience = np.zeros(self.n_fields)
        self.r_ref = 0.0
        self.a_ref = 0.0  # moving average of the pre-saccade total activation (credit "share")
        self.updates = 0
        self.resets = 0
        self.relearning = False

    def state(self) -> dict[str, Any]:
        """Preferences, reward estimates, experience, exploration reference and the generator."""
        return {
            "seed": self.seed,
            "rng": rng_state(self.rng),
            "pi": self.pi.copy(),
            "R": self.R.copy(),
            "experience": self.experience.copy(),
            "r_ref": self.r_ref,
            "a_ref": self.a_ref,
            "updates": self.updates,
            "resets": self.resets,
            "relearning": self.relearning,
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot of a learner with the same fields and action box."""
        pi = np.array(state["pi"], dtype=np.float64)
        R, experience = np.array(state["R"], dtype=np.float64), np.array(state["experience"], dtype=np.float64)
        if pi.shape != self.pi.shape or R.shape != self.R.shape or experience.shape != self.experience.shape:
            raise ValueError(f"saccade learner state is for {pi.shape[0]} fields, this learner has {self.n_fields}")
        self.seed = int(state["seed"])
        set_rng_state(self.rng, state["rng"])
        self.pi, self.R, self.experience = pi, R, experience
        self.r_ref = float(state["r_ref"])
        self.a_ref = float(state.get("a_ref", 0.0))  # absent in snapshots from before credit "share"
        self.updates, self.resets = int(state["updates"]), int(state["resets"])
        self.relearning = bool(state["relearning"])

    def reset_estimates(self) -> None:
        """After a large drop (lesion, reversal): forget the reward estimates so exploration rises."""
        self.R[:] = 0.0
        self.resets += 1
        self.relearning = True

    def end_relearning(self) -> None:
        """The reward has settled after a drop: stop the extra (gamma) exploration."""
        self.relearning = False

    @property
    def positions(self) -> np.ndarray:
        """Learned field positions -pi_k, [n_fields, dims]."""
        return -self.pi

    def greedy(self, delta: np.ndarray) -> np.ndarray:
        """pi*(s) (Eq 4.3): the activation-weighted mean of the fields' preferences; the centre of the
        action box when nothing is active.

        Parameters
        ----------
        delta : np.ndarray
            Pre-saccade field activations [n_fields].

        Returns
        -------
        np.ndarray
            The saccade, [action dims].
        """
        d = np.asarray(delta, dtype=np.float64)
        s = d.sum()
        if s <= 1e-12:
            return (self.low + self.high) / 2
        return d @ self.pi / s

    def expected_reward(self, delta: np.ndarray) -> float:
        """r_a: the activation-weighted mean reward estimate of the active fields (0 if none)."""
        d = np.asarray(delta, dtype=np.float64)
        s = d.sum()
        return float(d @ self.R / s) if s > 1e-12 else 0.0

    def act(self, delta: np.ndarray) -> np.ndarray:
        """The saccade to make: `greedy` plus exploration, clipped to the action box.

        Parameters
        ----------
        delta : np.ndarray
            Pre-saccade field activations [n_fields].

        Returns
        -------
        np.ndarray
            The saccade, [action dims].
        """
        a = self.greedy(delta)
        if self.exploration == "gamma" or (self.exploration == "relearn" and self.relearning):
            gamma = 0.0 if self.r_ref <= 0 else float(np.clip(self.expected_reward(delta) / self.r_ref, 0.0, 1.0))
            a = gamma * a + (1 - gamma) * self.rng.uniform(self.low, self.high)
        a = a + self.rng.normal(0.0, self.noise_sd, a.shape)
        return np.clip(a, self.low, self.high)

    def learn_one(self, delta: np.ndarray, action: np.ndarray, reward: float) -> None:
        """Learn from one saccade: update reward estimates and preferences of the active fields.

        Parameters
        ----------
        delta : np.ndarray
            Pre-saccade field activations [n_fields] (the same as given to `act`).
        action : np.ndarray
            The saccade made.
        reward : float
            The post-saccade reward (finite).
        """
        d = np.asarray(delta, dtype=np.float64)
        a = np.asarray(action, dtype=np.float64)
        if d.shape != (self.n_fields,) or a.shape != self.low.shape:
            raise ValueError(
                f"expected delta [{self.n_fields}] and action {list(self.low.shape)}, "
                f"got {list(d.shape)} and {list(a.shape)}"
            )
        if not np.isfinite(reward):
            raise ValueError("reward must be finite")
        self.r_ref += self.REF_RATE * (float(reward) - self.r_ref) if self.updates else float(reward)
        total = float(d.sum())
        self.a_ref += self.REF_RATE * (total - self.a_ref) if self.updates else total
        better = reward > self.R
        step = d * self.alpha
        if self.rule == "robust":
            self.R += step * (reward - self.R)
        else:
            self.R = np.where(better, self.R + step * (reward - self.R), self.R)
        credited = d * share_factor(total, self.a_ref) if self.credit == "share" else d
        w = np.where(better, credited * self.alpha, 0.0)[:, None]
        self.pi += w * (a - self.pi)
        self.experience += credited
        self.updates += 1
