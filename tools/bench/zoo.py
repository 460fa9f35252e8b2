"""`sme bench zoo`: the generic program on worlds nobody here wrote (Gymnasium toy text, classic
control, MiniGrid, panda-gym) and on arms of 6 and 7 joints, in-process and seeded. Per world and seed: final and best Procrustes
error of the embeddings against the declared truth, trustworthiness of the final one, the fraction
of starts whose greedy trace reached the goal, steps and seconds to the first embedding below 0.1,
whether any version after convergence was over 1.5x worse than the best before it without a detected
drop (and the worst ratio of a version to the best before it, after convergence), drops detected in
a run with no perturbation (false alarms: nothing here perturbs the world), how many missed starts
were doubted and run once more before counting, and beside them the sensor-only peers (PCA and
Isomap of the start observations, as ch. 6 does)."""

from __future__ import annotations

import argparse
import json
import sys
import time
import warnings
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import EventKind
from sensorimotor.tools.bench.ceiling import toy_text_ceiling
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.registry import make_world


@dataclass(frozen=True)
class ZooWorld:
    """One zoo entry: the world name, its parameters, program parameters and step budget."""

    label: str
    world: str
    params: dict[str, Any] = field(default_factory=dict)
    program: dict[str, str] = field(default_factory=dict)
    steps: int = 100_000
    quick_steps: int = 20_000
    needs: str = ""  # a module the world needs (skipped, and said, when missing)


def _random_lake(seed: int) -> tuple[str, ...]:
    """Gymnasium's random 10 x 10 FrozenLake map of `seed` (p = 0.8 frozen)."""
    from gymnasium.envs.toy_text.frozen_lake import generate_random_map

    return tuple(generate_random_map(size=10, p=0.8, seed=seed))


def _lakes() -> tuple[ZooWorld, ...]:
    return tuple(
        ZooWorld(
            f"FrozenLake random 10x10 (map {s}){'' if slip else ', not slippery'}",
            "gym:FrozenLake-v1",
            {"desc": list(_random_lake(s)), "is_slippery": str(slip).lower()},
            {},
            100_000,
            30_000,
        )
        for slip in (False, True)
        for s in (0, 1, 2)
    )


def _arms() -> tuple[ZooWorld, ...]:
    """Arms commanded in 6 and 7 joints (`sme world arm`, docs/arm.md): 128 sampled start poses each,
    the joints' angles served beside the camera (the arm world's default from 5 joints)."""
    return (
        ZooWorld("Arm Kuka iiwa, 7 joints", "arm", {"n_joints": "7"}, {}, 30_000, 12_000),
        ZooWorld("Arm xArm6, 6 joints", "arm", {"urdf": "xarm/xarm6_robot.urdf", "n_joints": "6"}, {}, 20_000, 12_000),
    )


ZOO: tuple[ZooWorld, ...] = (
    ZooWorld("FrozenLake 8x8", "gym:FrozenLake-v1", {"map_name": "8x8", "is_slippery": "false"}, {}, 50_000, 10_000),
    ZooWorld("FrozenLake 4x4 slippery", "gym:FrozenLake-v1", {}, {}, 60_000, 20_000),
    ZooWorld("FrozenLake 4x4 slippery, mean estimator", "gym:FrozenLake-v1", {}, {"estimator": "mean"}, 60_000, 20_000),
    ZooWorld(
        "FrozenLake 4x4 slippery, mean trace",
        "gym:FrozenLake-v1",
        {},
        {"estimator": "mean_trace", "samples": "64"},
        100_000,
        30_000,
    ),
    ZooWorld(
        "FrozenLake 4x4 slippery, plain estimator", "gym:FrozenLake-v1", {}, {"estimator": "plain"}, 60_000, 20_000
    ),
    ZooWorld("CliffWalking", "gym:CliffWalking-v1", {}, {}, 50_000, 10_000),
    # Gymnasium's own defaults of the 8x8 lake (slippery) and a slippery cliff: tried as a new user would
    ZooWorld("FrozenLake 8x8 slippery", "gym:FrozenLake-v1", {"map_name": "8x8"}, {}, 100_000, 30_000),
    ZooWorld("CliffWalking slippery", "gym:CliffWalking-v1", {"is_slippery": "true"}, {}, 100_000, 30_000),
    ZooWorld("MiniGrid Empty 8x8", "gym:MiniGrid-Empty-8x8-v0", {}, {}, 60_000, 20_000, "minigrid"),
    ZooWorld("MiniGrid Empty 16x16", "gym:MiniGrid-Empty-16x16-v0", {}, {}, 100_000, 30_000, "minigrid"),
    ZooWorld("MiniGrid LavaGap S7", "gym:MiniGrid-LavaGapS7-v0", {}, {}, 100_000, 30_000, "minigrid"),
    ZooWorld("MiniGrid SimpleCrossing S9N1", "gym:MiniGrid-SimpleCrossingS9N1-v0", {}, {}, 100_000, 30_000, "minigrid"),
    ZooWorld("MiniGrid FourRooms", "gym:MiniGrid-FourRooms-v0", {}, {}, 100_000, 30_000, "minigrid"),
    ZooWorld("MountainCar", "gym:MountainCar-v0", {}, {}, 100_000, 30_000),
    ZooWorld("MountainCarContinuous", "gym:MountainCarContinuous-v0", {}, {}, 100_000, 30_000),
    ZooWorld("MountainCarContinuous, DTW", "gym:MountainCarContinuous-v0", {}, {"distance": "dtw"}, 100_000, 30_000),
    ZooWorld("PandaReach (state)", "gym:panda_gym:PandaReach-v3", {}, {}, 60_000, 15_000, "panda_gym"),
    ZooWorld(
        "PandaReach (state), net move, half moves",
        "gym:panda_gym:PandaReach-v3",
        {},
        {"distance": "net", "action_scale": "0.5"},
        60_000,
        15_000,
        "panda_gym",
    ),
    ZooWorld(
        "PandaReach (pixels)", "gym:panda_gym:PandaReach-v3", {"observe": "pixels"}, {}, 60_000, 10_000, "panda_gym"
    ),
    ZooWorld(
        "PandaReach (pixels), half moves, whole-move warm-up",
        "gym:panda_gym:PandaReach-v3",
        {"observe": "pixels"},
        {"distance": "net", "action_scale": "0.5", "motor_scale": "1"},
        60_000,
        10_000,
        "panda_gym",
    ),
    *_lakes(),
    *_arms(),
)


def _trustworthiness(truth: np.ndarray, coords: np.ndarray) -> float | None:
    try:
        from sklearn.manifold import trustworthiness
    except ImportError:  # the experiments extra
        return None
    k = max(1, min(5, (len(truth) - 1) // 2 - 1))
    return float(trustworthiness(truth, coords, n_neighbors=k)) if len(truth) > 2 * k + 1 else None


def sensor_peers(world: Any, dims: int) -> dict[str, float | None]:
    """PCA and Isomap (best of a few neighbourhood sizes) of the observations at the start states."""
    truth = world.truth()
    if truth is None:
        return {"pca_error": None, "isomap_error": None}
    from sklearn.decomposition import PCA
    from sklearn.manifold import Isomap

    spec = world.spec()
    rows = []
    for i in range(spec.n_starts):
        r = world.reset(start=i)
        rows.append(np.concatenate([np.asarray(r.tensors[s.name], dtype=np.float64).reshape(-1) for s in spec.sensors]))
    X = np.array(rows)
    X = X + 1e-9 * np.random.default_rng(0).standard_normal(X.shape)  # identical rows would break Isomap
    pos = np.asarray(truth.tensors["positions"], dtype=np.float64)
    d = min(dims, X.shape[1])
    out: dict[str, float | None] = {"pca_error": procrustes_error(pos, PCA(n_components=d).fit_transform(X))}
    best = None
    for k in (4, 6, 8, 12):
        if k < X.shape[0]:
            with warnings.catch_warnings():  # a neighbour graph in pieces is completed, and says so at length
                warnings.simplefilter("ignore")
                try:
                    e = procrustes_error(pos, Isomap(n_neighbors=k, n_components=d).fit_transform(X))
                except ValueError:
                    continue
            best = e if best is None else min(best, e)
    out["isomap_error"] = best
    return out


def post_convergence(embs: list[Any], drops: list[int]) -> tuple[int, float | None]:
    """After convergence (the first version that reached the goal from >= 90 % of starts, or that
    the program published while it watched its policy as converged: a stochastic world's best policy
    may reach fewer): how many versions were more than 1.5x worse than the best before them, and the
    worst such ratio (version error / best error before it), leaving out versions that follow a
    detected drop."""
    regressions, worst = 0, None
    best = None
    converged = False
    for e in embs:
        m = e.metrics
        converged = converged or m.get("goal_reached_fraction", 0.0) >= 0.9 or m.get("watched", 0.0) == 1.0
        err = float(e.procrustes_error or 0.0)
        if converged and best is not None and not any(d < e.step for d in drops):
            ratio = err / max(best, 1e-9)
            worst = ratio if worst is None else max(worst, ratio)
            regressions += int(err > 1.5 * best + 1e-9)
        best = err if best is None else min(best, err)
    return regressions, worst


def run_one(z: ZooWorld, seed: int, steps: int) -> dict[str, Any]:
    """One seeded in-process run of entry `z`."""
    with make_world(z.world, None, seed, z.params) as w:
        spec = w.spec()
        program = make_program(spec, seed, **z.program)
        detector = make_detector("cusum", **program.detector_params)
        first: dict[str, float] = {}
        t0 = time.perf_counter()

        def seen(msg: Any) -> None:
            e = getattr(msg, "procrustes_error", None)
            if e is not None and e < 0.1 and "step" not in first:
                first.update(step=float(msg.step), seconds=time.perf_counter() - t0)

        run = run_inprocess(w, program, steps, detector=detector, on_output=seen)
        seconds = time.perf_counter() - t0
        embs = [e for e in run.embeddings if e.procrustes_error is not None]
        peers = sensor_peers(w, program.dims if hasattr(program, "dims") else 2) if embs else {}
        truth = w.truth()
        ceiling = toy_text_ceiling(w, program) if embs else None
    errors = [float(e.procrustes_error) for e in embs if e.procrustes_error is not None]
    drops = [e.step for e in run.events(EventKind.DROP_DETECTED)]
    # after convergence (the first version that reached the goal from >= 90 % of starts, or that was
    # published while the program watched its policy), no version more than 1.5x worse than the best
    # before it, unless a drop was detected before it
    regressions, worst = post_convergence(embs, drops)
    trust = None
    if embs and truth is not None:
        pos = np.asarray(truth.tensors["positions"], dtype=np.float64)[np.asarray(embs[-1].ids)]
        trust = _trustworthiness(pos, np.asarray(embs[-1].coordinates))
    last = embs[-1] if embs else None
    # learning speed: the first version within 1.5x of the final error
    near = next((e.step for e in embs if errors and float(e.procrustes_error or 0.0) <= 1.5 * errors[-1] + 1e-9), None)
    return {
        "world": z.label,
        "name": z.world,
        "seed": seed,
        "steps": run.steps,
        "seconds": round(seconds, 1),
        "learner": getattr(program, "learner", program.name),
        "goal": str(spec.goal),
        "n_starts": spec.n_starts,
        "embeddings": len(errors),
        "final_error": errors[-1] if errors else None,
        "best_error": min(errors) if errors else None,
        "trustworthiness": trust,
        "goal_reached_fraction": last.metrics.get("goal_reached_fraction") if last else None,
        "stochastic": bool(last.metrics.get("stochastic", 0.0)) if last else False,
        "steps_to_0.1": first.get("step"),
        "steps_to_1.5x_final": near,
        "steps_per_second": round(run.steps / max(seconds, 1e-9), 1),
        "optimal_goal_fraction": None if ceiling is None else ceiling.goal_reached_fraction,
        "optimal_error": None if ceiling is None else ceiling.error,
        "seconds_to_0.1": round(first["seconds"], 1) if "seconds" in first else None,
        "regressions": regressions,
        "worst_ratio": worst,
        "drops": len(drops),
        "retried_traces": int(last.metrics.get("retried_traces", 0.0)) if last else 0,
        **peers,
        # every version: [step, error, fraction of starts that reached the goal, end disparity (planner)]
        "versions": [
            [
                int(e.step),
                round(float(e.procrustes_error or 0.0), 4),
                e.metrics.get("goal_reached_fraction"),
                None if e.metrics.get("end_disparity") is None else round(float(e.metrics["end_disparity"]), 4),
            ]
            for e in embs
        ],
    }


def _mean(rows: list[dict[str, Any]], key: str) -> float | None:
    vals = [r[key] for r in rows if r.get(key) is not None]
    return float(np.mean(vals)) if vals else None


def summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per world: means over seeds of the figures `run_one` reports."""
    out = []
    for label in dict.fromkeys(r["world"] for r in rows):
        rs = [r for r in rows if r["world"] == label]
        keys = (
            "final_error",
            "best_error",
            "trustworthiness",
            "goal_reached_fraction",
            "steps_to_0.1",
            "steps_to_1.5x_final",
            "steps_per_second",
            "optimal_goal_fraction",
            "optimal_error",
            "pca_error",
            "isomap_error",
        )
        out.append(
            {"world": label, "seeds": len(rs), "learner": rs[0]["learner"], "goal": rs[0]["goal"]}
            | {k: _mean(rs, k) for k in keys}
            | {k: sum(r.get(k, 0) for r in rs) for k in ("regressions", "drops", "retried_traces")}
            | {"worst_ratio": max((r["worst_ratio"] for r in rs if r.get("worst_ratio") is not None), default=None)}
        )
    return out


def _fmt(v: Any) -> str:
    return "-" if v is None else f"{v:.3f}" if isinstance(v, float) else str(v)


def _run_task(task: tuple[ZooWorld, int, int]) -> dict[str, Any]:
    return run_one(*task)


def main(
    seeds: int = 3,
    quick: bool = False,
    only: list[str] | None = None,
    json_out: bool = False,
    workers: int = 1,
    seed_list: list[int] | None = None,
    defaults: bool = False,
) -> int:
    """Run the zoo; print one line per run and a summary table (or JSON lines). With `workers` > 1
    the runs go to that many processes (each run is seeded: the figures are the same). `seed_list`:
    exactly these seeds instead of 0 .. seeds-1 (a run of seed 2 alone gives what seed 2 gives in
    `--seeds 3`). `defaults`: every world once, with no program parameter set (the rows that differ
    only by their program parameters are one row then)."""
    import importlib.util
    import multiprocessing as mp

    labels = {z.label.lower() for z in ZOO}

    def chosen_by(o: str, z: ZooWorld) -> bool:  # a whole label names that entry alone
        o = o.lower()
        return z.label.lower() == o if o in labels else o in z.label.lower() or o == z.world.lower()

    tasks = []
    seen: set[str] = set()
    for z in ZOO:
        if defaults:
            key = json.dumps([z.world, z.params], sort_keys=True)
            if key in seen:
                continue
            seen.add(key)
            z = replace(z, program={})
        if only and not any(chosen_by(o, z) for o in only):
            continue
        if z.needs and importlib.util.find_spec(z.needs) is None:
            print(f"zoo: {z.label}: skipped ({z.needs} is not installed: pip install -e '.[worlds]')", file=sys.stderr)
            continue
        chosen = seed_list if seed_list else range(seeds)
        tasks += [(z, seed, z.quick_steps if quick else z.steps) for seed in chosen]
    pool = mp.get_context("spawn").Pool(workers) if workers > 1 and len(tasks) > 1 else None
    try:
        runs = pool.imap(_run_task, tasks) if pool is not None else map(_run_task, tasks)
        rows = []
        for r in runs:
            rows.append(r)
            seed = r["seed"]
            if json_out:
                print(json.dumps({"bench": "zoo", **r}), flush=True)
            else:
                print(
                    f"zoo: {r['world']} seed {seed}: final {_fmt(r['final_error'])} best {_fmt(r['best_error'])} "
                    f"goal {_fmt(r['goal_reached_fraction'])} ({r['learner']}, {r['steps']} steps, {r['seconds']} s)",
                    file=sys.stderr,
                    flush=True,
                )
    finally:
        if pool is not None:
            pool.terminate()
    table = summary(rows)
    if json_out:
        for t in table:
            print(json.dumps({"bench": "zoo", "summary": True, **t}))
        return 0
    cols = (
        "world",
        "learner",
        "final_error",
        "best_error",
        "trustworthiness",
        "goal_reached_fraction",
        "optimal_goal_fraction",
        "optimal_error",
        "steps_to_0.1",
        "steps_to_1.5x_final",
        "steps_per_second",
        "pca_error",
        "isomap_error",
        "regressions",
        "worst_ratio",
        "drops",
        "retried_traces",
    )
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for t in table:
        print("| " + " | ".join(_fmt(t[c]) for c in cols) + " |")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "zoo", help="the generic program on Gymnasium, MiniGrid and panda-gym worlds", description=__doc__
    )
    p.add_argument("--seeds", type=int, default=3, help="seeds per world: 0 .. N-1 (default 3)")
    p.add_argument(
        "--seed",
        type=int,
        action="append",
        metavar="S",
        help="run seed S only (repeatable; instead of --seeds): each run is seeded, so it gives what it gives in --seeds",
    )
    p.add_argument("--quick", action="store_true", help="shorter runs (a smoke test, not the figures)")
    p.add_argument(
        "--world",
        action="append",
        metavar="NAME",
        help="only these entries (a whole label names that entry alone; else every label containing NAME, or the gym: name)",
    )
    p.add_argument("--json", action="store_true", help="one JSON object per run, then per world")
    p.add_argument("--workers", type=int, default=1, help="processes the runs are spread over (default 1)")
    p.add_argument(
        "--defaults",
        action="store_true",
        help="every world once with no program parameter set (what a new user gets); rows that differ only "
        "by their program parameters are one row then",
    )
    p.set_defaults(func=lambda a: main(a.seeds, a.quick, a.world, a.json, a.workers, a.seed, a.defaults))


__all__ = ["ZOO", "ZooWorld", "main", "post_convergence", "run_one", "sensor_peers", "summary"]
