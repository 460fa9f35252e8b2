"""Chapter 9 experiments (beyond the dissertation): probabilistic sensorimotor embedding in a
slippery gridworld, option discovery, policy maps of the mountain car, and two variations
(Isomap in place of MDS; state-aided vergence traces).

The experiments live in `chapter9_embedding` (9.4, 9.5) and `chapter9_policies` (9.6); this module
is the chapter as `sme reproduce chapter9` runs it: the seeded jobs, the table and the figures."""

from __future__ import annotations

from typing import Any

import numpy as np

from sensorimotor.tools.experiments import scoring
from sensorimotor.tools.experiments.chapter9_embedding import (
    ProbabilisticResult,
    far_error,
    greedy_trace,
    isomap_coordinates,
    isomap_job,
    probabilistic_gridworld,
    probabilistic_job,
    state_aided_job,
    substep_offset,
    train_lspi_gridworld,
)
from sensorimotor.tools.experiments.chapter9_policies import (
    OUTCOMES,
    GridTable,
    OptionCurve,
    greedy_steps,
    mountaincar_traces,
    option_world,
    options_job,
    policy_map_job,
    train_mountaincar,
    train_options_agent,
)
from sensorimotor.tools.experiments.shared import ci95, fmt, pool_map

__all__ = [
    "AGENTS",
    "OUTCOMES",
    "GridTable",
    "OptionCurve",
    "ProbabilisticResult",
    "chapter",
    "far_error",
    "greedy_steps",
    "greedy_trace",
    "isomap_coordinates",
    "isomap_job",
    "mountaincar_traces",
    "option_world",
    "options_job",
    "policy_map_job",
    "probabilistic_gridworld",
    "probabilistic_job",
    "state_aided_job",
    "substep_offset",
    "train_lspi_gridworld",
    "train_mountaincar",
    "train_options_agent",
]

# --- sme reproduce chapter9 -------------------------------------------------------------------------

AGENTS = ("none", "random", "discovered")


def _figure(out: str, name: str, draw: Any, ncols: int = 1, width: float = 6.4) -> None:
    """A matplotlib figure of `ncols` panels drawn by `draw(axes)`, saved as OUT/name."""
    import os

    from sensorimotor.tools.common import require

    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, ncols, figsize=(width, 4.0), squeeze=False)
    draw(list(axes[0]))
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=110)
    plt.close(fig)


def _censored(r: dict, name: str, budget: int) -> float:
    v = r[name]["steps_to_level"]
    return float(budget if v is None else v)


def chapter(runs: int, quick: bool, workers: int, out: str) -> dict:
    """`sme reproduce chapter9`: probabilistic embedding, options, policy maps, variations."""
    from scipy import stats

    budget, opt_size = (40_000, 15) if quick else (80_000, 15)
    pm_train, pm_starts = (30_000, 500) if quick else (30_000, 1000)
    slip_size = 7 if quick else 9
    runs = min(runs, 5) if quick else runs
    seeds = list(range(runs))

    prob = pool_map(probabilistic_job, [(s, 0.2, slip_size) for s in seeds], workers)
    opts = pool_map(options_job, [(s, budget, 4, opt_size) for s in seeds], workers)
    maps = pool_map(policy_map_job, [(s, pm_train, pm_starts, 5) for s in seeds], workers)
    iso = pool_map(isomap_job, [(s, b) for b in (False, True) for s in seeds], workers)
    verg = pool_map(state_aided_job, [(n,) for n in ((20,) if quick else (20, 30, 40))], workers)

    # options: training steps to the level (censored at the budget when never reached)
    level = opts[0]["level"]
    to_level = {a: [_censored(r, a, budget) for r in opts] for a in AGENTS}
    steps_to_level = {
        a: {
            "mean": ci95(v)[0],
            "ci95": ci95(v)[1],
            "runs": v,
            "reached": sum(r[a]["steps_to_level"] is not None for r in opts),
        }
        for a, v in to_level.items()
    }
    welch = {
        f"discovered vs {b}": float(stats.ttest_ind(to_level["discovered"], to_level[b], equal_var=False).pvalue)
        if runs > 1
        else float("nan")
        for b in ("none", "random")
    }
    saving = 1.0 - float(np.mean(to_level["discovered"])) / float(np.mean(to_level["none"]))
    # policy maps: clusters per seed, and which true outcomes have a cluster of their own
    covered = [sorted({c["majority"] for c in m["clusters"] if c["purity"] >= 0.6 and c["size"] >= 5}) for m in maps]
    prob_ci = {k: ci95([r[k] for r in prob]) for k in ("plain", "mode", "mean", "mean_debiased")}
    samples = {k: ci95([r[k] for r in prob]) for k in ("samples_mode", "samples_mean")}
    iso_ci = {(b, k): ci95([r[k] for r in iso if r["barrier"] == b]) for b in (False, True) for k in ("mds", "isomap")}

    def pcell(name: str) -> str:
        return scoring.cell([r["field_scores"].get(name) for r in prob])

    def icell(barrier: bool, key: str) -> str:
        return scoring.cell([r[f"{key}_scores"] for r in iso if r["barrier"] == barrier])

    L = [
        f"Chapter 9 (beyond the dissertation): {runs} seeded runs per condition{' (quick)' if quick else ''}; "
        "mean ± 95 % CI (t) over seeds.",
        "",
        f"### Probabilistic sensorimotor embedding (9.4): gridworld {slip_size}x{slip_size}, slip 0.2",
        "",
        f"| estimator | Procrustes error | {scoring.HEADER} | samples per start (chosen) |",
        "|---|---|---|---|",
        f"| plain (one sampled trace per start) | {fmt(prob_ci['plain'], 4)} | {pcell('plain')} | 1 |",
        f"| mode of sampled traces | {fmt(prob_ci['mode'], 4)} | {pcell('mode')} | {fmt(samples['samples_mode'], 1)} |",
        f"| mean distance over sampled pairs | {fmt(prob_ci['mean'], 4)} | {pcell('mean')} "
        f"| {fmt(samples['samples_mean'], 1)} |",
        f"| mean distance, spread removed | {fmt(prob_ci['mean_debiased'], 4)} | {pcell('mean_debiased')} "
        "| same samples |",
        "",
        f"### Option discovery (9.6, Fig 9.3): {opt_size}x{opt_size} gridworld, goal in the far corner",
        "",
        f"Training steps (primitive world steps) until the greedy policy's mean steps to goal from 40 fixed "
        f"starts is <= {level:.1f} (1.25 x optimal); budget {budget} (runs that never reach it count as the budget).",
        "",
        "| agent | training steps to the level | reached |",
        "|---|---|---|",
    ]
    for a in AGENTS:
        t = steps_to_level[a]
        L.append(f"| {a} options | {t['mean']:.0f} ± {t['ci95']:.0f} | {t['reached']}/{runs} |")
    L += [
        "",
        f"Discovered options need {100 * saving:.0f} % fewer training steps than none. Welch t-test: "
        + ", ".join(f"{k}: p = {p:.3g}" for k, p in welch.items()),
        f"Discovered options (seed 0): {opts[0]['discovered_options']}; random (seed 0): {opts[0]['random_options']} "
        "(0 up, 1 down, 2 left, 3 right).",
        "",
        f"### Policy map of the mountain car (9.6, Fig 9.2): {pm_starts} random starts, Sarsa(λ) "
        f"trained {pm_train} steps, 5 k-means clusters of the 2-D embedding",
        "",
        "| seed | cluster sizes (majority outcome, purity) | outcomes with a cluster of their own |",
        "|---|---|---|",
    ]
    for m, cov in zip(maps, covered, strict=True):
        desc = ", ".join(f"{c['size']} ({c['majority']}, {c['purity']:.2f})" for c in m["clusters"])
        L.append(f"| {m['seed']} | {desc} | {', '.join(cov)} |")
    L += [
        "",
        "### Variations (9.5)",
        "",
        f"| gridworld | Procrustes, classical MDS | {scoring.HEADER}, MDS | Procrustes, Isomap (8 neighbours) "
        f"| {scoring.HEADER}, Isomap |",
        "|---|---|---|---|---|",
        f"| plain | {fmt(iso_ci[(False, 'mds')], 4)} | {icell(False, 'mds')} | {fmt(iso_ci[(False, 'isomap')], 4)} "
        f"| {icell(False, 'isomap')} |",
        f"| barrier | {fmt(iso_ci[(True, 'mds')], 4)} | {icell(True, 'mds')} | {fmt(iso_ci[(True, 'isomap')], 4)} "
        f"| {icell(True, 'isomap')} |",
        "",
        "| vergence starts | far starts sharing a goal step | far-half error, plain (rad) | state-aided (rad) | "
        f"Procrustes plain | state-aided | {scoring.HEADER}, plain | state-aided |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for v in verg:
        L.append(
            f"| {v['n_starts']} | {v['aliased_far_starts']} | {v['plain']['far_error_rad']:.5f} | "
            f"{v['state_aided']['far_error_rad']:.5f} | {v['plain']['procrustes']:.4f} | "
            f"{v['state_aided']['procrustes']:.4f} | {scoring.cell([v['plain']['scores']])} | "
            f"{scoring.cell([v['state_aided']['scores']])} |"
        )

    # figures
    m0 = maps[0]
    X, lab, outc = np.array(m0["coordinates"]), np.array(m0["labels"]), np.array(m0["outcomes"])

    def draw_map(axes: list) -> None:
        for c in range(lab.max() + 1):
            axes[0].scatter(*X[lab == c].T, s=6, label=f"cluster {c}")
        for o, col in zip(OUTCOMES, ("tab:red", "tab:green", "tab:blue"), strict=True):
            axes[1].scatter(*X[outc == o].T, s=6, c=col, label=o)
        axes[0].set(title="Policy map: clusters", xlabel="dim 1", ylabel="dim 2")
        axes[1].set(title="True outcome", xlabel="dim 1")
        for ax in axes:
            ax.legend(fontsize=7, markerscale=2)

    _figure(out, "policy_map.png", draw_map, ncols=2, width=10)

    def draw_options(axes: list) -> None:
        ax = axes[0]
        for a in AGENTS:
            grid = np.arange(500, budget + 1, 500)
            ys = []
            for r in opts:
                xs, ms = r[a]["steps"], r[a]["mean_steps"]
                ys.append([ms[min(np.searchsorted(xs, g), len(ms) - 1)] if ms else np.nan for g in grid])
            ax.plot(grid, np.nanmean(np.array(ys, dtype=float), axis=0), label=f"{a} options")
        ax.axhline(level, color="k", ls="--", lw=0.8, label="level")
        ax.set(title="Option discovery (Fig 9.3)", xlabel="training steps", ylabel="greedy steps to goal", yscale="log")
        ax.legend(fontsize=7)

    _figure(out, "options_learning.png", draw_options)

    def draw_bars(axes: list) -> None:
        names = ["plain", "mode", "mean"]
        axes[0].bar(names, [prob_ci[k][0] for k in names], yerr=[prob_ci[k][1] for k in names], color="tab:gray")
        axes[0].axhline(0.05, color="k", ls="--", lw=0.8)
        axes[0].set(title="Slip 0.2: Procrustes error", ylabel="Procrustes error")
        vv = verg[0]
        axes[1].bar(
            ["plain", "state-aided"],
            [vv["plain"]["far_error_rad"], vv["state_aided"]["far_error_rad"]],
            color=["tab:gray", "tab:green"],
        )
        axes[1].set(title="Vergence: far-half error", ylabel="rad")

    _figure(out, "probabilistic_and_state_aided.png", draw_bars, ncols=2, width=9)

    return {
        "probabilistic": {"results": prob, "ci95": prob_ci, "samples": samples},
        "options": {
            "level": level,
            "budget": budget,
            "steps_to_level": steps_to_level,
            "saving_vs_none": saving,
            "welch_p": welch,
            "results": opts,
        },
        "policy_map": {
            "clusters": m0["clusters"],
            "per_seed": [{"seed": m["seed"], "clusters": m["clusters"]} for m in maps],
            "outcomes_covered": covered,
        },
        "variations": {"isomap": iso, "state_aided": verg},
        "markdown": "\n".join(L),
    }
