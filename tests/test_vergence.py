"""Depth from vergence (ch. 7): the PyBullet robot and the Middlebury stereo pair."""

import numpy as np
import pytest

from sensorimotor.agent.embedding import procrustes_error
from sensorimotor.agent.learners.lspi import LSPI, RBFBasis
from sensorimotor.agent.programs.vergence import VergenceProgram
from sensorimotor.protocol.messages import Control
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.stereo_pair import StereoPairWorld
from sensorimotor.worlds.vergence import VergenceWorld


@pytest.fixture(scope="module")
def world():
    w = VergenceWorld()
    yield w
    w.close()


def test_vergence_geometry_and_perceptual_goal(world):
    # Eq 7.5 per eye: Z = (B/2) / tan(theta)
    assert world.true_angle(3.0) == pytest.approx(np.arctan(0.25 / 3.0))
    goals = []
    for s in range(len(world.distances)):
        world.reset(start=s)
        goals.append(world.goal)
    true_steps = world.true_angle(world.distances) / world.step_rad
    assert np.abs(np.array(goals) - true_steps).max() <= 1.7  # d(r,l) is minimal at the true angle, +-1.7 steps
    assert goals == sorted(goals, reverse=True)  # nearer means more vergence


def test_converging_reaches_the_goal_with_reward(world):
    world.reset(start=5)
    for _ in range(world.goal - 1):
        r = world.step(np.array([0]))
        assert not r.done and r.reward == 0
    r = world.step(np.array([0]))
    assert r.done and r.reward == 1.0
    with pytest.raises(ValueError):
        world.step(np.array([2]))


def test_lspi_learns_a_perfect_vergence_policy_and_a_good_depth_map(world):
    p = VergenceProgram(world.spec(), seed=0)
    run = run_inprocess(world, p, 12000, stop_when=lambda r: len(r.embeddings) >= 9)
    perfect = [e.metrics["policy_success"] == 1.0 for e in run.embeddings]
    assert any(perfect[:9])  # a perfect policy within 9 LSPI iterations
    best = min(e.procrustes_error for e, ok in zip(run.embeddings, perfect, strict=True) if ok)
    assert best <= 0.0257  # the dissertation's figure
    assert run.embeddings[-1].coordinates.shape == (20, 1)


def test_morphology_control_changes_the_goal(world):
    world.reset(start=0)
    g = world.goal
    world.perturb(Control(world.world_id, "morph", {"baseline": "0.7"}))
    world.reset(start=0)
    assert world.goal > g  # a wider baseline needs more vergence for the same distance
    world.perturb(Control(world.world_id, "heal"))
    world.reset(start=0)
    assert world.goal == g


def test_stereo_pair_disparities_within_2px_of_ground_truth():
    w = StereoPairWorld()
    gt = w.truth().tensors["positions"][:, 0]
    goals = []
    for s in range(len(w.points)):
        w.reset(start=s)
        goals.append(w.goal)
    err = np.abs(np.array(goals) - gt)
    assert len(goals) == 30 and (err <= 2).mean() >= 0.95 and err.max() < 3, err  # distinct salient points only
    assert procrustes_error(gt[:, None], np.array(goals, float)[:, None]) < 0.005
    p = VergenceProgram(w.spec(), seed=0)
    run = run_inprocess(w, p, 60000, stop_when=lambda r: len(r.embeddings) >= 3)
    assert run.embeddings[0].metrics["policy_success"] == 1.0  # perfect at the first LSPI iteration
    e = run.embeddings[-1]
    assert e.metrics["policy_success"] == 1.0  # and after (one action: converge until rewarded)
    # with a perfect policy the trace lengths are the disparities of the matching minimum
    assert procrustes_error(np.array(goals, float)[:, None], e.coordinates) < 1e-12


def test_rbf_basis_shapes():
    b = RBFBasis((0.0, 0.5, 1.0), 0.3, 2)
    F = b.phi(np.array([0.1, 0.9]), np.array([0, 1]))
    assert F.shape == (2, 8) and F[0, 4:].sum() == 0 and F[1, :4].sum() == 0 and F[0, 0] == 1.0
    LSPI(b).learn_one(0.3, 1, 0.0, 0.2, False)
