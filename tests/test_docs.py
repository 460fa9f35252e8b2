"""The documentation keeps its promises: every shell block either runs in a test (and says which)
or says why it is not run; the blocks marked `run` are run here; the result tables and samples
equal the files of the commands they cite (tools/docgen/results_doc.py)."""

from __future__ import annotations

import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = sorted(
    [ROOT / "README.md", ROOT / "protocol" / "README.md"]
    + [p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts and "_generated" not in p.parts]
)
SHELL = {"sh", "bash", "shell", "console", "zsh"}
FENCE = re.compile(r"^(`{3,}|~{3,})\s*([\w-]*)")
MARK = re.compile(r"^<!-- (tested|run|not run): (.+?) -->$")


def shell_blocks(path: Path) -> list[tuple[int, list[str], re.Match[str] | None]]:
    """(line number, lines, the marker before it or None) of every shell block of a page: fences
    tagged sh/bash/shell/console, and untagged ones whose first line is a command."""
    lines = path.read_text().split("\n")
    out, i = [], 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, info = m.group(1), m.group(2)
        j = i + 1
        while j < len(lines) and not lines[j].startswith(fence):
            j += 1
        body = lines[i + 1 : j]
        first = next((b.strip() for b in body if b.strip()), "")
        if info in SHELL or (not info and re.match(r"^(\$ )?(sme|python3?(\.\d+)?|pip|\.venv/)\b", first)):
            prev = next((lines[k].strip() for k in range(i - 1, -1, -1) if lines[k].strip()), "")
            out.append((i + 1, body, MARK.match(prev)))
        i = j + 1
    return out


BLOCKS = [(p, n, body, mark) for p in PAGES for n, body, mark in shell_blocks(p)]


def _id(block) -> str:
    return f"{block[0].relative_to(ROOT)}:{block[1]}"


def test_the_pages_have_shell_blocks_to_check():
    assert len(BLOCKS) >= 10 and any(m and m.group(1) == "run" for *_, m in BLOCKS)


@pytest.mark.parametrize("block", BLOCKS, ids=_id)
def test_every_shell_block_runs_in_a_test_or_says_why_not(block):
    path, n, body, mark = block
    assert mark, (
        f"{path.relative_to(ROOT)}:{n}: a shell block without `<!-- tested: tests/FILE.py::TEST -->`, "
        "`<!-- run: WHAT -->` or `<!-- not run: WHY -->` on the line before it"
    )
    if mark.group(1) == "tested":
        ref = mark.group(2).split()[0]
        file, _, name = ref.partition("::")
        assert (ROOT / file).is_file(), ref
        assert re.search(rf"^def {re.escape(name.split('[')[0])}\(", (ROOT / file).read_text(), re.M), ref


def _commands(body: list[str]) -> list[list[str]]:
    out = []
    for line in body:
        line = line.split(" #", 1)[0].strip().removeprefix("$ ")
        if line:
            argv = shlex.split(line)
            assert argv[0] == "sme", f"a `run` block runs sme commands only: {line}"
            out.append([sys.executable, "-m", "sensorimotor.tools.cli", *argv[1:]])
    return out


RUN = [b for b in BLOCKS if b[3] and b[3].group(1) == "run"]


@pytest.mark.parametrize("block", RUN, ids=_id)
def test_blocks_marked_run_run(block):
    for argv in _commands(block[2]):
        out = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, (argv, out.stderr[-2000:])


def test_result_tables_and_samples_equal_their_sources():
    from sensorimotor.tools.docgen.results_doc import SOURCES, main

    assert main(["--check"]) == 0, "run `python -m sensorimotor.tools.docgen.results_doc` after refreshing a result"
    pages = "".join(p.read_text() for p in PAGES)
    for name in SOURCES:  # every source is shown somewhere
        assert f"<!-- BEGIN results: {name} -->" in pages, name


def test_the_readme_is_short_and_keeps_the_two_commands():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    assert "python3.11 -m venv .venv && .venv/bin/pip install -e . && .venv/bin/sme demo" in text
    ci = (ROOT / ".ci" / "run").read_text()
    test_cmd = "python3.11 -m venv .venv && .venv/bin/pip install -e '.[test]' && .venv/bin/python -m pytest"
    assert test_cmd in text and test_cmd in ci


def test_a_changed_number_in_a_generated_block_is_drift(tmp_path):
    from sensorimotor.tools.docgen.results_doc import main, render

    page = tmp_path / "page.md"
    block = render("objectpose")
    page.write_text(f"<!-- BEGIN results: objectpose -->\n{block}\n<!-- END results: objectpose -->\n")
    assert main(["--check", str(page)]) == 0
    assert "0.0092" in block  # the sensorimotor embedding's error after 10 embeddings, from results.json
    page.write_text(page.read_text().replace("0.0092", "0.0091", 1))
    assert main(["--check", str(page)]) == 1
    assert main([str(page)]) == 0 and "0.0092" in page.read_text()  # regenerated from the file


#: what may carry a decimal outside a generated block: figure, table, chapter and equation numbers
_LABEL = re.compile(r"(Figs?|Table|Chapter|ch\.|section|Eq|chapter) \d+(\.\d+)*(-\d+(\.\d+)*)?")


def numbers_outside_blocks(text: str) -> list[str]:
    """Measured-looking numbers (decimals, durations in seconds) outside generated blocks, inline
    code, images and headings: a page's figures must come from its blocks."""
    text = re.sub(r"<!-- BEGIN results: ([\w.-]+) -->.*?<!-- END results: \1 -->", "", text, flags=re.S)
    text = "\n".join(ln for ln in text.splitlines() if not ln.startswith(("#", "![")))
    text = _LABEL.sub("", re.sub(r"`[^`]*`", "", text))
    return re.findall(r"\d+\.\d+|\d[\d,]* s\b", text)


def test_results_page_has_no_number_outside_its_generated_blocks():
    assert (
        numbers_outside_blocks("Fig 5.4 (`--steps 1.5`)\n<!-- BEGIN results: a -->\n0.5 ± 1\n<!-- END results: a -->")
        == []
    )
    assert numbers_outside_blocks("the error fell to 0.01 in 485 s") == ["0.01", "485 s"]
    for page in ("docs/results.md",):
        assert numbers_outside_blocks((ROOT / page).read_text()) == [], page


def test_the_index_lists_every_page_once():
    """docs/index.md names each top-level page in exactly one toctree (no glob repeating the named
    pages, no page left for a reader to find by chance)."""
    text = (ROOT / "docs" / "index.md").read_text()
    entries = []
    for body in re.findall(r"```\{toctree\}\n(.*?)```", text, re.S):
        assert ":glob:" not in body, "a glob toctree lists the named pages again"
        entries += [ln.strip() for ln in body.splitlines() if ln.strip() and not ln.startswith(":")]
    assert len(entries) == len(set(entries)), sorted(e for e in entries if entries.count(e) > 1)
    pages = {p.stem for p in (ROOT / "docs").glob("*.md")} - {"index"}
    assert pages <= set(entries), f"pages missing from the index: {sorted(pages - set(entries))}"
    for e in entries:
        assert (ROOT / "docs" / f"{e}.md").exists(), e
