import numpy as np
import pytest
from scipy.stats import spearmanr

from sensorimotor.agent.learners.lspi import LSPI, TabularBasis
from sensorimotor.agent.programs.gridworld import GridworldProgram
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld


def embeddings(run):
    return run.embeddings


@pytest.mark.parametrize("seed", [0, 1])
def test_plain_gridworld_embedding_beats_005_and_error_falls_with_lspi(seed):
    w = GridWorld(seed=seed)
    p = GridworldProgram(w.spec(), seed=seed)
    run = run_inprocess(w, p, 12000)
    errs = run.errors
    assert len(errs) >= 8
    assert errs[-1] < 0.05
    assert errs[0] > 0.5  # the first policy is poor
    rho = spearmanr(np.arange(len(errs)), errs).statistic
    assert rho < -0.6, errs  # error falls as LSPI iterates (Fig 5.4)
    last = embeddings(run)[-1]
    assert last.coordinates.shape == (81, 2) and last.metrics["goal_reached_fraction"] == 1.0


@pytest.mark.parametrize("seed", [0, 1])
def test_barrier_gridworld_embedding_beats_010(seed):
    w = GridWorld(seed=seed, barrier=True)
    p = GridworldProgram(w.spec(), seed=seed)
    run = run_inprocess(w, p, 12000)
    assert len(w.cells) == 81 - 10
    assert run.errors[-1] < 0.10


def test_random_policy_embedding_is_random():
    w = GridWorld(seed=3)
    p = GridworldProgram(w.spec(), seed=3, policy="random", samples_per_iteration=50)
    run = run_inprocess(w, p, 9000, stop_when=lambda r: len(r.errors) >= 2)
    assert run.errors and min(run.errors) > 0.5


def test_state_ids_carry_no_geometry():
    w = GridWorld(seed=0)
    ids = [int(w.reset(start=i).tensors["state"][0]) for i in range(len(w.cells))]
    assert sorted(ids) == list(range(81)) and ids != list(range(81))


def test_gridworld_dynamics_walls_and_goal():
    w = GridWorld(barrier=True)
    x, y = sorted(w.walls)[0]
    w.pos = (x + 1, y)
    w.step(np.array([2]))  # left, into the wall: stays put
    assert w.pos == (x + 1, y)
    w.pos = (w.goal[0], w.goal[1] - 1)
    r = w.step(np.array([0]))  # up into the goal
    assert r.reward == 1.0 and r.done
    assert w.reset(start=w.index[w.goal]).done  # starting at the goal: an empty trace


def test_gridworld_rejects_bad_params():
    with pytest.raises(ValueError, match="actions"):
        GridWorld(actions=5)
    from sensorimotor.worlds.registry import make_world

    with pytest.raises(ValueError, match="is not an int"):
        make_world("gridworld", params={"size": "nine"})
    with pytest.raises(ValueError, match="unknown world"):
        make_world("nowhere")


def test_lspi_recovers_optimal_values_on_a_chain():
    # chain 0-1-2-3 (goal 3), actions 0=left 1=right; exhaustive samples
    b = TabularBasis(4, 2)
    lspi = LSPI(b, gamma=0.9, ridge=1e-9)
    for s in range(3):
        for a in (0, 1):
            s2 = max(0, s - 1) if a == 0 else s + 1
            lspi.learn_one(s, a, 1.0 if s2 == 3 else 0.0, s2, s2 == 3)
    for _ in range(5):
        lspi.iterate()
    assert [lspi.greedy(s) for s in range(3)] == [1, 1, 1]
    np.testing.assert_allclose([lspi.q(s)[1] for s in range(3)], [0.81, 0.9, 1.0], atol=1e-6)


def test_lspi_validates_hyperparameters():
    with pytest.raises(ValueError):
        LSPI(TabularBasis(2, 2), gamma=1.0)
    with pytest.raises(ValueError):
        LSPI(TabularBasis(2, 2), ridge=-1)


def test_program_is_deterministic_given_seed():
    def final(seed):
        w = GridWorld(seed=seed)
        run = run_inprocess(w, GridworldProgram(w.spec(), seed=seed), 4000)
        return embeddings(run)[-1].coordinates.tobytes()

    assert final(5) == final(5)
