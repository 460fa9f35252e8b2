"""Every `>>>` example in the package runs and prints what it says (the examples a reader copies
are checked like any other test). Examples that need a running bus are marked ``+SKIP``."""

from __future__ import annotations

import doctest
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MODULES = sorted(
    "sensorimotor." + ".".join(p.relative_to(ROOT).with_suffix("").parts)
    for pkg in ("protocol", "agent", "worlds", "tools")
    for p in (ROOT / pkg).rglob("*.py")
    if ">>>" in p.read_text()
)


def test_the_examples_are_found():
    assert len(MODULES) >= 15, MODULES


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_of(name: str):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, report=True)
    assert result.attempted > 0
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed (see above)"
