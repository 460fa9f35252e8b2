"""Chapter 4 experiments on the PyBullet retina, in-process through the daemon's WorldLink.

- learning: saccade error (1 and 2 saccades, px of the 128-px retina, 30 random repositions) and
  E_geometry every `every` steps (Fig 4.2-4.3).
- lesion: a small off-centre part of the fovea is lesioned at `at`; mean post-saccade activation,
  basic vs robust rule (Fig 4.4).
- reversal: up/down motor commands swapped at `at`; the link's detector must notice by itself;
  detection delay, steps to relearn 90 % of the pre-reversal reward, the embedding it publishes.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.programs.retina import RetinaProgram
from sensorimotor.protocol.messages import Control, Observation, Trigger
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import scores_of
from sensorimotor.tools.experiments.shared import fmt, mean_se, plot, pool_map
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


# --- `sme reproduce retina`: the seeded jobs and the chapter's table and plots ------------------------


def job_learning(seed: int, steps: int, every: int, supersample: int) -> dict:
    c = learning(seed, steps=steps, every=every, supersample=supersample)
    return {
        "seed": seed,
        "steps": c.steps,
        "one": c.one,
        "two": c.two,
        "activation": c.activation,
        "geometry": c.geometry,
    }


def job_lesion(seed: int, rule: str, at: int, steps: int, every: int, supersample: int) -> dict:
    r = perturbation(
        seed,
        "lesion",
        at=at,
        steps=steps,
        rule=rule,
        detector=None,
        supersample=supersample,
        exploration="gaussian",
        every=every,
        embed_every=10**9,
    )
    return {
        "seed": seed,
        "rule": rule,
        "steps": r.curve.steps,
        "activation": r.curve.activation,
        "train_reward": moving_average(r.rewards, 200)[::every].tolist(),
    }


def job_reversal(seed: int, at: int, steps: int, supersample: int) -> dict:
    r = perturbation(seed, "reverse", at=at, steps=steps, supersample=supersample)
    embs = [
        {
            "version": e.version,
            "trigger": e.trigger,
            "procrustes_error": e.procrustes_error,
            "scores": scores_of(e),
            "step": e.step,
            "n_points": int(e.coordinates.shape[0]),
        }
        for e in r.run.embeddings
    ]
    after = [d for d in r.drop_episodes if d >= at]
    return {
        "seed": seed,
        "detection_delay": (after[0] - at) if after else None,
        "false_alarms": sum(d < at for d in r.drop_episodes),
        "relearn_episodes": relearn_episodes(r.rewards, at),
        "embeddings": embs,
        "reward_ma": moving_average(r.rewards, 200)[::50].tolist(),
    }


def job_retina(kind: str, *args: Any) -> dict:
    """One retina job of `sme reproduce retina` by name (one pool runs all three experiments)."""
    jobs: dict[str, Callable[..., dict]] = {"learning": job_learning, "lesion": job_lesion, "reversal": job_reversal}
    return jobs[kind](*args)


def chapter(runs: int, quick: bool, workers: int, out: str, supersample: int = 2) -> dict:
    L = dict(steps=1500, every=500) if quick else dict(steps=5000, every=100)
    les = dict(at=1000, steps=2500, every=250) if quick else dict(at=2000, steps=6000, every=250)
    rev = dict(at=2000, steps=4500) if quick else dict(at=4000, steps=8000)
    # one pool for the three experiments, the longest jobs first, so that both cores stay busy
    jobs: list[tuple[Any, ...]] = [("reversal", s, rev["at"], rev["steps"], supersample) for s in range(runs)]
    jobs += [
        ("lesion", s, rule, les["at"], les["steps"], les["every"], supersample)
        for rule in ("basic", "robust")
        for s in range(runs)
    ]
    jobs += [("learning", s, L["steps"], L["every"], supersample) for s in range(runs)]
    done = pool_map(job_retina, jobs, workers)
    reversal, lesion, learning = done[:runs], done[runs : 3 * runs], done[3 * runs :]

    one = mean_se([r["one"][-1] for r in learning])
    two = mean_se([r["two"][-1] for r in learning])
    geo0 = mean_se([r["geometry"][0] for r in learning])
    geo = mean_se([r["geometry"][-1] for r in learning])
    end = {
        rule: mean_se([np.mean(r["activation"][-4:]) for r in lesion if r["rule"] == rule])
        for rule in ("basic", "robust")
    }
    post = {
        rule: mean_se(
            [
                np.mean([a for s, a in zip(r["steps"], r["activation"], strict=True) if s > les["at"]])
                for r in lesion
                if r["rule"] == rule
            ]
        )
        for rule in ("basic", "robust")
    }
    delays = [r["detection_delay"] for r in reversal]
    relearn = [r["relearn_episodes"] for r in reversal]
    relearned = [any(e["trigger"] == Trigger.RELEARNED for e in r["embeddings"]) for r in reversal]
    finals = [r["embeddings"][-1] for r in reversal if r["embeddings"]]
    last_err = [float(e["procrustes_error"]) for e in finals if e["procrustes_error"] is not None]
    last_scores = [e["scores"] for e in finals]
    lines = [
        f"Retina (ch. 4): {runs} seeded runs; mean ± standard error.",
        "",
        "| measure | ours | dissertation |",
        "|---|---|---|",
        f"| 1-saccade error after {L['steps']} steps (px) | {fmt(one)} | about 5 |",
        f"| 2-saccade error after {L['steps']} steps (px) | {fmt(two)} | lower than 1 saccade |",
        f"| E_geometry (px), start → after {L['steps']} steps | {fmt(geo0)} → {fmt(geo)} | falls with training |",
        f"| lesion at {les['at']}: greedy post-saccade activation at the end, basic rule | {fmt(end['basic'], 1)} | does not adapt |",
        f"| lesion at {les['at']}: same, robust rule | {fmt(end['robust'], 1)} | recovers |",
        f"| lesion: mean activation over all post-lesion evaluations, basic / robust | {fmt(post['basic'], 1)} / {fmt(post['robust'], 1)} | |",
        f"| reversal at {rev['at']}: detection delay (saccades), per run | {delays} | about 1000 |",
        f"| reversal: saccades to 90 % of pre-reversal reward, per run | {relearn} | |",
        f"| reversal: a 'relearned' embedding was published, per run | {relearned} | |",
        f"| reversal: last embedding's Procrustes error | {fmt(mean_se(last_err), 4)} | |",
        f"| reversal: last embedding's {scoring.HEADER} (95 % CI) | {scoring.cell(last_scores)} | |",
    ]
    xs = learning[0]["steps"]
    plot(
        out,
        "retina_learning.png",
        "Saccade error while learning (Fig 4.3)",
        "training saccades",
        "px",
        [
            ("1 saccade", xs, np.mean([r["one"] for r in learning], axis=0)),
            ("2 saccades", xs, np.mean([r["two"] for r in learning], axis=0)),
            ("E_geometry", xs, np.mean([r["geometry"] for r in learning], axis=0)),
        ],
    )
    plot(
        out,
        "retina_lesion.png",
        f"Greedy post-saccade activation, lesion at {les['at']} (Fig 4.4)",
        "training saccades",
        "activation",
        [
            (rule, lesion[0]["steps"], np.mean([r["activation"] for r in lesion if r["rule"] == rule], axis=0))
            for rule in ("basic", "robust")
        ],
        vline=les["at"],
    )
    plot(
        out,
        "retina_reversal.png",
        f"Reward (moving average), reversal at {rev['at']} (Fig 4.5)",
        "training saccades",
        "post-saccade reward",
        [(f"seed {r['seed']}", list(range(0, 50 * len(r["reward_ma"]), 50)), r["reward_ma"]) for r in reversal],
        vline=rev["at"],
    )
    return {
        "learning": learning,
        "lesion": lesion,
        "reversal": reversal,
        "markdown": "\n".join(lines),
        "summary": {
            "one": one,
            "two": two,
            "geometry_start": geo0,
            "geometry_end": geo,
            "lesion_end": end,
            "lesion_post_mean": post,
            "detection_delays": delays,
            "relearn_episodes": relearn,
        },
    }
