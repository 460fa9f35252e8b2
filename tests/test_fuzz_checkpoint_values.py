"""Checkpoints are checked by value before they are trusted: every mutated file or shared
checkpoint is restored or set aside with a reason (CheckpointError / the `bad_checkpoint` counter),
never anything else; a small file that would inflate to hundreds of MB is refused unread."""

from __future__ import annotations

import dataclasses
import functools
import io
import os
import tempfile
import time
import zipfile
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sensorimotor.agent.checkpoint import (
    MAX_CLOCK_SKEW,
    MAX_INFLATED_BYTES,
    MAX_VERSION,
    Checkpoint,
    CheckpointError,
    _arrays,
    check_shapes,
    decode_checkpoint,
    encode_checkpoint,
)
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusMessage
from sensorimotor.protocol.messages import ActionSpace, AgentEvent, SensorSpec, SharedCheckpoint, WorldSpec
from sensorimotor.protocol.params import as_strings
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld

FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _good(**over) -> Checkpoint:
    base = dict(
        world_id="g1",
        kind="gridworld",
        program="gridworld",
        sensors=(SensorSpec("state", "int32", (1,), 0, 80),),
        action_space=ActionSpace(n=4),
        version=3,
        program_class="GridworldProgram",
        program_state={"w": np.arange(6, dtype=np.float64), "n": 5},
        detector_state={"name": "ph", "mean": np.zeros(2)},
        saved_at=time.time() - 10,
        steps=1000,
    )
    base.update(over)
    return Checkpoint(**base)


@pytest.mark.parametrize(
    "over, why",
    [
        (dict(version=-1), "version"),
        (dict(version=2**60), "version"),
        (dict(version=2**32 + 5), "version"),  # beyond the wire's uint32 embedding version
        (dict(epoch=2**64), "epoch"),  # beyond the wire's uint64 lease epoch
        (dict(steps=-5), "steps"),
        (dict(saved_at=time.time() + 10 * MAX_CLOCK_SKEW), "dated"),
        (dict(saved_at=float("nan")), "dated"),
        (dict(saved_at=-1.0), "dated"),
        (dict(world_id="g 1"), "world id"),
        (dict(program_state={"w": np.array([1.0, np.nan])}), "NaN or infinite"),
        (dict(detector_state={"name": "ph", "m": np.array([np.inf])}), "NaN or infinite"),
    ],
)
def test_values_that_cannot_be_right_are_refused_with_the_reason(over, why) -> None:
    with pytest.raises(CheckpointError, match=why):
        decode_checkpoint(encode_checkpoint(_good(**over)))


def test_a_good_checkpoint_is_restored() -> None:
    ck = decode_checkpoint(encode_checkpoint(_good()))
    assert ck.version == 3 and np.array_equal(ck.program_state["w"], np.arange(6.0))


def test_a_file_that_inflates_to_hundreds_of_mb_is_refused_before_inflating() -> None:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as z:
        z.writestr("checkpoint.json.npy", b"\0" * (MAX_INFLATED_BYTES + 1024))
    data = buf.getvalue()
    assert len(data) < 2 * 1024 * 1024  # small on disk / on the bus
    t0 = time.perf_counter()
    with pytest.raises(CheckpointError, match="inflate"):
        decode_checkpoint(data)
    assert time.perf_counter() - t0 < 0.5  # refused from the zip directory, nothing inflated


values = st.one_of(
    st.integers(min_value=-(2**70), max_value=2**70),
    st.floats(allow_nan=True, allow_infinity=True),
)


@FUZZ
@given(version=values, steps=values, saved_at=values, flip=st.lists(st.integers(0, 10**6), max_size=4))
def test_mutated_checkpoints_are_restored_or_refused_with_a_reason(version, steps, saved_at, flip) -> None:
    try:
        ck = _good(version=int(version) if float(version).is_integer() else 0, steps=0, saved_at=float(saved_at))
        ck = _good(
            version=ck.version,
            steps=int(steps) if isinstance(steps, int) else 0,
            saved_at=ck.saved_at if np.isfinite(ck.saved_at) else float("nan"),
        )
        raw = bytearray(encode_checkpoint(ck))
    except (ValueError, OverflowError):
        return  # not encodable (e.g. a float that is no number at all for JSON ints)
    for i in flip:
        raw[i % len(raw)] ^= 0xFF
    try:
        got = decode_checkpoint(bytes(raw))
    except CheckpointError as e:
        assert str(e)
        return
    assert 0 <= got.version <= MAX_VERSION and 0 <= got.steps < 2**53 and 0 <= got.epoch < 2**64
    assert np.isfinite(got.saved_at) and got.saved_at <= time.time() + MAX_CLOCK_SKEW


class _NoBus:
    closed = False


@FUZZ
@given(data=st.binary(max_size=400), flip=st.lists(st.integers(0, 10**6), max_size=3), wrap=st.booleans())
def test_shared_checkpoints_are_kept_or_counted_never_raise(data, flip, wrap) -> None:
    d = AgentDaemon(_NoBus(), "a0")  # type: ignore[arg-type]
    good = bytearray(encode_checkpoint(_good()))
    for i in flip:
        good[i % len(good)] ^= 0x5A
    payload = codec.encode(SharedCheckpoint("g1", bytes(good), owner="b")) if wrap else data
    d._on_checkpoint(BusMessage(keys.agent_checkpoint("b", "g1"), payload, ""))
    copy = d.store.newest("g1")
    kept = copy is not None
    assert kept != bool(d.counters["bad_checkpoint"])
    if copy is not None:
        assert copy.checkpoint.world_id == "g1"


def test_a_shared_checkpoint_for_another_world_is_refused() -> None:
    d = AgentDaemon(_NoBus(), "a0")  # type: ignore[arg-type]
    payload = codec.encode(SharedCheckpoint("g2", encode_checkpoint(_good(world_id="g2")), owner="b"))
    d._on_checkpoint(BusMessage(keys.agent_checkpoint("b", "g1"), payload, ""))
    assert d.store.newest("g1") is None and d.counters["bad_checkpoint"] == 1


# checked by shape: arrays that do not fit the world's program are set aside, never loaded -------------


class _EventBus:
    """Stands in for the bus: keeps the events the daemon puts (a set-aside checkpoint is one)."""

    closed = False

    def __init__(self) -> None:
        self.events: list[AgentEvent] = []

    def put(self, key: str, payload: bytes, schema: str | None = None) -> None:  # noqa: ARG002
        self.events.append(codec.decode(AgentEvent, payload))


@functools.cache
def _learned_grid() -> tuple[WorldSpec, Checkpoint]:
    """A gridworld program's real checkpoint after some learning (its spec, and the checkpoint)."""
    world = GridWorld(seed=0)
    program = make_program(world.spec(), 0)
    run_inprocess(world, program, 1000)
    spec = world.spec()
    ck = Checkpoint(
        world_id=spec.world_id,
        kind=spec.kind,
        program=spec.program,
        sensors=tuple(spec.sensors),
        action_space=spec.action_space,
        version=2,
        program_class=type(program).__name__,
        program_params=as_strings(program.params),
        program_state=program.state(),
        saved_at=time.time() - 5,
        steps=1000,
    )
    return spec, ck


def _replaced(tree: Any, path: list[str], value: Any) -> Any:
    """`tree` (dicts and lists) with the item at `path` replaced by `value` (copies along the path)."""
    if not path:
        return value
    head, rest = path[0], path[1:]
    if isinstance(tree, dict):
        return {**tree, head: _replaced(tree[head], rest, value)}
    out = list(tree)
    out[int(head)] = _replaced(out[int(head)], rest, value)
    return out


def _fixed_arrays() -> list[tuple[str, tuple[int, ...], str]]:
    """(path, shape, dtype kind) of every array whose shape the program fixes (non-empty when fresh)."""
    spec, ck = _learned_grid()
    fresh = make_program(spec, 0, **ck.program_params).state()
    return [(p, a.shape, a.dtype.kind) for p, a in _arrays(fresh) if a.size]


shapes = st.one_of(st.lists(st.integers(0, 12), max_size=3).map(tuple), st.integers(0, 400).map(lambda n: (n,)))
dtypes = st.sampled_from(["float64", "float32", "int64", "bool"])


@FUZZ
@given(which=st.integers(0, 100), shape=shapes, dtype=dtypes, same=st.booleans(), shared=st.booleans())
def test_arrays_of_the_wrong_shape_are_set_aside_never_loaded(which, shape, dtype, same, shared) -> None:
    spec, ck = _learned_grid()
    fixed = _fixed_arrays()
    assert fixed, "the gridworld program keeps arrays of a fixed shape (its LSPI weights)"
    path, want, kind = fixed[which % len(fixed)]
    if same:
        shape = want
    a = np.zeros(shape, dtype=dtype)
    fits = a.shape == want and a.dtype.kind == kind
    mutated = dataclasses.replace(ck, program_state=_replaced(ck.program_state, path.split("."), a))
    data = encode_checkpoint(mutated)
    bus = _EventBus()
    with tempfile.TemporaryDirectory() as state_dir:
        d = AgentDaemon(bus, "a0", state_dir=None if shared else state_dir)  # type: ignore[arg-type]
        if shared:  # another owner's copy: checked by value when it arrives, by shape when restored
            payload = codec.encode(SharedCheckpoint(spec.world_id, data, owner="b"))
            d._on_checkpoint(BusMessage(keys.agent_checkpoint("b", spec.world_id), payload, ""))
            assert d.store.newest(spec.world_id) is not None
        else:
            with open(os.path.join(state_dir, f"{spec.world_id}.ckpt.npz"), "wb") as f:
                f.write(data)
        restored = d._load_checkpoint(spec)
        d.status()  # the agent's status never breaks
        aside = [f for f in os.listdir(state_dir) if ".ckpt.npz.bad-" in f]
    if fits:
        assert restored is not None and d.counters["bad_checkpoint"] == 0
        got = restored.program.state()
        assert np.array_equal(np.asarray(_lookup(got, path)), a)
        return
    assert restored is None, f"{path} {a.dtype}{list(a.shape)} was loaded into a program that keeps {want}"
    assert d.counters["bad_checkpoint"] == 1
    assert [e.reason for e in bus.events] == ["bad_checkpoint"]
    assert path in bus.events[0].detail  # the reason names the array
    if shared:
        assert d.store.newest(spec.world_id) is None  # dropped, never offered again
    else:
        assert len(aside) == 1  # set aside as NAME.bad-<time>, never written back


def _lookup(tree: Any, path: str) -> Any:
    for k in path.split("."):
        tree = tree[k] if isinstance(tree, dict) else tree[int(k)]
    return tree


def test_a_learned_state_of_every_shape_check_fits_its_program() -> None:
    """The shape check compares with a fresh program's state: what the program learned (growing
    sample buffers, weights) passes it (every program kind: tests/test_checkpoint.py restores each)."""
    spec, ck = _learned_grid()
    check_shapes(ck.program_state, make_program(spec, 0, **ck.program_params).state())
    with pytest.raises(CheckpointError, match=r"program_state.lspi.w has shape \[3\]"):
        check_shapes(_replaced(ck.program_state, ["lspi", "w"], np.zeros(3)), make_program(spec, 0).state())
