"""The generic body changes (worlds.body_changes), in process: what each kind does to the actions
the world applies and the observations the agent receives, that they compose and restore, that a
world's own kind takes precedence, that bad ones are refused with the valid choices before anything
changes, and the `sme_perturb` hook of Gymnasium environments and `EmbeddableEnv`."""

from __future__ import annotations

import json
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import ActionSpace, Control, EventKind, SensorSpec, Trigger, Truth, WorldSpec
from sensorimotor.protocol.params import ParamError, option
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.base import PerturbationError, StepResult, World
from sensorimotor.worlds.body_changes.advertise import advertised
from sensorimotor.worlds.body_changes.layer import BodyChanges
from sensorimotor.worlds.gym_world import EmbeddableEnv, GymWorld
from tests.test_generic_program import Beacons


@dataclass(frozen=True)
class HealOnly:
    """Undo the world's own changes."""


@dataclass(frozen=True)
class OwnReverse:
    """The world's own reversal."""


class Probe(World):
    """A world that reports the action it applied: sensor ``applied`` is that action, ``ramp`` ten
    fixed values 1..10 and ``cell`` an int32 state id 0..9; `steps` counts the world's own steps."""

    kind = "probe"
    max_episode_steps = 20

    def __init__(self, space: ActionSpace, own: dict | None = None) -> None:
        super().__init__("p", 0)
        self.space = space
        self.Perturbations = own or {}  # type: ignore[misc]
        self.applied = np.zeros(space.dims)
        self.steps = 0
        self.own_calls: list[str] = []

    def spec(self) -> WorldSpec:
        sensors = (
            SensorSpec("applied", "float32", (self.space.dims,), -10.0, 10.0),
            SensorSpec("ramp", "float32", (10,), 0.0, 10.0),
            SensorSpec("cell", "int32", (1,), 0.0, 9.0),
        )
        return WorldSpec("p", self.kind, sensors, self.space, n_starts=1)

    def _obs(self) -> StepResult:
        return StepResult(
            {
                "applied": self.applied.astype(np.float32),
                "ramp": np.arange(1, 11, dtype=np.float32),
                "cell": np.array([5], dtype=np.int32),
            }
        )

    def reset(self, seed=None, start=None) -> StepResult:
        self.applied = np.zeros(self.space.dims)
        return self._obs()

    def step(self, action) -> StepResult:
        self.applied = np.asarray(action, dtype=np.float64).reshape(-1)
        self.steps += 1
        return self._obs()

    def perturb(self, control: Control) -> str:
        self.perturbation_params(control)
        self.own_calls.append(control.kind)
        return f"own {control.kind}"


DISCRETE = ActionSpace(n=4, names=("up", "down", "left", "right"))
UNNAMED = ActionSpace(n=5)
BOX = ActionSpace(low=(-1.0, 0.0), high=(1.0, 2.0))


def body(space: ActionSpace, own: dict | None = None) -> BodyChanges:
    w = BodyChanges(Probe(space, own))
    w.reset()
    return w


def change(w: World, kind: str, **params) -> str:
    return w.perturb(Control("p", kind, {k: str(v) for k, v in params.items()}))


def applied(w: BodyChanges, a) -> list[float]:
    """The action the world applied for agent action `a` (None when it did not step)."""
    before = w.world.steps
    r = w.step(np.atleast_1d(np.asarray(a, dtype=np.float64)))
    if w.world.steps == before:
        return None
    return r.tensors["applied"].tolist()


# reverse -------------------------------------------------------------------------------------------
def test_reverse_swaps_named_opposites_and_twice_is_the_body_as_it_was():
    w = body(DISCRETE)
    assert change(w, "reverse") == "swapped actions 0<->1, 2<->3"
    assert [applied(w, i) for i in range(4)] == [[1.0], [0.0], [3.0], [2.0]]
    change(w, "reverse")
    assert [applied(w, i) for i in range(4)] == [[0.0], [1.0], [2.0], [3.0]]


def test_reverse_without_names_mirrors_the_index_or_takes_given_pairs():
    w = body(UNNAMED)
    assert change(w, "reverse") == "swapped actions 0<->4, 1<->3"
    assert [applied(w, i)[0] for i in range(5)] == [4.0, 3.0, 2.0, 1.0, 0.0]
    w = body(UNNAMED)
    change(w, "reverse", pairs="0:2", index=2)
    assert [applied(w, i)[0] for i in range(5)] == [2.0, 1.0, 0.0, 3.0, 4.0]


def test_reverse_mirrors_a_box_dimension_about_the_middle_of_its_range():
    w = body(BOX)
    change(w, "reverse", index=1)
    assert applied(w, [0.5, 0.5]) == [0.5, 1.5]
    change(w, "reverse", index=0)
    assert applied(w, [0.5, 0.5]) == [-0.5, 1.5]


def test_reverse_in_gymnasium_families_swaps_true_opposites():
    fl = BodyChanges(GymWorld("FrozenLake-v1", "fl", env_kwargs={"is_slippery": False}))
    assert change(fl, "reverse") == "swapped actions 0<->2, 1<->3"  # left/right, down/up
    fl.reset(start=0)
    assert int(fl.step(np.array([2.0])).tensors["observation"][0]) == 0  # "right" went left, into the wall
    assert int(fl.step(np.array([3.0])).tensors["observation"][0]) == 4  # "up" went down
    fl.close()


# permute, gain --------------------------------------------------------------------------------------
def test_permute_exchanges_actions_and_rescales_box_dimensions():
    w = body(DISCRETE)
    assert change(w, "permute") == "actions exchanged: 0->1, 1->2, 2->3, 3->0"
    assert [applied(w, i)[0] for i in range(4)] == [1.0, 2.0, 3.0, 0.0]
    w = body(DISCRETE)
    change(w, "permute", order="3,2,0,1")
    assert [applied(w, i)[0] for i in range(4)] == [3.0, 2.0, 0.0, 1.0]
    w = body(BOX)
    change(w, "permute", order="0:1")
    # -1..1 in dimension 0 acts as 0..2 in dimension 1, and the other way round
    assert applied(w, [0.5, 0.5]) == [-0.5, 1.5]


def test_gain_scales_a_box_dimension_about_its_middle_within_its_range():
    w = body(BOX)
    change(w, "gain", index=0, gain=0.5)
    assert applied(w, [0.8, 2.0]) == pytest.approx([0.4, 2.0])
    change(w, "gain", index=1, gain=3)
    assert applied(w, [0.8, 1.5]) == pytest.approx([0.4, 2.0])  # 1 + 3 * 0.5, clipped to 2


def test_gain_repeats_a_discrete_action_and_a_fractional_gain_acts_that_often():
    w = body(DISCRETE)
    assert change(w, "gain", index=1, gain=2) == "action(s) [1] act 2 times per step"
    applied(w, 1)
    assert w.world.steps == 2
    applied(w, 0)
    assert w.world.steps == 3  # the other actions as they were
    w = body(DISCRETE)
    change(w, "gain", gain=0.5, seed=3)
    for _ in range(400):
        w.step(np.array([2.0]))
    assert 170 <= w.world.steps <= 230  # every other step on average
    fl = BodyChanges(GymWorld("FrozenLake-v1", "fl", env_kwargs={"is_slippery": False}))
    change(fl, "gain", gain=2)
    fl.reset(start=0)
    assert int(fl.step(np.array([2.0])).tensors["observation"][0]) == 2  # "right" went two cells
    fl.close()


# lesion ----------------------------------------------------------------------------------------------
def test_a_lesioned_discrete_action_leaves_the_body_where_it_was():
    w = body(DISCRETE)
    assert change(w, "lesion", index=2) == "action(s) [2] no longer act"
    assert applied(w, 1) == [1.0]
    r = w.step(np.array([2.0]))
    assert w.world.steps == 1 and r.reward == 0.0 and r.tensors["applied"].tolist() == [1.0] and not r.done
    for _ in range(Probe.max_episode_steps - 2):
        r = w.step(np.array([2.0]))
    assert r.done and r.truncated  # the episode still ends at the world's step limit


def test_a_lesioned_box_dimension_is_held_at_the_middle_of_its_range():
    w = body(BOX)
    change(w, "lesion", index=1)
    assert applied(w, [0.3, 2.0]) == pytest.approx([0.3, 1.0])


def test_a_sensor_lesion_zeroes_a_region_of_the_flattened_sensor():
    w = body(DISCRETE)
    assert (
        change(w, "lesion", what="sensor", sensor="ramp", start=0.2, stop=0.5)
        == "sensor region 0.2..0.5 of ramp reads 0"
    )
    r = w.step(np.array([0.0]))
    assert r.tensors["ramp"].tolist() == [1, 2, 0, 0, 0, 6, 7, 8, 9, 10]
    assert r.tensors["ramp"].dtype == np.float32 and r.tensors["applied"].tolist() == [0.0]


# noise, delay -------------------------------------------------------------------------------------
def test_noise_has_the_given_sd_is_seeded_and_keeps_dtype_and_bounds():
    w = body(DISCRETE)
    change(w, "noise", sd=0.5, sensor="ramp", seed=7)
    xs = np.array([w.step(np.array([0.0])).tensors["ramp"] for _ in range(400)])
    assert xs.dtype == np.float32 and xs.min() >= 0.0 and xs.max() <= 10.0
    assert np.std(xs[:, 4] - 5.0) == pytest.approx(0.5, rel=0.1)
    again = body(DISCRETE)
    change(again, "noise", sd=0.5, sensor="ramp", seed=7)
    assert np.array_equal(again.step(np.array([0.0])).tensors["ramp"], xs[0])
    w = body(DISCRETE)
    change(w, "noise", sd=3, sensor="cell")
    cells = np.array([w.step(np.array([0.0])).tensors["cell"][0] for _ in range(300)])
    assert cells.dtype == np.int32 and cells.min() >= 0 and cells.max() <= 9 and len(set(cells)) > 3


def test_delay_applies_each_action_k_steps_late_and_a_new_episode_starts_at_rest():
    w = body(DISCRETE)
    assert change(w, "delay", steps=2) == "actions applied 2 step(s) late"
    assert [applied(w, a) for a in (1, 2, 3, 0)] == [None, None, [1.0], [2.0]]
    w.reset()
    assert [applied(w, a) for a in (3, 3, 0)] == [None, None, [3.0]]
    b = body(BOX)
    change(b, "delay", steps=1)
    assert applied(b, [0.5, 0.5]) == [0.0, 1.0]  # at rest: the middle of the range
    assert applied(b, [-0.5, 2.0]) == [0.5, 0.5]


# composition, restore, precedence ----------------------------------------------------------------
def test_changes_compose_in_the_order_applied_and_restore_undoes_them_all():
    w = body(DISCRETE)
    change(w, "permute")
    change(w, "reverse")  # after the permutation: 0 -> 1 -> 0
    change(w, "noise", sd=1, sensor="ramp")
    assert [applied(w, i) for i in range(4)] == [[0.0], [3.0], [2.0], [1.0]]  # i -> i+1 -> its opposite
    assert change(w, "restore") == "restored: 3 generic change(s) undone"
    r = w.step(np.array([3.0]))
    assert r.tensors["applied"].tolist() == [3.0] and r.tensors["ramp"].tolist() == list(range(1, 11))


def test_a_worlds_own_kind_takes_precedence_and_restore_also_heals_it():
    w = body(DISCRETE, own={"reverse": OwnReverse, "heal": HealOnly})
    assert change(w, "reverse") == "own reverse"
    assert applied(w, 0) == [0.0]  # the generic reversal was not applied
    assert change(w, "permute").startswith("actions exchanged")
    assert change(w, "restore") == "restored: 1 generic change(s) undone; own heal"
    assert w.world.own_calls == ["reverse", "heal"]
    kinds = advertised(w.spec())
    assert kinds["reverse"]["from"] == "world" and kinds["heal"]["from"] == "world"
    generic = [k for k, v in kinds.items() if v["from"] == "generic"]
    assert generic == ["permute", "gain", "lesion", "noise", "delay", "restore"]


def test_the_spec_advertises_the_kinds_with_their_parameters():
    kinds = advertised(body(BOX).spec())
    assert list(kinds) == ["reverse", "permute", "gain", "lesion", "noise", "delay", "restore"]
    gain = {p[0]: p for p in kinds["gain"]["params"]}
    assert gain["gain"][1:3] == ["float", "2.0"] and "-10.0..10.0" in gain["gain"][3]
    assert list(advertised(body(DISCRETE).spec())) == list(kinds)  # every kind, for discrete actions too
    assert json.loads(body(BOX).spec().params["perturbations"]) == kinds


# refusals ---------------------------------------------------------------------------------------
REFUSED = [
    (
        DISCRETE,
        "melt",
        {},
        ["probe has no perturbation 'melt'", "valid: reverse, permute, gain, lesion, noise, delay, restore"],
    ),
    (DISCRETE, "gain", {"gain": "-1"}, ["gain=-1: a discrete action is repeated 0..10 times", "valid: 0.0..10.0"]),
    (DISCRETE, "reverse", {"index": 4}, ["index=4 is out of range", "4 discrete actions (0..3)", "valid: -1..3"]),
    (DISCRETE, "reverse", {"pairs": "0-1"}, ["pairs='0-1'", "'a:b,c:d'"]),
    (DISCRETE, "reverse", {"pairs": "0:1,1:2"}, ["none used twice"]),
    (DISCRETE, "permute", {"order": "0,0,1,2"}, ["a permutation of 0..3", "1,2,3,0"]),
    (BOX, "gain", {"gain": "11"}, ["gain=", "above the maximum", "-10.0..10.0"]),
    (BOX, "gain", {"index": 2}, ["index=2", "a box of 2 dimensions", "valid: -1..1"]),
    (BOX, "lesion", {"what": "motor"}, ["what='motor'", "action|sensor"]),
    (BOX, "lesion", {"what": "sensor", "sensor": "eye"}, ["sensor='eye'", "valid: applied, ramp, cell"]),
    (BOX, "lesion", {"what": "sensor", "start": "0.5", "stop": "0.2"}, ["stop=0.2 must be above start=0.5"]),
    (BOX, "noise", {"sd": "-1"}, ["sd=", "below the minimum", "0.0..1000000.0"]),
    (BOX, "noise", {"sigma": "1"}, ["unknown parameter 'sigma'", "sd: float"]),
    (BOX, "delay", {"steps": "0"}, ["steps=", "1..1000"]),
    (BOX, "restore", {"all": "1"}, ["unknown parameter 'all'"]),
]


@pytest.mark.parametrize(("space", "kind", "params", "words"), REFUSED, ids=[f"{r[1]}-{r[2]}" for r in REFUSED])
def test_a_bad_change_is_refused_naming_the_valid_choices_and_changes_nothing(space, kind, params, words):
    w = body(space)
    change(w, "reverse", index=0)
    before = (len(w.actions), len(w.senses))
    with pytest.raises(PerturbationError) as err:
        change(w, kind, **params)
    for text in words:
        assert text in str(err.value), (text, str(err.value))
    assert (len(w.actions), len(w.senses)) == before


# the agent notices a generic change ---------------------------------------------------------------
def test_the_generic_program_notices_a_generic_reversal_and_relearns():
    world = BodyChanges(Beacons())
    program = make_program(world.spec(), 0, samples_per_iteration=150)
    flip_at = 3_000

    def settled(r) -> bool:
        t = [e.trigger for e in r.embeddings]
        return Trigger.RELEARNED in t

    run = run_inprocess(
        world,
        program,
        20_000,
        detector=make_detector("cusum", **program.detector_params),
        perturb=lambda k: Control("b", "reverse") if k == flip_at else None,
        stop_when=settled,
    )
    drops = run.events(EventKind.DROP_DETECTED)
    assert drops and flip_at < drops[0].step <= flip_at + 300, [d.step for d in drops]
    relearned = next(e for e in run.embeddings if e.trigger == Trigger.RELEARNED)
    assert relearned.drop_step == drops[0].step and relearned.procrustes_error < 0.1


# the hook -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Longer:
    """A longer stride: every move goes `cells` cells."""

    cells: int = option(2, "cells per move", min=1, max=3)


class Corridor(gym.Env):
    """A corridor of 9 cells, moves left/right; offers `stride` (typed) and `wind` (described)."""

    metadata = {"render_modes": []}
    sme_perturbations = {"stride": Longer, "wind": "a push of --param cells=K each step"}

    def __init__(self) -> None:
        self.observation_space = spaces.Discrete(9)
        self.action_space = spaces.Discrete(2)
        self.stride, self.wind, self.s = 1, 0, 4

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.s = 4
        return self.s, {}

    def step(self, action):
        self.s = int(np.clip(self.s + (self.stride if action == 1 else -self.stride) + self.wind, 0, 8))
        return self.s, float(self.s == 8), self.s == 8, False, {}

    def sme_perturb(self, kind, params):
        if kind == "stride":
            self.stride = params.cells
            return f"stride {params.cells}"
        self.wind = int(params["cells"])  # a described kind: the strings as they came
        return f"wind {self.wind}"

    def sme_start_states(self):
        return list(range(8))

    def sme_reset_to(self, s):
        self.s = s
        return s

    def sme_truth(self):
        return np.arange(8, dtype=float)[:, None]


gym.register("test/Corridor-v0", entry_point=Corridor, max_episode_steps=30)


def test_an_environments_own_kinds_are_offered_listed_checked_and_take_precedence():
    w = BodyChanges(GymWorld("test/Corridor-v0", "c"))
    kinds = advertised(w.spec())
    assert kinds["stride"]["from"] == "world" and kinds["stride"]["params"][0][:3] == ["cells", "int", "2"]
    assert kinds["wind"] == {"from": "world", "doc": "a push of --param cells=K each step", "params": None}
    assert change(w, "stride", cells=3) == "stride 3"
    w.reset(start=0)
    assert int(w.step(np.array([1.0])).tensors["observation"][0]) == 3
    with pytest.raises(PerturbationError, match=r"cells=.*above the maximum.*1\.\.3"):
        change(w, "stride", cells=9)
    with pytest.raises(PerturbationError, match="ValueError"):  # the hook's own refusal
        change(w, "wind", cells="strong")
    assert change(w, "wind", cells=-1) == "wind -1"
    with pytest.raises(PerturbationError, match="valid: stride, wind, reverse, permute"):
        change(w, "melt")
    w.close()


def _wrapped_lake(**kw):
    def perturb(env, kind, params):
        if kind == "reverse":
            env.unwrapped.sme_swapped = True
            return "my own reversal"
        return f"{kind} {params.cells}"

    return EmbeddableEnv(
        gym.make("FrozenLake-v1", is_slippery=False, **kw),  # any environment: the wrapper offers the kinds
        starts=[0, 1],
        reset_to=lambda e, s: s,
        truth=[[0.0], [1.0]],
        perturb=perturb,
        perturbations={"stride": Longer, "reverse": "my own reversal"},
    )


gym.register("test/WrappedLake-v0", entry_point=_wrapped_lake, max_episode_steps=30)


def test_embeddable_env_takes_a_perturb_hook_and_its_kinds_take_precedence():
    w = BodyChanges(GymWorld("test/WrappedLake-v0", "wl"))
    kinds = advertised(w.spec())
    assert kinds["reverse"]["from"] == "world" and kinds["stride"]["from"] == "world"
    assert change(w, "reverse") == "my own reversal" and not w.actions  # not the generic one
    assert w.world.u.sme_swapped
    assert change(w, "stride", cells=2) == "stride 2"
    assert change(w, "permute").startswith("actions exchanged")  # the generic kinds are still there
    with pytest.raises(ValueError, match="go together"):
        EmbeddableEnv(gym.make("FrozenLake-v1"), [0], lambda e, s: s, [[0.0]], perturb=lambda e, k, p: "")
    w.close()


class Corridor3(Corridor):
    """The corridor with a third action (stay) and the opposites it declares itself."""

    sme_opposites = [(0, 1)]

    def __init__(self) -> None:
        super().__init__()
        self.action_space = spaces.Discrete(3)


gym.register("test/Corridor3-v0", entry_point=Corridor3, max_episode_steps=30)


def test_an_environment_declares_its_opposite_actions():
    w = BodyChanges(GymWorld("test/Corridor3-v0", "c3"))
    assert change(w, "reverse") == "swapped actions 0<->1"  # not the mirrored 0<->2
    w.close()


def test_a_hook_without_its_declaration_is_refused_at_start_naming_the_fix():
    class Undeclared(Corridor):
        sme_perturbations = None

    gym.register("test/Undeclared-v0", entry_point=Undeclared, max_episode_steps=30)
    with pytest.raises(ParamError, match="defines sme_perturb but not sme_perturbations"):
        GymWorld("test/Undeclared-v0", "u")


def test_truth_and_frames_pass_through_the_layer():
    w = BodyChanges(Beacons())
    assert isinstance(w.truth(), Truth) and w.frame() is None and w.spec().kind == "beacons"


def test_reverse_in_minigrid_swaps_the_turns():
    pytest.importorskip("minigrid")
    w = BodyChanges(GymWorld("MiniGrid-Empty-5x5-v0", "mg"))
    assert change(w, "reverse") == "swapped actions 0<->1, 3<->4"  # turn left/right, pick up/drop
    w.reset(start=0)  # facing east
    w.step(np.array([0.0]))  # "turn left" turns right: facing south
    assert w.world.u.agent_dir == 1
    w.close()
