"""Any Gymnasium environment with discrete actions as a world (`sme world gym:ENV_ID`), learned by
the generic program: start states and truth where the environment's state can be set, none (and
saying so) where it cannot, typed environment keyword arguments, clear refusals."""

from __future__ import annotations

import importlib.util
import logging

import gymnasium as gym
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import EventKind
from sensorimotor.protocol.params import ParamError
from sensorimotor.tools.cli import main as sme
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.registry import make_world

FROZEN_8x8 = {"map_name": "8x8", "is_slippery": "false"}


class _MultiDiscreteEnv(gym.Env):
    """An action space a world cannot serve."""

    observation_space = gym.spaces.Discrete(3)
    action_space = gym.spaces.MultiDiscrete([2, 2])

    def reset(self, seed=None, options=None):
        super().reset(seed=seed)
        return 0, {}

    def step(self, action):
        return 0, 0.0, False, False, {}


@pytest.fixture(autouse=True)
def one_blas_thread():
    """LSPI solves small systems: a multi-threaded BLAS only slows them on a busy machine."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


@pytest.mark.parametrize("learner", ["model", "tabular"])
def test_frozenlake_8x8_embedding_of_the_reachable_cells_matches_row_col(learner):
    with make_world("gym:FrozenLake-v1", None, 0, FROZEN_8x8) as world:
        spec, truth = world.spec(), world.truth()
        program = make_program(spec, 0, samples_per_iteration=400, learner=learner)
        assert isinstance(program, GenericProgram) and program.tabular
        run = run_inprocess(
            world, program, 15_000, stop_when=lambda r: any(e is not None and e < 0.1 for e in r.errors)
        )
    # 64 cells - 10 holes - the goal: the reachable cells a trace can start from
    assert spec.world_id == "FrozenLake-v1" and spec.n_starts == 53 and truth is not None
    rows = truth.tensors["positions"]
    assert rows.shape == (53, 2) and rows[0].tolist() == [0, 0] and [7, 7] not in rows.tolist()
    errors = [e for e in run.errors if e is not None]
    if learner == "tabular":  # LSPI over random samples: the map appears as the policy does
        assert errors[0] > 0.3 and errors[-1] < 0.1, errors
    else:  # the model is swept once it has tried every action of every cell it met: its first map holds
        assert errors[0] < 0.1 and len(errors) == 1, errors


def test_frozenlake_start_states_are_set_and_truth_is_row_col():
    with make_world("gym:FrozenLake-v1", None, 3, {"is_slippery": "false"}) as w:
        pos = w.truth().tensors["positions"]
        assert pos.tolist() == [[0, 0], [0, 1], [0, 2], [0, 3], [1, 0], [1, 2], [2, 0], [2, 1], [2, 2], [3, 1], [3, 2]]
        for k in (0, 5, 10):
            r, c = pos[k]
            assert int(w.reset(start=k).tensors["observation"][0]) == r * 4 + c
        r = w.reset(start=10)  # (3, 2): one step right reaches the goal
        step = w.step(np.array([2.0]))
        assert step.reward == 1.0 and step.done and step.info["terminated"]
        with pytest.raises(ValueError):
            w.reset(start=11)


def test_mountaincar_start_states_are_a_grid_of_position_and_velocity():
    with make_world("gym:MountainCar-v0", "car", 0, {"start_grid": "5"}) as w:
        spec, truth = w.spec(), w.truth()
        assert spec.world_id == "car" and spec.n_starts == 25 and spec.action_space.n == 3
        s = spec.sensors[0]
        assert (s.dtype, s.shape) == ("float32", (2,)) and (s.low, s.high) == pytest.approx((-1.2, 0.6))
        raw = truth.tensors["state"]
        assert raw[0] == pytest.approx([-1.2, -0.07]) and raw[-1] == pytest.approx([0.45, 0.07])
        assert truth.tensors["positions"].min() == 0 and truth.tensors["positions"].max() == 1
        obs = w.reset(start=7).tensors["observation"]
        assert obs == pytest.approx(raw[7].astype(np.float32))


def test_a_world_whose_state_cannot_be_set_runs_without_start_states_and_says_so(caplog):
    with caplog.at_level(logging.WARNING, logger="sme.world"):
        world = make_world("gym:Blackjack-v1", None, 0)
    assert "no start states" in caplog.text
    with world:
        spec = world.spec()
        assert spec.n_starts == 0 and world.truth() is None and "cannot be set" in spec.params["start_states"]
        assert spec.sensors[0].shape == (45,)  # Tuple of Discretes, flattened (one-hot)
        program = make_program(spec, 0, samples_per_iteration=100)
        run = run_inprocess(world, program, 300)
    assert run.steps == 300 and not run.embeddings
    said = [e for e in run.events(EventKind.POLICY_ITERATION) if e.reason == "no_start_states"]
    assert len(said) == 1 and "learned, not embedded" in said[0].detail


def test_environment_keyword_arguments_are_typed_and_checked():
    with make_world("gym:FrozenLake-v1", None, 0, {"is_slippery": "no", "success_rate": "0.5"}) as w:
        assert w.env_kwargs == {"is_slippery": False, "success_rate": 0.5}
        assert w.spec().params["is_slippery"] == "False"
    with pytest.raises(ParamError, match="unknown parameter of gym:FrozenLake-v1 'slippery'.*is_slippery"):
        make_world("gym:FrozenLake-v1", None, 0, {"slippery": "true"})
    with pytest.raises(ParamError, match="is_slippery='maybe' is not a bool"):
        make_world("gym:FrozenLake-v1", None, 0, {"is_slippery": "maybe"})
    gym.register("sme-test/MultiDiscrete-v0", entry_point=_MultiDiscreteEnv)
    with pytest.raises(ParamError, match="MultiDiscrete action space.*serves Discrete actions and bounded"):
        make_world("gym:sme-test/MultiDiscrete-v0", None, 0)
    with pytest.raises(ParamError, match="did you mean 'FrozenLake-v1'"):
        make_world("gym:FrozenLak-v1", None, 0)


@pytest.mark.parametrize(
    "args",
    [
        ["gym:FrozenLake-v1", "--param", "slippery=false"],
        ["gym:no_such_pkg:Thing-v0"],
        ["gym:NoSuchEnv-v0"],
        ["gym:FrozenLake-v1", "--param", "is_slippery=maybe"],
        ["gym:LunarLander-v3"],  # Box2D is not a dependency: refused with gymnasium's install hint
    ],
)
def test_sme_world_refuses_bad_gym_input_with_exit_2(args, capsys):
    if args == ["gym:LunarLander-v3"] and importlib.util.find_spec("Box2D") is not None:
        pytest.skip("Box2D is installed here")
    assert sme(["world", *args, "--steps", "1"]) == 2
    assert "sme world:" in capsys.readouterr().err


def test_sme_world_lists_a_gym_environment_s_parameters(capsys):
    assert sme(["world", "gym:FrozenLake-v1", "--list-params"]) == 0
    out = capsys.readouterr().out
    assert "start_grid" in out and "map_name = '4x4'" in out and "is_slippery = True" in out
