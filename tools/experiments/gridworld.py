"""Chapter 5 (`sme reproduce gridworld`): the Procrustes error of the gridworld embedding per LSPI
iteration, plain and with a barrier, and under a random policy (Fig 5.4)."""

from __future__ import annotations

from typing import TypedDict

from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.scoring import scores_of
from sensorimotor.tools.experiments.shared import fmt, known, mean_se, plot, pool_map


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
        "errors": [known(e) for e in run.errors],
        "scores": [scores_of(e) for e in run.embeddings],
    }


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict:
    steps = 8000 if quick else 20000
    jobs = [(s, b, steps) for b in (False, True) for s in range(runs)] + [
        (s, False, 10000, "random") for s in range(runs)
    ]
    res = pool_map(job_grid, jobs, workers)
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
                "first": mean_se(first),
                "final": mean_se(final),
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
        f"| {t['case']} | {fmt(t['first'], 4)} | {fmt(t['final'], 4)} | {cells[t['case']]} | {t['runs']} |"
        for t in table
    ]
    plot(
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
