import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

COMMANDS = [["agent"], ["world"], ["watch"], ["status"], ["demo"], ["bench"], ["bench", "loop"]]


@pytest.mark.parametrize("cmd", COMMANDS, ids=[" ".join(c) for c in COMMANDS])
def test_every_command_explains_itself(cmd):
    out = subprocess.run([sys.executable, "-m", "sensorimotor.tools.cli", *cmd, "--help"], cwd=ROOT, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    assert "usage: sme" in out.stdout
    if cmd[0] not in ("bench",) or len(cmd) > 1:
        assert len(out.stdout) > 300


def test_zenoh_flags_on_bus_commands():
    for cmd in ("agent", "world", "watch", "status"):
        out = subprocess.run([sys.executable, "-m", "sensorimotor.tools.cli", cmd, "--help"], cwd=ROOT, capture_output=True,
                             text=True, timeout=60).stdout
        for flag in ("--mode", "--connect", "--listen", "--config", "--no-multicast-scouting"):
            assert flag in out, (cmd, flag)


def test_unknown_world_is_a_clear_error():
    out = subprocess.run([sys.executable, "-m", "sensorimotor.tools.cli", "world", "nowhere"], cwd=ROOT, capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2 and "unknown world 'nowhere'" in out.stderr


@pytest.mark.integration
@pytest.mark.parametrize("params,bound", [([], 0.05), (["--param", "barrier=true"], 0.10)], ids=["plain", "barrier"])
def test_demo_ends_with_a_good_gridworld_embedding(endpoint, params, bound):
    # bounded by steps, not time: on a loaded machine 10 s may be too few LSPI iterations
    out = subprocess.run([sys.executable, "-m", "sensorimotor.tools.cli", "demo", "--world", "gridworld", "--steps", "12000",
                          "--seconds", "120", "--listen", endpoint, *params], cwd=ROOT, capture_output=True, text=True,
                         timeout=180)
    assert out.returncode == 0, out.stderr
    m = re.search(r"Procrustes error against truth ([0-9.]+)", out.stdout)
    assert m, out.stdout
    assert float(m.group(1)) < bound
    assert "summary" in out.stdout and "embedding v1 " in out.stdout


def _sme(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "sensorimotor.tools.cli", *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)


def test_world_refuses_an_unknown_param_naming_the_valid_keys(endpoint):
    out = _sme("world", "gridworld", "--param", "sise=5", "--connect", endpoint, "--steps", "1")
    assert out.returncode == 2, out.stderr
    assert "unknown parameter 'sise'" in out.stderr and "did you mean 'size'?" in out.stderr
    assert "size, barrier, actions, goal, max_episode_steps" in out.stderr


@pytest.mark.parametrize("param,message", [("size=abc", "gridworld: size='abc' is not an int"),
                                           ("actions=5", "gridworld: actions='5' is not one of 4, 8"),
                                           ("size", "--param expects key=value")])
def test_world_refuses_a_bad_value(endpoint, param, message):
    out = _sme("world", "gridworld", "--param", param, "--connect", endpoint, "--steps", "1")
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_world_lists_its_params():
    out = _sme("world", "gridworld", "--list-params")
    assert out.returncode == 0, out.stderr
    for text in ("size", "int", "9", "side of the square grid", "goal", "int,int | none", "max_episode_steps"):
        assert text in out.stdout
    every = _sme("world", "--list-params")
    assert every.returncode == 0 and all(name in every.stdout for name in ("retina:", "mountaincar:", "stereo:"))
    assert _sme("world", "nowhere", "--list-params").returncode == 2


@pytest.mark.parametrize("param,message", [
    ("retna.embed_every=5", "unknown program 'retna' (did you mean 'retina'?)"),
    ("retina.embed_evry=5", "retina: unknown parameter 'embed_evry' (did you mean 'embed_every'?)"),
    ("retina.embed_every=abc", "retina: embed_every='abc' is not an int"),
    ("retina.rule=fancy", "retina: rule='fancy' is not one of basic, robust"),
    ("retina", "--program-param expects PROGRAM.KEY=VALUE"),
])
def test_agent_validates_program_params_at_start_up(endpoint, param, message):
    out = _sme("agent", "--listen", endpoint, "--seconds", "5", "--program-param", param)
    assert out.returncode == 2 and message in out.stderr, out.stderr


def test_agent_lists_program_params():
    out = _sme("agent", "--list-params")
    assert out.returncode == 0, out.stderr
    assert all(f"{name}:" in out.stdout for name in ("gridworld", "retina", "vergence", "mountaincar", "echo"))
    one = _sme("agent", "--list-params", "retina")
    assert one.returncode == 0 and "embed_every" in one.stdout and "gridworld:" not in one.stdout
    assert "float | none" in one.stdout
    bad = _sme("agent", "--list-params", "retna")
    assert bad.returncode == 2 and "did you mean 'retina'?" in bad.stderr


def test_demo_refuses_an_unknown_param(endpoint):
    out = _sme("demo", "--world", "gridworld", "--param", "sise=5", "--listen", endpoint, "--steps", "10")
    assert out.returncode == 2 and "did you mean 'size'?" in out.stderr, out.stderr
