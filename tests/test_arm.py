"""The arm world: any URDF (pybullet_data's Kuka iiwa, Franka Panda, xArm6, and a 3-link planar arm
this test writes), its camera, perceptual goal, truth and body changes, learned by the generic
program with no arm code in the agent. Shortened: 5 x 5 lattices (`sme reproduce arm` runs 7 x 7)."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.protocol.messages import Control
from sensorimotor.protocol.params import ParamError
from sensorimotor.tools.experiments.arm import learn, planar_urdf
from sensorimotor.worlds.arm import ArmWorld, morph_urdf, scalable_links
from sensorimotor.worlds.base import PerturbationError
from sensorimotor.worlds.registry import make_world


@pytest.fixture(scope="module")
def kuka():
    with ArmWorld(lattice=5) as w:
        yield w


def test_spec_moves_goal_and_truth(kuka):
    spec = kuka.spec()
    assert spec.program == "generic" and spec.n_starts == 25 and spec.action_space.n == 4
    assert spec.params["joints"] == "lbr_iiwa_joint_2,lbr_iiwa_joint_4"  # the two that move the hand most
    r = kuka.reset(start=0)
    img = r.tensors["camera"]
    assert img.shape == (48, 48) and img.dtype == np.float32 and 0.0 <= img.min() and img.max() <= 1.0
    assert np.allclose(kuka.angles, kuka.poses[0])
    kuka.step(np.array([1.0]))  # joint 2 minus, at the edge of the lattice: the arm stays
    assert np.allclose(kuka.angles, kuka.poses[0])
    r2 = kuka.step(np.array([0.0]))  # joint 2 plus
    assert np.allclose(kuka.angles, kuka.poses[0] + [0.2, 0.0]) and not np.array_equal(img, r2.tensors["camera"])
    with pytest.raises(ValueError):
        kuka.step(np.array([4.0]))
    # the perceptual goal: the marker is seen nearest the image centre at the lattice's centre pose
    assert np.allclose(kuka.goal, kuka.poses[12])
    m = kuka.marker_position(kuka.goal)
    assert m is not None and np.hypot(*(m - 47.5)) < 3.0
    truth = kuka.truth().tensors
    assert truth["positions"].shape == (25, 2) and truth["hand"].shape == (25, 3)
    assert np.ptp(truth["hand"], axis=0).max() > 0.2  # the hand really moves over the lattice


def test_kuka_is_learned_by_the_generic_program(kuka):
    run, _ = learn(kuka, 0, 3000, stop_when=lambda r: len(r.embeddings) >= 3)
    errors = [e.procrustes_error for e in run.embeddings]
    assert errors and errors[-1] < 0.1, errors
    assert run.embeddings[-1].metrics["goal_reached_fraction"] == 1.0
    assert "lspi" in run.events("attached")[0].detail


def test_a_planar_arm_written_here_is_learned_too(tmp_path):
    with make_world("arm", seed=1, params={"urdf": planar_urdf(tmp_path), "lattice": "5", "bend": "0.3"}) as w:
        assert w.spec().params["joints"] == "j0,j1"  # the two nearest the base move the hand most
        run, _ = learn(w, 1, 4000, stop_when=lambda r: len(r.embeddings) >= 3)
        errors = [e.procrustes_error for e in run.embeddings]
        assert errors and errors[-1] < 0.15, errors


def test_bad_urdf_joint_and_link_are_refused_naming_the_valid_ones(tmp_path, kuka):
    with pytest.raises(ParamError, match="neither a file nor in pybullet_data"):
        ArmWorld(urdf=str(tmp_path / "none.urdf"))
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot><link name='a'/>")
    with pytest.raises(ParamError, match="not a URDF"):
        ArmWorld(urdf=str(bad))
    with pytest.raises(ParamError, match=r"no movable joint 'elbow'.*valid: lbr_iiwa_joint_1"):
        ArmWorld(joints=("elbow",))
    with pytest.raises(PerturbationError, match=r"cannot scale link 'nope'.*valid: .*lbr_iiwa_link_4"):
        kuka.perturb(Control("arm", "morph", {"link": "nope"}))
    with pytest.raises(PerturbationError, match=r"no moving joint 'lbr_iiwa_joint_7'; valid: lbr_iiwa_joint_2"):
        kuka.perturb(Control("arm", "reverse", {"joint": "lbr_iiwa_joint_7"}))
    with pytest.raises(PerturbationError, match="scale"):
        kuka.perturb(Control("arm", "morph", {"scale": "9"}))


def test_morph_rewrites_the_urdf_and_keeps_the_pose(kuka):
    text = open(kuka.urdf).read()
    out = morph_urdf(text, "/base", {"lbr_iiwa_link_4": 1.5})
    assert 'xyz="0 0.27675 0"' in out  # joint 5's offset 0.1845 x 1.5
    assert "/base/meshes/link_0.obj" in out
    assert "lbr_iiwa_link_4" in scalable_links(kuka._root)
    kuka.reset(start=7)
    before, hand0 = kuka.angles.copy(), kuka.truth().tensors["hand"]
    msg = kuka.perturb(Control("arm", "morph", {"link": "lbr_iiwa_link_4", "scale": "1.3"}))
    try:
        assert "x 1.3" in msg and np.allclose(kuka.angles, before)
        hand1 = kuka.truth().tensors["hand"]
        assert np.linalg.norm(hand1 - hand0, axis=1).max() > 0.05  # the hand is elsewhere now
        assert np.allclose(kuka.truth().tensors["positions"], kuka.poses)  # the joints' lattice is not
    finally:
        kuka.perturb(Control("arm", "heal", {}))
    assert np.allclose(kuka.truth().tensors["hand"], hand0)


def test_lesion_reverse_and_gain_change_what_an_action_does(kuka):
    kuka.reset(start=12)
    try:
        kuka.perturb(Control("arm", "reverse", {"joint": "lbr_iiwa_joint_4"}))
        kuka.step(np.array([2.0]))  # joint 4 plus, reversed
        assert np.allclose(kuka.angles, kuka.poses[12] - [0.0, 0.2])
        kuka.perturb(Control("arm", "gain", {"joint": "lbr_iiwa_joint_2", "gain": "2"}))
        kuka.step(np.array([1.0]))
        assert np.allclose(kuka.angles, kuka.poses[12] - [0.4, 0.2])
        kuka.perturb(Control("arm", "lesion", {"joint": "lbr_iiwa_joint_2", "at": "0.2"}))
        kuka.step(np.array([0.0]))
        assert kuka.angles[0] == pytest.approx(0.2)
        truth = kuka.truth().tensors["positions"]
        assert np.allclose(truth[:, 0], 0.2)  # every start shares the locked angle
        assert kuka.goal[0] == pytest.approx(0.2)  # the goal is found again among what can be reached
    finally:
        kuka.perturb(Control("arm", "heal", {}))
    assert np.allclose(kuka.goal, kuka.poses[12]) and not kuka.locked


@pytest.mark.parametrize(
    "kind,params",
    [
        ("reverse", {"joint": "lbr_iiwa_joint_4"}),
        ("lesion", {"joint": "lbr_iiwa_joint_2", "at": "0.0"}),
        ("morph", {"link": "lbr_iiwa_link_4", "scale": "1.3"}),
    ],
)
def test_a_body_change_is_detected_and_relearned(kind, params):
    """Learned by step 2000; the change then; the agent's own detector notices the drop and the
    relearned embedding fits the changed body's truth."""
    at = 2000
    with ArmWorld(lattice=5) as w:
        ctl = Control("arm", kind, params)
        run, _ = learn(
            w,
            0,
            8000,
            perturb=lambda k: ctl if k == at else None,
            stop_when=lambda r: bool(r.events("relearned")),
        )
        before = [e for e in run.embeddings if e.step < at]
        assert before and before[-1].procrustes_error < 0.05
        drops = [e.step for e in run.events("drop_detected")]
        assert len(drops) == 1 and at < drops[0] <= at + 1500, drops
        relearned = [e for e in run.embeddings if e.trigger == "relearned"]
        assert relearned and relearned[0].drop_step == drops[0]
        truth = w.truth().tensors["positions"]
        assert procrustes_error(truth, np.asarray(relearned[0].coordinates)) < 0.15
        assert relearned[0].procrustes_error < 0.15


@pytest.mark.integration
def test_the_arm_live_over_the_bus_is_learned_and_relearned_after_a_morph(procs, endpoint, monkeypatch):
    """As a user would: `sme agent`, `sme world arm`, `sme watch`; `sme perturb morph` once learned;
    the agent notices by itself and publishes a relearned embedding that fits the longer arm."""
    import json
    import threading

    from tests.conftest import agent_status, wait_for, world_link

    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")
    procs.start("agent", "--listen", endpoint, "-q")
    procs.start("world", "arm", "--param", "lattice=5", "--connect", endpoint, "-q")
    watch = procs.start("watch", "--json", "--timeout", "170", "--connect", endpoint)
    rows: list[dict] = []
    threading.Thread(target=lambda: rows.extend(json.loads(line) for line in watch.stdout), daemon=True).start()

    def learned() -> bool:
        link = world_link(agent_status(endpoint), "arm")
        return link is not None and link.embedding_version > 0 and link.last_procrustes_error < 0.1

    assert wait_for(learned, 90, every=0.5)
    bad = procs.start("perturb", "morph", "--world", "arm", "--param", "link=elbow", "--connect", endpoint)
    assert bad.wait(20) == 1  # refused by the world, which names the links it can scale
    assert "lbr_iiwa_link_4" in bad.stderr.read()
    pert = procs.start(
        "perturb",
        "morph",
        "--world",
        "arm",
        "--param",
        "link=lbr_iiwa_link_4",
        "--param",
        "scale=1.3",
        "--connect",
        endpoint,
    )
    assert pert.wait(20) == 0
    assert wait_for(lambda: any(r.get("trigger") == "relearned" for r in rows), 120), [
        (r.get("kind"), r.get("trigger")) for r in rows
    ]
    drops = [r for r in rows if r.get("kind") == "drop_detected"]
    relearned = next(r for r in rows if r.get("trigger") == "relearned")
    assert len(drops) == 1 and relearned["drop_step"] == drops[0]["step"]
    assert relearned["procrustes_error"] < 0.15


@pytest.mark.integration
def test_bench_world_arm_reports_in_process_bus_and_raw_pybullet_rows():
    import json
    import subprocess
    import sys

    out = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "bench", "world", "--world", "arm", "--steps", "200", "--json"]
        + ["--param", "lattice=3"],
        capture_output=True,
        text=True,
        timeout=180,
    )
    assert out.returncode == 0, out.stderr
    rows = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    names = [r["world"] + " " + r.get("where", "") for r in rows]
    assert any("stepSimulation (model.urdf)" in n for n in names) and any("48x48 frame of it" in n for n in names)
    inproc = next(r for r in rows if r.get("where") == "in-process")
    bus = next(r for r in rows if r.get("where", "").startswith("over the bus"))
    assert inproc["steps"] == bus["steps"] == 200 and min(r["steps_per_s"] for r in rows) > 0
    assert bus["ratio_to_in_process"] == pytest.approx(bus["steps_per_s"] / inproc["steps_per_s"], rel=0.01)


def test_proprioception_and_box_actions():
    with ArmWorld(lattice=3, proprioception=True, actions="box", image=24, goal_image=48) as w:
        spec = w.spec()
        assert [s.name for s in spec.sensors] == ["camera", "joints"] and spec.action_space.dims == 2
        r = w.reset(start=0)
        assert np.allclose(r.tensors["joints"], w.poses[0])
        r = w.step(np.array([0.5, 1.0]))  # half a step of joint 2, a whole one of joint 4
        assert np.allclose(r.tensors["joints"], w.poses[0] + [0.1, 0.2], atol=1e-6)
        with pytest.raises(ValueError):
            w.step(np.array([np.nan, 0.0]))
        # a camera with box moves of 2+ joints: the generic program plans over motor coordinates
        assert "over motor coordinates" in GenericProgram(spec, seed=0).describe()


def test_sme_world_arm_exits_2_naming_the_valid_joints(tmp_path):
    import subprocess
    import sys

    for param, says in (
        ("joints=elbow", "valid: lbr_iiwa_joint_1"),
        (f"urdf={tmp_path / 'own.urdf'}", "neither a file"),
    ):
        out = subprocess.run(
            [sys.executable, "-m", "sensorimotor.tools.cli", "world", "arm", "--param", param],
            capture_output=True,
            text=True,
            timeout=60,
        )
        assert out.returncode == 2 and says in out.stderr, out.stderr
