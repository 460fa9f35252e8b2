"""The three "your first world in ten minutes" tutorials, run as written in docs/tutorials/: each
file served to a stock `sme agent` over loopback, learned to a Procrustes error below 0.05, with no
file of this project changed (the World subclass runs from a package of the user's own)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, agent_status, wait_for, world_link

pytestmark = pytest.mark.integration

TUTORIALS = ROOT / "docs" / "tutorials"
# the command the tutorial pages give (a small world learns faster with fewer samples per iteration)
AGENT = ("agent", "-q", "--program-param", "generic.samples_per_iteration=150")


def _learned(endpoint: str, wid: str, seen: list) -> bool:
    link = world_link(agent_status(endpoint), wid)
    if link is None or not link.embedding_version:
        return False
    seen.append((link.program, link.embedding_version, round(link.last_procrustes_error, 4)))
    return link.last_procrustes_error < 0.05


def _serve(cmd: list[str], cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONUNBUFFERED": "1", "PYTHONPATH": str(cwd)}
    return subprocess.Popen(cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _stop(p: subprocess.Popen) -> tuple[int, str]:
    if p.poll() is None:
        p.send_signal(signal.SIGINT)
        try:
            p.wait(15)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()
    out, err = p.communicate()
    return p.returncode, out + err


@pytest.mark.parametrize(
    "route,wid",
    [("world_subclass", "beacons"), ("gymnasium", "Room-v0"), ("raw_zenoh", "line")],
)
def test_tutorial_world_is_learned_over_the_bus(route, wid, procs, endpoint, tmp_path):
    procs.start(*AGENT, "--listen", endpoint)
    if route == "world_subclass":  # the user's own package, outside this repository
        pkg = tmp_path / "my_robot"
        pkg.mkdir()
        (pkg / "__init__.py").write_text("")
        shutil.copy(TUTORIALS / "beacons.py", pkg / "beacons.py")
        cmd = [sys.executable, "-m", "my_robot.beacons", "--connect", endpoint]
    elif route == "gymnasium":
        shutil.copy(TUTORIALS / "gym_room.py", tmp_path / "gym_room.py")
        cmd = [sys.executable, "gym_room.py", "--connect", endpoint]
    else:
        shutil.copy(TUTORIALS / "raw_zenoh_line.py", tmp_path / "raw_zenoh_line.py")
        cmd = [sys.executable, "raw_zenoh_line.py", "--connect", endpoint]
    world = _serve(cmd, tmp_path)
    seen: list = []
    try:
        assert wait_for(lambda: _learned(endpoint, wid, seen), 150, every=0.5), (seen[-5:], world.poll())
        assert seen[-1][0] == "generic"
    finally:
        code, text = _stop(world)
    assert code == 0, text[-2000:]
