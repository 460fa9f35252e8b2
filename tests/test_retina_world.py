import numpy as np
import pytest

from sensorimotor.protocol.messages import Control
from sensorimotor.worlds.base import PerturbationError
from sensorimotor.worlds.retina import RetinaWorld, field_layout


@pytest.fixture(scope="module")
def world():
    w = RetinaWorld(seed=0, supersample=1)
    yield w
    w.close()


def test_layout_is_4_layers_of_32x32_halving_and_centred():
    lay = field_layout(4, 32, 4.0)
    assert lay.shape == (4096, 3)
    assert sorted(set(lay[:, 2])) == [0.5, 1.0, 2.0, 4.0]
    for size in (0.5, 1.0, 2.0, 4.0):
        sel = lay[lay[:, 2] == size]
        assert np.allclose(sel[:, :2].mean(axis=0), 0) and np.isclose(sel[:, 0].max(), 15.5 * size)


def test_spec_and_shuffled_order(world):
    spec = world.spec()
    assert spec.sensor("fields").shape == (4096,) and spec.action_space.dims == 2 and spec.program == "retina"
    assert not np.array_equal(world.order, np.arange(world.n))
    assert sorted(world.order) == list(range(world.n))


def test_activation_peaks_when_the_spot_is_centred(world):
    world._look_at_offset(0.0, 0.0)
    centred = world.render().sum()
    rewards = []
    for off in (5, 10, 20, 40):
        world._look_at_offset(off, 0.0)
        rewards.append(world.render().sum())
    assert centred > rewards[0] > rewards[1] > rewards[2] > rewards[3] > 0
    a = world.render()
    assert a.dtype == np.float32 and a.min() >= 0 and a.max() <= 1


def test_exact_saccade_centres_the_target_and_truth_matches_it(world):
    world.reset(seed=5)
    u, v = world.target_offset_px()
    r = world.step(world.saccade_for(u, v))
    assert np.linalg.norm(world.target_offset_px()) < 1.0 and r.done and r.reward > 100
    # truth: -saccade for each field; a field at (u, 0) px has position -(atan(u/f)) deg
    pos = world.truth().tensors["positions"]
    i = int(np.argmax(world.centres[:, 0]))
    u = world.centres[i, 0]
    assert pos[i, 0] == pytest.approx(-np.degrees(np.arctan2(u, world.focal)))


def test_lesion_zeroes_an_off_centre_part_of_the_fovea(world):
    world._look_at_offset(0.0, 0.0)
    before = world.render()
    world.perturb(Control(world.world_id, "lesion"))
    after = world.render()
    dead = world.lesion
    assert 50 < dead.sum() < 1000
    assert np.all(after[dead] == 0) and np.allclose(after[~dead], before[~dead])
    d = np.hypot(world.centres[dead, 0] - 6, world.centres[dead, 1])
    assert d.max() <= 6.0
    assert after.sum() < 0.9 * before.sum()
    world.perturb(Control(world.world_id, "heal"))
    assert not world.lesion.any()


def test_reverse_swaps_up_and_down(world):
    world.reset(seed=1)
    world.pan, world.tilt = 0.0, 0.0
    world.perturb(Control(world.world_id, "reverse"))
    world.step(np.array([0.0, 5.0]))
    assert world.tilt == pytest.approx(-5.0)
    assert world.truth().tensors["positions"][:, 1] == pytest.approx(
        world.saccade_for(world.centres[:, 0], world.centres[:, 1])[:, 1]
    )  # the truth stays the healthy geometry
    world.perturb(Control(world.world_id, "heal"))
    assert not world.reversed


def test_noise_and_bad_controls(world):
    world._look_at_offset(30.0, 0.0)
    clean = world.render()
    world.perturb(Control(world.world_id, "noise", {"sd": "0.1"}))
    noisy = world.render()
    assert np.abs(noisy - clean).mean() > 0.01
    world.perturb(Control(world.world_id, "heal"))
    with pytest.raises(PerturbationError, match="no perturbation"):
        world.perturb(Control(world.world_id, "melt"))
    with pytest.raises(ValueError, match="2 finite numbers"):
        world.step(np.array([1.0]))


def test_params_are_validated():
    with pytest.raises(ValueError, match="scene"):
        RetinaWorld(scene="fog")
    from sensorimotor.worlds.registry import make_world

    with pytest.raises(ValueError, match="is not an int"):
        make_world("retina", params={"layers": "four"})
