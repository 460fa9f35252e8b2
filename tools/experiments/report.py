"""The one report of `sme reproduce all`: per chapter, each claim of the dissertation beside our number
(mean ± 95 % CI over seeded runs) and a verdict — met, not met, or not comparable — with the reason;
then the machine, versions, seeds and wall time. Written as report.md (figures linked) and
report.html (self-contained: figures embedded as data URIs, no server, no script).

The rows are read from each chapter's result dict (what `sme reproduce CHAPTER` writes to
results.json); the dissertation's numbers are those of `shared/SEED-NOTES.md`."""

from __future__ import annotations

import base64
import html
import importlib.metadata
import os
import platform
import re
import subprocess

from sensorimotor.tools.experiments.report_rows import (
    CHAPTER_ROWS,
    STEREO_BAR,
    chapter_rows,
    rows_chapter9,
    rows_gridworld,
    rows_mountaincar,
    rows_objectpose,
    rows_retina,
    rows_retina_natural,
    rows_rovingeye,
    rows_vergence,
)
from sensorimotor.tools.experiments.report_stats import (
    MET,
    NOT_COMPARABLE,
    NOT_MET,
    ChapterReport,
    Paired,
    Row,
    _paired_lower,
    ci95,
    fmt,
    paired,
)


def environment(root: str) -> dict[str, str]:
    """Machine, Python, the versions of the libraries the numbers depend on, and the git commit."""
    out = {
        "host": platform.node(),
        "platform": platform.platform(),
        "cpus": str(os.cpu_count()),
        "python": platform.python_version(),
    }
    for dist in (
        "sensorimotor-embedding",
        "numpy",
        "scipy",
        "scikit-learn",
        "pybullet",
        "eclipse-zenoh",
        "river",
        "ray",
    ):
        try:
            out[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            continue
    try:
        out["commit"] = subprocess.run(
            ["git", "-C", root, "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=5, check=True
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return out


# --- writing ------------------------------------------------------------------------------------------


def _secs(x: float) -> str:
    """A wall time for a heading: ``12 s``, or ``time unknown`` (a report rebuilt without run.json)."""
    return "time unknown" if x != x else f"{x:.0f} s"


def _md_cell(s: str) -> str:
    return s.replace("|", "\\|").replace("\n", " ")


def markdown(chapters: list[ChapterReport], header: dict[str, str], out: str) -> str:
    """report.md: the header, then per chapter its verdict table and figures (paths relative to `out`)."""
    lines = ["# The dissertation reproduced: `sme reproduce all`", ""]
    lines += [f"- **{k}**: {v}" for k, v in header.items()]
    counts = {v: sum(r.verdict == v for c in chapters for r in c.rows) for v in (MET, NOT_MET, NOT_COMPARABLE)}
    failed = [c.name for c in chapters if c.error]
    lines += [
        "",
        f"Verdicts: {counts[MET]} met, {counts[NOT_MET]} not met, {counts[NOT_COMPARABLE]} not comparable"
        + (f"; chapters that failed: {', '.join(failed)}" if failed else "; every chapter ran")
        + ".",
        "",
    ]
    for c in chapters:
        lines += [f"## {c.title} (`{c.name}`, {_secs(c.seconds)})", ""]
        if c.error:
            lines += ["**This chapter failed**; the others ran:", "", "```", c.error.rstrip(), "```", ""]
            continue
        lines += ["| measure | ours (mean ± 95 % CI) | dissertation | verdict | why |", "|---|---|---|---|---|"]
        lines += [
            f"| {' | '.join(_md_cell(x) for x in (r.measure, r.ours, r.dissertation, '**' + r.verdict + '**', r.why))} |"
            for r in c.rows
        ]
        lines.append("")
        lines += [f"![{os.path.basename(f)}]({os.path.relpath(f, out)})" for f in c.figures]
        lines += [
            "",
            f"<details><summary>The chapter's full table ({c.name}/table.md)</summary>",
            "",
            c.table,
            "",
            "</details>",
            "",
        ]
    return "\n".join(lines) + "\n"


_CSS = """body{font-family:system-ui,sans-serif;max-width:1100px;margin:2em auto;padding:0 1em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:90%}td,th{border:1px solid #ccc;padding:4px 8px;vertical-align:top}
th{background:#f3f3f3}.met{color:#176f2c;font-weight:bold}.notmet{color:#a32020;font-weight:bold}
.nc{color:#777;font-weight:bold}img{max-width:100%;margin:.5em 0;border:1px solid #eee}pre{background:#f7f7f7;padding:1em;overflow:auto}"""


def _inline(text: str) -> str:
    """Markdown inline code and bold to HTML (the chapters' tables use no other markup)."""
    t = html.escape(text)
    t = re.sub(r"`([^`]+)`", r"<code>\1</code>", t)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", t)


def md_to_html(md: str) -> str:
    """A chapter's table.md as HTML: pipe tables become tables, headings h4, other lines paragraphs."""
    out: list[str] = []
    table: list[list[str]] = []

    def flush() -> None:
        if table:
            head, *body = table
            out.append("<table><tr>" + "".join(f"<th>{_inline(c)}</th>" for c in head) + "</tr>")
            out.extend("<tr>" + "".join(f"<td>{_inline(c)}</td>" for c in row) + "</tr>" for row in body)
            out.append("</table>")
            table.clear()

    for line in md.splitlines():
        st = line.strip()
        if st.startswith("|"):
            cells = [c.strip() for c in st.strip("|").split("|")]
            if not all(set(c) <= set("-: ") for c in cells):
                table.append(cells)
            continue
        flush()
        if st.startswith("#"):
            out.append(f"<h4>{_inline(st.lstrip('#').strip())}</h4>")
        elif st.startswith("- "):
            out.append(f"<p>• {_inline(st[2:])}</p>")
        elif st:
            out.append(f"<p>{_inline(st)}</p>")
    flush()
    return "\n".join(out)


def _data_uri(path: str) -> str:
    with open(path, "rb") as f:
        return "data:image/png;base64," + base64.b64encode(f.read()).decode("ascii")


def html_report(chapters: list[ChapterReport], header: dict[str, str]) -> str:
    """report.html: the same content, self-contained (figures as data URIs, inline style, no script)."""
    e = html.escape
    cls = {MET: "met", NOT_MET: "notmet", NOT_COMPARABLE: "nc"}
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'>",
        "<title>sme reproduce all: report</title>",
        f"<style>{_CSS}</style></head><body>",
        "<h1>The dissertation reproduced: <code>sme reproduce all</code></h1><ul>",
    ]
    parts += [f"<li><b>{e(k)}</b>: {e(v)}</li>" for k, v in header.items()]
    parts.append("</ul>")
    for c in chapters:
        parts.append(f"<h2 id='{e(c.name)}'>{e(c.title)} (<code>{e(c.name)}</code>, {_secs(c.seconds)})</h2>")
        if c.error:
            parts.append(f"<p class='notmet'>This chapter failed; the others ran.</p><pre>{e(c.error)}</pre>")
            continue
        parts.append(
            "<table><tr><th>measure</th><th>ours (mean ± 95 % CI)</th><th>dissertation</th><th>verdict</th><th>why</th></tr>"
        )
        for r in c.rows:
            parts.append(
                f"<tr><td>{e(r.measure)}</td><td>{e(r.ours)}</td><td>{e(r.dissertation)}</td>"
                f"<td class='{cls.get(r.verdict, 'nc')}'>{e(r.verdict)}</td><td>{e(r.why)}</td></tr>"
            )
        parts.append("</table>")
        for f in c.figures:
            parts.append(
                f"<figure><img alt='{e(os.path.basename(f))}' src='{_data_uri(f)}'>"
                f"<figcaption>{e(os.path.basename(f))}</figcaption></figure>"
            )
        if c.table:
            parts.append(f"<details><summary>The chapter's full table</summary>{md_to_html(c.table)}</details>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def write_report(chapters: list[ChapterReport], header: dict[str, str], out: str) -> tuple[str, str]:
    """Write OUT/report.md and OUT/report.html; return their paths."""
    md, page = os.path.join(out, "report.md"), os.path.join(out, "report.html")
    with open(md, "w") as f:
        f.write(markdown(chapters, header, out))
    with open(page, "w") as f:
        f.write(html_report(chapters, header))
    return md, page


# the verdicts, statistics and rows are importable from here, as before the split
__all__ = [
    "CHAPTER_ROWS",
    "MET",
    "NOT_COMPARABLE",
    "NOT_MET",
    "STEREO_BAR",
    "ChapterReport",
    "Paired",
    "Row",
    "_paired_lower",
    "chapter_rows",
    "ci95",
    "environment",
    "fmt",
    "markdown",
    "html_report",
    "md_to_html",
    "paired",
    "rows_chapter9",
    "rows_gridworld",
    "rows_mountaincar",
    "rows_objectpose",
    "rows_retina",
    "rows_retina_natural",
    "rows_rovingeye",
    "rows_vergence",
    "write_report",
]
