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
by itself). Runs go to worker processes (spawned); results are written to OUT/CHAPTER/results.json,
table.md and PNG plots. Each chapter is one file of tools/experiments/; this module is the command
and the report.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import shutil
import sys
import time
from collections.abc import Callable
from typing import Any

from sensorimotor.tools.common import require
from sensorimotor.tools.experiments.shared import job_cache, use_cluster


def _chapter(module: str, attr: str = "chapter") -> Callable[[int, bool, int, str], dict]:
    """The chapter `attr` of `sensorimotor.tools.experiments.<module>`, imported when it runs (the CLI
    starts without loading PyBullet worlds or scipy)."""

    def run(runs: int, quick: bool, workers: int, out: str) -> dict:
        mod = importlib.import_module(f"sensorimotor.tools.experiments.{module}")
        return getattr(mod, attr)(runs, quick, workers, out)

    run.__name__ = run.__qualname__ = module.replace("_", "-")
    return run


#: `sme reproduce CHAPTER`: each chapter is `chapter(runs, quick, workers, out)` in its own file of
#: tools/experiments/
CHAPTERS: dict[str, Callable[[int, bool, int, str], dict]] = {
    name: _chapter(name)
    for name in ("arm", "gridworld", "retina", "vergence", "mountaincar", "objectpose", "rovingeye", "chapter9")
}
retina_natural = _chapter("retina_natural")
CHAPTERS["mountaincar-ablation"] = _chapter("mountaincar", "ablation")  # not in `all`: docs/reproduce.md

#: the chapters of `sme reproduce all`, in the dissertation's order (4, 4 natural, 5, 5.2, 6, 7, 8, 9)
ALL: dict[str, Callable[[int, bool, int, str], dict]] = {
    "retina": CHAPTERS["retina"],
    "retina-natural": retina_natural,
    "gridworld": CHAPTERS["gridworld"],
    "rovingeye": CHAPTERS["rovingeye"],
    "objectpose": CHAPTERS["objectpose"],
    "vergence": CHAPTERS["vergence"],
    "mountaincar": CHAPTERS["mountaincar"],
    "chapter9": CHAPTERS["chapter9"],
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
    p.add_argument(
        "chapter",
        choices=sorted(CHAPTERS) + ["all"],
        metavar="CHAPTER",
        help="which experiment (" + ", ".join(sorted(CHAPTERS)) + "), or all",
    )
    p.add_argument("--runs", type=int, default=10, help="seeded runs per condition (default 10)")
    p.add_argument(
        "--quick",
        action="store_true",
        help="shortened runs, for a first look (on 2 cores: seconds for gridworld, about 8 min for retina and 7 "
        "for mountaincar, 17 min for all; see docs/reproduce.md)",
    )
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
    from sensorimotor.tools.experiments import report

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

    from sensorimotor.tools.experiments import report

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
    from sensorimotor.tools.experiments import report

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

    from sensorimotor.tools.experiments import report

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
