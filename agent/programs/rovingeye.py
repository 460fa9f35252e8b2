"""The roving-eye program (ch. 5.2): learn one ballistic jump per start state with the ch. 4
stochastic estimator, and publish the ballistic embedding of the start states.

Each start state is a field that is active (1) while the eye starts there: the program asks the
world for its start states in turn (`Decision(start=...)`) and so knows which one it is in. The
learned jump pi_s takes start s to the perceptual goal, so the ballistic trace distance between
starts i and j is ||pi_i - pi_j|| and classical MDS of it is -pi up to a rigid motion: the program
publishes -pi_s (px of the eye's own moves; the goal at the origin). Exploration noise follows each
start's reward estimate (the reward exp(-d / scale) says how far the jumps land, d; the noise is a
fraction of d), so it is wide while far and fine on target. The fraction is 0.25 rather than the
experiment's 0.5: after a gain g the landing noise is g times the motor noise, and the noise only
shrinks while fraction x g x ~1.25 < 1. Drop detection, relearning and the relearned embedding are the
retina program's: after `sme perturb gain` every jump lands `gain` times as far, the reward drops,
the estimates are reset, the jumps are relearned (now pi / gain) and the map is published again.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from sensorimotor.agent.programs.base import Decision
from sensorimotor.agent.programs.retina import RetinaProgram, RetinaProgramParams
from sensorimotor.protocol.errors import SpecMismatch
from sensorimotor.protocol.messages import Observation, WorldSpec
from sensorimotor.protocol.params import option


@dataclass(frozen=True)
class RovingEyeProgramParams(RetinaProgramParams):
    """Hyperparameters of the roving-eye program (ch. 5.2)."""

    exploration: str = option("gaussian", "exploration of the jump learner", choices=("relearn", "gamma", "gaussian"))
    noise_sd: float | None = option(
        None, "not used: the noise follows each start's reward estimate (noise_* below)", min=0.0
    )
    embed_every: int = option(500, "jumps between periodic embeddings", min=1)
    settle_min: int = option(500, "jumps after a drop before the reward may count as settled", min=0)
    settle_window: int = option(200, "jumps in the settled-reward window", min=1)
    noise_scale_px: float = option(5.0, "distance scale of the reward, px: noise = fraction x scale x -ln(R)", min=0.01)
    noise_fraction: float = option(
        0.25, "exploration noise as a fraction of the distance the reward estimate implies", min=0.0, max=1.0
    )
    noise_min_px: float = option(0.2, "smallest exploration noise, px", min=0.0)
    noise_max_px: float = option(48.0, "largest exploration noise, px", min=0.0)


class RovingEyeProgram(RetinaProgram):
    """Ballistic jumps to the perceptual goal, one per start state; -pi_s published as the map.

    Built by `make_program` as `RovingEyeProgram(spec, seed, params=None, **overrides)`. Needs a
    2-D box action space and start states.
    """

    name = "rovingeye"
    Params = RovingEyeProgramParams
    # Once the jumps are learned the reward barely varies, so the detector's reference sd is tiny and
    # a 2-sigma wobble of exploration is no body change: only sustained drops of several sigma count
    # (a gain change drops the reward to ~0, dozens of sigma: still detected within a few jumps).
    detector_params = {"k": 2.0, "h": 20.0}
    INIT_SPREAD = 0.0
    ABSOLUTE = False

    def __init__(self, spec: WorldSpec, seed: int = 0, params: Any = None, **overrides: Any) -> None:
        super().__init__(spec, seed, params, **overrides)
        self._onehot = np.zeros(self.n)

    def input_size(self, spec: WorldSpec) -> int:
        """One field per start state."""
        if spec.n_starts < 3:
            raise SpecMismatch(f"rovingeye program needs start states, world {spec.world_id} has {spec.n_starts}")
        return int(spec.n_starts)

    def _next_start(self) -> int:
        return int(self.rng.integers(self.n))

    def noise(self, expected_reward: float) -> float:
        """Exploration noise for a start whose jumps earn `expected_reward` (see the module doc)."""
        prm = self.params
        d = -prm.noise_scale_px * np.log(max(float(expected_reward), 1e-300))
        return float(np.clip(prm.noise_fraction * d, prm.noise_min_px, prm.noise_max_px))

    def act(self, obs: Observation) -> Decision:
        """A jump from the start state this episode began in; learn from its reward at the end."""
        if obs.t == 0 and not obs.done:
            if not 0 <= obs.start < self.n:  # a random start (the first episode): ask for a known one
                return Decision(reset=True, start=self._next_start())
            self._onehot[:] = 0.0
            self._onehot[obs.start] = 1.0
            self._pre = self._onehot.copy()
            self.learner.noise_sd = self.noise(self.learner.R[obs.start])
            self._action = self.learner.act(self._pre)
            return Decision(tuple(float(v) for v in self._action))
        self._finish(obs)
        return Decision(reset=True, start=self._next_start())
