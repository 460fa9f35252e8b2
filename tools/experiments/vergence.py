"""Chapter 7 (`sme reproduce vergence`): LSPI iterations to a perfect vergence policy and the 1-D
depth map, on the PyBullet robot and on the Middlebury stereo pair."""

from __future__ import annotations

import numpy as np

from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import scores_of
from sensorimotor.tools.experiments.shared import fmt, mean_se, plot, pool_map


def job_vergence(seed: int, world: str, iterations: int) -> dict:

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


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict:
    iters = 5 if quick else 12
    res = pool_map(job_vergence, [(s, w, iters) for w in ("vergence", "stereo") for s in range(runs)], workers)
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
            f"| {w} | {[r['first_perfect_iteration'] for r in rs]} | {fmt(mean_se([r['errors'][-1] for r in rs]), 4)} "
            f"| {scoring.cell([r['scores'][-1] for r in rs])} | {match} | {ref} |"
        )
    plot(
        out,
        "vergence_lspi.png",
        "Procrustes error per LSPI iteration (ch. 7)",
        "LSPI iteration",
        "Procrustes error",
        [(f"{r['world']} seed {r['seed']}", list(range(1, len(r["errors"]) + 1)), r["errors"]) for r in res],
        logy=True,
    )
    return {"results": res, "markdown": "\n".join(lines)}
