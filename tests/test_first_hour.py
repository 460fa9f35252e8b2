"""The first hour of a new user (issue 24): honest summaries, pictures of the map, and commands that
answer (the demo's length and flags, BusEnv exiting, replay without an agent, status as a table)."""

from __future__ import annotations

import dataclasses
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sensorimotor.protocol.messages import AgentEvent, Embedding, Truth
from sensorimotor.tools.summary import verdict

ROOT = Path(__file__).resolve().parents[1]


def _emb(version: int, err: float | None, n: int = 9, goal: float | None = None) -> Embedding:
    metrics = {} if goal is None else {"goal_reached_fraction": goal}
    return Embedding(
        "a0", "w", version, "policy_iteration", tuple(range(n)), np.zeros((n, 2)), (2.0, 1.0), err, metrics=metrics
    )


def _text(v) -> str:
    return "\n".join(v.lines)


def _at(version: int, err: float, step: int, goal: float | None = None) -> Embedding:
    return dataclasses.replace(_emb(version, err, goal=goal), step=step)


def test_the_summary_says_best_final_and_whether_the_map_held():
    v = verdict([_emb(1, 0.8), _emb(2, 0.2), _emb(3, 0.011), _emb(4, 0.010), _emb(5, 0.012)])
    assert (v.first, v.best, v.final, v.near_best) == (0.8, 0.010, 0.012, True)
    t = _text(v)
    assert "first 0.8000 (v1), best 0.0100 (v4), final 0.0120 (v5)" in t and "the map held" in t
    assert "Procrustes error against truth 0.0120" in t  # the line scripts and tests read
    assert "fell from 0.8000 (v1) to 0.0120" in t


def test_a_map_that_did_not_hold_is_not_called_learned():
    # CliffWalking as a new user saw it: best 0.0477, final 0.27
    v = verdict([_emb(1, 0.88), _emb(2, 0.0477), _emb(3, 0.15), _emb(4, 0.27)])
    t = _text(v)
    assert v.near_best is False and "5.7x the best (v2): the map did not hold" in t
    assert "fell" not in t


def test_a_map_that_never_improved_says_so_and_why():
    # MountainCar as a new user saw it: 0.6982 at v1, final 0.9388, the goal never reached
    v = verdict([_emb(1, 0.6982, goal=0.0), _emb(2, 0.80, goal=0.0), _emb(3, 0.9388, goal=0.0)])
    t = _text(v)
    assert "fell" not in t and "not a map of the world" in t and "reached the goal from none" in t


def test_a_world_that_cannot_be_embedded_is_told_why_not_to_run_longer():
    ev = AgentEvent("a0", "bj", "policy_iteration", "world declares 0 start states", reason="no_start_states")
    v = verdict([], [ev], n_starts=0)
    t = _text(v)
    assert not v.embedded and "declares 0 start states" in t and "never embedded" in t
    assert "run longer" not in t
    v = verdict([], [], n_starts=81, seconds=15)
    assert "no embedding yet in 15 s" in _text(v) and "run longer" in _text(v)


def test_a_world_without_truth_is_not_scored():
    v = verdict([_emb(1, None), _emb(2, None)], has_truth=False)
    t = _text(v)
    assert v.embedded and v.best is None and "not scored" in t and "no ground truth" in t


def test_plot_colours_the_map_by_truth_beside_its_spectrum(tmp_path):
    from PIL import Image

    from sensorimotor.tools.plot import plot_embedding

    xy = np.array([(x, y) for y in range(5) for x in range(5)], dtype=float)
    truth = Truth("w", "start_states", {"positions": xy})
    rot = xy @ np.array([[0.0, -1.0], [1.0, 0.0]]) * 3 + 7  # the map, rotated, scaled and moved
    emb = Embedding("a0", "w", 4, "policy_iteration", tuple(range(25)), rot, (9.0, 8.0, 0.1), 0.0)
    drawn = plot_embedding(emb, truth, str(tmp_path))
    assert drawn.n_points == 25 and drawn.coloured_by_truth
    assert drawn.aligned is not None and np.allclose(drawn.aligned, xy)  # in the truth's units, not ±0.15
    assert drawn.curve_points == 0
    img = np.asarray(Image.open(drawn.path).convert("RGB"))
    assert img.shape[0] > 200 and img.shape[1] > 600
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 50  # colours, not a blank page
    bare = plot_embedding(emb, None, str(tmp_path / "bare"))
    assert not bare.coloured_by_truth and Path(bare.path).exists()


def _sme(*args: str, timeout: float = 240.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


@pytest.mark.integration
def test_demo_plot_writes_the_9x9_lattice_coloured_by_true_cell(endpoint, tmp_path):
    """`sme demo --plot DIR` on the gridworld, with the Zenoh flags every command takes."""
    from PIL import Image

    out = _sme(
        "demo", "--steps", "8000", "--seconds", "120", "-l", endpoint, "--no-multicast-scouting", "--plot",
        str(tmp_path),
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    m = re.search(r"wrote (\S+): embedding v(\d+), (\d+) points, coloured by true position", out.stdout)
    assert m, out.stdout
    assert Path(m.group(1)) == tmp_path / "gridworld.png" and int(m.group(3)) == 81
    img = np.asarray(Image.open(m.group(1)).convert("RGB"))
    assert len(np.unique(img.reshape(-1, 3), axis=0)) > 81
    assert "argv[0]" not in out.stdout


@pytest.mark.integration
def test_demo_retina_at_its_default_length_shows_an_embedding(endpoint):
    """The retina's first embedding comes after 1,000 saccades, past the default 15 s on a slow
    machine: an unbounded demo waits for it; PyBullet's start-up lines are shown nowhere (issue 40:
    `argv[0]=` was back on the terminal's second line, through stderr)."""
    out = _sme("demo", "--world", "retina", "--listen", endpoint, timeout=300)
    assert out.returncode == 0, (out.stdout[-2000:], out.stderr[-2000:])
    assert re.search(r"\[retina\] embedding v1 ", out.stdout), out.stdout[-2000:]
    assert "final embedding v" in out.stdout
    for stream in (out.stdout, out.stderr):
        assert "argv[0]" not in stream and "pybullet build time" not in stream, stream[:500]


_MY_ENV = """
import gymnasium as gym
import numpy as np


class MyLine(gym.Env):
    observation_space = gym.spaces.Discrete(5)
    action_space = gym.spaces.Discrete(2)

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        self.s = 0
        return self.s, {}

    def step(self, a):
        self.s = int(np.clip(self.s + (1 if a else -1), 0, 4))
        return self.s, float(self.s == 4), self.s == 4, False, {}


gym.register(id="MyLine-v0", entry_point=MyLine)
"""


def _sme_script(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    """`sme ...` as the console script runs it: the current directory is not on the import path
    (`python -P`, unlike `python -m`)."""
    return subprocess.run(
        [sys.executable, "-P", "-m", "sensorimotor.tools.cli", *args],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_gym_module_in_the_current_folder_is_found_without_pythonpath(tmp_path):
    """`sme world gym:mymodule:MyEnv-v0` from the module's own folder (issue 40, first hour 1)."""
    (tmp_path / "my_line_env.py").write_text(_MY_ENV)
    out = _sme_script("world", "gym:my_line_env:MyLine-v0", "--list-params", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "start_grid" in out.stdout
    # a module that is nowhere: the error says where it looked and how to point elsewhere
    out = _sme_script("world", "gym:no_such_env_mod:Nope-v0", "--list-params", cwd=tmp_path)
    assert out.returncode == 2
    assert "cannot import 'no_such_env_mod'" in out.stderr and "PYTHONPATH" in out.stderr
    assert str(tmp_path) in out.stderr


def test_the_zoo_hook_snippet_is_complete_and_embeddable():
    """docs/zoo.md's hook snippet runs as written (it once used an undefined `MyLine`) and makes a
    world with 14 start states and their truth."""
    from sensorimotor.worlds.registry import make_world

    text = (ROOT / "docs" / "zoo.md").read_text()
    section = text[text.index("## Make your own environment embeddable") :]
    block = re.search(r"```python\n(.*?)```", section, re.S)
    assert block and "class MyLine" in block.group(1)
    exec(compile(block.group(1), "docs/zoo.md", "exec"), {"__name__": "zoo_snippet"})
    with make_world("gym:my/Line-v0", "line", 0) as w:
        spec = w.spec()
        assert spec.n_starts == 14 and spec.goal == "terminated"
        truth = w.truth()
        assert truth is not None and truth.tensors["positions"][:, 0].tolist() == list(range(14))
        assert int(np.argmax(w.reset(start=5).tensors["observation"])) == 5


_EVERY_WORLD = """
import sys
import numpy as np
from sensorimotor.worlds.registry import WORLDS, make_world
for name in sorted(WORLDS) + ["gym:FrozenLake-v1"]:
    with make_world(name, None, 0, {}) as w:
        w.reset(start=0 if w.spec().n_starts else None)
        print("made", name, flush=True)
print("something of our own on stderr", file=sys.stderr)
"""


def test_no_world_prints_pybullet_start_up_lines():
    """Every world kind is made and reset (imported and connected, as `sme demo --world NAME` and
    `sme world NAME` do) in a fresh process: PyBullet's `pybullet build time` and `argv[0]=` lines
    reach neither stdout nor stderr, and what else is written there still is."""
    from sensorimotor.worlds.registry import WORLDS

    out = subprocess.run(
        [sys.executable, "-P", "-c", _EVERY_WORLD], cwd=ROOT, capture_output=True, text=True, timeout=240
    )
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.count("made ") == len(WORLDS) + 1
    assert "something of our own on stderr" in out.stderr
    for stream in (out.stdout, out.stderr):
        assert "argv[0]" not in stream and "pybullet build time" not in stream, stream[:1000]


def test_the_plot_has_an_error_and_goal_curve_and_a_1d_map_in_truth_units(tmp_path):
    from sensorimotor.tools.plot import in_truth_units, plot_embedding

    line = np.linspace(2.0, 9.0, 12)[:, None]  # a 1-D truth in metres
    assert np.allclose(in_truth_units(line, -3.0 * line + 40.0), line)
    history = [_at(v, err, 1000 * v, goal) for v, err, goal in ((1, 0.9, 0.0), (2, 0.3, 0.5), (3, 0.01, 1.0))]
    truth = Truth("w", "start_states", {"positions": np.array([(x, y) for y in range(3) for x in range(3)], float)})
    emb = dataclasses.replace(history[-1], coordinates=truth.tensors["positions"] * -2.0)
    drawn = plot_embedding(emb, truth, str(tmp_path), history=history)
    assert drawn.curve_points == 3 and np.allclose(drawn.aligned, truth.tensors["positions"])


def test_embedding_lines_and_the_summary_show_the_goal_fraction():
    from sensorimotor.tools.common import EMBEDDING_COLUMNS, format_embedding

    e = _emb(3, 0.02, goal=0.75)
    assert "goal=0.75 " in format_embedding(e)  # `sme watch` and the demo print this line
    assert "goal=" not in format_embedding(_emb(3, 0.02))
    assert all(c in EMBEDDING_COLUMNS for c in ("procrustes", "T, C", "Dm, Dt", "goal", "eig"))
    v = verdict([_emb(1, 0.5, goal=0.2), _emb(2, 0.03, goal=0.75)])
    assert "reached the goal from 75% of the 9 start states" in _text(v)


def test_an_error_of_0_9_is_never_called_held():
    """Issue 40: a gym world's summary said "the map held" and "this is not a map of the world" at 0.91."""
    from sensorimotor.tools.summary import settled

    runs = [_emb(1, 0.92, goal=1.0), _emb(2, 0.91, goal=1.0), _emb(3, 0.91, goal=1.0)]
    t = _text(verdict(runs))
    assert "held" not in t and "no map to hold yet" in t and "not a map of the world" in t
    assert not settled(runs)
    assert settled([_emb(1, 0.8), _emb(2, 0.02), _emb(3, 0.021), _emb(4, 0.02)])
    assert not settled([_emb(1, 0.8), _emb(2, 0.02)])  # two versions: too early
    assert settled([_emb(1, None)])  # no truth: the first embedding is all a run can show


def test_a_run_stopped_at_its_bound_says_what_it_would_need():
    from sensorimotor.tools.summary import still_to_go

    falling = [_at(1, 0.9, 10_000), _at(2, 0.6, 20_000), _at(3, 0.6, 30_000)]
    # log-linear from 0.9 to 0.6 in 10,000 steps: 0.3 after another 17,095 steps from v2, 7,095 after v3
    msg = still_to_go(falling, steps_per_second=100.0)
    assert "about 7,095 more steps to an error below 0.3" in msg and "about 71 s more" in msg
    flat = [_at(1, 0.9, 10_000), _at(2, 0.95, 20_000)]
    assert "has not fallen" in still_to_go(flat, 100.0)
    assert "no pace" in still_to_go(flat[:1], 100.0)


@pytest.mark.integration
def test_demo_of_a_gym_world_runs_until_its_map_holds(endpoint):
    """Unbounded, the demo goes past its 15 s until the map holds (CliffWalking holds within seconds
    of that), and its summary says so with the goal fraction; every embedding line carries goal=."""
    out = _sme("demo", "--world", "gym:CliffWalking-v1", "--listen", endpoint, timeout=300)
    assert out.returncode == 0, (out.stdout[-2000:], out.stderr[-2000:])
    assert "(columns: procrustes = error" in out.stdout and "goal = fraction of the start states" in " ".join(
        out.stdout.split()
    )
    lines = [ln for ln in out.stdout.splitlines() if "] embedding v" in ln]
    assert lines and all("goal=" in ln for ln in lines)
    assert "the map held" in out.stdout and "reached the goal from" in out.stdout
    assert "stopped at the demo's" not in out.stdout
    m = re.search(r"Procrustes error against truth ([0-9.]+)", out.stdout)
    assert m and float(m.group(1)) <= 0.3


@pytest.mark.parametrize("module", ["gym_embed", "repeatable"])
def test_experiment_help_says_its_first_paragraph_whole(module):
    """`gym_embed --help` ended mid-sentence ("the Procrustes error of each")."""
    out = subprocess.run(
        [sys.executable, "-m", f"sensorimotor.tools.experiments.{module}", "--help"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        env={**os.environ, "COLUMNS": "200"},
    )
    assert out.returncode == 0, out.stderr
    description = out.stdout.split("\n\n")[1]
    assert description.rstrip().endswith((".", ")")), description


def test_pybullet_quiet_drops_only_the_start_up_lines_and_nests(capfd):
    from sensorimotor.worlds.quiet import pybullet_quiet

    with pybullet_quiet():
        os.write(1, b"argv[0]=\nours on stdout\n")
        with pybullet_quiet():  # a nested use (a module that makes a world while imported) must not wait
            os.write(2, b"pybullet build time: Jan 29 2025 23:17:20\nours on stderr\n")
    out, err = capfd.readouterr()
    assert out == "ours on stdout\n" and err == "ours on stderr\n"


def test_a_map_the_program_holds_is_held_after_one_version():
    """The generic program publishes a new version only for a better policy (watched), or says its
    stochastic world's policy `settled`: one version can be the map that held, but never at 0.8."""
    from sensorimotor.tools.summary import settled

    def watched(version, err, step=1000):
        e = _at(version, err, step, goal=1.0)
        return dataclasses.replace(e, metrics={**e.metrics, "watched": 1.0})

    one = [watched(1, 0.0499)]
    assert settled(one) and "the program holds this version" in _text(verdict(one))
    assert "the map held" in _text(verdict(one))
    poor = [watched(1, 0.82)]
    assert not settled(poor) and "held" not in _text(verdict(poor))
    lake = [_at(1, 0.57, 11_510, 0.6), _at(2, 0.2165, 25_396, 0.74)]
    ev = AgentEvent("a0", "w", "policy_iteration", "watched from here", step=26_000, reason="settled")
    assert not settled(lake) and settled(lake, [ev])
    assert "the map held" in _text(verdict(lake, [ev])) and "the map held" not in _text(verdict(lake))
