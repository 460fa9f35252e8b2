"""The documentation's result tables and sample outputs, generated from the files of the commands
they cite, so that no number in them is typed by hand.

Each source is a command and the file it wrote, kept under docs/ (docs/results/NAME/: `results.json`
of `sme reproduce CHAPTER ... --out DIR`, the stdout of `sme demo` or of a bench's `--json`;
docs/reproduce/report-quick/: the folder of `sme reproduce all --quick`). A page holds a block between
``<!-- BEGIN results: NAME -->`` and ``<!-- END results: NAME -->``;
`python -m sensorimotor.tools.docgen.results_doc PAGE...` rewrites every block from its source and
`--check` exits 1 when a page has drifted (tests/test_results_doc.py runs the check). To refresh a
result: run its command with ``--out DIR``, copy ``DIR/CHAPTER/results.json`` over the stored one,
and run this module on the pages."""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCS = ROOT / "docs"
BLOCK = re.compile(r"(<!-- BEGIN results: ([\w.-]+) -->\n)(.*?)(<!-- END results: \2 -->)", re.S)
PAGES = (
    "README.md",
    "docs/getting-started.md",
    "docs/results.md",
    "docs/reproduce.md",
    "docs/commands/bench.md",
    "docs/arm.md",
    "docs/zoo.md",
    "docs/body-changes.md",
)


@dataclass(frozen=True)
class Source:
    """A command and the file it wrote, rendered into a block of markdown."""

    command: str
    file: str  # relative to docs/
    render: Callable[[Source, str], str]


def reproduce_table(src: Source, text: str) -> str:
    """The table `sme reproduce` wrote (its results.json's ``markdown``), with the command and file."""
    data = json.loads(text)
    return f"{data['markdown'].strip()}\n\nFrom `{src.command}` (its `results.json`: `docs/{src.file}`)."


def demo_output(src: Source, text: str) -> str:
    """The demo's stdout: its first lines up to the second embedding (the column legend included),
    the last embeddings and the summary."""
    lines = text.rstrip("\n").split("\n")
    cut = lines.index("summary") if "summary" in lines else len(lines)
    progress = [ln for ln in lines[:cut] if ln.strip()]
    firsts = [i for i, ln in enumerate(progress) if "] embedding v" in ln][:2]
    head = firsts[-1] + 1 if firsts else 4
    shown = (
        progress[:head] + (["   ..."] if len(progress) > head + 3 else []) + progress[max(head, len(progress) - 3) :]
    )
    return "```text\n$ " + src.command + "\n" + "\n".join(shown + [""] + lines[cut:]) + "\n```"


def command_output(src: Source, text: str) -> str:
    """A command's stdout, whole, under the command."""
    return "```text\n$ " + src.command + "\n" + text.rstrip("\n") + "\n```"


def _cell(v: object) -> str:
    if isinstance(v, float):
        return f"{v:,.4g}" if abs(v) < 1000 else f"{v:,.0f}"
    return "" if v is None else str(v)


def _dig(row: dict, key: str) -> object:
    """`row[key]`, where a dotted key reaches into nested objects (``cpu.fuzz.bench``)."""
    v: object = row
    for part in key.split("."):
        v = v.get(part) if isinstance(v, dict) else None
    return v


def jsonl_table(
    columns: tuple[tuple[str, str], ...], keep: Callable[[dict], bool] = lambda r: True
) -> Callable[[Source, str], str]:
    """A renderer for a command's JSON lines (a bench's ``--json``): one table row per kept line,
    one column per (header, key; dotted keys reach into nested objects)."""

    def render_jsonl(src: Source, text: str) -> str:
        rows = [json.loads(ln) for ln in text.splitlines() if ln.strip().startswith("{")]
        lines = ["| " + " | ".join(h for h, _ in columns) + " |", "|" + "---|" * len(columns)]
        lines += ["| " + " | ".join(_cell(_dig(r, k)) for _, k in columns) + " |" for r in rows if keep(r)]
        return "\n".join(lines) + f"\n\nFrom `{src.command}` (its output: `docs/{src.file}`)."

    return render_jsonl


def zoo_seed_means(rows: tuple[tuple[str, str, str, str], ...]) -> Callable[[Source, str], str]:
    """A renderer of `sme bench zoo --json` runs kept in several files: per (label, world as the bench
    names it, file under docs/, the command that wrote it), the means over the file's seeds of the
    final error, trustworthiness, goal fraction and the sensor-only peers; the worst ratio after
    convergence (the largest over the seeds) and the false alarms (summed)."""

    def mean(runs: list[dict], key: str) -> float | None:
        vals = [float(r[key]) for r in runs if r.get(key) is not None]
        return sum(vals) / len(vals) if vals else None

    def render(src: Source, text: str) -> str:
        head = (
            "world",
            "learner",
            "final error",
            "trustworthiness",
            "goal reached",
            "PCA",
            "Isomap",
            "worst after convergence",
            "false alarms",
            "seeds",
            "command (its output)",
        )
        lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
        for label, world, file, command in rows:
            found = [json.loads(ln) for ln in (DOCS / file).read_text().splitlines() if ln.strip().startswith("{")]
            runs = [r for r in found if not r.get("summary") and r.get("world") == world]
            if not runs:
                raise ValueError(f"no runs of {world!r} in docs/{file}")
            worst = [float(r["worst_ratio"]) for r in runs if r.get("worst_ratio") is not None]
            cells = (
                label,
                runs[0].get("learner"),
                mean(runs, "final_error"),
                mean(runs, "trustworthiness"),
                mean(runs, "goal_reached_fraction"),
                mean(runs, "pca_error"),
                mean(runs, "isomap_error"),
                f"{max(worst):.2f}x" if worst else None,
                sum(int(r.get("drops") or 0) for r in runs),
                len(runs),
                (command if command.startswith("(") else f"`{command}`") + f" (`docs/{file}`)",
            )
            lines.append("| " + " | ".join(_cell(c) for c in cells) + " |")
        return "\n".join(lines)

    return render


def markdown_file(src: Source, text: str) -> str:
    """A markdown file the command wrote itself (its ``--out FILE.md``), as it is."""
    return f"{text.strip()}\n\n(`docs/{src.file}`, as `{src.command}` wrote it.)"


def report_summary(src: Source, text: str) -> str:
    """Per chapter of a `sme reproduce all` folder: wall time and the verdicts of its rows, judged
    again from the chapter's results.json by the report's own rules (tools/experiments/report.py)."""
    from sensorimotor.tools.experiments import report

    meta = json.loads(text)
    folder = (DOCS / src.file).parent
    quick = "--quick" in src.command
    lines = ["| chapter | wall time | CPU time | met | not met | not comparable |", "|---|---|---|---|---|---|"]

    def cpu(info: dict) -> str:
        c = info.get("cpu_seconds")
        return "not recorded" if c is None else f"{c:.0f} s"

    totals = dict.fromkeys((report.MET, report.NOT_MET, report.NOT_COMPARABLE), 0)
    for name, info in meta["chapters"].items():
        if info.get("error"):
            lines.append(f"| {name} | {info['seconds']:.0f} s | {cpu(info)} | failed | | |")
            continue
        rows = report.chapter_rows(name, json.loads((folder / name / "results.json").read_text()), quick)
        n = {v: sum(r.verdict == v for r in rows) for v in totals}
        totals = {v: totals[v] + n[v] for v in totals}
        lines.append(
            f"| {name} | {info['seconds']:.0f} s | {cpu(info)} | {n[report.MET]} | {n[report.NOT_MET]} "
            f"| {n[report.NOT_COMPARABLE]} |"
        )
    total = meta.get("total")
    cpus = [c.get("cpu_seconds") for c in meta["chapters"].values()]
    cpu_all = "not recorded" if None in cpus else f"{sum(cpus):.0f} s"
    lines.append(
        f"| all | {'unknown' if total is None else f'{total:.0f} s ({total / 60:.1f} min)'} | {cpu_all} | {totals[report.MET]} "
        f"| {totals[report.NOT_MET]} | {totals[report.NOT_COMPARABLE]} |"
    )
    rel = folder.relative_to(DOCS)
    out = (
        "\n".join(lines)
        + f"\n\nFrom `{src.command}` (its `run.json` and each chapter's `results.json`: `docs/{rel}/`)."
    )
    load = folder / "load.log"  # `date +%T` and /proc/loadavg, sampled every minute while it ran
    if load.exists():
        one = [float(ln.split()[1]) for ln in load.read_text().splitlines() if ln.strip()]
        out += (
            f" The machine's 1-minute load average while it ran: {min(one):.1f} to {max(one):.1f} "
            f"(median {sorted(one)[len(one) // 2]:.1f}; {len(one)} samples of `/proc/loadavg`, `docs/{rel}/load.log`)."
        )
    return out


def lesion_sweep_table(src: Source, text: str) -> str:
    """The lesion sweep's table (its JSON's ``markdown``), with the command and file."""
    data = json.loads(text)
    return f"{data['markdown'].strip()}\n\nFrom `{data['command']} --out ...` (its JSON: `docs/{src.file}`)."


def objectpose_isomap(src: Source, text: str) -> str:
    """Isomap's Procrustes error per neighbourhood size, and the generic program's per embedding
    (seed 0): the caveat under the object-pose table."""
    r = json.loads(text)["results"][0]
    iso = ", ".join(f"{k} neighbours {v:.3f}" for k, v in r["isomap_errors"].items())
    errs = ", ".join(f"{e:.4f}" for e in r["errors"])
    return (
        f"Seed {r['seed']}: Isomap {iso}; the generic program's embeddings in turn {errs}.\n\n"
        f"From `{src.command}` (its `results.json`: `docs/{src.file}`)."
    )


SOURCES: dict[str, Source] = {
    "demo": Source("sme demo --steps 12000 --seconds 120", "results/demo/output.txt", demo_output),
    "gridworld-quick": Source(
        "sme reproduce gridworld --runs 3 --quick", "results/gridworld-quick/results.json", reproduce_table
    ),
    "gridworld": Source("sme reproduce gridworld --runs 3", "results/gridworld/results.json", reproduce_table),
    "vergence-quick": Source(
        "sme reproduce vergence --runs 2 --quick", "results/vergence-quick/results.json", reproduce_table
    ),
    "chapter9-quick": Source("sme reproduce chapter9 --quick", "results/chapter9-quick/results.json", reproduce_table),
    "objectpose": Source("sme reproduce objectpose --runs 5", "results/objectpose/results.json", reproduce_table),
    "rovingeye": Source("sme reproduce rovingeye --runs 5", "results/rovingeye/results.json", reproduce_table),
    "objectpose-isomap": Source(
        "sme reproduce objectpose --runs 5", "results/objectpose/results.json", objectpose_isomap
    ),
    "lesion-sweep": Source("", "results/lesion-sweep/lesion_sweep.json", lesion_sweep_table),
    "arm": Source("sme reproduce arm --runs 5", "results/arm/results.json", reproduce_table),
    "arm-live": Source(
        "python -m sensorimotor.tools.experiments.arm_live --seeds 5 --seconds 480",
        "results/arm-live/output.txt",
        command_output,
    ),
    "arm-live-changes": Source(
        "python -m sensorimotor.tools.experiments.arm_live --seeds 3 --seconds 300 --changes",
        "results/arm-live-changes/output.txt",
        command_output,
    ),
    "bench-world-arm": Source("sme bench world --world arm", "results/bench-world-arm/output.txt", command_output),
    "arm-truth": Source(
        "python -m sensorimotor.tools.experiments.arm_truth --n-joints 7 --poses 200000",
        "results/arm-truth/output.md",
        markdown_file,
    ),
    "arm-many-joints": Source(
        "sme bench zoo --defaults --seeds 3 --json --world kuka --world xarm6",
        "results/bench-zoo-arms/runs.jsonl",
        jsonl_table(
            (
                ("world (`--world` names it)", "world"),
                ("seed", "seed"),
                ("steps", "steps"),
                ("learner", "learner"),
                ("starts", "n_starts"),
                ("final error", "final_error"),
                ("best", "best_error"),
                ("trustworthiness", "trustworthiness"),
                ("goal reached", "goal_reached_fraction"),
                ("maps published", "embeddings"),
                ("steps/s", "steps_per_second"),
                ("PCA", "pca_error"),
                ("Isomap", "isomap_error"),
                ("worse than 1.5x the best before", "regressions"),
                ("false alarms", "drops"),
            ),
            keep=lambda r: not r.get("summary"),
        ),
    ),
    "zoo-defaults": Source(
        'sme bench zoo --defaults --seeds 3 --json --world FrozenLake --world CliffWalking --world "CliffWalking slippery" --world MiniGrid',
        "results/bench-zoo-defaults/runs.jsonl",
        jsonl_table(
            (
                ("world (`--world` names it)", "world"),
                ("learner", "learner"),
                ("final error", "final_error"),
                ("best", "best_error"),
                ("trustworthiness", "trustworthiness"),
                ("goal reached", "goal_reached_fraction"),
                ("optimal policy: goal", "optimal_goal_fraction"),
                ("optimal policy: error", "optimal_error"),
                ("steps to 1.5x final", "steps_to_1.5x_final"),
                ("steps/s", "steps_per_second"),
                ("PCA", "pca_error"),
                ("Isomap", "isomap_error"),
                ("worst after convergence", "worst_ratio"),
                ("false alarms", "drops"),
            ),
            keep=lambda r: bool(r.get("summary")),
        ),
    ),
    "zoo-defaults-short": Source(
        'sme bench zoo --defaults --seeds 3 --json --world FrozenLake --world CliffWalking --world "CliffWalking slippery" --world MiniGrid',
        "results/bench-zoo-defaults/runs.jsonl",
        jsonl_table(
            (
                ("world", "world"),
                ("learner", "learner"),
                ("final error", "final_error"),
                ("goal reached", "goal_reached_fraction"),
                ("optimal policy's goal", "optimal_goal_fraction"),
                ("optimal policy's error", "optimal_error"),
            ),
            keep=lambda r: bool(r.get("summary")),
        ),
    ),
}
SOURCES["detectors-quick"] = Source(
    "sme bench detectors --worlds gridworld,retina,vergence,mountaincar --quick --out FILE.md",
    "reproduce/detectors-quick.md",
    markdown_file,
)
SOURCES["bench-detectors"] = Source(
    "sme bench detectors --retina-seeds 0 --worlds none --json",
    "results/bench-detectors/output.jsonl",
    jsonl_table(
        (
            ("detector", "detector"),
            ("median delay (steps)", "median_delay"),
            ("missed (of the seeds)", "missed"),
            ("seeds", "seeds"),
            ("false alarms / 10k", "false_alarms_per_10k"),
        ),
        lambda r: r.get("streams") == "synthetic",
    ),
)
SOURCES["bench-loop"] = Source("sme bench loop --steps 20000", "results/bench-loop/output.txt", command_output)
SOURCES["bench-world"] = Source("sme bench world --world retina", "results/bench-world/output.txt", command_output)
SOURCES["bench-gap"] = Source("sme bench gap --seconds 20", "results/bench-gap/output.txt", command_output)
SOURCES["bench-scale"] = Source("sme bench scale", "results/bench-scale/output.txt", command_output)
SOURCES["bench-scale-work"] = Source(
    "sme bench scale --worlds 8 --agent-work-us 2000 --rounds 1 --no-failover",
    "results/bench-scale-work/output.txt",
    command_output,
)
SOURCES["bench-soak"] = Source(
    "sme bench soak --minutes 30 --out DIR  # its lines after the JSON summary (kept as summary.json beside)",
    "results/bench-soak/output.txt",
    command_output,
)
SOURCES["bench-fuzz"] = Source(
    "sme bench fuzz --messages 10000 --json",
    "results/bench-fuzz/output.jsonl",
    jsonl_table(
        (
            ("sent", "sent"),
            ("counted", "counted"),
            ("crashes", "crashes"),
            ("good world Procrustes", "good_world_procrustes"),
            ("steps/s without (mean of before and after)", "baseline_steps_per_s"),
            ("steps/s during the fuzz", "fuzz_steps_per_s"),
            ("ratio", "step_rate_ratio"),
            ("hand-offs", "handoffs"),
            ("settled after (s)", "settle_seconds"),
            ("cores: agent", "cpu.fuzz.agent"),
            ("workers", "cpu.fuzz.workers"),
            ("world", "cpu.fuzz.world"),
            ("fuzzer", "cpu.fuzz.bench"),
            ("machine busy", "cpu.fuzz.machine_busy"),
        )
    ),
)
SOURCES["zoo-continuous"] = Source(
    "sme bench zoo --seeds 3 --json --world NAME",
    "results/bench-zoo-mountaincar/runs.jsonl",
    zoo_seed_means(
        (
            (
                "MountainCar-v0",
                "MountainCar",
                "results/bench-zoo-mountaincar/runs.jsonl",
                "sme bench zoo --seeds 3 --world MountainCar",
            ),
            (
                "MountainCarContinuous-v0, padded sum",
                "MountainCarContinuous",
                "results/bench-zoo-mountaincar/runs.jsonl",
                "(the same command)",
            ),
            (
                "MountainCarContinuous-v0, DTW (`distance=dtw`)",
                "MountainCarContinuous, DTW",
                "results/bench-zoo-mountaincar/runs.jsonl",
                "(the same command)",
            ),
            (
                "PandaReach-v3, hand position, at the defaults (the program picks net moves, half moves)",
                "PandaReach (state)",
                "results/bench-zoo-panda/state-defaults.jsonl",
                'sme bench zoo --defaults --seeds 3 --world "PandaReach (state)"',
            ),
            (
                "PandaReach-v3, hand position, net moves, half moves (`distance=net`, `action_scale=0.5`)",
                "PandaReach (state), net move, half moves",
                "results/bench-zoo-panda/state-net-half-moves.jsonl",
                'sme bench zoo --seeds 3 --world "PandaReach (state), net move"',
            ),
            (
                "PandaReach-v3, 64 x 64 grey frames (`observe=pixels`), at the defaults (the program picks net moves, half moves)",
                "PandaReach (pixels)",
                "results/bench-zoo-panda/pixels-defaults.jsonl",
                'sme bench zoo --defaults --seeds 3 --world "PandaReach (pixels)"',
            ),
            (
                "PandaReach-v3, 64 x 64 grey frames, net moves, half moves, whole-move warm-up (`distance=net`, `action_scale=0.5`, `motor_scale=1`)",
                "PandaReach (pixels), half moves, whole-move warm-up",
                "results/bench-zoo-panda/pixels-ranked-by-ends.jsonl",
                'sme bench zoo --seeds 3 --world "PandaReach (pixels), half moves, whole-move warm-up"',
            ),
        )
    ),
)


def _bench_changes(name: str) -> Callable[[Source, str], str]:
    """A renderer of tools/bench/changes.py (imported when a page is rendered)."""

    def render(src: Source, text: str) -> str:
        from sensorimotor.tools.bench import changes

        return str(getattr(changes, name)(src, text))

    return render


SOURCES["demo-perturb"] = Source(
    "sme demo --world gym:FrozenLake-v1 --param map_name=8x8 --param is_slippery=false --perturb permute@3000 "
    "--seconds 40",
    "results/demo-perturb/output.txt",
    demo_output,
)
SOURCES["bench-changes"] = Source(
    "sme bench changes --seeds 3 --json", "results/bench-changes/runs.jsonl", _bench_changes("render_scorecard")
)
#: the project's own worlds in the scorecard (tools/bench/changes_families.py), one kept output each
for _family, _world, _seeds in (
    ("gridworld", "Gridworld", 3),
    ("arm", "2 joints", 3),
    ("rovingeye", "Roving eye", 3),
    ("retina", "Retina", 3),
    ("mountaincar", "Mountain car", 3),
):
    SOURCES[f"bench-changes-{_family}"] = Source(
        f'sme bench changes --seeds {_seeds} --world "{_world}" --json',
        f"results/bench-changes-{_family}/runs.jsonl",
        _bench_changes("render_scorecard"),
    )
SOURCES["bench-changes-life"] = Source(
    "sme bench changes --life 20 --seeds 1 --json",
    "results/bench-changes-life/runs.jsonl",
    _bench_changes("render_life"),
)
SOURCES["bench-changes-life-families"] = Source(
    'sme bench changes --life 20 --seeds 1 --json --world Gridworld --world "2 joints" --world "Roving eye"',
    "results/bench-changes-life/families.jsonl",
    _bench_changes("render_life"),
)
#: `sme reproduce all --quick --runs 10 --out docs/reproduce/report-quick`: its summary and chapter tables
QUICK_ALL = "sme reproduce all --quick --runs 10"
SOURCES["report-quick"] = Source(QUICK_ALL, "reproduce/report-quick/run.json", report_summary)
for _chapter, _block in (
    ("retina", "retina-quick"),
    ("retina-natural", "retina-natural-quick"),
    ("gridworld", "gridworld-all-quick"),
):
    SOURCES[_block] = Source(QUICK_ALL, f"reproduce/report-quick/{_chapter}/results.json", reproduce_table)


def render(name: str) -> str:
    """The markdown of block `name` from its stored file."""
    src = SOURCES[name]
    return src.render(src, (DOCS / src.file).read_text())


def rewrite(text: str) -> str:
    """`text` with every results block regenerated (a ValueError for a block with no source)."""

    def sub(m: re.Match[str]) -> str:
        name = m.group(2)
        if name not in SOURCES:
            raise ValueError(f"no source for results block {name!r}; known: {', '.join(SOURCES)}")
        return f"{m.group(1)}{render(name)}\n{m.group(4)}"

    return BLOCK.sub(sub, text)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensorimotor.tools.docgen.results_doc", description=__doc__)
    p.add_argument("pages", nargs="*", help=f"pages to rewrite (default: {', '.join(PAGES)})")
    p.add_argument("--check", action="store_true", help="exit 1 if a page's blocks differ from their sources")
    args = p.parse_args(argv)
    drift = []
    for page in args.pages or [str(ROOT / x) for x in PAGES]:
        path = Path(page)
        text = path.read_text()
        new = rewrite(text)
        if args.check:
            if new != text:
                drift.append(str(path))
        elif new != text:
            path.write_text(new)
    if drift:
        print(f"results drifted from their sources in: {', '.join(drift)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
