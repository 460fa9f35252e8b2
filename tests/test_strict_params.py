"""Strict parameters (issue 41): one parser for every numeric and boolean world, perturbation and
program parameter, with limits, and Controls checked against the key they arrive on.

Examples of what was let through (`radius=1_0` read as 10, `sd=1e-400` as 0, `vertical=TRUE`, a
100 KB `0.999...`, a repeated `--param`, a Control for world v1 applied by r1, errors that echoed a
100 KB value), then property tests generating values at and beyond each limit."""

from __future__ import annotations

import math
import re
import subprocess
import sys
from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusMessage
from sensorimotor.protocol.messages import Control, WorldEvent
from sensorimotor.protocol.params import (
    MAX_NUMBER_CHARS,
    MAX_VALUE_CHARS,
    QUOTE_CHARS,
    ParamError,
    assignments,
    format_value,
    option,
    parse,
)
from sensorimotor.worlds.base import PerturbationError, check_perturbation
from sensorimotor.worlds.registry import world_perturbations
from tests.conftest import ROOT

BOUND = 4 * QUOTE_CHARS + 400  # an error message about one value: its bounded quote plus the words


@dataclass(frozen=True)
class P:
    """One parameter of each kind."""

    n: int = option(3, "an int")
    x: float = option(0.5, "a float")
    on: bool = option(False, "a switch")
    name: str = option("a", "a name")
    xs: tuple[float, ...] = option((), "floats")
    opt: float | None = option(None, "an optional float")


def refused(values: dict) -> str:
    with pytest.raises(ParamError) as e:
        parse(P, values, name="p")
    return str(e.value)


# examples ----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "key,raw,why",
    [
        ("n", "1_0", "is not an int"),
        ("x", "1_0.5", "is not a float"),
        ("x", "1e-400", "underflows to 0"),
        ("x", "-0.000000000000000000000000000001e-300", "underflows to 0"),
        ("on", "TRUE", "is not a bool"),
        ("on", "True", "is not a bool"),
        ("opt", "None", "is not a float or none"),
        ("n", "\u0661\u0662", "is not an int"),  # Arabic-Indic digits: Python's int() takes them
        ("x", "\uff11.5", "is not a float"),  # a full-width 1
        ("x", "nan", "is not a float"),
        ("x", "Infinity", "is not a float"),
        ("x", "1e999", "is not finite"),
        ("xs", "0.1,1_0", "is not comma-separated floats"),
    ],
)
def test_lenient_spellings_are_refused(key, raw, why):
    assert why in refused({key: raw})


def test_what_is_documented_still_parses():
    p = parse(P, {"n": "-12", "x": "+1.5e-3", "on": "yes", "xs": "(.5, 2., 1e2)", "opt": "none"})
    assert (p.n, p.x, p.on, p.xs, p.opt) == (-12, 0.0015, True, (0.5, 2.0, 100.0), None)
    assert parse(P, {"x": "0e-400", "opt": "null"}).x == 0.0  # a zero written as one is no underflow
    assert parse(P, {"x": "5e-324"}).x == 5e-324  # the smallest subnormal is not 0


def test_a_100_kb_value_is_refused_and_quoted_short():
    big = "0." + "9" * 100_000
    why = refused({"x": big})
    assert f"has {len(big)} characters, at most {MAX_VALUE_CHARS}" in why and len(why) < BOUND
    why = refused({"name": "n" * (MAX_VALUE_CHARS + 1)})
    assert "at most" in why and len(why) < BOUND
    assert parse(P, {"name": "n" * MAX_VALUE_CHARS}).name == "n" * MAX_VALUE_CHARS
    why = refused({"k" * 100_000: "1"})  # an unknown key is quoted short too
    assert "unknown parameter" in why and len(why) < BOUND + 200


def test_a_repeated_param_is_refused_with_both_values():
    with pytest.raises(ParamError, match=r"--param 'size' is given twice \('5' and '7'\): give it once"):
        assignments(["size=5", "size=7"])
    with pytest.raises(ParamError, match="given twice"):
        parse(P, ["n=1", " n = 2"])
    assert assignments(["a=1", "b=1"]) == {"a": "1", "b": "1"}


@pytest.mark.parametrize(
    "args",
    [
        ["world", "gridworld", "--param", "size=5", "--param", "size=7"],
        ["perturb", "lesion", "--world", "r1", "--param", "radius=1", "--param", "radius=2"],
    ],
)
def test_the_cli_refuses_a_repeated_param(args):
    # refused before any bus is opened (nothing listens on port 1)
    p = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args, "--connect", "tcp/127.0.0.1:1"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2 and "is given twice" in p.stderr and "Traceback" not in p.stderr, p.stderr


def test_perturbations_refuse_lenient_values_with_a_bounded_message():
    kinds = world_perturbations("retina")
    for params, why in [
        ({"radius": "1_0"}, "radius='1_0' is not a float"),
        ({"sd": "1e-400"}, "underflows to 0"),
        ({"radius": "0." + "9" * 100_000}, "characters, at most"),
    ]:
        kind = "noise" if "sd" in params else "lesion"
        with pytest.raises(PerturbationError, match=re.escape(why)) as e:
            check_perturbation("retina", kinds, Control("r1", kind, params, 1))
        assert len(str(e.value)) < BOUND + 300
    from sensorimotor.tools.commands.perturb import refuse_locally  # what `sme perturb` prints before sending
    from sensorimotor.worlds.registry import make_world

    spec = make_world("retina", "r1", seed=0).spec()
    why = refuse_locally(spec, Control("r1", "lesion", {"radius": "0." + "9" * 100_000}, 1))
    assert why is not None and len(why) < BOUND + 300


class _Bus:
    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes]] = []

    def put(self, key: str, payload: bytes, schema: str | None = None) -> None:  # noqa: ARG002
        self.puts.append((key, payload))


def _node(wid: str = "r1", kind: str = "gridworld"):
    from sensorimotor.worlds.node import WorldNode
    from sensorimotor.worlds.registry import make_world

    bus = _Bus()
    return WorldNode(make_world(kind, wid, seed=0), bus), bus  # type: ignore[arg-type]


def test_a_control_for_another_world_is_refused_and_counted():
    node, bus = _node("r1")
    for ctl in (Control("v1", "heal", {}, 11), Control("r1" * 60_000, "heal", {}, 12)):
        node._on_control(BusMessage(keys.world_ctl("r1"), codec.encode(ctl), ""))
    assert node._controls == [] and node.stats.rejected == {"spec_mismatch": 2}
    events = [codec.decode(WorldEvent, p) for k, p in bus.puts if k == keys.world_event("r1")]
    assert [(e.kind, e.control_id) for e in events] == [("control_refused", 11), ("control_refused", 12)]
    assert "control for world 'v1' arrived on 'r1''s key" in events[0].detail
    assert all(len(p) < 2000 for _, p in bus.puts)  # the 120 KB world id is not echoed
    node._on_control(BusMessage(keys.world_ctl("r1"), codec.encode(Control("r1", "heal", {}, 13)), ""))
    assert [c.id for c in node._controls] == [13]  # its own: queued for the next step


# property tests ------------------------------------------------------------------------------------

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])


@SETTINGS
@given(st.floats(allow_nan=False, allow_infinity=False))
def test_every_finite_float_round_trips_exactly(v):
    assert parse(P, {"x": format_value(v)}).x == v


@SETTINGS
@given(st.integers(min_value=-(10 ** (MAX_NUMBER_CHARS - 1)) + 1, max_value=10**MAX_NUMBER_CHARS - 1))
def test_ints_up_to_the_length_limit_parse_and_longer_ones_are_refused(n):
    assert parse(P, {"n": str(n)}).n == n
    longer = str(n) + "0" * (MAX_NUMBER_CHARS + 1 - len(str(n)))
    assert "a number at most" in refused({"n": longer})


@SETTINGS
@given(
    st.integers(min_value=1, max_value=9),
    st.integers(min_value=-400, max_value=400),
)
def test_floats_at_the_ends_of_the_exponent_range(digit, exp):
    text = f"{digit}e{exp}"
    v = float(text)
    if v == 0.0:
        assert "underflows to 0" in refused({"x": text})
    elif math.isinf(v):
        assert "is not finite" in refused({"x": text})
    else:
        assert parse(P, {"x": text}).x == v


@SETTINGS
@given(st.text(max_size=80))
def test_any_text_is_a_strict_number_or_a_bounded_refusal(text):
    for key in ("n", "x"):
        try:
            value = getattr(parse(P, {key: text}), key)
        except ParamError as e:
            assert len(str(e)) < BOUND
            continue
        s = text.strip()
        assert re.fullmatch(r"[+-]?[0-9.eE]+", s) and "_" not in s
        assert value == (int(s) if key == "n" else float(s)) and math.isfinite(value)


@SETTINGS
@given(st.text(max_size=12))
def test_booleans_are_exactly_the_documented_words(text):
    words = {"true": True, "yes": True, "on": True, "1": True, "false": False, "no": False, "off": False, "0": False}
    try:
        value = parse(P, {"on": text}).on
    except ParamError:
        assert text.strip() not in words
    else:
        assert value is words[text.strip()]


@SETTINGS
@given(st.sampled_from(("n", "x", "on", "name", "xs", "opt")), st.integers(min_value=0, max_value=3 * MAX_VALUE_CHARS))
def test_values_beyond_the_length_limit_are_refused_for_every_type(key, length):
    text = "1" * length
    try:
        parse(P, {key: text})
    except ParamError as e:
        assert len(str(e)) < BOUND
        assert length > MAX_NUMBER_CHARS or key in ("on", "name") or length == 0
    else:
        assert length <= MAX_VALUE_CHARS


world_ids = st.one_of(
    st.just("r1"),
    st.text(alphabet="abcdefghijklmnopqrstuvwxyz0123456789-_.", min_size=1, max_size=70),
    st.text(max_size=300),
)
values = st.one_of(
    st.text(max_size=50),
    st.floats().map(repr),
    st.integers(min_value=-(10**80), max_value=10**80).map(str),
    st.integers(min_value=MAX_VALUE_CHARS - 2, max_value=MAX_VALUE_CHARS + 2).map(lambda n: "9" * n),
)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(world_ids, st.sampled_from(("lesion", "noise", "reverse", "heal", "melt")), st.dictionaries(
    st.sampled_from(("u", "v", "radius", "sd", "x")), values, max_size=3
))  # fmt: skip
def test_controls_at_and_beyond_the_limits_are_applied_or_refused_never_more(wid, kind, params):
    """A Control through the wire and the node: applied only when it names this world and its values
    parse strictly; otherwise refused with a bounded event, counted, and the world keeps going."""
    assume(all(isinstance(v, str) for v in params.values()))
    node, bus = _node("r1", "retina")
    ctl = Control(wid, kind, params, 5)
    node._on_control(BusMessage(keys.world_ctl("r1"), codec.encode(ctl), ""))
    node._apply_controls(7)
    events = [codec.decode(WorldEvent, p) for k, p in bus.puts if k == keys.world_event("r1")]
    assert len(events) == 1 and events[0].control_id == 5
    assert all(len(p) < 4000 for k, p in bus.puts if k == keys.world_event("r1"))  # bounded echo
    if events[0].kind == "control_applied":
        assert wid == "r1" and events[0].step == 7  # the first observation of the changed body
        check_perturbation("retina", world_perturbations("retina"), ctl)  # it did parse strictly
    else:
        assert events[0].kind == "control_refused"
        assert sum(node.stats.rejected.values()) == 1


def test_a_repeated_program_param_is_refused():
    from sensorimotor.tools.commands.agent import parse_program_params

    assert parse_program_params(["gridworld.gamma=0.9"])["gridworld"]["gamma"] == 0.9
    with pytest.raises(ParamError, match="'gridworld.gamma' is given twice"):
        parse_program_params(["gridworld.gamma=0.9", "gridworld.gamma=0.8"])


def test_generic_perturbations_read_their_index_lists_strictly():
    from sensorimotor.worlds.body_changes.motor import _order

    order = ",".join(str(i) for i in range(1, 11)) + ",0"
    assert _order(order, 11) == [*range(1, 11), 0]
    with pytest.raises(PerturbationError, match="permute: order="):
        _order("1_0," + ",".join(str(i) for i in range(10)), 11)  # main read 1_0 as 10
    with pytest.raises(PerturbationError, match="permute: order="):
        _order("\u0661:0", 2)  # an Arabic-Indic 1
    with pytest.raises(PerturbationError) as e:
        _order("9" * 1000, 11)
    assert len(str(e.value)) < BOUND


def test_a_100_kb_perturbation_kind_is_not_echoed():
    from sensorimotor.tools.commands.perturb import refuse_locally
    from sensorimotor.worlds.registry import make_world

    spec = make_world("retina", "r1", seed=0).spec()
    why = refuse_locally(spec, Control("r1", "k" * 100_000, {}, 1))
    assert why is not None and "has no perturbation 'kkk" in why and len(why) < BOUND + 300
