"""The control plane: every perturbation declares its parameters once; a bad Control is refused
before anything changes (in process), and over the bus the world stays up and the agent passes the
refusal on as a `world_event` naming the parameter and its range."""

from __future__ import annotations

import copy
import dataclasses
import subprocess
import sys
import typing
from typing import Any

import numpy as np
import pytest

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import AgentEvent, Control, EventKind, WorldEventKind
from sensorimotor.worlds.base import PerturbationError, World
from sensorimotor.worlds.mountaincar import MountainCarWorld
from sensorimotor.worlds.registry import WORLDS, world_perturbations
from sensorimotor.worlds.retina import RetinaWorld
from sensorimotor.worlds.vergence import VergenceWorld
from tests.conftest import agent_status as status
from tests.conftest import wait_for
from tests.conftest import world_link as link


@pytest.fixture(scope="module")
def retina():
    w = RetinaWorld("r", seed=3, layers=2, fields=8, supersample=1)
    yield w
    w.close()


@pytest.fixture(scope="module")
def vergence():
    w = VergenceWorld("v", seed=3)
    yield w
    w.close()


@pytest.fixture(scope="module")
def mountaincar():
    w = MountainCarWorld("m", seed=3, n_eval=1)
    yield w
    w.close()


def snapshot(world: World) -> dict[str, Any]:
    """Everything a perturbation may change, copied: body, sensors, caches, random state, truth."""
    names = (
        "lesion",
        "reversed",
        "noise_sd",
        "baseline",
        "vertical",
        "_goal_cache",
        "_images",
        "_goals",
        "pan",
        "tilt",
    )
    out = {n: copy.deepcopy(getattr(world, n)) for n in names if hasattr(world, n)}
    out["rng"] = copy.deepcopy(world.rng.bit_generator.state)
    tr = world.truth()
    out["truth"] = None if tr is None else dict(tr.tensors)
    return out


def same(x: Any, y: Any) -> bool:
    """Exact equality through dicts (in order), lists, tuples and arrays."""
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        return isinstance(x, np.ndarray) and isinstance(y, np.ndarray) and x.dtype == y.dtype and np.array_equal(x, y)
    if isinstance(x, dict):
        return isinstance(y, dict) and list(x) == list(y) and all(same(x[k], y[k]) for k in x)
    if isinstance(x, (list, tuple)):
        return type(x) is type(y) and len(x) == len(y) and all(same(a, b) for a, b in zip(x, y, strict=True))
    return type(x) is type(y) and x == y


# (world fixture, control kind, params, words the refusal must contain: the parameter and its range)
BAD = [
    ("retina", "lesion", {"radius": "-1"}, ["radius", "below the minimum", "0.0..512.0"]),
    ("retina", "lesion", {"radius": "nan"}, ["radius", "is not a float", "0.0..512.0"]),
    ("retina", "lesion", {"u": "inf"}, ["u=", "is not a float", "-512.0..512.0"]),
    ("retina", "lesion", {"u": "1e6"}, ["u=", "above the maximum", "-512.0..512.0"]),
    ("retina", "lesion", {"rad": "3"}, ["unknown parameter 'rad'", "did you mean 'radius'", "0.0..512.0"]),
    ("retina", "lesion", {"radius": "2", "v": "x"}, ["v='x' is not a float", "-512.0..512.0"]),
    ("retina", "noise", {"sd": "1e9"}, ["sd=", "above the maximum", "0.0..1.0"]),
    ("retina", "noise", {"sd": "-0.1"}, ["sd=", "below the minimum", "0.0..1.0"]),
    ("retina", "noise", {"sd": "NaN"}, ["sd=", "is not a float"]),
    ("retina", "noise", {"sd": "0.1", "seed": "3"}, ["unknown parameter 'seed'", "sd: float in 0.0..1.0"]),
    ("retina", "reverse", {"axis": "up"}, ["unknown parameter 'axis'", "no parameters"]),
    ("retina", "heal", {"all": "1"}, ["unknown parameter 'all'"]),
    ("retina", "melt", {}, ["no perturbation 'melt'", "lesion, reverse, noise, heal"]),
    ("vergence", "morph", {"baseline": "0"}, ["baseline=", "below the minimum", "0.05..2.0"]),
    ("vergence", "morph", {"baseline": "-1"}, ["baseline=", "0.05..2.0"]),
    ("vergence", "morph", {"baseline": "inf"}, ["baseline=", "is not a float"]),
    ("vergence", "morph", {"baseline": "1.4", "vertical": "maybe"}, ["vertical='maybe' is not a bool"]),
    ("vergence", "morph", {"baselin": "1.4"}, ["did you mean 'baseline'"]),
    ("vergence", "lesion", {}, ["no perturbation 'lesion'", "morph, heal"]),
    ("mountaincar", "morph", {"baseline": "0"}, ["baseline=", "0.05..2.0"]),
    ("mountaincar", "morph", {"baseline": "1e9"}, ["baseline=", "above the maximum", "0.05..2.0"]),
]


@pytest.mark.parametrize(("fixture", "kind", "params", "words"), BAD, ids=[f"{b[0]}-{b[1]}-{b[2]}" for b in BAD])
def test_a_bad_perturbation_is_refused_and_changes_nothing(request, fixture, kind, params, words):
    world = request.getfixturevalue(fixture)
    if fixture == "retina":  # a lesion and noise already in place must stay exactly as they are
        world.perturb(Control(world.world_id, "heal"))
        world.perturb(Control(world.world_id, "lesion", {"u": "-4", "radius": "3"}))
        world.perturb(Control(world.world_id, "noise", {"sd": "0.02"}))
        assert world.lesion.any() and world.noise_sd == 0.02
    else:
        world.perturb(Control(world.world_id, "heal"))
        world.perturb(Control(world.world_id, "morph", {"baseline": "0.9"}))
        world.reset(start=1)  # fills the goal cache (and the mountain car's render cache)
    before = snapshot(world)
    with pytest.raises(PerturbationError) as err:
        world.perturb(Control(world.world_id, kind, params))
    msg = str(err.value)
    for w in words:
        assert w in msg, (w, msg)
    assert same(before, snapshot(world)), "a refused perturbation changed the world"


def test_good_perturbations_still_apply(retina, vergence):
    retina.perturb(Control("r", "heal"))
    assert "fields within 2.5 px" in retina.perturb(Control("r", "lesion", {"u": "0", "v": "0", "radius": "2.5"}))
    assert retina.lesion.any()
    retina.perturb(Control("r", "noise", {"sd": "1"}))  # the bounds are inclusive
    assert retina.noise_sd == 1.0
    retina.perturb(Control("r", "reverse"))
    assert retina.reversed
    retina.perturb(Control("r", "heal"))
    assert not retina.lesion.any() and not retina.reversed and retina.noise_sd == 0.0
    vergence.perturb(Control("v", "heal"))
    b0 = vergence.baseline
    assert vergence.perturb(Control("v", "morph", {"vertical": "true"})).endswith("cameras vertical")
    assert vergence.vertical and vergence.baseline == b0  # none: unchanged
    vergence.perturb(Control("v", "morph", {"baseline": "2"}))
    assert vergence.baseline == 2.0 and vergence.vertical
    vergence.perturb(Control("v", "heal"))
    assert (vergence.baseline, vergence.vertical) == (b0, False)


def test_every_perturbation_declares_typed_bounded_parameters():
    found = set()
    for name in WORLDS:
        for kind, cls in world_perturbations(name).items():
            found.add((name, kind))
            assert dataclasses.is_dataclass(cls) and cls.__dataclass_params__.frozen, cls
            assert (cls.__doc__ or "").strip(), f"{name} {kind}: no docstring"
            hints = typing.get_type_hints(cls)
            for f in dataclasses.fields(cls):
                assert f.metadata.get("doc"), (name, kind, f.name)
                if float in (hints[f.name], *typing.get_args(hints[f.name])):
                    assert "min" in f.metadata and "max" in f.metadata, f"{name} {kind}: {f.name} has no range"
            cls()  # the defaults are valid
    assert {("retina", "lesion"), ("retina", "noise"), ("vergence", "morph"), ("mountaincar", "heal")} <= found


def test_perturb_list_prints_every_table(capsys):
    from sensorimotor.tools.cli import main

    assert main(["perturb", "--list"]) == 0
    out = capsys.readouterr().out
    for text in ("retina:", "lesion:", "radius", "0.0..512.0", "noise:", "vergence:", "morph:", "0.05..2.0"):
        assert text in out, text
    assert main(["perturb", "lesion"]) == 2
    assert "--world ID are required" in capsys.readouterr().err


@pytest.mark.integration
def test_over_the_bus_a_refused_control_is_reported_and_the_world_stays_up(procs, endpoint):
    agent = procs.start("agent", "--listen", endpoint, "-q")
    world = procs.start(
        "world", "retina", "--id", "r7", "--connect", endpoint, "-q", "--param", "supersample=1",
        "--param", "layers=2", "--param", "fields=8",
    )  # fmt: skip
    assert wait_for(lambda: (ln := link(status(endpoint), "r7")) is not None and ln.steps > 20, 60)
    events: list[AgentEvent] = []
    bad = [
        ("lesion", {"radius": "-1"}, ["radius", "0.0..512.0"]),
        ("noise", {"sd": "1e9"}, ["sd", "0.0..1.0"]),
        ("lesion", {"u": "nan"}, ["u=", "-512.0..512.0"]),
        ("noise", {"sigma": "0.1"}, ["unknown parameter 'sigma'", "0.0..1.0"]),
    ]
    with Bus(BusConfig.for_role("tool", endpoint)) as bus:
        bus.subscribe(keys.agent_event("a0", "r7"), lambda m: events.append(codec.decode(AgentEvent, m.payload)))
        assert bus.get(keys.agent_status("a0"), timeout=10.0)  # the router has the subscription

        def world_events(kind: str) -> list[AgentEvent]:
            return [e for e in list(events) if e.kind == EventKind.WORLD_EVENT and e.reason == kind]

        for i, (kind, params, words) in enumerate(bad):
            bus.put(keys.world_ctl("r7"), codec.encode(Control("r7", kind, params)), codec.schema_name(Control))
            # one at a time (the agent rate-limits events): each refusal its own event
            assert wait_for(lambda: len(world_events(WorldEventKind.CONTROL_REFUSED)) >= i + 1, 30), (i, events)  # noqa: B023
            detail = world_events(WorldEventKind.CONTROL_REFUSED)[i].detail
            assert f"retina {kind}" in detail and all(w in detail for w in words), detail
        steps = link(status(endpoint), "r7").steps
        # the world is still up and still takes a good control
        bus.put(keys.world_ctl("r7"), codec.encode(Control("r7", "noise", {"sd": "0.01"})), codec.schema_name(Control))
        assert wait_for(lambda: world_events(WorldEventKind.CONTROL_APPLIED), 30), events
        applied = world_events(WorldEventKind.CONTROL_APPLIED)[0]
        assert "sd 0.01" in applied.detail
        # `steps` counts the observations learned (0 .. steps-1), so the first the changed body
        # can give is observation `steps`: the control may reach the world before that one is made
        assert applied.step >= steps
    assert wait_for(lambda: link(status(endpoint), "r7").steps > steps + 20, 30)
    assert world.poll() is None and agent.poll() is None


def _sme(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args], capture_output=True, text=True, timeout=timeout
    )


@pytest.mark.integration
def test_sme_perturb_answers_with_the_worlds_words(procs, endpoint):
    """`sme perturb` waits for the world's answer to its request id: exit 0 with what the world
    applied; exit 1, nothing sent, for what the world's advertised kinds or their declarations rule
    out, naming the valid ones; a world of ours takes the generic kinds too."""
    procs.start("agent", "--listen", endpoint, "-q")
    procs.start(
        "world", "retina", "--id", "r8", "--connect", endpoint, "-q", "--param", "supersample=1",
        "--param", "layers=2", "--param", "fields=8",
    )  # fmt: skip
    procs.start("world", "gridworld", "--id", "g8", "--connect", endpoint, "-q")
    assert wait_for(lambda: (ln := link(status(endpoint), "r8")) is not None and ln.steps > 5, 60)
    ok = _sme("perturb", "noise", "--world", "r8", "--param", "sd=0.01", "--connect", endpoint)
    assert ok.returncode == 0, ok.stderr
    assert "world r8 applied noise" in ok.stdout and "sd 0.01" in ok.stdout, ok.stdout
    out = _sme("perturb", "lesion", "--world", "r8", "--param", "radius=-1", "--connect", endpoint)
    assert out.returncode == 1 and "not sent" in out.stderr, (out.stdout, out.stderr)
    assert "radius" in out.stderr and "0.0..512.0" in out.stderr, out.stderr
    assert wait_for(lambda: link(status(endpoint), "g8") is not None, 30)
    out = _sme("perturb", "heal", "--world", "g8", "--connect", endpoint)
    assert out.returncode == 1 and "gridworld has no perturbation 'heal'" in out.stderr, out.stderr
    assert "valid: reverse, permute, gain, lesion, noise, delay, restore" in out.stderr, out.stderr
    assert "sent" not in out.stdout
    out = _sme("perturb", "reverse", "--world", "g8", "--connect", endpoint)  # generic: applied
    assert out.returncode == 0 and "world g8 applied reverse: swapped actions" in out.stdout, (out.stdout, out.stderr)


@pytest.mark.integration
def test_sme_perturb_exits_1_when_the_world_refuses_or_does_not_answer(endpoint):
    """A world of a kind this installation does not know decides alone: its refusal is exit 1 with
    its words; a world that never answers is exit 1 after --timeout, saying why."""
    from sensorimotor.protocol.messages import ActionSpace, SensorSpec, WorldEvent, WorldSpec

    seen: list[Control] = []
    with Bus(BusConfig.for_role("agent", endpoint)) as bus:
        spec = WorldSpec("x1", "outside-kind", (SensorSpec("s", "float32", (1,)),), ActionSpace(n=2))
        bus.queryable(keys.world_spec("x1"), lambda k, p: codec.encode(spec), codec.schema_name(WorldSpec))

        def on_ctl(msg):
            ctl = codec.decode(Control, msg.payload)
            seen.append(ctl)
            if ctl.kind == "silence":
                return
            ev = WorldEvent("x1", WorldEventKind.CONTROL_REFUSED, ctl.kind, "too hot to melt", control_id=ctl.id)
            bus.put(keys.world_event("x1"), codec.encode(ev), codec.schema_name(WorldEvent))

        bus.subscribe(keys.world_ctl("x1"), on_ctl)
        bus.token(keys.alive_world("x1"))
        out = _sme("perturb", "melt", "--world", "x1", "--connect", endpoint)
        assert out.returncode == 1, (out.stdout, out.stderr)
        assert "world x1 refused melt: too hot to melt" in out.stderr
        assert seen and seen[-1].id != 0
        out = _sme("perturb", "--list", "--world", "x1", "--connect", endpoint)  # it advertises nothing
        assert out.returncode == 0 and "does not say which perturbations it takes" in out.stdout, out
        out = _sme("perturb", "silence", "--world", "x1", "--timeout", "1", "--connect", endpoint)
        assert out.returncode == 1 and "did not answer within 1 s" in out.stderr, out.stderr
