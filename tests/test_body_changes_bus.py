"""The generic body changes over the bus: `sme perturb KIND --world ID` applies every generic kind
to worlds nobody here wrote for it - FrozenLake, MiniGrid, panda-gym, the tutorials (a `World`
subclass in a user's package, a Gymnasium environment of one's own) - and exits 0; a kind or value
the world cannot take exits 1 naming the valid ones. And an environment's own kind, offered through
`sme_perturb` from a package of the user's own, is applied by `sme perturb`, noticed by the agent
and relearned."""

from __future__ import annotations

import os
import shutil
import sys

import pytest

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import AgentEvent, EventKind
from sensorimotor.tools.cli import main
from tests.conftest import ROOT, agent_status, wait_for, world_link
from tests.test_tutorials import _serve, _stop

pytestmark = pytest.mark.integration

# every generic kind, with parameters where the default would not show (one call each)
CALLS = [
    ("reverse", []),
    ("permute", ["--param", "order=0:1"]),
    ("lesion", ["--param", "index=0"]),
    ("lesion", ["--param", "what=sensor", "--param", "stop=0.25"]),
    ("gain", ["--param", "index=0", "--param", "gain=0.5"]),
    ("noise", ["--param", "sd=0.01"]),
    ("delay", ["--param", "steps=2"]),
    ("restore", []),
]


def _perturb(capsys, endpoint: str, *args: str) -> tuple[int, str, str]:
    code = main(["perturb", *args, "--connect", endpoint, "--timeout", "30"])
    out = capsys.readouterr()
    return code, out.out, out.err


def _every_kind_applies_and_bad_ones_are_refused(capsys, endpoint: str, wid: str) -> None:
    assert wait_for(lambda: (ln := world_link(agent_status(endpoint), wid)) is not None and ln.steps > 5, 120)
    code, out, err = _perturb(capsys, endpoint, "--list", "--world", wid)
    assert code == 0 and all(f"{k} (generic)" in out for k, _ in CALLS), (out, err)
    for kind, params in CALLS:
        code, out, err = _perturb(capsys, endpoint, kind, "--world", wid, *params)
        assert code == 0 and f"world {wid} applied {kind}: " in out, (kind, out, err)
    code, out, err = _perturb(capsys, endpoint, "melt", "--world", wid)
    assert code == 1 and "no perturbation 'melt'" in err and "valid: " in err and "restore" in err, err
    code, out, err = _perturb(capsys, endpoint, "reverse", "--world", wid, "--param", "index=99")
    assert code == 1 and "index=99 is out of range" in err and "valid: -1.." in err, err  # the world's words
    code, out, err = _perturb(capsys, endpoint, "noise", "--world", wid, "--param", "sd=-1")
    assert code == 1 and "not sent" in err and "0.0..1000000.0" in err, err  # checked before sending
    code, out, err = _perturb(capsys, endpoint, "gain", "--world", wid, "--param", "gain=-20")
    assert code == 1 and "gain='-20' is below the minimum" in err and "-10.0..10.0" in err, err


GYM_WORLDS = [
    ("gym:FrozenLake-v1", ["--param", "is_slippery=false"], "FrozenLake-v1", None),
    ("gym:MiniGrid-Empty-5x5-v0", [], "MiniGrid-Empty-5x5-v0", "minigrid"),
    ("gym:panda_gym:PandaReach-v3", ["--param", "start_grid=2"], "PandaReach-v3", "panda_gym"),  # box actions
]


@pytest.mark.parametrize(("world", "params", "wid", "needs"), GYM_WORLDS, ids=[w[2] for w in GYM_WORLDS])
def test_sme_perturb_applies_every_generic_kind_to_gymnasium_worlds(procs, endpoint, capsys, world, params, wid, needs):
    if needs:
        pytest.importorskip(needs)
    procs.start("agent", "--listen", endpoint, "-q")
    procs.start("world", world, *params, "--connect", endpoint, "-q")
    _every_kind_applies_and_bad_ones_are_refused(capsys, endpoint, wid)


SERVED = """
from my_robot.beacons import Beacons


class Served(Beacons):
    \"\"\"The tutorial's walker with the constructor `sme world package.module:Class` calls.\"\"\"

    kind = "served-beacons"

    def __init__(self, world_id="served", seed=0, params=None):
        super().__init__(world_id, seed)
"""


@pytest.mark.parametrize("route", ["world_subclass", "world_by_path", "gymnasium"])
def test_sme_perturb_applies_every_generic_kind_to_the_tutorial_worlds(
    procs, endpoint, capsys, tmp_path, monkeypatch, route
):
    """The tutorials of docs/tutorials, run as written from a directory of the user's own: the
    `World` subclass from a package (`python -m my_robot.beacons`, and served by path with `sme
    world my_robot.served:Served`) and the Gymnasium room."""
    procs.start("agent", "--listen", endpoint, "-q")
    tutorials = ROOT / "docs" / "tutorials"
    (tmp_path / "my_robot").mkdir()
    (tmp_path / "my_robot" / "__init__.py").write_text("")
    shutil.copy(tutorials / "beacons.py", tmp_path / "my_robot" / "beacons.py")
    if route == "world_by_path":
        (tmp_path / "my_robot" / "served.py").write_text(SERVED)
        monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
        procs.start("world", "my_robot.served:Served", "--id", "served", "--connect", endpoint, "-q")
        _every_kind_applies_and_bad_ones_are_refused(capsys, endpoint, "served")
        return
    if route == "world_subclass":
        cmd, wid = [sys.executable, "-m", "my_robot.beacons", "--connect", endpoint], "beacons"
    else:
        shutil.copy(tutorials / "gym_room.py", tmp_path / "gym_room.py")
        cmd, wid = [sys.executable, "gym_room.py", "--connect", endpoint, "-q"], "Room-v0"
    world = _serve(cmd, tmp_path)
    try:
        _every_kind_applies_and_bad_ones_are_refused(capsys, endpoint, wid)
    finally:
        code, text = _stop(world)
    assert code == 0, text[-2000:]


# the hook, live ---------------------------------------------------------------------------------
def test_an_environments_own_kind_is_applied_by_sme_perturb_noticed_and_relearned(
    procs, endpoint, capsys, tmp_path, monkeypatch
):
    """docs/tutorials/mirror_room.py, as the body-changes page gives it: no file of this project
    edited, the environment and its hook live in the user's package."""
    (tmp_path / "my_envs").mkdir()
    (tmp_path / "my_envs" / "__init__.py").write_text("")
    shutil.copy(ROOT / "docs" / "tutorials" / "mirror_room.py", tmp_path / "my_envs" / "mirror_room.py")
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")]))
    procs.start("agent", "--listen", endpoint, "-q", "--program-param", "generic.samples_per_iteration=150")
    procs.start("world", "gym:my_envs.mirror_room:MirrorRoom-v0", "--connect", endpoint, "-q")
    wid = "MirrorRoom-v0"
    events: list[AgentEvent] = []
    assert wait_for(lambda: agent_status(endpoint) is not None, 60)
    with Bus(BusConfig.for_role("tool", endpoint)) as bus:
        bus.subscribe(keys.agent_event("a0", wid), lambda m: events.append(codec.decode(AgentEvent, m.payload)))
        seen: list = []

        def learned() -> bool:
            ln = world_link(agent_status(endpoint), wid)
            if ln is None or not ln.embedding_version:
                return False
            seen.append((ln.embedding_version, round(ln.last_procrustes_error, 4)))
            return ln.last_procrustes_error < 0.05

        assert wait_for(learned, 150, every=0.5), seen[-5:]
        code, out, err = _perturb(capsys, endpoint, "--list", "--world", wid)
        assert code == 0 and "mirror (its own): Reverse the moves" in out and "rows|cols|both" in out, out
        code, out, err = _perturb(capsys, endpoint, "mirror", "--world", wid, "--param", "axis=up")
        assert code == 1 and "axis='up'" in err and "rows|cols|both" in err, err  # checked by its declaration
        mark = len(events)  # what the agent says from here on answers the change
        code, out, err = _perturb(capsys, endpoint, "mirror", "--world", wid)
        assert code == 0 and f"world {wid} applied mirror: moves along rows reversed, along columns reversed" in out, (
            out,
            err,
        )

        def kinds() -> set[str]:
            return {e.kind for e in list(events)[mark:]}

        assert wait_for(lambda: EventKind.DROP_DETECTED in kinds(), 120), [(e.kind, e.reason) for e in events]
        assert wait_for(lambda: EventKind.RELEARNED in kinds(), 180), [(e.kind, e.reason) for e in events]
    ln = world_link(agent_status(endpoint), wid)
    assert ln is not None and ln.last_procrustes_error < 0.1, ln
