"""`sme reproduce CHAPTER`: rerun a dissertation experiment, seeded, and write its table and plots.

Chapters: `gridworld` (ch. 5: Procrustes error per LSPI iteration, plain and barrier, random policy),
`retina` (ch. 4: saccade learning curves, lesion with the basic vs robust rule, reversal detected
by the agent itself), `vergence` (ch. 7: LSPI iterations to a perfect vergence policy and the
1-D depth map, on the PyBullet robot and on the Middlebury stereo pair), `mountaincar` (ch. 8:
steps-to-goal curves of the staged program on three bodies, against true-state and random agents,
and a baseline change while driving), `objectpose` (ch. 6: the generic program's embedding of
object pose against PCA and Isomap, Fig 6.3, and the alignment task of Fig 6.4), `rovingeye` (ch. 5.2:
Table 5.1, the five ways of making traces, Fig 5.8 scree and Fig 5.11 embeddings) and `chapter9`
(beyond the dissertation: probabilistic embedding in a slippery gridworld, option discovery,
mountain-car policy maps, Isomap and state-aided vergence traces); and `arm` (beyond the
dissertation: robot arms from URDFs against PCA and Isomap, and the body changes the agent notices
by itself). Runs go to worker processes
(spawned); results are written to
OUT/CHAPTER/results.json, table.md and PNG plots.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing as mp
import os
import shutil
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any, TypedDict

import numpy as np

from sensorimotor.protocol.messages import Trigger
from sensorimotor.tools.common import require
from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import scores_of


def _mean_se(x: list[float] | np.ndarray) -> tuple[float, float]:
    a = np.asarray(x, dtype=np.float64)
    return float(a.mean()), float(a.std(ddof=1) / np.sqrt(a.size)) if a.size > 1 else 0.0


def _fmt(ms: tuple[float, float], digits: int = 2) -> str:
    return f"{ms[0]:.{digits}f} ± {ms[1]:.{digits}f}"


def _known(x: float | None) -> float:
    """A Procrustes error that must exist (the world publishes its ground truth)."""
    if x is None:
        raise ValueError("an embedding has no Procrustes error: the world gave no ground truth")
    return float(x)


class _GridRow(TypedDict):
    case: str
    first: tuple[float, float]
    final: tuple[float, float]
    runs: int
    field: dict[str, tuple[float, float]]


# --- jobs (top-level functions: picklable for worker processes) ----------------------------------


def job_grid(seed: int, barrier: bool, steps: int, policy: str = "lspi") -> dict:
    from sensorimotor.agent.programs.gridworld import GridworldProgram
    from sensorimotor.tools.inprocess import run_inprocess
    from sensorimotor.worlds.gridworld import GridWorld

    w = GridWorld(seed=seed, barrier=barrier)
    p = GridworldProgram(w.spec(), seed=seed, policy=policy, samples_per_iteration=400 if policy == "lspi" else 50)
    run = run_inprocess(w, p, steps)
    return {
        "seed": seed,
        "barrier": barrier,
        "policy": policy,
        "errors": [_known(e) for e in run.errors],
        "scores": [scores_of(e) for e in run.embeddings],
    }


def job_learning(seed: int, steps: int, every: int, supersample: int) -> dict:
    from sensorimotor.tools.experiments import retina as R

    c = R.learning(seed, steps=steps, every=every, supersample=supersample)
    return {
        "seed": seed,
        "steps": c.steps,
        "one": c.one,
        "two": c.two,
        "activation": c.activation,
        "geometry": c.geometry,
    }


def job_lesion(seed: int, rule: str, at: int, steps: int, every: int, supersample: int) -> dict:
    from sensorimotor.tools.experiments import retina as R

    r = R.perturbation(
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
        "train_reward": R.moving_average(r.rewards, 200)[::every].tolist(),
    }


def job_reversal(seed: int, at: int, steps: int, supersample: int) -> dict:
    from sensorimotor.tools.experiments import retina as R

    r = R.perturbation(seed, "reverse", at=at, steps=steps, supersample=supersample)
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
        "relearn_episodes": R.relearn_episodes(r.rewards, at),
        "embeddings": embs,
        "reward_ma": R.moving_average(r.rewards, 200)[::50].tolist(),
    }


def job_retina(kind: str, *args: Any) -> dict:
    """One retina job of `sme reproduce retina` by name (one pool runs all three experiments)."""
    jobs: dict[str, Callable[..., dict]] = {"learning": job_learning, "lesion": job_lesion, "reversal": job_reversal}
    return jobs[kind](*args)


def job_vergence(seed: int, world: str, iterations: int) -> dict:
    import numpy as np

    from sensorimotor.agent.programs.vergence import VergenceProgram
    from sensorimotor.tools.inprocess import run_inprocess
    from sensorimotor.worlds.registry import make_world
    from sensorimotor.worlds.stereo_pair import StereoPairWorld
    from sensorimotor.worlds.vergence import VergenceWorld

    w = make_world(world, None, seed, {})
    if not isinstance(w, VergenceWorld | StereoPairWorld):
        raise TypeError(f"world {world!r} is not a vergence world (no perceptual goal)")
    goals = []
    for st in range(w.spec().n_starts):
        w.reset(start=st)
        goals.append(int(w.goal))
    world_truth = w.truth()
    if world_truth is None:
        raise ValueError(f"world {world!r} gives no ground truth")
    truth = np.asarray(world_truth.tensors["positions"][:, 0], dtype=np.float64)
    p = VergenceProgram(w.spec(), seed=seed)
    run = run_inprocess(w, p, 40000, stop_when=lambda r: len(r.embeddings) >= iterations)
    w.close()
    embs = run.embeddings
    first_perfect = next((i + 1 for i, e in enumerate(embs) if e.metrics["policy_success"] == 1.0), None)
    return {
        "seed": seed,
        "world": world,
        "errors": [e.procrustes_error for e in embs],
        "scores": [scores_of(e) for e in embs],
        "success": [e.metrics["policy_success"] for e in embs],
        "first_perfect_iteration": first_perfect,
        "goal_minus_truth": (np.array(goals) - truth).tolist()
        if world == "stereo"
        else (np.array(goals) - truth / 0.01).tolist(),
    }


def job_mountaincar(kind: str, seed: int, train: int, every: int, n_eval: int, morph_at: int | None = None) -> dict:
    from sensorimotor.tools.experiments import mountaincar as M

    if kind == "true":
        r = M.true_state(seed, train, every, n_eval)
    elif kind == "random":
        return {"kind": kind, "seed": seed, "curve": [(0, M.random_agent(seed, n_eval))]}
    elif kind == "live":
        if morph_at is None:
            raise ValueError("the live morph run needs morph_at")
        r = M.visual(
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
        r = M.visual(seed, train, every, n_eval, **body)
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


#: where `_pool_map` runs jobs: None = this machine's process pool, else a Ray cluster's address
#: (set by `--cluster` for one command; see `use_cluster`)
_CLUSTER: list[str | None] = [None]


@contextlib.contextmanager
def use_cluster(address: str | None) -> Iterator[None]:
    """Within the block, every chapter's jobs run on the Ray cluster at `address` (None: the local
    process pool)."""
    before = _CLUSTER[0]
    _CLUSTER[0] = address
    try:
        yield
    finally:
        _CLUSTER[0] = before


#: where `_pool_map` keeps each finished job's result (a folder, and whether to reuse what is there);
#: set by `sme reproduce all` for each chapter (see `job_cache`)
_JOBS: list[tuple[str, bool] | None] = [None]


@contextlib.contextmanager
def job_cache(folder: str, reuse: bool) -> Iterator[None]:
    """Within the block, `_pool_map` saves each job's result in `folder` as it finishes and, when
    `reuse`, takes the results already there instead of running those jobs again: a chapter cut
    short (hours of mountain car) goes on from its last finished job under `--resume`."""
    before = _JOBS[0]
    _JOBS[0] = (folder, reuse)
    try:
        yield
    finally:
        _JOBS[0] = before


def _job_path(folder: str, fn: Callable, job: tuple) -> str:
    import hashlib

    key = hashlib.sha1(f"{fn.__module__}.{fn.__qualname__}{job!r}".encode()).hexdigest()[:20]
    return os.path.join(folder, f"{fn.__name__}-{key}.pkl")


def _save_job(path: str, result: Any) -> None:
    import pickle

    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path + ".tmp", "wb") as f:
        pickle.dump(result, f)
    os.replace(path + ".tmp", path)  # a run killed while writing leaves no half a result


def _pool_map(fn: Callable, jobs: list[tuple], workers: int) -> list[Any]:
    """``[fn(*job) for job in jobs]`` in job order: on the Ray cluster of `use_cluster`, else in
    `workers` spawned processes (in this process when 1). Jobs are seeded by their arguments, so
    every way gives the same results. Under `job_cache`, finished jobs are kept (and reused)."""
    import pickle

    results: list[Any] = [None] * len(jobs)
    cache = _JOBS[0]
    paths = [_job_path(cache[0], fn, j) for j in jobs] if cache else []
    todo = list(range(len(jobs)))
    if cache and cache[1]:
        for i in list(todo):
            try:
                with open(paths[i], "rb") as f:
                    results[i] = pickle.load(f)
                todo.remove(i)
            except (OSError, pickle.UnpicklingError, EOFError):
                pass
        if len(todo) < len(jobs):
            print(
                f"    {len(jobs) - len(todo)}/{len(jobs)} jobs kept from the earlier run", file=sys.stderr, flush=True
            )

    def finished(i: int, r: Any) -> None:
        results[i] = r
        if cache:
            _save_job(paths[i], r)
        progress.done()

    progress = _Progress(len(todo))
    if not todo:
        return results
    if _CLUSTER[0] is not None:
        from sensorimotor.tools.ray_map import ray_map

        for i, r in zip(todo, ray_map(fn, [jobs[i] for i in todo], _CLUSTER[0]), strict=True):
            finished(i, r)
        return results
    if workers <= 1:
        for i in todo:
            finished(i, fn(*jobs[i]))
        return results
    with mp.get_context("spawn").Pool(workers) as pool:
        # one job at a time (chunksize 1): a chunk of several long jobs left one core idle at the end
        # of a chapter; results come back as they finish (for the progress) and are put in job order
        for i, r in pool.imap_unordered(_indexed, [(fn, i, jobs[i]) for i in todo], chunksize=1):
            finished(i, r)
    return results


def _indexed(task: tuple[Callable, int, tuple]) -> tuple[int, Any]:
    fn, i, job = task
    return i, fn(*job)


class _Progress:
    """A line on stderr as a chapter's jobs finish (at most one per 20 s, and the last): a long run is
    seen to move, with the time to go at the pace so far."""

    def __init__(self, total: int, every: float = 20.0) -> None:
        self.total, self.every, self.n = total, every, 0
        self.t0 = self.last = time.time()

    def done(self) -> None:
        self.n += 1
        now = time.time()
        if now - self.last < self.every and self.n < self.total:
            return
        self.last = now
        spent = now - self.t0
        left = spent / self.n * (self.total - self.n)
        print(
            f"    {self.n}/{self.total} jobs done, {spent:.0f} s, about {left:.0f} s to go", file=sys.stderr, flush=True
        )


# --- chapters ------------------------------------------------------------------------------------


def gridworld(runs: int, quick: bool, workers: int, out: str) -> dict:
    steps = 8000 if quick else 20000
    jobs = [(s, b, steps) for b in (False, True) for s in range(runs)] + [
        (s, False, 10000, "random") for s in range(runs)
    ]
    res = _pool_map(job_grid, jobs, workers)
    table: list[_GridRow] = []
    cells: dict[str, str] = {}
    for name, sel in (
        ("plain", lambda r: not r["barrier"] and r["policy"] == "lspi"),
        ("barrier", lambda r: r["barrier"]),
        ("random policy", lambda r: r["policy"] == "random"),
    ):
        rs = [r for r in res if sel(r)]
        final = [r["errors"][-1] for r in rs]
        first = [r["errors"][0] for r in rs]
        last = [r["scores"][-1] for r in rs]
        table.append(
            {
                "case": name,
                "first": _mean_se(first),
                "final": _mean_se(final),
                "runs": len(rs),
                "field": scoring.summary(last),
            }
        )
        cells[name] = scoring.cell(last)
    lines = [
        f"Gridworld (ch. 5): Procrustes error mean ± standard error; {scoring.HEADER} of the final embedding "
        "mean ± 95 % CI.",
        "",
        f"| case | Procrustes error, first embedding | final | {scoring.HEADER}, final | runs |",
        "|---|---|---|---|---|",
    ]
    lines += [
        f"| {t['case']} | {_fmt(t['first'], 4)} | {_fmt(t['final'], 4)} | {cells[t['case']]} | {t['runs']} |"
        for t in table
    ]
    _plot(
        out,
        "gridworld_lspi.png",
        "Procrustes error per LSPI iteration (Fig 5.4)",
        "LSPI iteration",
        "Procrustes error",
        [
            (
                f"{'barrier' if r['barrier'] else 'plain'} seed {r['seed']}",
                list(range(1, len(r["errors"]) + 1)),
                r["errors"],
            )
            for r in res
            if r["policy"] == "lspi"
        ],
        logy=True,
    )
    return {"results": res, "table": table, "markdown": "\n".join(lines)}


def retina(runs: int, quick: bool, workers: int, out: str, supersample: int = 2) -> dict:
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
    done = _pool_map(job_retina, jobs, workers)
    reversal, lesion, learning = done[:runs], done[runs : 3 * runs], done[3 * runs :]

    one = _mean_se([r["one"][-1] for r in learning])
    two = _mean_se([r["two"][-1] for r in learning])
    geo0 = _mean_se([r["geometry"][0] for r in learning])
    geo = _mean_se([r["geometry"][-1] for r in learning])
    end = {
        rule: _mean_se([np.mean(r["activation"][-4:]) for r in lesion if r["rule"] == rule])
        for rule in ("basic", "robust")
    }
    post = {
        rule: _mean_se(
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
        f"| 1-saccade error after {L['steps']} steps (px) | {_fmt(one)} | about 5 |",
        f"| 2-saccade error after {L['steps']} steps (px) | {_fmt(two)} | lower than 1 saccade |",
        f"| E_geometry (px), start → after {L['steps']} steps | {_fmt(geo0)} → {_fmt(geo)} | falls with training |",
        f"| lesion at {les['at']}: greedy post-saccade activation at the end, basic rule | {_fmt(end['basic'], 1)} | does not adapt |",
        f"| lesion at {les['at']}: same, robust rule | {_fmt(end['robust'], 1)} | recovers |",
        f"| lesion: mean activation over all post-lesion evaluations, basic / robust | {_fmt(post['basic'], 1)} / {_fmt(post['robust'], 1)} | |",
        f"| reversal at {rev['at']}: detection delay (saccades), per run | {delays} | about 1000 |",
        f"| reversal: saccades to 90 % of pre-reversal reward, per run | {relearn} | |",
        f"| reversal: a 'relearned' embedding was published, per run | {relearned} | |",
        f"| reversal: last embedding's Procrustes error | {_fmt(_mean_se(last_err), 4)} | |",
        f"| reversal: last embedding's {scoring.HEADER} (95 % CI) | {scoring.cell(last_scores)} | |",
    ]
    xs = learning[0]["steps"]
    _plot(
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
    _plot(
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
    _plot(
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


def _plot(
    out: str, name: str, title: str, xlabel: str, ylabel: str, series, logy: bool = False, vline: float | None = None
) -> None:
    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for label, x, y in series:
        ax.plot(x, y, label=label, lw=1.2)
    if vline is not None:
        ax.axvline(vline, color="k", ls="--", lw=0.8)
    if logy:
        ax.set_yscale("log")
    ax.set(title=title, xlabel=xlabel, ylabel=ylabel)
    if len(series) <= 12:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=110)
    plt.close(fig)


def vergence(runs: int, quick: bool, workers: int, out: str) -> dict:
    iters = 5 if quick else 12
    res = _pool_map(job_vergence, [(s, w, iters) for w in ("vergence", "stereo") for s in range(runs)], workers)
    lines = [
        f"Vergence (ch. 7): {runs} seeded runs; Procrustes error mean ± standard error, {scoring.HEADER} "
        "mean ± 95 % CI, both of the last embedding.",
        "",
        "| world | first perfect LSPI iteration (per run) | Procrustes error of the last embedding | "
        f"{scoring.HEADER} | matching minimum vs truth | dissertation |",
        "|---|---|---|---|---|---|",
    ]
    for w, ref in (
        ("vergence", "perfect in 9 iterations; Procrustes 0.0257"),
        ("stereo", "within 2 px; Procrustes 0.0003"),
    ):
        rs = [r for r in res if r["world"] == w]
        diff = np.abs(np.array(rs[0]["goal_minus_truth"]))
        unit = "px" if w == "stereo" else "steps of 0.01 rad"
        match = f"{(diff <= 2).mean() * 100:.0f} % within 2 {unit}, max {diff.max():.1f}"
        lines.append(
            f"| {w} | {[r['first_perfect_iteration'] for r in rs]} | {_fmt(_mean_se([r['errors'][-1] for r in rs]), 4)} "
            f"| {scoring.cell([r['scores'][-1] for r in rs])} | {match} | {ref} |"
        )
    _plot(
        out,
        "vergence_lspi.png",
        "Procrustes error per LSPI iteration (ch. 7)",
        "LSPI iteration",
        "Procrustes error",
        [(f"{r['world']} seed {r['seed']}", list(range(1, len(r["errors"]) + 1)), r["errors"]) for r in res],
        logy=True,
    )
    return {"results": res, "markdown": "\n".join(lines)}


def _ci95(x: list[float]) -> tuple[float, float]:
    from scipy import stats

    a = np.asarray(x, dtype=np.float64)
    if a.size < 2:
        return float(a.mean()), 0.0
    return float(a.mean()), float(stats.t.ppf(0.975, a.size - 1) * a.std(ddof=1) / np.sqrt(a.size))


def mountaincar(runs: int, quick: bool, workers: int, out: str) -> dict:
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
    res = _pool_map(job_mountaincar, jobs, workers)

    def final(r: dict) -> float:  # the end of training: the mean of the last three evaluations
        return float(np.mean([m for _, m in r["curve"][-3:]]))

    finals = {k: [final(r) for r in res if r["kind"] == k] for k in kinds + ("random",)}
    ci = {k: _ci95(v) for k, v in finals.items()}
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
        lines.append(f"| {label} | {_fmt(ci[k], 1)} | {ci[k][0] / t:.2f}x | {ref} |")
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
            f"| {k} | {_fmt(_mean_se(errs), 4) if errs else 'n/a'} | {scoring.cell([e.get('scores') for e in lastemb])} |"
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
    _plot(
        out,
        "mountaincar_learning.png",
        "Mean steps to goal (Fig 8.2, 8.4)",
        "training car steps",
        "steps to goal",
        series,
        logy=True,
    )
    if live:
        _plot(
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


def rovingeye(runs: int, quick: bool, workers: int, out: str) -> dict:
    from sensorimotor.tools.experiments.rovingeye import chapter

    return chapter(runs, quick, workers, out)


def objectpose(runs: int, quick: bool, workers: int, out: str) -> dict:
    from sensorimotor.tools.experiments.objectpose import chapter

    return chapter(runs, quick, workers, out)


def chapter9(runs: int, quick: bool, workers: int, out: str) -> dict:
    from sensorimotor.tools.experiments.chapter9 import chapter9 as run

    return run(runs, quick, workers, out)


def arm(runs: int, quick: bool, workers: int, out: str) -> dict:
    from sensorimotor.tools.experiments.arm import chapter

    return chapter(runs, quick, workers, out)


CHAPTERS = {
    "arm": arm,
    "gridworld": gridworld,
    "retina": retina,
    "vergence": vergence,
    "mountaincar": mountaincar,
    "objectpose": objectpose,
    "rovingeye": rovingeye,
    "chapter9": chapter9,
}


def retina_natural(runs: int, quick: bool, workers: int, out: str) -> dict:
    from sensorimotor.tools.experiments.retina_natural import chapter

    return chapter(runs, quick, workers, out)


#: the chapters of `sme reproduce all`, in the dissertation's order (4, 4 natural, 5, 5.2, 6, 7, 8, 9)
ALL: dict[str, Callable[[int, bool, int, str], dict]] = {
    "retina": retina,
    "retina-natural": retina_natural,
    "gridworld": gridworld,
    "rovingeye": rovingeye,
    "objectpose": objectpose,
    "vergence": vergence,
    "mountaincar": mountaincar,
    "chapter9": chapter9,
}


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reproduce",
        help="rerun a dissertation experiment (gridworld, retina, vergence, mountaincar, objectpose, rovingeye, "
        "chapter9), or all of them into one report; `arm`: robot arms from URDFs and their body changes",
        description=__doc__
        + "\n`all` runs every chapter (retina, retina-natural, gridworld, rovingeye, objectpose, vergence, mountaincar, "
        "chapter9) and writes OUT/report.md and OUT/report.html: each claim of the dissertation beside ours with a "
        "95 % CI and a verdict; a chapter that fails is reported and the others still run.",
    )
    p.add_argument("chapter", choices=sorted(CHAPTERS) + ["all"], help="which experiment, or all")
    p.add_argument("--runs", type=int, default=10, help="seeded runs per condition (default 10)")
    p.add_argument("--quick", action="store_true", help="shortened runs, for a first look (about a minute)")
    p.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1), help="worker processes")
    p.add_argument("--out", default="out", help="output folder (default ./out)")
    p.add_argument(
        "--cluster",
        default=None,
        metavar="ADDRESS",
        help="run the seeded jobs as tasks on the Ray cluster at ADDRESS (HOST:PORT of its head, ray://HOST:10001, "
        "or auto; needs the 'cluster' extra); default: --workers local processes",
    )
    p.add_argument(
        "--scene",
        choices=("wall", "natural"),
        default="wall",
        help="retina only: the dark wall with a spot (ch. 4, default) or a natural picture (Table 4.1)",
    )
    p.add_argument(
        "--chapters",
        default=None,
        metavar="LIST",
        help=f"all only: the chapters to run, comma-separated (default every one: {','.join(ALL)})",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="all only: keep the chapters an earlier run into --out finished (same --runs and --quick) and run the "
        "rest; a long run cut short goes on from where it stopped",
    )
    p.add_argument(
        "--report-only",
        action="store_true",
        help="all only: run nothing; judge the results.json already in --out again and rewrite the report",
    )
    p.set_defaults(func=main_args)


def _run_chapter(
    name: str, fn: Callable[[int, bool, int, str], dict], args: argparse.Namespace
) -> tuple[dict, str, float]:
    """Run one chapter into OUT/NAME (results.json, table.md, plots); return its result, folder and seconds."""
    out = os.path.join(args.out, name)
    os.makedirs(out, exist_ok=True)
    t0, cpu0 = time.time(), cpu_seconds()
    jobs = os.path.join(out, "jobs")
    with use_cluster(getattr(args, "cluster", None)), job_cache(jobs, bool(getattr(args, "resume", False))):
        res = fn(args.runs, args.quick, args.workers, out)
    res.setdefault("cpu_seconds", cpu_seconds() - cpu0)
    with open(os.path.join(out, "results.json"), "w") as f:
        json.dump(res, f, default=float)
    with open(os.path.join(out, "table.md"), "w") as f:
        f.write(res["markdown"] + "\n")
    shutil.rmtree(jobs, ignore_errors=True)  # the chapter's results.json holds them now
    return res, out, time.time() - t0


def cpu_seconds() -> float:
    """CPU time (user + system) of this process and of its finished worker processes: a chapter's
    cost apart from how busy the machine is (its wall time on idle cores is about this / workers)."""
    import resource

    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def _where(args: argparse.Namespace) -> str:
    cluster = getattr(args, "cluster", None)
    return f"{args.workers} workers" if cluster is None else f"Ray cluster {cluster}"


def _header(
    args: argparse.Namespace, names: list[str], chapters: list[Any], total: float | None, sittings: int = 1
) -> dict[str, str]:
    from sensorimotor.tools import report

    env = report.environment(os.path.dirname(os.path.abspath(__file__)))

    def secs(x: float | None) -> str:
        return "?" if x is None or x != x else f"{x:.0f} s"

    return {
        "command": f"sme reproduce all --runs {args.runs}{' --quick' if args.quick else ''}"
        + (f" --chapters {','.join(names)}" if getattr(args, "chapters", None) else ""),
        "seeds": f"0..{args.runs - 1} per condition"
        + (" (chapter9 --quick: at most 5)" if "chapter9" in names else ""),
        "wall time": ("?" if total is None else f"{total:.0f} s ({total / 60:.1f} min)")
        + (f" in {sittings} sittings (--resume; the sum of the chapters' times)" if sittings > 1 else "")
        + ", "
        + ", ".join(f"{c.name} {secs(c.seconds)}" for c in chapters),
        "executed on": _where(args),
        "machine": f"{env.pop('host', '?')}, {env.pop('platform', '?')}, {env.pop('cpus', '?')} CPUs",
        "versions": ", ".join(f"{k} {v}" for k, v in env.items()),
    }


def _chapter_report(name: str, res: dict, out: str, seconds: float, quick: bool) -> Any:
    import glob

    from sensorimotor.tools import report

    rows = report.chapter_rows(name, res, quick)
    figures = sorted(glob.glob(os.path.join(out, "*.png")))
    return report.ChapterReport(
        name, report.CHAPTER_ROWS[name][0], seconds, rows, figures, table=res.get("markdown", "")
    )


def _names(args: argparse.Namespace) -> list[str] | None:
    names = list(ALL) if not getattr(args, "chapters", None) else [c.strip() for c in args.chapters.split(",")]
    unknown = [c for c in names if c not in ALL]
    if unknown or not names:
        print(f"sme reproduce: unknown chapter(s) {', '.join(unknown)}; valid: {', '.join(ALL)}", file=sys.stderr)
        return None
    return names


def report_only(args: argparse.Namespace) -> int:
    """`sme reproduce all --report-only`: judge the chapters' results.json in OUT again and rewrite the
    report (wall times from OUT/run.json when the run wrote one, else unknown)."""
    from sensorimotor.tools import report

    names = _names(args)
    if names is None:
        return 2
    meta: dict[str, Any] = {}
    if os.path.exists(os.path.join(args.out, "run.json")):
        with open(os.path.join(args.out, "run.json")) as f:
            meta = json.load(f)
    chapters = []
    for name in names:
        out = os.path.join(args.out, name)
        info = meta.get("chapters", {}).get(name, {})
        seconds = info.get("seconds", float("nan"))
        if info.get("error"):
            chapters.append(report.ChapterReport(name, report.CHAPTER_ROWS[name][0], seconds, error=info["error"]))
            continue
        try:
            with open(os.path.join(out, "results.json")) as f:
                res = json.load(f)
        except (OSError, ValueError) as e:
            chapters.append(
                report.ChapterReport(name, report.CHAPTER_ROWS[name][0], seconds, error=f"no results to judge: {e}")
            )
            continue
        chapters.append(_chapter_report(name, res, out, seconds, args.quick))
    md, page = report.write_report(
        chapters, _header(args, names, chapters, meta.get("total"), int(meta.get("sittings", 1))), args.out
    )
    print(f"{md} and {page} rewritten from the results in {args.out}/")
    return 0


def _earlier_run(out: str, settings: dict[str, Any]) -> dict[str, Any] | None:
    """The run.json of the run `--resume` continues, or None (and why, on stderr) when it cannot."""
    path = os.path.join(out, "run.json")
    if not os.path.exists(path):
        return {}  # nothing to keep: a fresh run
    try:
        with open(path) as f:
            earlier = json.load(f)
    except (OSError, ValueError) as e:
        print(f"sme reproduce: --resume cannot read {path}: {e}", file=sys.stderr)
        return None
    if earlier.get("settings") != settings:
        was = earlier.get("settings") or "unrecorded settings"
        print(
            f"sme reproduce: --resume: {out}/ holds a run with {was}, not {settings}; rerun with the same "
            "--runs/--quick, or give another --out",
            file=sys.stderr,
        )
        return None
    return dict(earlier)


def _kept_chapter(out: str, name: str, info: dict[str, Any] | None) -> dict | None:
    """A chapter's results.json from the earlier run, when that run finished it; else None (run it again)."""
    if not info or info.get("error"):
        return None
    try:
        with open(os.path.join(out, name, "results.json")) as f:
            res = json.load(f)
    except (OSError, ValueError):
        return None
    return res if isinstance(res, dict) and "markdown" in res else None


def main_all(args: argparse.Namespace) -> int:
    """`sme reproduce all`: every chapter in turn (a failure is recorded and the rest run), then the report."""
    import traceback

    from sensorimotor.tools import report

    if getattr(args, "report_only", False):
        return report_only(args)
    names = _names(args)
    if names is None:
        return 2
    os.makedirs(args.out, exist_ok=True)
    t_all = time.time()
    settings = {"runs": args.runs, "quick": bool(args.quick)}
    meta: dict[str, Any] = {"chapters": {}, "total": None, "settings": settings, "sittings": 1}
    if getattr(args, "resume", False):
        earlier = _earlier_run(args.out, settings)
        if earlier is None:
            return 2
        meta["chapters"] = {k: v for k, v in earlier.get("chapters", {}).items() if not v.get("error")}
        if earlier:  # a fresh folder under --resume is the first sitting
            meta["sittings"] = int(earlier.get("sittings", 1)) + 1
    print(
        f"sme reproduce all: {len(names)} chapters, {args.runs} runs each{' (quick)' if args.quick else ''}, "
        f"{_where(args)}, writing {args.out}/ ...",
        flush=True,
    )
    chapters: list[report.ChapterReport] = []
    kept_seconds = 0.0

    def save_meta() -> None:  # after every chapter: a run cut short still leaves its times
        with open(os.path.join(args.out, "run.json"), "w") as f:
            json.dump(meta, f)

    for i, name in enumerate(names, 1):
        title = report.CHAPTER_ROWS[name][0]
        kept = _kept_chapter(args.out, name, meta["chapters"].get(name))
        if kept is not None:
            seconds = meta["chapters"][name]["seconds"]
            kept_seconds += seconds
            chapters.append(_chapter_report(name, kept, os.path.join(args.out, name), seconds, args.quick))
            print(f"[{i}/{len(names)}] {name}: kept from the earlier run ({seconds:.0f} s then)", flush=True)
            continue
        meta["chapters"].pop(name, None)
        print(f"[{i}/{len(names)}] {name}: {title} ...", flush=True)
        t0 = time.time()
        try:
            res, out, seconds = _run_chapter(name, ALL[name], args)
        except Exception:  # one chapter's failure must not lose the others: it goes into the report
            err = traceback.format_exc()
            chapters.append(report.ChapterReport(name, title, time.time() - t0, error=err))
            meta["chapters"][name] = {"seconds": time.time() - t0, "error": err}
            save_meta()
            print(
                f"[{i}/{len(names)}] {name} FAILED after {time.time() - t0:.0f} s: {err.strip().splitlines()[-1]}",
                flush=True,
            )
            continue
        chapters.append(_chapter_report(name, res, out, seconds, args.quick))
        meta["chapters"][name] = {"seconds": seconds, "cpu_seconds": res.get("cpu_seconds"), "error": None}
        save_meta()
        rows = chapters[-1].rows
        verdicts = ", ".join(
            f"{sum(r.verdict == v for r in rows)} {v}" for v in (report.MET, report.NOT_MET, report.NOT_COMPARABLE)
        )
        print(
            f"[{i}/{len(names)}] {name} done in {seconds:.0f} s ({res['cpu_seconds']:.0f} s of CPU): {verdicts}",
            flush=True,
        )
    total = time.time() - t_all + kept_seconds
    meta["total"] = total
    save_meta()
    md, page = report.write_report(chapters, _header(args, names, chapters, total, meta["sittings"]), args.out)
    print(f"\n({total:.0f} s; {md} and {page})")
    return 1 if any(c.error for c in chapters) else 0


def main_args(args: argparse.Namespace) -> int:
    if args.runs < 1 or args.workers < 1:
        print("sme reproduce: --runs and --workers must be >= 1", file=sys.stderr)
        return 2
    require("matplotlib")  # the plots need it: say so now, not after the runs
    if getattr(args, "cluster", None) is not None:
        require("ray", package="ray", extra="cluster")  # say so now, not after the first chapter's set-up
    scene = getattr(args, "scene", "wall")
    if scene != "wall" and args.chapter != "retina":
        print("sme reproduce: --scene applies to the retina chapter only", file=sys.stderr)
        return 2
    only_all = ("chapters", "report_only", "resume")
    if any(getattr(args, k, None) for k in only_all) and args.chapter != "all":
        print("sme reproduce: --chapters, --resume and --report-only apply to `all` only", file=sys.stderr)
        return 2
    if args.chapter == "all":
        return main_all(args)
    chapter_fn = CHAPTERS[args.chapter]
    name = args.chapter
    if scene == "natural":
        chapter_fn, name = retina_natural, "retina-natural"
    print(
        f"sme reproduce {name}: {args.runs} runs{' (quick)' if args.quick else ''}, {_where(args)}, "
        f"writing {os.path.join(args.out, name)}/ ...",
        flush=True,
    )
    res, out, seconds = _run_chapter(name, chapter_fn, args)
    print(res["markdown"])
    print(f"\n({seconds:.0f} s; table.md, results.json and PNG plots in {out}/)")
    return 0


if __name__ == "__main__":
    sys.exit(main_args(argparse.Namespace()))
