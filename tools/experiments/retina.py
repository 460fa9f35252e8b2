"""Chapter 4 experiments on the PyBullet retina, in-process through the daemon's WorldLink.

- learning: saccade error (1 and 2 saccades, px of the 128-px retina, 30 random repositions) and
  E_geometry every `every` steps (Fig 4.2-4.3).
- lesion: a small off-centre part of the fovea is lesioned at `at`; mean post-saccade activation,
  basic vs robust rule (Fig 4.4).
- reversal: up/down motor commands swapped at `at`; the link's detector must notice by itself;
  detection delay, steps to relearn 90 % of the pre-reversal reward, the embedding it publishes.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.programs.retina import RetinaProgram
from sensorimotor.protocol.messages import Control, Observation
from sensorimotor.tools.inprocess import InProcessRun, run_inprocess
from sensorimotor.worlds.retina import RetinaWorld

EVAL_SEED = 999


@dataclass(frozen=True)
class Evaluation:
    one: float  # px from the centre after one greedy saccade (mean over repositions)
    two: float  # ... after two
    activation: float  # post-saccade activation (reward) of the first greedy saccade


def evaluate(world: RetinaWorld, program: RetinaProgram, n: int = 30, seed: int = EVAL_SEED) -> Evaluation:
    """Greedy saccades (no exploration, no learning) from `n` seeded random repositions, as the
    dissertation's tests every 100 training steps. The world's state is restored afterwards."""
    saved = (world.pan, world.tilt, world.rng)
    world.rng = np.random.default_rng(seed)
    one, two, act = [], [], []
    try:
        for _ in range(n):
            f = world.reset().tensors["fields"]
            act.append(world.step(program.learner.greedy(f)).reward)
            one.append(float(np.linalg.norm(world.target_offset_px())))
            world.step(program.learner.greedy(world.render()))
            two.append(float(np.linalg.norm(world.target_offset_px())))
    finally:
        world.pan, world.tilt, world.rng = saved
    return Evaluation(float(np.mean(one)), float(np.mean(two)), float(np.mean(act)))


def saccade_errors(
    world: RetinaWorld, program: RetinaProgram, n: int = 30, seed: int = EVAL_SEED
) -> tuple[float, float]:
    e = evaluate(world, program, n, seed)
    return e.one, e.two


def e_geometry_px(world: RetinaWorld, program: RetinaProgram) -> float:
    """E_geometry (Eq 4.6) converted from motor units to px at the retina centre."""
    pos = world.truth().tensors["positions"]
    deg = np.linalg.norm(program.learner.positions - pos, axis=1).mean()
    return float(world.focal * np.tan(np.radians(deg)))


@dataclass
class Curve:
    steps: list[int] = field(default_factory=list)
    one: list[float] = field(default_factory=list)
    two: list[float] = field(default_factory=list)
    activation: list[float] = field(default_factory=list)
    geometry: list[float] = field(default_factory=list)

    def add(self, episode: int, e: Evaluation, geometry: float) -> None:
        self.steps.append(episode)
        self.one.append(e.one)
        self.two.append(e.two)
        self.activation.append(e.activation)
        self.geometry.append(geometry)


def make(seed: int, rule: str = "robust", supersample: int = 2, **program_kw) -> tuple[RetinaWorld, RetinaProgram]:
    world = RetinaWorld(seed=seed, supersample=supersample)
    program = RetinaProgram(world.spec(), seed=seed, rule=rule, **program_kw)
    return world, program


def _evaluator(world: RetinaWorld, program: RetinaProgram, curve: Curve, every: int, n_eval: int):
    def on_step(k: int, obs: Observation) -> None:
        ep = program.episodes
        if obs.t == 0 and ep % every == 0 and (not curve.steps or curve.steps[-1] != ep):
            curve.add(ep, evaluate(world, program, n_eval), e_geometry_px(world, program))

    return on_step


def learning(
    seed: int,
    steps: int = 5000,
    every: int = 500,
    rule: str = "robust",
    supersample: int = 2,
    n_eval: int = 30,
    exploration: str = "relearn",
) -> Curve:
    """Greedy evaluation every `every` training saccades; `steps` counts training saccades
    (episodes), as in the dissertation."""
    world, program = make(seed, rule, supersample, embed_every=10**9, exploration=exploration)
    curve = Curve()
    with world:
        run_inprocess(world, program, 2 * steps + 1, on_step=_evaluator(world, program, curve, every, n_eval))
    return curve


def moving_average(x: list[float] | np.ndarray, w: int) -> np.ndarray:
    x = np.asarray(x, dtype=np.float64)
    if x.size < w:
        return x.copy()
    c = np.cumsum(np.insert(x, 0, 0.0))
    return (c[w:] - c[:-w]) / w


@dataclass
class PerturbationRun:
    rewards: list[float]  # post-saccade reward per episode
    at: int  # episode of the perturbation
    run: InProcessRun
    drop_episodes: list[int]  # episodes at which the link's detector fired
    world: RetinaWorld
    program: RetinaProgram
    curve: Curve


def perturbation(
    seed: int,
    kind: str,
    at: int,
    steps: int,
    rule: str = "robust",
    detector: str | None = "cusum",
    supersample: int = 2,
    params: dict | None = None,
    embed_every: int = 1000,
    exploration: str = "relearn",
    every: int | None = None,
    n_eval: int = 30,
) -> PerturbationRun:
    """Train for `steps` saccades, perturb right after saccade `at`. With `every`, greedy
    evaluations (Curve) are made every `every` saccades."""
    world, program = make(seed, rule, supersample, embed_every=embed_every, exploration=exploration)
    curve = Curve()
    evaluator = _evaluator(world, program, curve, every, n_eval) if every else None
    rewards: list[float] = []
    drops: list[int] = []
    at_step: list[int] = []

    def on_step(k: int, obs: Observation) -> None:
        if obs.t > 0:
            rewards.append(obs.reward)
            if len(rewards) == at:
                at_step.append(k)
        if evaluator is not None:
            evaluator(k, obs)

    def on_output(msg) -> None:
        if getattr(msg, "kind", None) == "drop_detected":
            drops.append(len(rewards))

    def perturb(k: int) -> Control | None:  # right after the `at`-th saccade has been answered
        if at_step and k == at_step[0]:
            return Control(world.world_id, kind, {k2: str(v) for k2, v in (params or {}).items()})
        return None

    det = make_detector(detector) if detector else None
    with world:
        run = run_inprocess(
            world, program, 2 * steps + 1, detector=det, on_step=on_step, on_output=on_output, perturb=perturb
        )
    return PerturbationRun(rewards, at, run, drops, world, program, curve)


def relearn_episodes(rewards: list[float], at: int, frac: float = 0.9, pre: int = 500, window: int = 200) -> int | None:
    """Episodes after `at` until the `window` moving average of the reward is back to `frac` of its
    mean over the `pre` episodes before `at` (None if it never is)."""
    base = float(np.mean(rewards[max(0, at - pre) : at]))
    ma = moving_average(rewards[at:], window)
    hit = np.flatnonzero(ma >= frac * base)
    return int(hit[0] + window) if hit.size else None
