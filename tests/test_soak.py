"""`sme bench soak` smoke test: a short soak writes its samples, plot and summary."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from tests.conftest import ROOT

pytestmark = pytest.mark.integration


def test_short_soak_writes_json_lines_png_and_summary(tmp_path):
    out = tmp_path / "soak"
    r = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "bench", "soak", "--minutes", "0.25", "--every", "5"]
        + ["--out", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    rows = [json.loads(line) for line in (out / "soak.jsonl").read_text().splitlines()]
    assert len(rows) >= 3
    names = {"agent", "gridworld", "retina", "mountaincar", "recorder"}
    assert set(rows[-1]["procs"]) == names
    assert all(rows[-1]["procs"][n]["alive"] and rows[-1]["procs"][n]["rss_mb"] > 0 for n in names)
    assert (out / "soak.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    summary = json.loads((out / "summary.json").read_text())
    assert set(summary["procs"]) == names and "rss_growth_pct" in summary["procs"]["agent"]
    assert not (out / "soak.mcap").exists()  # the recording is deleted unless --keep-recording
    assert "after the warm-up" in r.stdout
