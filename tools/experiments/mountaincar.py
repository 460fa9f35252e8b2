"""Chapter 8 experiments, in-process through the daemon's WorldLink: the visual mountain car on a
body, the same task for an agent given the true (x, v), a random agent, and a body changed while the
agent drives."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from sensorimotor.agent.learners.sarsa_lambda import SarsaLambda, TileCoder
from sensorimotor.agent.programs.mountaincar_params import MountainCarProgramParams
from sensorimotor.protocol.messages import Trigger
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.shared import ci95, fmt, mean_se, plot, pool_map
from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, evaluation_states, random_state
from sensorimotor.worlds.mountaincar_dynamics import step as car_step

#: the embedding agent's driver settings, which the true-state agent shares so the two compare
_DRIVER = MountainCarProgramParams()


@dataclass
class DriveResult:
    curve: list[tuple[int, float]]  # (training car steps, mean steps to goal)
    embeddings: list[dict[str, Any]] = field(default_factory=list)
    drops: list[int] = field(default_factory=list)  # training steps at which the agent saw a drop
    morph_at: int | None = None  # training steps when the body changed
    world_steps: int = 0
    seconds: float = 0.0
    per_state: list[list[int]] = field(default_factory=list)  # car steps from each evaluation state, per evaluation


def visual(
    seed: int,
    train_steps: int,
    eval_every: int = 10_000,
    n_eval: int = 100,
    baseline: float = 1.0,
    vertical: bool = False,
    morph_at: int | None = None,
    morph: dict[str, str] | None = None,
    detector: str | None = None,
    **program_params: Any,
) -> DriveResult:
    """The staged program on the rendered robot; optionally the body changes (`morph`) after
    `morph_at` training car steps, with the agent's own detector watching (`detector`)."""
    from sensorimotor.agent.detectors import make_detector
    from sensorimotor.agent.programs.mountaincar import MountainCarProgram
    from sensorimotor.protocol.messages import Control, Embedding
    from sensorimotor.tools.experiments.scoring import scores_of
    from sensorimotor.tools.inprocess import run_inprocess
    from sensorimotor.worlds.mountaincar import MountainCarWorld

    world = MountainCarWorld(seed=seed, baseline=baseline, vertical=vertical, n_eval=n_eval)
    prog = MountainCarProgram(world.spec(), seed=seed, eval_every=eval_every, **program_params)
    res = DriveResult([])
    state = {"morphed": False}

    def on_output(msg: Any) -> None:
        if isinstance(msg, Embedding):
            res.embeddings.append(
                {
                    "version": msg.version,
                    "trigger": msg.trigger,
                    "training_steps": prog.training_steps,
                    "procrustes_error": msg.procrustes_error,
                    "scores": scores_of(msg),
                }
            )
        elif getattr(msg, "kind", None) == "drop_detected":
            res.drops.append(prog.training_steps)
        elif getattr(msg, "kind", None) == "evaluation":
            res.per_state.append(list(prog.evaluation_steps))

    def perturb(k: int) -> Control | None:
        if morph and morph_at is not None and not state["morphed"] and prog.training_steps >= morph_at:
            state["morphed"] = True
            res.morph_at = prog.training_steps
            return Control(world.world_id, "morph", dict(morph))
        return None

    n_evals = train_steps // eval_every
    det = make_detector(detector, **prog.detector_params) if detector else None
    with world:
        run = run_inprocess(
            world,
            prog,
            10**9,
            detector=det,
            on_output=on_output,
            perturb=perturb,
            stop_when=lambda r: len(prog.curve) >= n_evals,
        )
    res.curve, res.world_steps, res.seconds = list(prog.curve), run.steps, run.seconds
    return res


def true_state_agent(
    seed: int,
    prm: MountainCarParams,
    tiles: int = _DRIVER.tiles,
    n_tilings: int = _DRIVER.n_tilings,
    alpha: float = _DRIVER.alpha,
    gamma: float = _DRIVER.gamma,
    lam: float = _DRIVER.lam,
) -> SarsaLambda:
    """Sarsa(lambda) over a tile coding of the true (x, v): the agent given the state (ch. 8),
    with the embedding agent's own driver settings by default."""
    coder = TileCoder(
        np.array([prm.x_min, -prm.v_max]), np.array([prm.x_max, prm.v_max]), tiles=tiles, n_tilings=n_tilings
    )
    return SarsaLambda(coder, 3, alpha=alpha, gamma=gamma, lam=lam, epsilon=0.0, seed=seed)


def true_state_episode(agent: SarsaLambda, rng: np.random.Generator, prm: MountainCarParams, max_car_steps: int) -> int:
    """One training episode of `agent` from a random state (reward -1 per step); the car steps taken."""
    x, v = random_state(rng, prm)
    s = np.array([x, v])
    agent.begin_episode()
    a = agent.act(s)
    for n in range(1, max_car_steps + 1):
        x, v, done = car_step(x, v, a - 1, prm)
        s2 = np.array([x, v])
        if done:
            agent.learn_one(s, a, -1.0, s2, None)
            return n
        a2 = agent.act(s2)
        agent.learn_one(s, a, -1.0, s2, a2)
        s, a = s2, a2
    return max_car_steps


def true_state(
    seed: int,
    train_steps: int,
    eval_every: int = 10_000,
    n_eval: int = 100,
    tiles: int = _DRIVER.tiles,
    n_tilings: int = _DRIVER.n_tilings,
    alpha: float = _DRIVER.alpha,
    gamma: float = _DRIVER.gamma,
    lam: float = _DRIVER.lam,
    max_car_steps: int = 1000,
) -> DriveResult:
    """The same Sarsa(lambda) and tile coding, given the true position and velocity."""
    prm = MountainCarParams()
    rng = np.random.default_rng(seed)
    agent = true_state_agent(seed, prm, tiles, n_tilings, alpha, gamma, lam)
    evals = evaluation_states(n_eval)

    res = DriveResult([])
    n = 0
    while len(res.curve) < train_steps // eval_every:
        n += true_state_episode(agent, rng, prm, max_car_steps)
        if n // eval_every > len(res.curve):
            per = steps_from_each(agent.greedy, evals, max_car_steps)
            res.curve.append((n, float(np.mean(per))))
            res.per_state.append(per)
    return res


def steps_from_each(policy, states: np.ndarray, cap: int = 1000) -> list[int]:
    """Car steps to the goal from each (x, v) in `states` under `policy(s) -> 0|1|2` (`cap` when
    the goal is not reached)."""
    prm = MountainCarParams()
    steps = []
    for x, v in states:
        for t in range(1, cap + 1):  # noqa: B007 (t counts the steps taken, read after the loop)
            x, v, done = car_step(float(x), float(v), policy(np.array([x, v])) - 1, prm)
            if done:
                break
        steps.append(t)
    return steps


def steps_to_goal(policy, states: np.ndarray, cap: int = 1000) -> float:
    """Mean car steps to the goal from each (x, v) in `states` under `policy(s) -> 0|1|2`."""
    return float(np.mean(steps_from_each(policy, states, cap)))


def random_agent(seed: int, n_eval: int = 100, cap: int = 1000) -> float:
    rng = np.random.default_rng(seed)
    return steps_to_goal(lambda s: int(rng.integers(3)), evaluation_states(n_eval), cap)


# --- `sme reproduce mountaincar`: the seeded jobs and the chapter's table and plots -------------------


def job_mountaincar(kind: str, seed: int, train: int, every: int, n_eval: int, morph_at: int | None = None) -> dict:
    if kind == "true":
        r = true_state(seed, train, every, n_eval)
    elif kind == "random":
        return {"kind": kind, "seed": seed, "curve": [(0, random_agent(seed, n_eval))]}
    elif kind == "live":
        if morph_at is None:
            raise ValueError("the live morph run needs morph_at")
        r = visual(
            seed,
            train,
            every,
            n_eval,
            morph_at=morph_at,
            morph={"baseline": "1.4"},
            detector="cusum",
            watch_after=morph_at // 2,
        )
    else:
        bodies: dict[str, dict[str, Any]] = {
            "baseline-1.0": {},
            "baseline-1.4": {"baseline": 1.4},
            "vertical": {"vertical": True},
        }
        body = bodies[kind]
        r = visual(seed, train, every, n_eval, **body)
    return {
        "kind": kind,
        "seed": seed,
        "curve": r.curve,
        "embeddings": r.embeddings,
        "drops": r.drops,
        "morph_at": r.morph_at,
        "world_steps": r.world_steps,
        "seconds": r.seconds,
    }


#: where `pool_map` runs jobs: None = this machine's process pool, else a Ray cluster's address


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict:
    # --quick: 20,000 training car steps and one evaluation at the end (the full run evaluates every
    # 10,000 and scores the last three); one live body change, evaluated every 10,000 around it
    train, every, n_eval = (20_000, 20_000, 20) if quick else (100_000, 10_000, 100)
    live_every, n_live = (10_000, 1) if quick else (every, max(1, runs // 2))
    morph_at = train
    kinds = ("baseline-1.0", "baseline-1.4", "vertical", "true")
    # the longest jobs first (the live run drives twice as long), so that both cores stay busy
    jobs: list[tuple[Any, ...]] = [("live", s, 2 * train, live_every, n_eval, morph_at) for s in range(n_live)]
    jobs += [(k, s, train, every, n_eval) for k in kinds for s in range(runs)]
    jobs += [("random", s, train, every, n_eval) for s in range(runs)]
    res = pool_map(job_mountaincar, jobs, workers)

    def final(r: dict) -> float:  # the end of training: the mean of the last three evaluations
        return float(np.mean([m for _, m in r["curve"][-3:]]))

    finals = {k: [final(r) for r in res if r["kind"] == k] for k in kinds + ("random",)}
    ci = {k: ci95(v) for k, v in finals.items()}
    from scipy import stats

    lines = [
        f"Visual mountain car (ch. 8): {runs} seeded runs per body; {train} training car steps, evaluated every "
        f"{every} on {n_eval} fixed random states (mean steps to goal, lower is better; 1000 = never).",
        "",
        "| agent | steps to goal at the end (mean ± 95 % CI) | vs true state | dissertation |",
        "|---|---|---|---|",
    ]
    t = ci["true"][0]
    for k, label in (
        ("baseline-1.0", "sensorimotor features, baseline 1.0 m"),
        ("baseline-1.4", "same program, baseline 1.4 m"),
        ("vertical", "same program, vertical cameras"),
        ("true", "true position and velocity"),
        ("random", "random agent"),
    ):
        ref = {"true": "ideal", "random": "benchmark"}.get(k, "comparable to true state")
        lines.append(f"| {label} | {fmt(ci[k], 1)} | {ci[k][0] / t:.2f}x | {ref} |")
    lines += [
        "",
        "The vergence embedding each body's program drives on (its last one; Procrustes mean ± standard error, "
        f"{scoring.HEADER} mean ± 95 % CI):",
        "",
        f"| body | Procrustes error | {scoring.HEADER} |",
        "|---|---|---|",
    ]
    for k in ("baseline-1.0", "baseline-1.4", "vertical"):
        lastemb = [r["embeddings"][-1] for r in res if r["kind"] == k and r["embeddings"]]
        errs = [float(e["procrustes_error"]) for e in lastemb if e.get("procrustes_error") is not None]
        lines.append(
            f"| {k} | {fmt(mean_se(errs), 4) if errs else 'n/a'} | {scoring.cell([e.get('scores') for e in lastemb])} |"
        )
    pairs = [("baseline-1.0", "baseline-1.4"), ("baseline-1.0", "vertical"), ("baseline-1.4", "vertical")]
    tests = {
        f"{a} vs {b}": float(stats.ttest_ind(finals[a], finals[b], equal_var=False).pvalue)
        if len(finals[a]) > 1 and len(finals[b]) > 1
        else float("nan")
        for a, b in pairs
    }
    lines += [
        "",
        "Bodies compared (Welch t-test p, no significant difference when > 0.05): "
        + ", ".join(f"{k}: p = {p:.2f}" for k, p in tests.items()),
    ]
    live = []
    for r in (r for r in res if r["kind"] == "live"):
        pre = [m for s, m in r["curve"] if s <= r["morph_at"]][-2:]
        before = float(np.mean(pre)) if pre else float("nan")
        drops = [d for d in r["drops"] if d >= r["morph_at"]]
        relearned = [e for e in r["embeddings"] if e["trigger"] == Trigger.RELEARNED]
        back = next(
            (
                s
                for s, m in r["curve"]
                if s > r["morph_at"] and relearned and s >= relearned[0]["training_steps"] and m <= 1.2 * before
            ),
            None,
        )
        live.append(
            {
                "seed": r["seed"],
                "before": before,
                "detected_after": (drops[0] - r["morph_at"]) if drops else None,
                "relearned_embedding": bool(relearned),
                "recovered_after": (back - r["morph_at"]) if back else None,
                "after": [m for s, m in r["curve"] if s > r["morph_at"]],
            }
        )
    lines += ["", f"Live body change, baseline 1.0 → 1.4 m after {morph_at} training steps (per run): "]
    for lv in live:
        lines.append(
            f"- seed {lv['seed']}: before {lv['before']:.1f} steps to goal; drop detected "
            f"{lv['detected_after']} training steps after the change; new embedding: {lv['relearned_embedding']}; "
            f"back within 20 % after {lv['recovered_after']} training steps; evaluations after: "
            f"{[round(m, 1) for m in lv['after']]}"
        )
    series = []
    for k in kinds:
        rs = [r for r in res if r["kind"] == k]
        xs = [s for s, _ in rs[0]["curve"]]
        series.append((k, xs, np.mean([[m for _, m in r["curve"]][: len(xs)] for r in rs], axis=0)))
    series.append(("random", [series[0][1][0], series[0][1][-1]], [ci["random"][0]] * 2))
    plot(
        out,
        "mountaincar_learning.png",
        "Mean steps to goal (Fig 8.2, 8.4)",
        "training car steps",
        "steps to goal",
        series,
        logy=True,
    )
    if live:
        plot(
            out,
            "mountaincar_live_morph.png",
            "Baseline 1.0 → 1.4 m while driving",
            "training car steps",
            "steps to goal",
            [
                (f"seed {r['seed']}", [s for s, _ in r["curve"]], [m for _, m in r["curve"]])
                for r in res
                if r["kind"] == "live"
            ],
            logy=True,
            vline=morph_at,
        )
    return {"results": res, "finals": finals, "ci95": ci, "welch_p": tests, "live": live, "markdown": "\n".join(lines)}


# --- `sme reproduce mountaincar-ablation`: where the embedding agent loses to the true-state agent --

#: each stage of the embedding agent and what replaces it with its true-state counterpart (one at a time);
#: "none" and "steps" are the same runs (the first `train` car steps of runs twice as long)
ABLATIONS: dict[str, str] = {
    "none": "none: the embedding agent as it ships",
    "position": "position: the true x (mapped affinely onto the embedding's axis) instead of the vergence reading",
    "velocity": "velocity: the true v (same map) instead of the Kalman filter's estimate",
    "tiles": "tile coding: the true-state agent's box (x in [-2, 2], abs(v) <= 0.07, mapped) instead of the embedding's",
    "steps": "training steps: twice as many, scored at the end of those",
    "state": "position and velocity both true (the tile box still the embedding's)",
}


def _ablated_program(world: Any, swap: str, seed: int, eval_every: int, **params: Any) -> Any:
    """The mountain-car program with stage `swap` given its true-state counterpart; the truth comes
    from `world` (in process), mapped onto the embedding's axis by the affine fit of the first
    embedding's coordinates to the sweep states' true x."""
    from sensorimotor.agent.programs.mountaincar import MountainCarProgram

    class Ablated(MountainCarProgram):
        def _make_driver(self, lo: float, hi: float) -> None:
            coords0 = self.reading.coords0
            assert coords0 is not None
            xs = world.starts[: self.n_positions, 0]
            self.map_a, self.map_b = (float(c) for c in np.polyfit(xs, coords0[:, 0], 1))
            super()._make_driver(lo, hi)
            if swap == "tiles":
                prm, a, b = world.car, self.map_a, self.map_b
                ends = sorted((a * prm.x_min + b, a * prm.x_max + b))
                vmax = abs(a) * prm.v_max
                coder = TileCoder(
                    [ends[0], -vmax], [ends[1], vmax], tiles=self.params.tiles, n_tilings=self.params.n_tilings
                )
                assert self.sarsa is not None
                self.sarsa = self._sarsa(coder, self.sarsa.seed)

        def _car_state(self, p: float, first: bool) -> np.ndarray:
            a, b = self.map_a, self.map_b
            if swap == "position":
                return super()._car_state(a * world.x + b, first)
            if swap == "state":
                return np.array([a * world.x + b, a * world.v])
            s = super()._car_state(p, first)
            if swap == "velocity":
                s[1] = a * world.v
            return s

    return lambda spec, seed=seed: Ablated(spec, seed=seed, eval_every=eval_every, **params)


def ablated(seed: int, swap: str, train: int, every: int, n_eval: int, baseline: float = 1.0) -> dict:
    """One seeded run of the embedding agent on `baseline` with stage `swap` swapped (ABLATIONS)."""
    from sensorimotor.tools.inprocess import run_inprocess
    from sensorimotor.worlds.mountaincar import MountainCarWorld

    if swap not in ABLATIONS:
        raise ValueError(f"unknown ablation {swap!r}; choose one of {', '.join(ABLATIONS)}")
    train = 2 * train if swap == "steps" else train
    world = MountainCarWorld(seed=seed, baseline=baseline, n_eval=n_eval)
    prog = _ablated_program(world, swap, seed, every)(world.spec())
    with world:
        run = run_inprocess(world, prog, 10**10, stop_when=lambda r: len(prog.curve) >= train // every)
    return {"swap": swap, "seed": seed, "curve": list(prog.curve), "world_steps": run.steps, "seconds": run.seconds}


def ablation(runs: int, quick: bool, workers: int, out: str, baseline: float = 1.0) -> dict:
    """Each stage of the embedding agent swapped for its true-state counterpart, one at a time, on
    the same seeds as the true-state agent; the steps to goal at the end (the mean of the last
    three evaluations, as the chapter scores) and what each swap closes of the gap."""
    train, every, n_eval = (20_000, 10_000, 20) if quick else (100_000, 10_000, 100)
    jobs: list[tuple[Any, ...]] = [(s, "steps", train, every, n_eval, baseline) for s in range(runs)]
    jobs += [
        (s, k, train, every, n_eval, baseline) for k in ABLATIONS if k not in ("none", "steps") for s in range(runs)
    ]
    res = pool_map(ablated, jobs, workers)
    true = [
        float(np.mean([m for _, m in r.curve[-3:]])) for r in (true_state(s, train, every, n_eval) for s in range(runs))
    ]

    def final(curve: list) -> float:  # the end of training: the mean of the last three evaluations
        return float(np.mean([m for _, m in curve[-3:]]))

    finals = {k: [final(r["curve"]) for r in res if r["swap"] == k] for k in ABLATIONS if k != "none"}
    finals["none"] = [final(r["curve"][: train // every]) for r in res if r["swap"] == "steps"]
    t = float(np.mean(true))
    gap = float(np.mean(finals["none"])) - t
    lines = [
        f"Mountain car ablation (ch. 8), baseline {baseline} m: {runs} seeded runs per row (seeds 0..{runs - 1}, "
        f"the same seeds in every row); {train} training car steps, evaluated every {every} on {n_eval} fixed "
        "random states; steps to goal at the end = the mean of the last three evaluations (lower is better). "
        "One stage at a time is given its true-state counterpart; 'paired' is the mean over seeds of "
        "(row - as shipped), with its 95 % CI. The as-shipped row is the first half of the twice-as-long runs "
        "(the same program and seed; seconds: those runs').",
        "",
        "| stage swapped for the true state | steps to goal at the end | vs true state | paired change vs as shipped "
        "| share of the gap closed | mean seconds per run |",
        "|---|---|---|---|---|---|",
    ]
    for k, label in ABLATIONS.items():
        diffs = np.array(finals[k]) - np.array(finals["none"])
        secs = np.mean([r["seconds"] for r in res if r["swap"] == ("steps" if k == "none" else k)])
        d = ci95(list(diffs)) if k != "none" else None
        share = f"{-float(np.mean(diffs)) / gap:.0%}" if k != "none" and gap > 0 else ""
        lines.append(
            f"| {label} | {fmt(ci95(finals[k]), 1)} | {np.mean(finals[k]) / t:.2f}x | "
            f"{fmt(d, 1) if d else ''} | {share} | {secs:.0f} |"
        )
    lines.append(f"| the true-state agent (Sarsa on (x, v) itself) | {fmt(ci95(true), 1)} | 1.00x |  |  |  |")
    return {"results": res, "finals": finals, "true": true, "markdown": "\n".join(lines)}
