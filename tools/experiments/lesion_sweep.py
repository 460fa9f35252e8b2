"""Which lesion makes the basic rule fail to recover (Fig 4.4)? A sweep of lesion sizes.

A lesion of radius r centred r px right of the retina centre (off-centre, touching the centre where
the spot lands after a good saccade), at saccade `at`; the basic and the robust learning rules,
seeded runs each; greedy post-saccade activation (30 repositions) before the lesion, right after
it and at the end. Run: ``python -m sensorimotor.tools.experiments.lesion_sweep [--runs 3]
[--radii 3,6,10,16] [--out FILE.md]``; with ``--out`` it also writes FILE.json (the command, the
table's markdown and every run), which the documentation's table is generated from.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import numpy as np

from sensorimotor.tools.experiments.shared import pool_map


def job(seed: int, rule: str, radius: float, at: int, steps: int, every: int) -> dict[str, Any]:
    """One seeded run: the greedy activation curve around a lesion of `radius` at (radius, 0)."""
    from sensorimotor.tools.experiments import retina as R

    r = R.perturbation(
        seed,
        "lesion",
        at=at,
        steps=steps,
        rule=rule,
        detector=None,
        supersample=1,
        params={"u": radius, "v": 0.0, "radius": radius},
        exploration="gaussian",
        every=every,
        embed_every=10**9,
    )
    c = r.curve
    pre = [a for s, a in zip(c.steps, c.activation, strict=True) if s <= at][-2:]
    post = [a for s, a in zip(c.steps, c.activation, strict=True) if s > at]
    return {
        "seed": seed,
        "rule": rule,
        "radius": radius,
        "before": float(np.mean(pre)),
        "after": float(post[0]),
        "end": float(np.mean(post[-4:])),
        "steps": c.steps,
        "activation": c.activation,
    }


def table(res: list[dict[str, Any]], radii: list[float]) -> str:
    """Markdown: per radius and rule, activation before / right after / at the end (mean ± 95 % CI),
    the end as a fraction of before, and the Welch p of basic vs robust at the end."""
    from scipy import stats

    from sensorimotor.tools.experiments.report import ci95, fmt

    lines = [
        "| lesion radius (px, centre r px right of the centre) | rule | activation before | right after | at the end "
        "| end / before | basic vs robust at the end (Welch p) |",
        "|---|---|---|---|---|---|---|",
    ]
    for rad in radii:
        ends = {}
        for rule in ("basic", "robust"):
            rs = [r for r in res if r["radius"] == rad and r["rule"] == rule]
            ends[rule] = [r["end"] for r in rs]
            ratio = ci95([r["end"] / r["before"] for r in rs])
            p = ""
            if rule == "robust" and len(ends["basic"]) > 1 and len(ends["robust"]) > 1:
                p = f"{stats.ttest_ind(ends['basic'], ends['robust'], equal_var=False).pvalue:.3g}"
            lines.append(
                f"| {rad:g} | {rule} | {fmt(ci95([r['before'] for r in rs]), 1)} | {fmt(ci95([r['after'] for r in rs]), 1)} "
                f"| {fmt(ci95(ends[rule]), 1)} | {fmt(ratio, 2)} | {p} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensorimotor.tools.experiments.lesion_sweep", description=__doc__)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--radii", default="3,6,10,16")
    p.add_argument("--at", type=int, default=2000)
    p.add_argument("--steps", type=int, default=6000)
    p.add_argument("--every", type=int, default=250)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", default=None)
    a = p.parse_args(argv)
    radii = [float(x) for x in a.radii.split(",")]

    t0 = time.time()
    jobs = [
        (s, rule, rad, a.at, a.steps, a.every) for rad in radii for rule in ("basic", "robust") for s in range(a.runs)
    ]
    res = pool_map(job, jobs, a.workers)
    command = (
        f"python -m sensorimotor.tools.experiments.lesion_sweep --runs {a.runs} --radii {a.radii} --at {a.at} "
        f"--steps {a.steps} --every {a.every}"
    )
    seconds = time.time() - t0
    md = (
        f"Lesion sweep: {a.runs} seeds, lesion at saccade {a.at} of {a.steps}, greedy activation every {a.every} "
        f"(`{command}`, {seconds:.0f} s)\n\n" + table(res, radii)
    )
    print(md)
    if a.out:
        with open(a.out, "w") as f:
            f.write(md + "\n")
        with open(a.out.rsplit(".", 1)[0] + ".json", "w") as f:
            json.dump(
                {"command": command, "seconds": seconds, "radii": radii, "markdown": md, "results": res},
                f,
                default=float,
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
