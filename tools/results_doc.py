"""The documentation's result tables and sample outputs, generated from the files of the commands
they cite, so that no number in them is typed by hand.

Each source is a command and the file it wrote, kept under docs/results/NAME/ (`results.json` of
`sme reproduce CHAPTER ... --out DIR`, or the stdout of `sme demo`). A page holds a block between
``<!-- BEGIN results: NAME -->`` and ``<!-- END results: NAME -->``;
`python -m sensorimotor.tools.results_doc PAGE...` rewrites every block from its source and
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

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "docs" / "results"
BLOCK = re.compile(r"(<!-- BEGIN results: ([\w.-]+) -->\n)(.*?)(<!-- END results: \2 -->)", re.S)
PAGES = ("README.md", "docs/getting-started.md", "docs/results.md", "docs/arm.md")


@dataclass(frozen=True)
class Source:
    """A command and the file it wrote, rendered into a block of markdown."""

    command: str
    file: str  # relative to docs/results/
    render: Callable[[Source, str], str]


def reproduce_table(src: Source, text: str) -> str:
    """The table `sme reproduce` wrote (its results.json's ``markdown``), with the command and file."""
    data = json.loads(text)
    return f"{data['markdown'].strip()}\n\nFrom `{src.command}` (its `results.json`: `docs/results/{src.file}`)."


def demo_output(src: Source, text: str) -> str:
    """The demo's stdout: its first lines, the last embeddings and the summary."""
    lines = text.rstrip("\n").split("\n")
    cut = lines.index("summary") if "summary" in lines else len(lines)
    progress = [ln for ln in lines[:cut] if ln.strip()]
    shown = progress[:4] + (["   ..."] if len(progress) > 7 else []) + progress[max(4, len(progress) - 3) :]
    return "```text\n$ " + src.command + "\n" + "\n".join(shown + [""] + lines[cut:]) + "\n```"


def command_output(src: Source, text: str) -> str:
    """A command's stdout, whole, under the command."""
    return "```text\n$ " + src.command + "\n" + text.rstrip("\n") + "\n```"


SOURCES: dict[str, Source] = {
    "demo": Source("sme demo --steps 12000 --seconds 120", "demo/output.txt", demo_output),
    "gridworld-quick": Source(
        "sme reproduce gridworld --runs 3 --quick", "gridworld-quick/results.json", reproduce_table
    ),
    "gridworld": Source("sme reproduce gridworld --runs 3", "gridworld/results.json", reproduce_table),
    "vergence-quick": Source("sme reproduce vergence --runs 2 --quick", "vergence-quick/results.json", reproduce_table),
    "chapter9-quick": Source("sme reproduce chapter9 --quick", "chapter9-quick/results.json", reproduce_table),
    "objectpose": Source("sme reproduce objectpose --runs 5", "objectpose/results.json", reproduce_table),
    "rovingeye": Source("sme reproduce rovingeye --runs 5", "rovingeye/results.json", reproduce_table),
    "arm": Source("sme reproduce arm --runs 5", "arm/results.json", reproduce_table),
    "bench-world-arm": Source("sme bench world --world arm", "bench-world-arm/output.txt", command_output),
}


def render(name: str) -> str:
    """The markdown of block `name` from its stored file."""
    src = SOURCES[name]
    return src.render(src, (RESULTS / src.file).read_text())


def rewrite(text: str) -> str:
    """`text` with every results block regenerated (a ValueError for a block with no source)."""

    def sub(m: re.Match[str]) -> str:
        name = m.group(2)
        if name not in SOURCES:
            raise ValueError(f"no source for results block {name!r}; known: {', '.join(SOURCES)}")
        return f"{m.group(1)}{render(name)}\n{m.group(4)}"

    return BLOCK.sub(sub, text)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m sensorimotor.tools.results_doc", description=__doc__)
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
