"""Checkpoints are checked by value before they are trusted: every mutated file or shared
checkpoint is restored or set aside with a reason (CheckpointError / the `bad_checkpoint` counter),
never anything else; a small file that would inflate to hundreds of MB is refused unread."""

from __future__ import annotations

import io
import time
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sensorimotor.agent.checkpoint import (
    MAX_CLOCK_SKEW,
    MAX_INFLATED_BYTES,
    Checkpoint,
    CheckpointError,
    decode_checkpoint,
    encode_checkpoint,
)
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import BusMessage
from sensorimotor.protocol.messages import ActionSpace, SensorSpec, SharedCheckpoint

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
    assert 0 <= got.version < 2**53 and 0 <= got.steps < 2**53
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
