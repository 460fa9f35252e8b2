"""The report's rows, chapter by chapter: each claim of the dissertation (shared/SEED-NOTES.md) beside
our number from the chapter's result dict, with its verdict (`tools/experiments/report.py`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from sensorimotor.tools.experiments.report_stats import (
    MET,
    NOT_COMPARABLE,
    NOT_MET,
    Row,
    _at_least,
    _at_most,
    _paired_lower,
    _quick,
    ci95,
    fmt,
    paired,
)


def rows_gridworld(res: dict[str, Any], quick: bool) -> list[Row]:
    by = {"plain": [], "barrier": [], "random": []}  # type: dict[str, list[dict]]
    for r in res["results"]:
        by["random" if r["policy"] == "random" else "barrier" if r["barrier"] else "plain"].append(r)
    first = ci95([r["errors"][0] for r in by["plain"]])
    final = {k: ci95([r["errors"][-1] for r in v]) for k, v in by.items()}
    trust = ci95([(r["scores"][-1] or {}).get("trustworthiness") for r in by["plain"]])
    out = [
        Row(
            "plain: Procrustes error, first → last LSPI embedding",
            f"{fmt(first, 4)} → {fmt(final['plain'], 4)}",
            "falls as LSPI iterates (Fig 5.4)",
            *_paired_lower(
                [r["errors"][-1] for r in by["plain"]], [r["errors"][0] for r in by["plain"]], "last below first"
            ),
        )
    ]
    ratio = final["barrier"][0] / max(final["plain"][0], 1e-12)
    out.append(
        Row(
            "barrier: Procrustes error of the last embedding",
            fmt(final["barrier"], 4),
            "the barrier does not defeat sensorimotor embedding",
            MET if final["barrier"][0] <= 2 * final["plain"][0] + 0.02 else NOT_MET,
            f"{ratio:.2f}x the plain grid's (met: within 2x + 0.02)",
        )
    )
    out.append(
        Row(
            "random policy: Procrustes error",
            fmt(final["random"], 4),
            "a random policy gives a random embedding",
            MET if final["random"][0] > 0.5 else NOT_MET,
            "met when above 0.5 (unrelated shapes score near 1)",
        )
    )
    out.append(
        Row(
            "plain: trustworthiness of the last embedding (k = 5)",
            fmt(trust),
            "not reported",
            NOT_COMPARABLE,
            "the dissertation reports Procrustes error only",
        )
    )
    return out


#: Fig 4.4 (4.4.2): the share of the basic rule's steering weight whose reward estimate R_k must lie
#: above the best activation a lesion leaves for the dissertation's separation to be asked of a run
PREMISE = 0.5


def rows_retina(res: dict[str, Any], quick: bool) -> list[Row]:
    learning, lesion, reversal = res["learning"], res["lesion"], res["reversal"]
    steps = learning[0]["steps"][-1] if learning and learning[0]["steps"] else 0
    one = ci95([r["one"][-1] for r in learning])
    two = ci95([r["two"][-1] for r in learning])
    end = {
        rule: ci95([np.mean(r["activation"][-4:]) for r in lesion if r["rule"] == rule]) for rule in ("basic", "robust")
    }
    delays = [r["detection_delay"] for r in reversal]
    note = _quick(quick, f"{steps} training saccades", "5000")
    v, why = _at_most(one, 5.0, tol=0.2)
    out = [Row(f"1-saccade error after {steps} saccades (px)", fmt(one, 2), "about 5 px after 5000", v, why + note)]
    v, why = _paired_lower([r["two"][-1] for r in learning], [r["one"][-1] for r in learning], "2 below 1 saccade")
    out.append(Row("2-saccade error (px)", fmt(two, 2), "lower than 1 saccade", v, why))
    ls = res.get("lesion_summary") or {}
    if "basic" in ls and "robust" in ls:  # Fig 4.4: what the lesion did to each rule, paired by seed
        rb, rr = ls["basic"]["rise"], ls["robust"]["rise"]
        v, why = _paired_lower(rb, rr, "the basic rule's recovery below the robust rule's")
        gap_before = float(np.mean(ls["robust"]["last_before"]) - np.mean(ls["basic"]["last_before"]))
        gap_end = float(np.mean(ls["robust"]["end"]) - np.mean(ls["basic"]["end"]))
        why += (
            f". At the end robust {fmt(ci95(ls['robust']['end']), 1)} vs basic {fmt(ci95(ls['basic']['end']), 1)}: "
            f"{gap_end:+.1f}, of which {gap_before:+.1f} was there before the lesion"
        )
        ar = ls["basic"].get("arithmetic")
        frozen = ls["basic"].get("frozen_weight") or []
        if ar:
            why += (
                f". The lesion lowers the best activation from {ar['best_before']:.0f} to {ar['best_after']:.0f} "
                f"(target on the centre: {ar['centre_after']:.0f}); the basic rule updates a field only when R > R_k, "
                f"and at the lesion {100 * float(np.mean(frozen)):.0f} % of its steering weight "
                "had R_k above that best: the rest still learns (docs/reproduce.md, Fig 4.4)"
            )
        if v == NOT_MET and frozen and float(np.mean(frozen)) < PREMISE:
            # 4.4.2's separation follows from the basic rule freezing: with most of its steering weight
            # still below the best activation left, this lesion does not pose the dissertation's question
            v = NOT_COMPARABLE
            why = (
                "4.4.2's premise does not hold after this lesion: the basic rule stops only where R_k is above "
                f"the best activation left, {100 * float(np.mean(frozen)):.0f} % of its steering weight (the "
                f"premise: most of it, over {100 * PREMISE:.0f} %), so both rules go on learning; the claim is "
                "judged where the premise holds, in the next row. " + why
            )
        out.append(
            Row(
                "lesion (Fig 4.4): recovery of the greedy post-saccade activation after the lesion (end minus "
                "just after it), basic vs robust rule",
                f"basic {fmt(ci95(rb), 1)} / robust {fmt(ci95(rr), 1)}",
                "the robust rule recovers, the basic does not: a clear separation",
                v,
                why,
            )
        )
        iso = res.get("lesion_isolating_summary") or {}
        if "basic" in iso and "robust" in iso:  # the premise of 4.4.2 made to hold: estimates above the best left
            ib, ir = iso["basic"]["rise"], iso["robust"]["rise"]
            v, why = _paired_lower(ib, ir, "the basic rule's recovery below the robust rule's")
            ar = iso["basic"].get("arithmetic")
            if ar:
                why += (
                    f". A retina started from its true saccades, a lesion of {ar['lesioned_fields']} fields that "
                    f"leaves a best activation of {ar['best_after']:.0f} (of {ar['best_before']:.0f}): "
                    f"{100 * float(np.mean(iso['basic']['frozen_weight'])):.0f} % of the basic rule's steering weight "
                    f"has R_k above it; target moved {np.mean(iso['basic']['landing_shift_u']):+.1f} px (basic) / "
                    f"{np.mean(iso['robust']['landing_shift_u']):+.1f} px (robust) from the lesion, the best spot "
                    f"{ar['best_offset_after'][0]:+.0f} px"
                )
            out.append(
                Row(
                    "lesion, 4.4.2's premise isolated (the best activation left below the reward estimates): "
                    "recovery basic vs robust",
                    f"basic {fmt(ci95(ib), 1)} / robust {fmt(ci95(ir), 1)}",
                    "the basic rule makes no updates (R < R_k), the robust one recovers",
                    v,
                    why,
                )
            )
    else:  # results from before the lesion summary: the activations at the end
        ends = {rule: [float(np.mean(r["activation"][-4:])) for r in lesion if r["rule"] == rule] for rule in end}
        v, why = _paired_lower(ends["basic"], ends["robust"], "basic below robust")
        out.append(
            Row(
                "lesion: greedy post-saccade activation at the end, basic vs robust rule",
                f"basic {fmt(end['basic'], 1)} / robust {fmt(end['robust'], 1)}",
                "the robust rule recovers, the basic does not (Fig 4.4)",
                v,
                why,
            )
        )
    detected = [d for d in delays if d is not None]
    out.append(
        Row(
            "reversal: detected by the agent itself (saccades after)",
            f"{delays}",
            "the moving average falls for about 1000 saccades, then the retina resets (Fig 4.5)",
            MET if len(detected) == len(delays) and delays else NOT_MET,
            f"{len(detected)} of {len(delays)} runs detected it, mean {np.mean(detected) if detected else float('nan'):.0f} saccades",
        )
    )
    return out


def rows_retina_natural(res: dict[str, Any], quick: bool) -> list[Row]:
    s, d = res["summary"], res["dissertation"]
    labels = {"one": "1 saccade", "two": "2 saccades", "fixed": "fixed point", "geometry": "mean geometry error"}
    out = []
    for k, label in labels.items():
        ci = (s[k]["mean"], s[k]["ci95"])
        v, why = _at_most(ci, float(d[k]), tol=0.2)
        out.append(
            Row(
                f"Table 4.1 {label} (px)",
                fmt(ci, 1),
                f"{'about ' if k == 'geometry' else ''}{d[k]} px",
                v,
                why + " (met: ours at most 1.2x theirs); a different image than the Berkeley set",
            )
        )
    return out


def rows_rovingeye(res: dict[str, Any], quick: bool) -> list[Row]:
    out = []
    for m, target in res["dissertation"]["errors"].items():
        e = res["errors"][m]
        v, why = _at_most((e["mean"], e["ci95"]), float(target))
        out.append(Row(f"Table 5.1 Procrustes error, {m}", fmt((e["mean"], e["ci95"]), 3), f"{target}", v, why))
    const, fit = res.get("score_constants"), res.get("score_fit")
    for m, target in res["dissertation"]["scores"].items():
        sc = res["scores"][m]
        why = (
            "ch. 5.2 defines the score (a reward on termination from the distance to the goal, discounted by the "
            "number of actions) but gives neither the reward scale nor the discount"
        )
        if const:
            why += f"; ours: exp(-d / {const['reward_px']:g} px) x {const['discount']:g}^actions"
        if fit:
            why += (
                f"; no constants recover theirs (the closest, {fit['reward_px']:.1f} px and {fit['discount']:.3f}, "
                f"still differ by RMS {fit['rms']:.2f} over the four)"
            )
        out.append(Row(f"Table 5.1 score, {m}", fmt((sc["mean"], sc["ci95"]), 3), f"{target}", NOT_COMPARABLE, why))
    out.append(_ordering_row(res, "errors", "better policies give better embeddings (errors fall in order)", False))
    if all("per_seed" in res["scores"][m] for m in res["dissertation"]["scores"]):
        row = _ordering_row(res, "scores", "scores rise as errors fall (Table 5.1's order)", True)
        if fit:
            row = Row(
                row.measure,
                row.ours,
                row.dissertation,
                row.verdict,
                row.why
                + f"; the order holds under {100 * fit['rising_share']:.0f} % of other constants ({fit['grid']})",
            )
        out.append(row)
    return out


def _ordering_row(res: dict[str, Any], key: str, measure: str, rising: bool) -> Row:
    """Table 5.1's methods in the dissertation's order: each step met by a one-sided paired t-test
    over the seeds (the methods run on the same points of each seed)."""
    names = [m for m in ("sensor_mds", "gradient", "epsilon_gradient", "hand_coded", "ballistic") if m in res[key]]
    steps = []
    ok = True
    for a, b in zip(names, names[1:], strict=False):
        lo, hi = (
            (res[key][a]["per_seed"], res[key][b]["per_seed"])
            if rising
            else (res[key][b]["per_seed"], res[key][a]["per_seed"])
        )
        t = paired(lo, hi, "less")
        good = t.p_t == t.p_t and t.p_t < 0.05
        ok &= good
        steps.append(f"{a} {'<' if rising else '>'} {b}: p = {t.p_t:.2g}")
    means = " < ".join if rising else " > ".join
    return Row(
        measure,
        means(f"{res[key][m]['mean']:.3g}" for m in names),
        " < ".join(names) if rising else " > ".join(names),
        MET if ok else NOT_MET,
        "each step by a one-sided paired t-test over the seeds (same points per seed; met: every p < 0.05): "
        + "; ".join(steps),
    )


def rows_objectpose(res: dict[str, Any], quick: bool) -> list[Row]:
    s = res["summary"]
    ratio = s["ratio_to_better_peer"]
    out = [
        Row(
            "sensorimotor embedding Procrustes error vs the better of PCA and Isomap",
            f"{fmt(tuple(s['se_error']), 4)} vs PCA {fmt(tuple(s['pca_error']), 4)}, Isomap {fmt(tuple(s['isomap_error']), 4)}",
            "far lower than PCA or Isomap (Fig 6.3)",
            MET if ratio <= 1 / 3 else NOT_MET,
            f"ratio {ratio:.3f} (met: at most 1/3)",
        )
    ]
    fin = tuple(s["alignment_final_success"])
    out.append(
        Row(
            "alignment task: starts that reach the target after 5 LSPI iterations",
            fmt(fin, 3),
            "solvable in a few LSPI iterations (Fig 6.4)",
            *_at_least(fin, 0.95),
        )
    )
    return out


def rows_vergence(res: dict[str, Any], quick: bool) -> list[Row]:
    out = []
    for w, perfect_in, proc in (("vergence", 9, 0.0257), ("stereo", None, 0.0003)):
        rs = [r for r in res["results"] if r["world"] == w]
        if not rs:
            continue
        err = ci95([r["errors"][-1] for r in rs])
        if perfect_in is not None:
            firsts = [r["first_perfect_iteration"] for r in rs]
            ok = all(f is not None and f <= perfect_in for f in firsts)
            out.append(
                Row(
                    f"{w}: first LSPI iteration with a perfect policy",
                    str(firsts),
                    f"{perfect_in}",
                    MET if ok else NOT_MET,
                    f"every run at or before iteration {perfect_in}" if ok else "some run later or never",
                )
            )
        else:
            diff = np.abs(np.concatenate([np.asarray(r["goal_minus_truth"]) for r in rs]))
            frac = float((diff <= 2).mean())
            out.append(
                Row(
                    "stereo: perceptual-goal disparity within 2 px of truth",
                    f"{100 * frac:.0f} % of starts",
                    "within 2 px (126 vs 128 px)",
                    MET if frac >= 0.9 else NOT_MET,
                    "met: at least 90 % of starts",
                )
            )
        if perfect_in is None:  # the stereo pair: every run, against the dataset's disparities
            per_run = [float(r["errors"][-1]) for r in rs]
            off = np.concatenate([np.asarray(r["goal_minus_truth"], dtype=np.float64) for r in rs[:1]])
            ok = max(per_run) <= STEREO_BAR
            truth = rs[0].get("truth")
            span = f", over disparities of {min(truth):.0f}-{max(truth):.0f} px" if truth else ""
            out.append(
                Row(
                    "stereo: Procrustes error of the depth map, every run",
                    f"{fmt(err, 4)} (per run {', '.join(f'{e:.4f}' for e in per_run)})",
                    f"{proc}",
                    MET if ok else NOT_MET,
                    f"{'every' if ok else 'not every'} run at most {STEREO_BAR} against the Middlebury 2014 ground-truth "
                    "disparities that scikit-image ships (motorcycle, down-sampled by 4). The dissertation's 0.0003 is on "
                    "a Middlebury pair it does not name, at its resolution: the error is the squared residual over the "
                    "spread of the disparities, and ours is the perceptual goals' offset from the truth "
                    f"({np.sqrt(np.mean(off**2)):.2f} px rms, at most {np.abs(off).max():.1f} px{span}), the same in every run",
                )
            )
            continue
        v, why = _at_most(err, proc)
        out.append(Row(f"{w}: Procrustes error of the depth map", fmt(err, 4), f"{proc}", v, why))
    return out


#: the stereo pair's bar per run (issue 38): the dissertation's 0.0003 was on another pair
STEREO_BAR = 0.01


def _ratio_ci(a: Sequence[float], b: Sequence[float]) -> tuple[float, float, float]:
    """mean(a) / mean(b) and its 95 % interval by the delta method (the two means independent,
    each with its t interval's relative half-width)."""
    (ma, ha), (mb, hb) = ci95(a), ci95(b)
    r = ma / mb
    rel = float(np.hypot(ha / ma, hb / mb)) if ma and mb else float("nan")
    return r, r * (1 - rel), r * (1 + rel)


#: the chapter's bound for "comparable": the embedding agent within 1.2x of the true-state agent, and
#: two bodies within 1.2x of each other
BOUND = 1.2


def _bodies_row(pair: str, welch_p: float, a: Sequence[float], b: Sequence[float]) -> Row:
    """Fig 8.4, "performance is the same across all morphologies": with the same seeds, judged by
    equivalence (two one-sided paired t-tests on the per-seed log ratio, margin `BOUND`: met when
    the 90 % interval of the ratio lies within 1/BOUND-BOUND), the paired t-test's p beside it; a
    p > 0.05 alone would also pass two bodies that differ, whenever the runs are noisy enough."""
    from scipy import stats

    if len(a) == len(b) > 1:
        d = np.log(np.asarray(a, dtype=np.float64) / np.asarray(b, dtype=np.float64))
        n, m = len(d), float(np.mean(d))
        se = float(np.std(d, ddof=1)) / np.sqrt(n)
        t = float(stats.t.ppf(0.95, n - 1))
        lo, hi = float(np.exp(m - t * se)), float(np.exp(m + t * se))
        margin = float(np.log(BOUND))
        p_tost = (
            max(float(stats.t.sf((m + margin) / se, n - 1)), float(stats.t.sf((margin - m) / se, n - 1)))
            if se > 0
            else (0.0 if abs(m) < margin else 1.0)
        )
        p = paired(a, b, "two-sided").p_t
        same = 1 / BOUND <= lo and hi <= BOUND
        return Row(
            f"bodies {pair}: the same within {BOUND}x (paired equivalence, same seeds)",
            f"ratio {np.exp(m):.3f} (90 % CI {lo:.3f}-{hi:.3f})",
            "the same on every body; differences not statistically significant (Fig 8.4)",
            MET if same else NOT_MET,
            f"equivalence within {BOUND}x either way: two one-sided paired t-tests over {n} seeds on the "
            f"per-seed ratio, p = {p_tost:.3g} (met: the 90 % interval inside {1 / BOUND:.3f}-{BOUND}); "
            f"the difference itself: paired t p = {p:.3f}"
            + (" (significant: the dissertation's own wording would not allow it)" if p < 0.05 else ""),
        )
    comparable = welch_p == welch_p  # NaN with one run
    return Row(
        f"bodies {pair}: Welch t-test",
        "n/a" if not comparable else f"p = {welch_p:.3f}",
        "no significant difference",
        (MET if welch_p > 0.05 else NOT_MET) if comparable else NOT_COMPARABLE,
        "p > 0.05: no significant difference" if comparable else "one run per body: no test",
    )


def rows_mountaincar(res: dict[str, Any], quick: bool) -> list[Row]:
    from scipy import stats

    ci = {k: tuple(v) for k, v in res["ci95"].items()}
    finals = res.get("finals", {})
    out = []
    for k in ("baseline-1.0", "baseline-1.4", "vertical"):
        r = ci[k][0] / ci["true"][0]
        why = f"{r:.2f}x the true-state agent (met: within {BOUND}x)"
        if len(finals.get(k, [])) > 1 and len(finals.get("true", [])) > 1:
            r, lo, hi = _ratio_ci(finals[k], finals["true"])
            over = f"; {r - BOUND:.2f}x above the bound" if r > BOUND else ""
            same = len(finals[k]) == len(finals["true"])  # the same seeds: a paired test
            p = (
                paired(finals[k], finals["true"], "two-sided").p_t
                if same
                else float(stats.ttest_ind(finals[k], finals["true"], equal_var=False).pvalue)
            )
            why = (
                f"{r:.2f}x the true-state agent, 95 % CI of the ratio {lo:.2f}-{hi:.2f} (met: within {BOUND}x){over}; "
                f"{'paired t' if same else 'Welch'} p vs the true-state agent {p:.3f}"
            )
        out.append(
            Row(
                f"{k}: steps to goal at the end",
                f"{fmt(ci[k], 1)} ({r:.2f}x true state {fmt(ci['true'], 1)})",
                "comparable to the agent given true position and velocity",
                MET if r <= BOUND else NOT_MET,
                why + _quick(quick, "20000 training car steps, one evaluation", "100000 car steps (full run)"),
            )
        )
    for pair, p in res["welch_p"].items():
        a, _, b = pair.partition(" vs ")
        out.append(_bodies_row(pair, p, finals.get(a, []), finals.get(b, [])))
    out.append(
        Row(
            "random agent: steps to goal",
            fmt(ci["random"], 1),
            "the benchmark",
            NOT_COMPARABLE,
            "a baseline, not a claim",
        )
    )
    return out


def rows_chapter9(res: dict[str, Any], quick: bool) -> list[Row]:
    opt = res["options"]
    st = opt["steps_to_level"]
    disc = (st["discovered"]["mean"], st["discovered"]["ci95"])
    out = []
    for other in ("none", "random"):
        o = (st[other]["mean"], st[other]["ci95"])
        v, why = _paired_lower(st["discovered"]["runs"], st[other]["runs"], f"discovered options below {other}")
        out.append(
            Row(
                f"options: training steps to the level, discovered vs {other}",
                f"{fmt(disc, 0)} vs {fmt(o, 0)}",
                "the agent with discovered options learns faster than with none or random ones (9.6)",
                v,
                why + " (a gridworld here; the dissertation's was the mountain car)",
            )
        )
    prob = res["probabilistic"]["ci95"]
    out.append(
        Row(
            "probabilistic embedding (9.4): Procrustes error plain / mode / mean",
            " / ".join(fmt(tuple(prob[k]), 4) for k in ("plain", "mode", "mean")),
            "future work, no number",
            NOT_COMPARABLE,
            "the dissertation names it as future work only",
        )
    )
    return out


#: chapter name -> (title, the rows of its result)
CHAPTER_ROWS: dict[str, tuple[str, Callable[[dict[str, Any], bool], list[Row]]]] = {
    "retina": ("Chapter 4: foveated retina and saccades", rows_retina),
    "retina-natural": ("Chapter 4: natural scenes (Table 4.1)", rows_retina_natural),
    "gridworld": ("Chapter 5: robot position in a gridworld", rows_gridworld),
    "rovingeye": ("Chapter 5.2: roving eye (Table 5.1)", rows_rovingeye),
    "objectpose": ("Chapter 6: object pose", rows_objectpose),
    "vergence": ("Chapter 7: depth from vergence", rows_vergence),
    "mountaincar": ("Chapter 8: visual mountain car", rows_mountaincar),
    "chapter9": ("Chapter 9: beyond the dissertation", rows_chapter9),
}


def chapter_rows(name: str, res: dict[str, Any], quick: bool) -> list[Row]:
    """The rows of chapter `name`; a row that cannot be read says so instead of failing the report."""
    try:
        return CHAPTER_ROWS[name][1](res, quick)
    except (KeyError, IndexError, TypeError, ValueError) as e:
        return [Row("(the chapter's results)", "unreadable", "", NOT_COMPARABLE, f"{type(e).__name__}: {e}")]


# --- the environment --------------------------------------------------------------------------------
