"""Typed parameters declared once: the parser, the declarations of every world and program, the
README tables rendered from them."""

from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass, field

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sensorimotor.agent.programs.registry import PROGRAMS, check_program_params, make_program, program_params
from sensorimotor.protocol.params import (
    ParamError,
    assignments,
    cast_values,
    describe,
    option,
    parse,
    table_markdown,
    table_text,
)
from sensorimotor.worlds.registry import WORLDS, make_world, parse_world_params, world_params
from tests.conftest import ROOT


@dataclass(frozen=True)
class Demo:
    """A declaration exercising every supported type."""

    size: int = option(9, "grid side", min=3, max=99)
    rate: float = option(0.5, "a rate", min=0.0, max=1.0)
    flag: bool = option(False, "a switch")
    scene: str = option("spot", "what to show", choices=("spot", "spots", "texture"))
    goal: tuple[int, int] | None = option(None, "a cell x,y")
    centres: tuple[float, ...] = option((0.0, 0.1), "RBF centres", min=0.0)
    limit: int | None = option(None, "an optional limit", min=0)
    plain: int = field(default=3, metadata={"doc": "declared with dataclasses.field"})


# the parser ------------------------------------------------------------------------------------


def test_defaults_and_string_values():
    assert parse(Demo) == Demo()
    p = parse(
        Demo,
        {
            "size": "7",
            "rate": "0.25",
            "flag": "yes",
            "scene": "texture",
            "goal": "1,2",
            "centres": "0, 0.05,0.1",
            "limit": "5",
            "plain": "4",
        },
        name="demo",
    )
    assert p == Demo(7, 0.25, True, "texture", (1, 2), (0.0, 0.05, 0.1), 5, 4)
    assert isinstance(p.rate, float) and isinstance(p.size, int)


def test_k_equals_v_strings_and_typed_values():
    assert parse(Demo, ["size=5", "flag=true"]) == Demo(size=5, flag=True)
    assert parse(Demo, {"size": 5, "rate": 1, "goal": [3, 4], "centres": (0.2,), "limit": None}) == Demo(
        size=5, rate=1.0, goal=(3, 4), centres=(0.2,)
    )
    assert assignments(["a=1", " b = x=y "]) == {"a": "1", "b": "x=y"}
    with pytest.raises(ParamError, match="key=value"):
        assignments(["novalue"])


def test_unknown_key_names_the_valid_ones_and_suggests_the_closest():
    with pytest.raises(ParamError) as e:
        parse(Demo, {"sise": "5"}, name="gridworld")
    msg = str(e.value)
    assert msg.startswith("gridworld: unknown parameter 'sise'")
    assert "did you mean 'size'?" in msg
    assert "size, rate, flag, scene, goal, centres, limit, plain" in msg
    with pytest.raises(ParamError) as e:
        parse(Demo, {"zzzzzz": "1"})
    assert "did you mean" not in str(e.value) and "Demo: unknown parameter 'zzzzzz'" in str(e.value)
    assert isinstance(e.value, ValueError)


@pytest.mark.parametrize(
    "key,raw,expect",
    [
        ("size", "abc", "demo: size='abc' is not an int"),
        ("size", "7.5", "is not an int"),
        ("size", True, "is not an int"),
        ("rate", "fast", "demo: rate='fast' is not a float"),
        ("rate", "nan", "is not a float"),
        ("rate", "inf", "is not a float"),
        ("flag", "maybe", "flag='maybe' is not a bool"),
        ("flag", 2, "is not a bool"),
        ("scene", 3, "scene=3 is not a str"),
        ("goal", "1", "goal='1' is not 2 comma-separated ints or none"),
        ("goal", "1,2,3", "is not 2 comma-separated ints"),
        ("goal", "a,b", "is not 2 comma-separated ints"),
        ("centres", "0.1,x", "is not comma-separated floats"),
        ("limit", "many", "is not an int or none"),
    ],
)
def test_bad_values_name_the_key_and_the_type(key, raw, expect):
    with pytest.raises(ParamError, match=expect.replace("(", r"\(").replace(")", r"\)")):
        parse(Demo, {key: raw}, name="demo")


@pytest.mark.parametrize(
    "raw,value",
    [
        ("true", True),
        ("1", True),
        ("yes", True),
        ("on", True),
        ("false", False),
        ("0", False),
        ("no", False),
        ("off", False),
        (True, True),
        (0, False),
    ],
)
def test_bool(raw, value):
    assert parse(Demo, {"flag": raw}).flag is value


def test_tuples_and_optionals():
    assert parse(Demo, {"goal": "(4, 5)"}).goal == (4, 5)
    assert parse(Demo, {"goal": "none"}).goal is None
    assert parse(Demo, {"centres": "[0.1, 0.2]"}).centres == (0.1, 0.2)
    assert parse(Demo, {"centres": "0.3,"}).centres == (0.3,)
    assert parse(Demo, {"centres": ""}).centres == ()
    assert parse(Demo, {"limit": "none"}).limit is None and parse(Demo, {"limit": "null"}).limit is None


def test_ranges_and_choices():
    with pytest.raises(ParamError, match="size='2' is below the minimum 3"):
        parse(Demo, {"size": "2"}, name="demo")
    with pytest.raises(ParamError, match="is above the maximum 99"):
        parse(Demo, {"size": "100"})
    with pytest.raises(ParamError, match="is above the maximum 1"):
        parse(Demo, {"rate": "1.5"})
    with pytest.raises(ParamError, match="centres='0.1,-1' is below the minimum 0"):
        parse(Demo, {"centres": "0.1,-1"}, name="demo")
    with pytest.raises(ParamError, match="scene='fog' is not one of spot, spots, texture"):
        parse(Demo, {"scene": "fog"}, name="demo")
    assert parse(Demo, {"size": "3", "rate": "1"}) == Demo(size=3, rate=1.0)


def test_all_problems_are_reported_at_once_and_base_is_kept():
    with pytest.raises(ParamError) as e:
        parse(Demo, {"sise": "1", "rate": "x"}, name="demo")
    assert "sise" in str(e.value) and "rate='x'" in str(e.value)
    base = Demo(size=11)
    assert parse(Demo, {"flag": "1"}, base=base) == Demo(size=11, flag=True)
    assert cast_values(Demo, {"size": "4"}) == {"size": 4}
    with pytest.raises(TypeError):
        parse(Demo, {}, base=object())


def test_tables():
    rows = {p.name: p for p in describe(Demo)}
    assert (rows["size"].type, rows["size"].default) == ("int", "9")
    assert rows["size"].doc == "grid side (3..99)"
    assert rows["goal"].type == "int,int | none" and rows["goal"].default == "none"
    assert rows["centres"].type == "float,..." and rows["centres"].default == "0.0,0.1"
    assert rows["flag"].default == "false" and "one of spot|spots|texture" in rows["scene"].doc
    text = table_text(Demo, "demo")
    assert text.splitlines()[0] == "demo" and "rate" in text and "a switch" in text
    md = table_markdown(Demo).splitlines()
    assert md[0] == "| name | type | default | doc |" and len(md) == 2 + len(rows)
    assert "int,int \\| none" in table_markdown(Demo)


_KEYS = st.sampled_from([f.name for f in dataclasses.fields(Demo)] + ["sise", "", "x y"])


@settings(max_examples=300, deadline=None)
@given(
    st.dictionaries(
        _KEYS, st.text(max_size=12) | st.sampled_from(["1", "0.5", "1,2", "none", "true", "spot"]), max_size=5
    )
)
def test_any_string_values_give_an_instance_or_a_param_error(values):
    try:
        p = parse(Demo, values, name="demo")
    except ParamError:
        return
    assert isinstance(p, Demo)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.text(max_size=15), max_size=4))
def test_any_assignment_strings_give_an_instance_or_a_param_error(items):
    try:
        parse(Demo, items, name="demo")
    except ParamError:
        pass


# every world and program -----------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(WORLDS))
def test_every_world_declares_params_and_builds_from_defaults(name):
    P = world_params(name)
    assert dataclasses.is_dataclass(P) and P.__dataclass_params__.frozen
    for f in dataclasses.fields(P):
        assert f.metadata.get("doc"), f"{name}.{f.name} has no doc"
    assert parse_world_params(name) == P()
    params = {"supersample": "1"} if name == "retina" else {}
    with make_world(name, None, 0, params) as w:
        assert isinstance(w.params, WORLDS[name].world_class().Params)
        for f in dataclasses.fields(P):
            if f.name not in params:
                assert getattr(w.params, f.name) == f.default
        w.reset(start=0)


def test_world_registry_variants_and_errors():
    assert world_params("gridworld-barrier")().barrier is True
    with make_world("gridworld-barrier", params={"barrier": "false"}) as w:
        assert not w.walls
    with make_world("gridworld", params={"size": "5", "goal": "1,1", "actions": "8"}) as w:
        assert (w.size, w.goal, len(w.moves)) == (5, (1, 1), 8)
    with pytest.raises(ParamError, match="did you mean 'size'"):
        make_world("gridworld", params={"sise": "5"})
    with pytest.raises(ParamError, match="did you mean 'retina'"):
        make_world("retna")


def test_world_constructors_take_keywords_or_a_params_instance():
    from sensorimotor.worlds.gridworld import GridWorld, GridWorldParams

    a = GridWorld(seed=1, size=5)
    b = GridWorld("g0", 1, GridWorldParams(size=5))
    assert a.params == b.params and (a.state_id == b.state_id).all()
    assert GridWorld(seed=1, params=GridWorldParams(size=5), barrier=True).params == GridWorldParams(
        size=5, barrier=True
    )
    with pytest.raises(ValueError, match="actions=5 is not one of 4, 8"):
        GridWorld(actions=5)


@pytest.mark.parametrize("name", sorted(PROGRAMS))
def test_every_program_declares_params_and_builds_from_defaults(name):
    from sensorimotor.worlds.registry import make_world as mw

    P = program_params(name)
    assert dataclasses.is_dataclass(P) and P.__dataclass_params__.frozen
    for f in dataclasses.fields(P):
        assert f.metadata.get("doc"), f"{name}.{f.name} has no doc"
    world = {
        "gridworld": "gridworld",
        "retina": "retina",
        "vergence": "stereo",
        "mountaincar": "mountaincar",
        "echo": "bench",
        "generic": "gridworld",
        "rovingeye": "rovingeye",
    }[name]
    with mw(
        world, None, 0, {"supersample": "1"} if world == "retina" else {"n_eval": "2"} if world == "mountaincar" else {}
    ) as w:
        spec = dataclasses.replace(w.spec(), program=name)
    prog = make_program(spec, 0)
    assert prog.params == P() and type(prog).Params is P


def test_program_params_are_validated_and_typed():
    assert check_program_params(
        {"retina": {"embed_every": "500", "noise_sd": "none"}, "vergence": {"centres": "0,0.1"}}
    ) == {"retina": {"embed_every": 500, "noise_sd": None}, "vergence": {"centres": (0.0, 0.1)}}
    assert check_program_params(None) == {}
    with pytest.raises(ParamError, match="did you mean 'retina'"):
        check_program_params({"retna": {}})
    with pytest.raises(ParamError, match="retina: unknown parameter 'embed_evry' \\(did you mean 'embed_every'\\?\\)"):
        check_program_params({"retina": {"embed_evry": "5"}})
    with pytest.raises(ParamError, match="gridworld: policy='greedy' is not one of lspi, random"):
        check_program_params({"gridworld": {"policy": "greedy"}})


def test_daemon_refuses_bad_program_params_at_construction():
    from sensorimotor.agent.daemon import AgentDaemon

    with pytest.raises(ParamError, match="unknown parameter"):
        AgentDaemon(bus=None, program_params={"retina": {"embed_evry": 5}})


def test_agent_command_validates_before_the_bus_opens(monkeypatch, capsys):
    from sensorimotor.tools.commands import agent as agent_cmd

    def no_bus(*a, **k):
        raise AssertionError("the bus must not be opened for bad parameters")

    monkeypatch.setattr(agent_cmd, "Bus", no_bus)
    args = argparse.Namespace(program_param=["retina.rule=fancy"])
    assert agent_cmd.run_agent(args) == 2
    assert "retina: rule='fancy' is not one of basic, robust" in capsys.readouterr().err


# the documentation -----------------------------------------------------------------------------


def test_documented_parameter_tables_equal_the_declarations():
    from sensorimotor.tools.docgen.params_doc import current_section, render_section

    page = (ROOT / "docs" / "worlds.md").read_text()
    assert current_section(page) == render_section(), (
        "docs/worlds.md drifted: run `python -m sensorimotor.tools.docgen.params_doc docs/worlds.md`"
    )
    for name in WORLDS:
        assert f"`{name}`:" in page
    for name in PROGRAMS:
        assert f"`{name}`:" in page
