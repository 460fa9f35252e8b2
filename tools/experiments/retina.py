"""Chapter 4 experiments on the PyBullet retina, in-process through the daemon's WorldLink.

- learning: saccade error (1 and 2 saccades, px of the 128-px retina, 30 random repositions) and
  E_geometry every `every` steps (Fig 4.2-4.3).
- lesion: a small off-centre part of the fovea is lesioned at `at`; mean post-saccade activation,
  basic vs robust rule (Fig 4.4).
- reversal: up/down motor commands swapped at `at`; the link's detector must notice by itself;
  detection delay, steps to relearn 90 % of the pre-reversal reward, the embedding it publishes.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
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
    landing_u: float = 0.0  # where the target lands after one greedy saccade, px right of the centre (mean)
    landing_v: float = 0.0  # ... px up


def evaluate(world: RetinaWorld, program: RetinaProgram, n: int = 30, seed: int = EVAL_SEED) -> Evaluation:
    """Greedy saccades (no exploration, no learning) from `n` seeded random repositions, as the
    dissertation's tests every 100 training steps. The world's state is restored afterwards."""
    saved = (world.pan, world.tilt, world.rng)
    world.rng = np.random.default_rng(seed)
    one, two, act, land = [], [], [], []
    try:
        for _ in range(n):
            f = world.reset().tensors["fields"]
            act.append(world.step(program.learner.greedy(f)).reward)
            land.append(world.target_offset_px())
            one.append(float(np.linalg.norm(land[-1])))
            world.step(program.learner.greedy(world.render()))
            two.append(float(np.linalg.norm(world.target_offset_px())))
    finally:
        world.pan, world.tilt, world.rng = saved
    u, v = np.mean(land, axis=0)
    return Evaluation(float(np.mean(one)), float(np.mean(two)), float(np.mean(act)), float(u), float(v))


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
    landing_u: list[float] = field(default_factory=list)
    landing_v: list[float] = field(default_factory=list)

    def add(self, episode: int, e: Evaluation, geometry: float) -> None:
        self.steps.append(episode)
        self.one.append(e.one)
        self.two.append(e.two)
        self.activation.append(e.activation)
        self.geometry.append(geometry)
        self.landing_u.append(e.landing_u)
        self.landing_v.append(e.landing_v)


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


def activation_map(world: RetinaWorld, radius_px: int = 10) -> np.ndarray:
    """Post-saccade activation with the target seen at each whole-pixel offset (u, v) within
    `radius_px` of the retina centre: [2 r + 1, 2 r + 1], rows u from -r, columns v from -r (the
    landscape a saccade lands in; the camera's pose is restored)."""
    saved = (world.pan, world.tilt)
    r = radius_px
    out = np.zeros((2 * r + 1, 2 * r + 1))
    try:
        for i, u in enumerate(range(-r, r + 1)):
            for j, v in enumerate(range(-r, r + 1)):
                world._look_at_offset(float(u), float(v))
                out[i, j] = float(world.render().sum(dtype=np.float64))
    finally:
        world.pan, world.tilt = saved
    return out


@dataclass(frozen=True)
class LesionArithmetic:
    """What the basic rule can still learn after a lesion: the best post-saccade activation before
    and after it, the activation with the target on the centre after it, and the fields whose
    reward estimate R_k at the lesion is already above the best the lesioned retina can give (the
    basic rule updates a field only when R > R_k: those never learn again)."""

    best_before: float
    best_after: float
    centre_after: float
    best_offset_after: tuple[float, float]  # (u, v) px where the lesioned retina is most active
    lesioned_fields: int
    experienced_fields: int  # fields lit at least once (summed activation >= 1) before the lesion
    frozen_fields: int  # ... of those, with R_k >= best_after
    frozen_weight: float  # their share of the summed pre-lesion activation (how often they steer)
    r_quantiles: tuple[float, ...]  # R_k of the experienced fields at the lesion: 10, 50, 90 %


@dataclass
class PerturbationRun:
    rewards: list[float]  # post-saccade reward per episode
    at: int  # episode of the perturbation
    run: InProcessRun
    drop_episodes: list[int]  # episodes at which the link's detector fired
    world: RetinaWorld
    program: RetinaProgram
    curve: Curve
    arithmetic: LesionArithmetic | None = None  # lesions only


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
    init: str = "random",
    arithmetic: bool = False,
) -> PerturbationRun:
    """Train for `steps` saccades, perturb right after saccade `at`. With `every`, greedy
    evaluations (Curve) are made every `every` saccades. `init`: the learner's first preferences,
    "random" (the dissertation's) or "optimal" (each field's true saccade, Fig 4.3's reference: a
    retina that needs no training, so a lesion meets settled reward estimates). With `arithmetic`, a
    lesion's `LesionArithmetic` is measured (two activation maps: a few seconds)."""
    if init not in ("random", "optimal"):
        raise ValueError(f"init must be 'random' or 'optimal', got {init!r}")
    world, program = make(seed, rule, supersample, embed_every=embed_every, exploration=exploration)
    if init == "optimal":
        program.learner.pi = -np.asarray(world.truth().tensors["positions"], dtype=np.float64)
    snapshot: list[tuple[np.ndarray, np.ndarray]] = []  # (R_k, experience) at the perturbation
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
            snapshot.append((program.learner.R.copy(), program.learner.experience.copy()))
            return Control(world.world_id, kind, {k2: str(v) for k2, v in (params or {}).items()})
        return None

    det = make_detector(detector) if detector else None
    found = None
    with world:
        before = activation_map(world) if kind == "lesion" and arithmetic else None
        run = run_inprocess(
            world, program, 2 * steps + 1, detector=det, on_step=on_step, on_output=on_output, perturb=perturb
        )
        if before is not None and snapshot:
            found = lesion_arithmetic(world, before, *snapshot[0])
    return PerturbationRun(rewards, at, run, drops, world, program, curve, found)


def lesion_arithmetic(
    world: RetinaWorld, before: np.ndarray, R: np.ndarray, experience: np.ndarray
) -> LesionArithmetic:
    """`LesionArithmetic` of a lesioned `world`, from its activation map `before` the lesion and the
    learner's R_k and experience at the lesion."""
    after = activation_map(world)
    r = (after.shape[0] - 1) // 2
    i, j = np.unravel_index(int(np.argmax(after)), after.shape)
    lit = experience >= 1.0
    frozen = lit & (R >= after.max())
    return LesionArithmetic(
        float(before.max()),
        float(after.max()),
        float(after[r, r]),
        (float(i - r), float(j - r)),
        int(world.lesion.sum()),
        int(lit.sum()),
        int(frozen.sum()),
        float(experience[frozen].sum() / max(experience[lit].sum(), 1e-12)),
        tuple(float(q) for q in np.quantile(R[lit], [0.1, 0.5, 0.9])) if lit.any() else (0.0, 0.0, 0.0),
    )


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


#: the isolating run's lesion (Fig 4.4): off the centre like the default one, large enough that the
#: best activation left (243 of 422) is below the reward estimates of a trained retina - the premise
#: of 4.4.2 ("the maximum achievable reward may decrease to a level below the current reward
#: estimate ... and so no updates will take place")
ISOLATING_LESION = {"u": 6.0, "v": 0.0, "radius": 10.0}


def job_lesion(
    seed: int,
    rule: str,
    at: int,
    steps: int,
    every: int,
    supersample: int,
    init: str = "random",
    lesion: dict[str, float] | None = None,
) -> dict:
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
        init=init,
        arithmetic=True,
        params=lesion,
    )
    return {
        "seed": seed,
        "rule": rule,
        "init": init,
        "lesion": lesion,
        "steps": r.curve.steps,
        "activation": r.curve.activation,
        "landing_u": r.curve.landing_u,
        "landing_v": r.curve.landing_v,
        "train_reward": moving_average(r.rewards, 200)[::every].tolist(),
        "arithmetic": None if r.arithmetic is None else asdict(r.arithmetic),
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


def lesion_summary(lesion: list[dict], at: int) -> dict[str, Any]:
    """Per rule, per seed: the greedy activation at the last evaluation before the lesion, just after
    it (the evaluation at saccade `at`), at the end (mean of the last four evaluations), the rise
    from just after to the end, and the landing shift (px, u) over the same span; plus the lesion
    arithmetic (the first run's world, the frozen share per run)."""
    out: dict[str, Any] = {}
    for rule in ("basic", "robust"):
        rs = [r for r in lesion if r["rule"] == rule]
        if not rs:
            continue
        # the evaluation at saccade `at` is made just after the lesion (before any saccade learns from it)
        i = next(k for k, s in enumerate(rs[0]["steps"]) if s >= at)
        first = [float(r["activation"][i]) for r in rs]
        before = [float(r["activation"][i - 1]) for r in rs]  # the last evaluation before the lesion
        end = [float(np.mean(r["activation"][-4:])) for r in rs]
        shift = [float(np.mean(r["landing_u"][-4:]) - r["landing_u"][i]) if r.get("landing_u") else 0.0 for r in rs]
        ar = [r["arithmetic"] for r in rs if r.get("arithmetic")]
        out[rule] = {
            "seeds": [r["seed"] for r in rs],
            "last_before": before,
            "first_after": first,
            "end": end,
            "rise": [e - f for e, f in zip(end, first, strict=True)],
            "landing_shift_u": shift,
            "frozen_weight": [a["frozen_weight"] for a in ar],
            "frozen_fields": [a["frozen_fields"] for a in ar],
            "arithmetic": ar[0] if ar else None,
        }
    return out


def plot_fig_4_4(out: str, panels: list[tuple[str, list[dict], int]]) -> None:
    """Fig 4.4 as the dissertation draws it: greedy post-saccade activation over training saccades,
    both rules (mean and 95 % band over seeds), the lesion marked; beside it where the first greedy
    saccade puts the target (px right of the centre: the lesion lies to the right)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sensorimotor.tools.experiments.shared import ci95

    fig, axes = plt.subplots(len(panels), 2, figsize=(10.0, 3.6 * len(panels)), squeeze=False)
    for (title, runs, at), (a1, a2) in zip(panels, axes, strict=True):
        for rule, colour in (("basic", "tab:red"), ("robust", "tab:blue")):
            rs = [r for r in runs if r["rule"] == rule]
            if not rs:
                continue
            x = np.asarray(rs[0]["steps"])
            for ax, key in ((a1, "activation"), (a2, "landing_u")):
                if not all(r.get(key) for r in rs):
                    continue
                y = np.asarray([r[key] for r in rs], dtype=np.float64)
                m = y.mean(axis=0)
                h = np.array([ci95(list(col))[1] for col in y.T])
                ax.plot(x, m, color=colour, lw=1.4, label=f"{rule} rule ({len(rs)} run{'s' if len(rs) > 1 else ''})")
                ax.fill_between(x, m - h, m + h, color=colour, alpha=0.2, lw=0)
        ar = next((r["arithmetic"] for r in runs if r.get("arithmetic")), None)
        for ax in (a1, a2):
            ax.axvline(at, color="k", ls="--", lw=0.8)
            ax.set_xlabel("training saccades")
        if ar:
            a1.axhline(ar["best_after"], color="grey", ls=":", lw=0.9, label="best the lesioned retina gives")
            a1.axhline(ar["centre_after"], color="grey", ls="-.", lw=0.9, label="target on the centre, lesioned")
            a2.axhline(
                ar["best_offset_after"][0], color="grey", ls=":", lw=0.9, label="where the lesioned retina is best"
            )
        a1.set_title(f"{title}\ngreedy post-saccade activation", fontsize=9)
        a2.set_title(f"{title}\nwhere one greedy saccade puts the target", fontsize=9)
        a1.set_ylabel("activation (sum of fields)")
        a2.set_ylabel("px right of the centre (the lesion is right)")
        a1.legend(fontsize=7)
        a2.legend(fontsize=7)
        if not a2.lines[1:] or not any(r.get("landing_u") for r in runs):  # results from before it was recorded
            a2.clear()
            a2.text(0.5, 0.5, "where the target lands was\nnot recorded in these runs", ha="center", va="center")
            a2.set_axis_off()
    fig.tight_layout()
    fig.savefig(os.path.join(out, "retina_fig4_4.png"), dpi=110)
    plt.close(fig)


def chapter(runs: int, quick: bool, workers: int, out: str, supersample: int = 2) -> dict:
    L = dict(steps=1500, every=500) if quick else dict(steps=5000, every=100)
    les = dict(at=1000, steps=2500, every=250) if quick else dict(at=2000, steps=6000, every=250)
    # the isolating run: a retina that starts from its true saccades (settled estimates at the
    # lesion) and a lesion that leaves less than they expect (ISOLATING_LESION), fewer seeds
    iso = (
        dict(at=1000, steps=2000, every=250, runs=min(runs, 3))
        if quick
        else dict(at=2000, steps=4000, every=250, runs=min(runs, 5))
    )
    rev = dict(at=2000, steps=4500) if quick else dict(at=4000, steps=8000)
    # one pool for the three experiments, the longest jobs first, so that both cores stay busy
    jobs: list[tuple[Any, ...]] = [("reversal", s, rev["at"], rev["steps"], supersample) for s in range(runs)]
    jobs += [
        ("lesion", s, rule, les["at"], les["steps"], les["every"], supersample)
        for rule in ("basic", "robust")
        for s in range(runs)
    ]
    jobs += [
        ("lesion", s, rule, iso["at"], iso["steps"], iso["every"], supersample, "optimal", ISOLATING_LESION)
        for rule in ("basic", "robust")
        for s in range(iso["runs"])
    ]
    jobs += [("learning", s, L["steps"], L["every"], supersample) for s in range(runs)]
    done = pool_map(job_retina, jobs, workers)
    n_iso = 2 * iso["runs"]
    reversal, lesion = done[:runs], done[runs : 3 * runs]
    isolating, learning = done[3 * runs : 3 * runs + n_iso], done[3 * runs + n_iso :]
    les_sum, iso_sum = lesion_summary(lesion, les["at"]), lesion_summary(isolating, iso["at"])

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
        f"| lesion: rise of the activation from the first evaluation after the lesion to the end, basic / robust | "
        f"{fmt(mean_se(les_sum['basic']['rise']), 1)} / {fmt(mean_se(les_sum['robust']['rise']), 1)} | basic none, robust rises |",
        f"| lesion: target's shift (px, negative: away from the lesion) over the same span, basic / robust | "
        f"{fmt(mean_se(les_sum['basic']['landing_shift_u']), 2)} / {fmt(mean_se(les_sum['robust']['landing_shift_u']), 2)} "
        "| robust: just outside the damaged region |",
        f"| lesion: basic rule's steering weight frozen at the lesion (R_k above the lesioned retina's best) | "
        f"{fmt(mean_se(les_sum['basic']['frozen_weight']), 3)} | all (the rule cannot adapt) |",
        f"| isolating run (true saccades from the start; lesion of radius 10 px at (6, 0) px at {iso['at']}, "
        f"{iso['runs']} seeds): rise basic / robust | "
        f"{fmt(mean_se(iso_sum['basic']['rise']), 1)} / {fmt(mean_se(iso_sum['robust']['rise']), 1)} | |",
        f"| isolating run: shift basic / robust; basic's frozen weight | "
        f"{fmt(mean_se(iso_sum['basic']['landing_shift_u']), 2)} / {fmt(mean_se(iso_sum['robust']['landing_shift_u']), 2)}; "
        f"{fmt(mean_se(iso_sum['basic']['frozen_weight']), 3)} | |",
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
    ar = les_sum["basic"]["arithmetic"]
    if ar:
        lines += [
            "",
            f"The lesion: {ar['lesioned_fields']} fields within 6 px of (6, 0) px read 0 (the world's default lesion: "
            f"off the centre, its edge through it). The best post-saccade activation falls from {ar['best_before']:.0f} to "
            f"{ar['best_after']:.0f} (reached with the target at {ar['best_offset_after']} px); with the target on the "
            f"centre it gives {ar['centre_after']:.0f}. R_k of the basic rule's experienced fields at the lesion "
            f"(10/50/90 %): {', '.join(f'{q:.0f}' for q in ar['r_quantiles'])}.",
        ]
    ai = iso_sum["basic"]["arithmetic"]
    if ai:
        lines.append(
            f"The isolating run's lesion: {ai['lesioned_fields']} fields within 10 px of (6, 0) px; the best activation "
            f"left is {ai['best_after']:.0f} (target at {ai['best_offset_after']} px), {ai['centre_after']:.0f} on the "
            f"centre; R_k of the basic rule at the lesion (10/50/90 %): {', '.join(f'{q:.0f}' for q in ai['r_quantiles'])}."
        )
    plot_fig_4_4(
        out,
        [
            (f"lesion at {les['at']} (as the dissertation)", lesion, les["at"]),
            (f"isolating: trained estimates, radius-10 lesion at {iso['at']}", isolating, iso["at"]),
        ],
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
        "lesion_isolating": isolating,
        "lesion_summary": les_sum,
        "lesion_isolating_summary": iso_sum,
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
