"""The report's verdicts and the statistics they rest on: rows and chapters, 95 % intervals, and the
paired tests used wherever two conditions ran on the same seeds (`tools/experiments/report.py`)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

MET, NOT_MET, NOT_COMPARABLE = "met", "not met", "not comparable"


@dataclass(frozen=True)
class Row:
    """One claim: what is measured, our value, the dissertation's, the verdict and why."""

    measure: str
    ours: str
    dissertation: str
    verdict: str
    why: str


@dataclass
class ChapterReport:
    """One chapter of the report: its rows, figures (file paths), wall time, and the error that
    stopped it (then no rows)."""

    name: str
    title: str
    seconds: float
    rows: list[Row] = field(default_factory=list)
    figures: list[str] = field(default_factory=list)
    error: str | None = None
    table: str = ""  # the chapter's own table (its table.md): every number of the chapter


def ci95(values: Sequence[float | None] | np.ndarray) -> tuple[float, float]:
    """Mean and the half-width of its 95 % t interval (0 for fewer than two values)."""
    from scipy import stats

    a = np.asarray([v for v in values if v is not None], dtype=np.float64)
    if a.size == 0:
        return float("nan"), float("nan")
    if a.size < 2:
        return float(a.mean()), 0.0
    return float(a.mean()), float(stats.t.ppf(0.975, a.size - 1) * a.std(ddof=1) / np.sqrt(a.size))


def fmt(ci: tuple[float, float], digits: int = 3) -> str:
    return f"{ci[0]:.{digits}f} ± {ci[1]:.{digits}f}"


def _at_most(ci: tuple[float, float], target: float, tol: float = 0.0) -> tuple[str, str]:
    """Lower is better: met when our mean is at most `target * (1 + tol)`; the reason says where
    the interval lies (a wide interval alone never meets a claim)."""
    bound = target * (1 + tol)
    lo, hi = ci[0] - ci[1], ci[0] + ci[1]
    if ci[0] <= bound:
        sure = "the whole interval too" if hi <= bound else f"the interval reaches {hi:.4g}"
        return MET, f"mean {ci[0]:.4g} at most {bound:.4g} ({sure})"
    if lo <= bound:
        return NOT_MET, f"mean {ci[0]:.4g} above {bound:.4g}, though the interval reaches {lo:.4g}"
    return NOT_MET, f"the whole interval is above {bound:.4g} (lower bound {lo:.4g})"


def _at_least(ci: tuple[float, float], target: float) -> tuple[str, str]:
    """Higher is better: met when our mean is at least `target` (the reason says where the interval lies)."""
    lo, hi = ci[0] - ci[1], ci[0] + ci[1]
    if ci[0] >= target:
        sure = "the whole interval too" if lo >= target else f"the interval reaches {lo:.4g}"
        return MET, f"mean {ci[0]:.4g} at least {target:.4g} ({sure})"
    if hi >= target:
        return NOT_MET, f"mean {ci[0]:.4g} below {target:.4g}, though the interval reaches {hi:.4g}"
    return NOT_MET, f"the whole interval is below {target:.4g} (upper bound {hi:.4g})"


def _lower(a: tuple[float, float], b: tuple[float, float], what: str) -> tuple[str, str]:
    """Met when interval `a` lies entirely below interval `b`."""
    if a[0] + a[1] < b[0] - b[1]:
        return MET, f"{what}: the intervals do not overlap"
    if a[0] < b[0]:
        return NOT_MET, f"{what}: lower on average, but the intervals overlap"
    return NOT_MET, f"{what}: not lower"


@dataclass(frozen=True)
class Paired:
    """A paired comparison of two conditions run on the same seeds: the mean of the per-seed
    differences a - b with its 95 % t interval, the paired t-test's p and the Wilcoxon signed-rank
    test's p (both for `alternative`: "less" = a below b, "two-sided")."""

    n: int
    diff: float
    half: float
    p_t: float
    p_wilcoxon: float

    def text(self, alternative: str) -> str:
        side = "one-sided" if alternative != "two-sided" else "two-sided"
        return (
            f"paired t-test over {self.n} seeds, {side} p = {self.p_t:.3g} (Wilcoxon signed-rank p = "
            f"{self.p_wilcoxon:.3g}); mean difference {self.diff:.4g} ± {self.half:.2g}"
        )


def paired(a: Sequence[float], b: Sequence[float], alternative: str = "less") -> Paired:
    """Paired tests of `a` against `b` (index i of both is the same seed); NaN p with fewer than 2
    pairs or no differences at all."""
    from scipy import stats

    x, y = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    if x.shape != y.shape:
        raise ValueError(f"paired samples differ in length: {x.size} and {y.size}")
    d = x - y
    m, h = ci95(d) if d.size else (float("nan"), float("nan"))
    if d.size < 2 or not np.any(d != 0):
        return Paired(int(d.size), m, h, float("nan"), float("nan"))
    p_t = float(stats.ttest_rel(x, y, alternative=alternative).pvalue)
    p_w = float(stats.wilcoxon(x, y, alternative=alternative).pvalue)
    return Paired(int(d.size), m, h, p_t, p_w)


def _paired_lower(a: Sequence[float], b: Sequence[float], what: str, alpha: float = 0.05) -> tuple[str, str]:
    """Met when condition `a` is below `b` on the same seeds: the one-sided paired t-test's p < alpha
    (the Wilcoxon p is given beside it)."""
    t = paired(a, b, "less")
    if t.p_t == t.p_t and t.p_t < alpha:
        return MET, f"{what}: {t.text('less')}"
    return NOT_MET, f"{what}: not shown ({t.text('less')}; met: p < {alpha})"


def _quick(quick: bool, ours: str, full: str) -> str:
    return f" (quick run: {ours}; the dissertation: {full})" if quick else ""


# --- per chapter ----------------------------------------------------------------------------------
