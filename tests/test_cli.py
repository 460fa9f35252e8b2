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
