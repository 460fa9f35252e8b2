"""Sphinx configuration of the documentation site (`sphinx-build -W -b html docs docs/_build/html`).

Sphinx with the furo theme and MyST markdown, as Gymnasium's site is built: MkDocs 1.x is no longer
maintained and mkdocs-material has been in maintenance mode since late 2025, while Sphinx's autodoc
reads the package's numpy-style docstrings directly (napoleon) for the API reference.

Every page under docs/ is listed once in the index's toctrees (tests/test_docs.py checks it); the
commands' `--help` texts are written into docs/_generated/ from the real parser at each build, so
the reference cannot drift."""

from __future__ import annotations

import os
from pathlib import Path

HERE = Path(__file__).resolve().parent

project = "sensorimotor-embedding"
author = "the sensorimotor-embedding authors"
copyright = "the sensorimotor-embedding authors"
extensions = ["myst_parser", "sphinx.ext.autodoc", "sphinx.ext.napoleon", "sphinx.ext.viewcode"]
source_suffix = {".md": "markdown"}
master_doc = "index"
exclude_patterns = [
    "_build",
    "_generated/**/*.md",
    "tutorials/*.py",
    "**/README.md",
    # each chapter's table as the command wrote it: the report beside it shows it already
    "reproduce/*/*/table.md",
]
html_theme = "furo"
html_title = "sensorimotor-embedding"
html_static_path = ["_static"]
myst_enable_extensions = ["colon_fence"]
myst_heading_anchors = 4
# generated result tables (docs/reproduce/...) are linked from their page, not listed in a toctree
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
napoleon_numpy_docstring = True
napoleon_google_docstring = False
napoleon_use_rtype = False
napoleon_use_ivar = (
    True  # dataclass fields: autodoc documents them; "Attributes" sections become fields, not duplicates
)
suppress_warnings = ["myst.strikethrough", "toc.not_included"]
nitpicky = False


def write_help_pages() -> None:
    """`sme COMMAND --help` of every command into docs/_generated/help/COMMAND.txt (100 columns)."""
    import argparse

    os.environ["COLUMNS"] = "100"
    from sensorimotor.tools.cli import build_parser

    out = HERE / "_generated" / "help"
    out.mkdir(parents=True, exist_ok=True)

    def walk(p: argparse.ArgumentParser, path: list[str]):
        for a in p._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, child in a.choices.items():
                    yield path + [name], child
                    yield from walk(child, path + [name])

    top = build_parser()
    (out / "sme.txt").write_text(top.format_help())
    for path, parser in walk(top, []):
        text = parser.format_help()
        target = out / ("-".join(path) + ".txt")
        if not target.exists() or target.read_text() != text:
            target.write_text(text)


write_help_pages()
