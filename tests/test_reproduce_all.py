"""`sme reproduce all`: a tiny configuration (one quick chapter, two runs, and a chapter that fails)
gives one report in which every row has a verdict and the failure is reported; the HTML report is
opened in headless Chromium (installed by `.ci/run` where apt-get can), and its figures load."""

import json
import os
import re
import shutil
import subprocess

import pytest

from sensorimotor.tools.cli import main
from sensorimotor.tools.commands import reproduce
from sensorimotor.tools.experiments import report, shared

VERDICTS = {report.MET, report.NOT_MET, report.NOT_COMPARABLE}


def broken(runs, quick, workers, out):
    raise RuntimeError("this chapter is broken on purpose")


@pytest.fixture(scope="module")
def tiny_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("all")
    mp = pytest.MonkeyPatch()
    mp.setitem(reproduce.ALL, "broken", broken)
    mp.setitem(report.CHAPTER_ROWS, "broken", ("A chapter that fails", lambda res, quick: []))
    try:
        code = main(
            [
                "reproduce",
                "all",
                "--quick",
                "--runs",
                "2",
                "--workers",
                "1",
                "--chapters",
                "gridworld,broken",
                "--out",
                str(out),
            ]
        )
    finally:
        mp.undo()
    return code, out


def test_reproduce_all_writes_one_report_with_a_verdict_per_row(tiny_report, capsys):
    code, out = tiny_report
    assert code == 1  # a chapter failed: reported, and the exit status says so
    md = (out / "report.md").read_text()
    assert "## Chapter 5: robot position in a gridworld (`gridworld`" in md
    assert "## A chapter that fails (`broken`" in md and "this chapter is broken on purpose" in md
    rows = [line for line in md.splitlines() if line.startswith("| ") and "**" in line]
    assert len(rows) == 4
    for line in rows:
        verdict = re.search(r"\*\*(.+?)\*\*", line).group(1)
        assert verdict in VERDICTS, line
    assert "| random policy: Procrustes error |" in md
    for key in ("wall time", "machine", "versions", "seeds", "numpy"):
        assert key in md
    assert "![gridworld_lspi.png](gridworld/gridworld_lspi.png)" in md
    assert "trustworthiness / continuity / D_metric / D_topo" in md  # the chapter's full table is in
    with open(out / "gridworld" / "results.json") as f:
        grid = json.load(f)
    assert len(grid["results"]) == 6  # 2 runs x (plain, barrier, random)
    with open(out / "run.json") as f:
        run = json.load(f)["chapters"]["gridworld"]
    # the chapter's CPU time (one worker: this process's own) is kept beside its wall time
    assert 0 < run["cpu_seconds"] == grid["cpu_seconds"] and run["cpu_seconds"] <= 2 * run["seconds"] + 1
    page = (out / "report.html").read_text()
    assert "data:image/png;base64," in page and "src='gridworld/" not in page  # self-contained
    assert "<td class='met'>met</td>" in page


def test_bad_chapter_list_is_a_usage_error(tmp_path, capsys):
    assert main(["reproduce", "all", "--chapters", "nope", "--out", str(tmp_path)]) == 2
    assert "unknown chapter(s) nope" in capsys.readouterr().err
    assert main(["reproduce", "gridworld", "--chapters", "gridworld", "--out", str(tmp_path)]) == 2


CHECK = """<script>
window.addEventListener('load', () => {
  const imgs = [...document.images];
  document.body.setAttribute('data-check', JSON.stringify({
    images: imgs.length,
    loaded: imgs.filter(i => i.complete && i.naturalWidth > 0).length,
    text: document.body.innerText.trim().length,
    height: document.body.scrollHeight}));
});
</script></body>"""


def test_report_html_opens_in_headless_chromium_with_every_figure(tiny_report, tmp_path):
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    if browser is None:
        pytest.skip("chromium is not installed (Debian: apt-get install -y chromium; .ci/run does it as root)")
    _, out = tiny_report
    page = tmp_path / "checked.html"  # the report plus a probe that records what loaded
    page.write_text((out / "report.html").read_text().replace("</body>", CHECK))
    flags = [
        browser,
        "--headless",
        "--no-sandbox",
        "--disable-gpu",
        "--no-first-run",
        f"--user-data-dir={tmp_path / 'profile'}",
    ]
    dom = subprocess.run(
        [*flags, "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
        capture_output=True,
        text=True,
        timeout=120,
        check=True,
    ).stdout
    found = re.search(r"data-check=\"([^\"]+)\"", dom)
    assert found, dom[:500]
    check = json.loads(found.group(1).replace("&quot;", '"'))
    assert check["images"] >= 1 and check["loaded"] == check["images"]
    assert check["text"] > 500 and check["height"] > 500
    shot = tmp_path / "shot.png"
    subprocess.run(
        [*flags, "--window-size=1200,1600", f"--screenshot={shot}", (out / "report.html").as_uri()],
        capture_output=True,
        timeout=120,
        check=True,
    )
    import matplotlib.image

    pixels = matplotlib.image.imread(str(shot))
    assert pixels.std() > 0.05  # not a blank page
    assert os.path.getsize(shot) > 10_000


def test_report_only_judges_the_results_again_without_running(tiny_report, tmp_path):
    _, out = tiny_report
    before = (out / "report.md").read_text()
    with open(out / "run.json") as f:
        meta = json.load(f)
    assert meta["chapters"]["broken"]["error"] and meta["total"] > 0
    (out / "report.md").unlink()
    mp = pytest.MonkeyPatch()
    mp.setitem(reproduce.ALL, "broken", broken)
    mp.setitem(report.CHAPTER_ROWS, "broken", ("A chapter that fails", lambda res, quick: []))
    try:
        args = ["reproduce", "all", "--quick", "--runs", "2", "--chapters", "gridworld,broken", "--out", str(out)]
        assert main([*args, "--report-only"]) == 0
    finally:
        mp.undo()
    after = (out / "report.md").read_text()
    table = [line for line in before.splitlines() if line.startswith("| ")]
    assert table == [line for line in after.splitlines() if line.startswith("| ")]
    assert "this chapter is broken on purpose" in after


def test_resume_keeps_the_finished_chapters_and_runs_the_rest(tiny_report, tmp_path, capsys):
    _, first = tiny_report
    out = tmp_path / "resumed"
    shutil.copytree(first, out)
    before = json.loads((out / "gridworld" / "results.json").read_text())
    calls = []

    def fixed(runs, quick, workers, out_dir):
        calls.append(runs)
        return {"markdown": "fixed now", "cpu_seconds": 0.0}

    mp = pytest.MonkeyPatch()
    mp.setitem(reproduce.ALL, "broken", fixed)
    mp.setitem(report.CHAPTER_ROWS, "broken", ("A chapter that fails", lambda res, quick: []))
    try:
        args = ["reproduce", "all", "--quick", "--runs", "2", "--workers", "1", "--chapters", "gridworld,broken"]
        assert main([*args, "--out", str(out), "--resume"]) == 0
        assert calls == [2]  # only the chapter that had failed ran again
        assert "gridworld: kept from the earlier run" in capsys.readouterr().out
        assert json.loads((out / "gridworld" / "results.json").read_text()) == before
        meta = json.loads((out / "run.json").read_text())
        assert meta["sittings"] == 2 and not meta["chapters"]["broken"]["error"]
        assert "in 2 sittings" in (out / "report.md").read_text()
        # other settings than the run in OUT: refused, nothing touched
        assert main(["reproduce", "all", "--runs", "3", "--out", str(out), "--resume"]) == 2
        assert "holds a run with" in capsys.readouterr().err
        assert json.loads((out / "run.json").read_text()) == meta
    finally:
        mp.undo()


_CALLS: list[int] = []
_FAIL = [True]


def _flaky_job(seed):
    _CALLS.append(seed)
    if seed == 2 and _FAIL[0]:
        raise RuntimeError("the machine went away")
    return {"seed": seed, "value": seed * 1.5}


def _flaky(runs, quick, workers, out):
    res = shared.pool_map(_flaky_job, [(s,) for s in range(runs)], workers)
    return {"markdown": repr(res), "cpu_seconds": 0.0}


def test_resume_goes_on_from_the_last_finished_job_of_a_chapter_cut_short(tmp_path, monkeypatch):
    monkeypatch.setitem(reproduce.ALL, "flaky", _flaky)
    monkeypatch.setitem(report.CHAPTER_ROWS, "flaky", ("A chapter cut short", lambda res, quick: []))
    args = ["reproduce", "all", "--runs", "4", "--workers", "1", "--chapters", "flaky", "--out", str(tmp_path)]
    assert main(args) == 1  # job 2 fails: the chapter fails, jobs 0 and 1 are kept
    assert _CALLS == [0, 1, 2] and len(list((tmp_path / "flaky" / "jobs").glob("*.pkl"))) == 2
    _CALLS.clear()
    _FAIL[0] = False
    assert main([*args, "--resume"]) == 0
    assert _CALLS == [2, 3]  # only the jobs that had not finished ran
    expected = [{"seed": s, "value": s * 1.5} for s in range(4)]
    assert json.loads((tmp_path / "flaky" / "results.json").read_text())["markdown"] == repr(expected)
    assert not (tmp_path / "flaky" / "jobs").exists()  # results.json holds them now
