"""Property-based fuzzing of every decoder and validator of the wire contract and the checkpoints.

Properties: any bytes, and structurally valid but hostile protobufs (huge shapes, wrong dtypes,
NaN/inf, wrong versions, duplicate tensor names, wrong sizes), decode to a message or raise a
`ProtocolError` subclass (`CheckpointError` for checkpoint files, `ValueError` for ids) - never
another exception; valid messages round-trip exactly (encode -> decode equal, arrays bitwise).
Seeded (derandomize) so a CI run is reproducible; ~200 examples per test.
"""

from __future__ import annotations

import io
import json
import math
import re
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from sensorimotor.agent.checkpoint import (
    Checkpoint,
    CheckpointError,
    decode_checkpoint,
    encode_checkpoint,
    read_checkpoint,
)
from sensorimotor.agent.link import check_against_spec, check_truth
from sensorimotor.protocol import codec, images, keys
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.errors import ProtocolError
from sensorimotor.protocol.messages import (
    Action,
    ActionSpace,
    AgentEvent,
    AgentStatus,
    AttachConfig,
    Control,
    Embedding,
    EmbeddingScores,
    Lease,
    LeaseRequest,
    LinkStatus,
    Observation,
    SensorSpec,
    Truth,
    WorldEvent,
    WorldSpec,
)
from sensorimotor.protocol.params import ParamError, parse

FUZZ = settings(
    max_examples=200, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow], database=None
)

MESSAGES = [
    WorldSpec,
    Observation,
    Action,
    Control,
    Truth,
    Embedding,
    AgentEvent,
    WorldEvent,
    AgentStatus,
    LeaseRequest,
    Lease,
]
PB = {cls: getattr(pb, cls.__name__) for cls in MESSAGES}
DTYPE_NAMES = sorted(codec.DTYPES)


def decode_or_refuse(cls: type, data: bytes) -> Any:
    """The decoded message, or None when it was refused with a ProtocolError (any other exception fails)."""
    try:
        msg = codec.decode(cls, data)
    except ProtocolError as e:
        assert e.kind and str(e)
        return None
    assert isinstance(msg, cls)
    return msg


# strategies: values --------------------------------------------------------------------------

ids = st.from_regex(r"[A-Za-z0-9_.-]{1,64}", fullmatch=True)
text = st.text(max_size=20)
u32 = st.integers(0, 2**32 - 1)
u64 = st.integers(0, 2**64 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
i64 = st.integers(-(2**63), 2**63 - 1)
finite = st.floats(allow_nan=False, allow_infinity=False)
hostile_float = st.floats() | st.sampled_from([math.nan, math.inf, -math.inf, 1e308, -0.0, 5e-324])


@st.composite
def arrays(draw: st.DrawFn, dtypes: list[str] | None = None, max_dims: int = 3) -> np.ndarray:
    """A small C-order array of an allowed dtype; float arrays are finite."""
    dt = np.dtype(draw(st.sampled_from(dtypes or DTYPE_NAMES)))
    shape = tuple(draw(st.lists(st.integers(0, 4), max_size=max_dims)))
    n = math.prod(shape)
    if dt.kind == "f":
        vals = draw(
            st.lists(st.floats(allow_nan=False, allow_infinity=False, width=dt.itemsize * 8), min_size=n, max_size=n)
        )
        return np.array(vals, dtype=dt).reshape(shape)
    if dt.kind == "b":
        return np.array(draw(st.lists(st.booleans(), min_size=n, max_size=n)), dtype=dt).reshape(shape)
    info = np.iinfo(dt)
    vals = draw(st.lists(st.integers(int(info.min), int(info.max)), min_size=n, max_size=n))
    return np.array(vals, dtype=dt).reshape(shape)


tensors = st.dictionaries(text, arrays(), max_size=4)
str_map = st.dictionaries(text, text, max_size=4)


# strategies: valid messages --------------------------------------------------------------------

sensor_specs = st.builds(
    SensorSpec,
    text,
    st.sampled_from(DTYPE_NAMES),
    st.lists(st.integers(0, 64), max_size=3).map(tuple),
    st.floats(allow_nan=False),
    st.floats(allow_nan=False),
    text,
)


@st.composite
def action_spaces(draw: st.DrawFn) -> ActionSpace:
    names = tuple(draw(st.lists(text, max_size=3)))
    if draw(st.booleans()):
        return ActionSpace(draw(st.integers(1, 2**32 - 1)), names=names)
    pairs = draw(st.lists(st.tuples(finite, finite).map(sorted), min_size=1, max_size=4))
    return ActionSpace(0, tuple(p[0] for p in pairs), tuple(p[1] for p in pairs), names)


world_specs = st.builds(
    WorldSpec,
    text,
    text,
    st.lists(sensor_specs, max_size=4, unique_by=lambda s: s.name).map(tuple),
    action_spaces(),
    st.floats(allow_nan=False),
    st.floats(allow_nan=False),
    text,
    u32,
    str_map,
    text,
)
observations = st.builds(Observation, text, u64, u64, u32, tensors, finite, st.booleans(), i32, finite, text)
owners = st.just("") | ids  # an action's owner: empty (an agent before leases) or an id
actions = st.builds(Action, text, u64, st.lists(finite, max_size=8).map(tuple), st.booleans(), i32, finite, owners, u64)
controls = st.builds(Control, text, text, str_map, u64, finite)
truths = st.builds(Truth, text, text, tensors, u64, finite)
embeddings = st.builds(
    Embedding,
    text,
    text,
    u32,
    text,
    st.lists(i32, max_size=5).map(tuple),
    arrays(["float64"], max_dims=2),
    st.lists(finite, max_size=4).map(tuple),
    st.none() | finite,
    u64,
    finite,
    st.dictionaries(text, finite, max_size=3),
    u32,
    st.none() | u64,
    scores=st.none() | st.builds(EmbeddingScores, finite, finite, finite, finite, u32, u32),
)
attach_configs = st.builds(AttachConfig, i64, text, text, str_map)
agent_events = st.builds(
    AgentEvent,
    text,
    text,
    text,
    text,
    u64,
    finite,
    st.dictionaries(text, finite, max_size=3),
    text,
    st.none() | attach_configs,
)
world_events = st.builds(WorldEvent, text, text, text, text, u64, text, finite, text, u64, text, u64)
lease_requests = st.builds(LeaseRequest, ids, ids, u64, st.booleans(), text)
leases = st.builds(
    Lease, ids, text, owners, u64, st.booleans(), text, st.floats(min_value=0.0) | st.just(math.inf), finite
)
link_statuses = st.builds(
    LinkStatus,
    text,
    text,
    text,
    text,
    u64,
    u64,
    u32,
    finite,
    st.dictionaries(text, u64, max_size=3),
    finite,
    finite,
    u64,
)
agent_statuses = st.builds(
    AgentStatus,
    text,
    finite,
    st.lists(link_statuses, max_size=3).map(tuple),
    st.dictionaries(text, u64, max_size=4),
    finite,
)
VALID = {
    WorldSpec: world_specs,
    Observation: observations,
    Action: actions,
    Control: controls,
    Truth: truths,
    Embedding: embeddings,
    AgentEvent: agent_events,
    WorldEvent: world_events,
    AgentStatus: agent_statuses,
    LeaseRequest: lease_requests,
    Lease: leases,
}


def same(a: Any, b: Any) -> bool:
    """Equality of decoded messages, arrays compared bitwise (dtype, shape and bytes)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (
            isinstance(a, np.ndarray)
            and isinstance(b, np.ndarray)
            and a.dtype == b.dtype
            and a.shape == b.shape
            and a.tobytes() == b.tobytes()
        )
    if isinstance(a, dict):
        return isinstance(b, dict) and a.keys() == b.keys() and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return type(a) is type(b) and len(a) == len(b) and all(same(x, y) for x, y in zip(a, b, strict=True))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(same(getattr(a, f), getattr(b, f)) for f in a.__dataclass_fields__)
    if isinstance(a, float) and isinstance(b, float):
        return a == b and math.copysign(1, a) == math.copysign(1, b) or (math.isnan(a) and math.isnan(b))
    return a == b and type(a) is type(b)


# round trips --------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", MESSAGES, ids=lambda c: c.__name__)
@FUZZ
@given(data=st.data())
def test_valid_messages_round_trip_exactly(cls, data):
    msg = data.draw(VALID[cls])
    back = codec.decode(cls, codec.encode(msg))
    assert same(back, msg), (msg, back)
    assert same(codec.decode(cls, codec.encode(back)), msg)  # bytes may differ: protobuf map order is free


# any bytes ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("cls", MESSAGES, ids=lambda c: c.__name__)
@FUZZ
@given(data=st.binary(max_size=512))
def test_any_bytes_decode_or_raise_a_protocol_error(cls, data):
    decode_or_refuse(cls, data)


@pytest.mark.parametrize("cls", MESSAGES, ids=lambda c: c.__name__)
@FUZZ
@given(data=st.data())
def test_mutated_valid_messages_decode_or_raise_a_protocol_error(cls, data):
    """Bit flips, truncations and splices of real encodings (closer to valid than random bytes)."""
    raw = bytearray(codec.encode(data.draw(VALID[cls])))
    for _ in range(data.draw(st.integers(1, 4))):
        op = data.draw(st.sampled_from(["flip", "cut", "insert", "dup"]))
        pos = data.draw(st.integers(0, len(raw)))
        if op == "flip" and pos < len(raw):
            raw[pos] ^= 1 << data.draw(st.integers(0, 7))
        elif op == "cut":
            del raw[pos:]
        elif op == "insert":
            raw[pos:pos] = data.draw(st.binary(min_size=1, max_size=8))
        else:
            raw += raw[pos:]
    decode_or_refuse(cls, bytes(raw))


# hostile but well-formed protobufs ------------------------------------------------------------------


@st.composite
def hostile_tensor(draw: st.DrawFn, out: Any) -> None:
    """Fill a pb.Tensor with any dtype string, huge or many dimensions, and data of any size."""
    out.name = draw(st.sampled_from(["state", "x", ""]) | text)
    out.dtype = draw(st.sampled_from(DTYPE_NAMES + ["float16", "complex128", "object", "", "<f8", "U4"]))
    dims = st.integers(0, 2**32 - 1) | st.integers(0, 8)
    out.shape.extend(draw(st.lists(dims, max_size=12)))
    size = draw(st.sampled_from([None, 0, 1, 7, 8, 64]))
    if size is None:  # the exact size the header claims (when small): reaches the value checks
        dt = codec.DTYPES.get(out.dtype)
        claimed = math.prod(out.shape) * (dt.itemsize if dt is not None else 1)
        size = claimed if claimed <= 256 else 8
    if draw(st.booleans()) and out.dtype in ("float32", "float64"):
        with np.errstate(over="ignore"):  # 1e308 as float32 is inf: hostile on purpose
            a = np.full(size // np.dtype(out.dtype).itemsize, draw(hostile_float), dtype=out.dtype)
        out.data = a.tobytes() + b"\0" * (size - a.nbytes)
    else:
        out.data = draw(st.binary(min_size=size, max_size=size))


@st.composite
def hostile_messages(draw: st.DrawFn, cls: type) -> bytes:
    p = PB[cls]()
    p.schema_version = draw(st.sampled_from([1, 1, 1, 0, 2, 99, 2**32 - 1]))
    fields = p.DESCRIPTOR.fields_by_name
    if "world_id" in fields:
        p.world_id = draw(st.sampled_from(["g", "g\n", "", "a/b", "*"]) | text)
    for name in ("reward", "timestamp", "procrustes_error", "uptime", "reward_min", "reward_max"):
        if name in fields and draw(st.booleans()):
            setattr(p, name, draw(hostile_float))
    hostile_id = st.sampled_from(["a", "", "a/b", "*", "a b", "x" * 65, "é"]) | text
    if cls in (Action, LeaseRequest):
        p.owner = draw(hostile_id)
    if cls is LeaseRequest:
        p.request_id = draw(st.sampled_from(["", "r1", "x" * 65]) | text)
        p.epoch, p.release = draw(u64), draw(st.booleans())
    if cls is Lease:
        p.holder, p.ttl, p.epoch = draw(hostile_id), draw(hostile_float), draw(u64)
    if cls is Action:
        p.values.extend(draw(st.lists(hostile_float, max_size=3) | st.lists(finite, min_size=65, max_size=70)))
    if cls is AgentEvent:
        for k, v in draw(st.dictionaries(text, hostile_float, max_size=3)).items():
            p.values[k] = v
    if "tensors" in fields:
        dup = draw(st.booleans())
        for i in range(draw(st.integers(0, 3))):
            t = p.tensors.add()
            draw(hostile_tensor(t))
            if dup and i:
                t.name = p.tensors[0].name  # duplicate tensor names
        if p.tensors and draw(st.integers(0, 9)) == 0:  # more tensors than allowed
            for i in range(codec.MAX_TENSORS):
                p.tensors.add().CopyFrom(p.tensors[0])
                p.tensors[-1].name = f"t{i}"
    if cls is Embedding:
        draw(hostile_tensor(p.coordinates))
        p.eigenvalues.extend(draw(st.lists(hostile_float, max_size=4)))
        p.has_procrustes = draw(st.booleans())
        if draw(st.booleans()):
            p.scores.trustworthiness = draw(hostile_float)
            p.scores.topological_dissimilarity = draw(hostile_float)
    if cls is WorldSpec:
        for _ in range(draw(st.integers(0, 2))):
            s = p.sensors.add(
                name=draw(st.sampled_from(["state", "x"])), dtype=draw(st.sampled_from(DTYPE_NAMES + ["f16"]))
            )
            s.shape.extend(draw(st.lists(st.integers(0, 2**32 - 1) | st.integers(0, 9), max_size=10)))
            s.low, s.high = draw(hostile_float), draw(hostile_float)
        if p.sensors and draw(st.integers(0, 9)) == 0:  # more sensors than an observation may carry
            for i in range(codec.MAX_TENSORS):
                p.sensors.add().CopyFrom(p.sensors[0])
                p.sensors[-1].name = f"s{i}"
        p.action_space.discrete_n = draw(st.sampled_from([0, 0, 4, 2**32 - 1]))
        p.action_space.low.extend(draw(st.lists(hostile_float, max_size=3)))
        p.action_space.high.extend(draw(st.lists(hostile_float, max_size=3)))
        p.n_starts = draw(u32)
    if cls is AgentStatus:
        for _ in range(draw(st.integers(0, 2))):
            ln = p.links.add(world_id=draw(text), reward_mean=draw(hostile_float), steps=draw(u64))
            ln.rejected[draw(text)] = draw(u64)
        p.counters[draw(text)] = draw(u64)
    if cls is AgentEvent and draw(st.booleans()):
        p.config.seed = draw(i64)
        p.config.program_params[draw(text)] = draw(text)
    return p.SerializeToString()


@pytest.mark.parametrize("cls", MESSAGES, ids=lambda c: c.__name__)
@FUZZ
@given(data=st.data())
def test_hostile_well_formed_messages_decode_or_raise_a_protocol_error(cls, data):
    msg = decode_or_refuse(cls, data.draw(hostile_messages(cls)))
    if msg is None:
        return
    # what was accepted keeps every promise of the contract
    for name, a in getattr(msg, "tensors", {}).items():
        assert a.ndim <= codec.MAX_DIMS and a.nbytes <= codec.MAX_TENSOR_BYTES, name
        assert a.dtype.kind != "f" or np.isfinite(a).all(), name
    if isinstance(msg, Observation):
        assert math.isfinite(msg.reward)
    if isinstance(msg, Action):
        assert all(math.isfinite(v) for v in msg.values) and len(msg.values) <= codec.MAX_TENSORS
        assert msg.owner == "" or keys.is_id(msg.owner)
    if isinstance(msg, LeaseRequest):
        assert keys.is_id(msg.owner) and keys.is_id(msg.world_id) and len(msg.request_id) <= 64
    if isinstance(msg, Lease):
        assert (msg.holder == "" or keys.is_id(msg.holder)) and keys.is_id(msg.world_id)
        assert msg.ttl >= 0 and not math.isnan(msg.ttl)
    if isinstance(msg, WorldSpec):
        assert len({s.name for s in msg.sensors}) == len(msg.sensors)
        assert all(math.isfinite(x) for x in msg.action_space.low + msg.action_space.high)
        assert all(lo <= hi for lo, hi in zip(msg.action_space.low, msg.action_space.high, strict=False))
        assert not any(math.isnan(x) for s in msg.sensors for x in (s.low, s.high))


def test_huge_claims_are_refused_without_allocating():
    p = pb.Observation(schema_version=1, world_id="g")
    p.tensors.add(name="x", dtype="float64", shape=[2**32 - 1] * 8, data=b"")
    with pytest.raises(ProtocolError) as e:
        codec.decode(Observation, p.SerializeToString())
    assert e.value.kind == "oversize"
    p = pb.WorldSpec(schema_version=1, world_id="g")
    p.action_space.discrete_n = 4
    p.sensors.add(name="x", dtype="uint8", shape=[2**32 - 1, 2**32 - 1])
    with pytest.raises(ProtocolError) as e:
        codec.decode(WorldSpec, p.SerializeToString())
    assert e.value.kind == "oversize"


@pytest.mark.parametrize(
    "mutate, kind",
    [
        (lambda p: p.sensors.add(name="state", dtype="int32"), "malformed"),  # duplicate sensor
        (lambda p: setattr(p, "reward_max", math.nan), "non_finite"),
        (lambda p: setattr(p.sensors[0], "high", math.nan), "non_finite"),
        (lambda p: (p.action_space.low.append(math.inf), p.action_space.high.append(math.inf)), "non_finite"),
        (lambda p: (p.action_space.low.append(1.0), p.action_space.high.append(0.0)), "malformed"),
        (lambda p: p.sensors[0].shape.extend([1] * 9), "shape_mismatch"),
    ],
)
def test_spec_refusals(mutate, kind):
    p = pb.WorldSpec(schema_version=1, world_id="g", reward_max=math.inf)  # an infinite reward bound is fine
    p.action_space.discrete_n = 4
    p.sensors.add(name="state", dtype="int32", shape=[1], low=-math.inf, high=80)
    assert codec.decode(WorldSpec, p.SerializeToString()).reward_max == math.inf
    mutate(p)
    with pytest.raises(ProtocolError) as e:
        codec.decode(WorldSpec, p.SerializeToString())
    assert e.value.kind == kind


# validators -----------------------------------------------------------------------------------------


@FUZZ
@given(obs=observations, spec=world_specs)
def test_check_against_spec_accepts_or_raises_spec_mismatch(obs, spec):
    try:
        check_against_spec(obs, spec)
    except ProtocolError as e:
        assert e.kind == "spec_mismatch"
        return
    for s in spec.sensors:
        assert obs.tensors[s.name].dtype.name == s.dtype and obs.tensors[s.name].shape == s.shape


@FUZZ
@given(spec=world_specs, data=st.data())
def test_an_observation_built_from_its_spec_passes(spec, data):
    tensors = {s.name: np.zeros(s.shape, dtype=s.dtype) for s in spec.sensors if math.prod(s.shape) < 10**5}
    assume(len(tensors) == len(spec.sensors))
    extra = data.draw(
        st.dictionaries(text.filter(lambda n: all(n != s.name for s in spec.sensors)), arrays(), max_size=2)
    )
    check_against_spec(Observation(spec.world_id, 0, 0, 0, {**tensors, **extra}), spec)


@FUZZ
@given(truth=truths, world=text)
def test_check_truth_accepts_or_raises_spec_mismatch(truth, world):
    try:
        check_truth(truth, world)
    except ProtocolError as e:
        assert e.kind == "spec_mismatch"
        return
    pos = truth.tensors["positions"]
    assert truth.world_id == world and pos.ndim == 2 and pos.dtype.kind == "f"


@FUZZ
@given(st.text(max_size=80) | ids | ids.map(lambda s: s + "\n") | st.from_type(object))
def test_check_id_accepts_exactly_the_id_alphabet(value):
    ok = isinstance(value, str) and re.fullmatch(r"[A-Za-z0-9_.-]{1,64}", value) is not None
    try:
        assert keys.check_id(value) is value and ok
    except ValueError:
        assert not ok


# images -------------------------------------------------------------------------------------------------


@FUZZ
@given(data=st.binary(max_size=256))
def test_any_bytes_decode_as_an_image_or_raise_a_protocol_error(data):
    try:
        a = images.decode_image(data)
    except ProtocolError:
        return
    assert a.dtype == np.uint8 and a.ndim in (2, 3)


@FUZZ
@given(
    frame=st.tuples(st.integers(0, 6), st.integers(0, 6), st.booleans()).flatmap(
        lambda t: st.binary(min_size=t[0] * t[1] * (3 if t[2] else 1), max_size=t[0] * t[1] * (3 if t[2] else 1)).map(
            lambda b: np.frombuffer(b, np.uint8).reshape((t[0], t[1], 3) if t[2] else (t[0], t[1]))
        )
    ),
    ts=st.floats(0, 4e9),
)
def test_images_round_trip_bitwise(frame, ts):
    back = images.decode_image(images.encode_image(frame, "cam", ts))
    assert back.dtype == frame.dtype and back.shape == frame.shape and back.tobytes() == frame.tobytes()


# checkpoints -----------------------------------------------------------------------------------------

json_values = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | text,
    lambda kids: st.lists(kids, max_size=3) | st.dictionaries(text | st.just("__array__"), kids, max_size=3),
    max_leaves=12,
)
checkpoints = st.builds(
    Checkpoint,
    ids,
    text,
    text,
    st.lists(sensor_specs, max_size=2).map(tuple),
    action_spaces(),
    u32,
    text,
    st.dictionaries(st.from_regex(r"[a-z]{1,6}", fullmatch=True), st.integers() | finite | text, max_size=3),
    st.dictionaries(st.from_regex(r"[a-z]{1,6}", fullmatch=True), arrays() | st.integers() | text, max_size=3),
    st.none() | st.dictionaries(st.from_regex(r"[a-z]{1,6}", fullmatch=True), finite | arrays(["float64"]), max_size=2),
)


def _npz(entries: dict[str, np.ndarray]) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **entries)
    return buf.getvalue()


def read_or_refuse(data: bytes) -> Checkpoint | None:
    try:
        ck = decode_checkpoint(data)
    except CheckpointError as e:
        assert str(e)
        return None
    assert isinstance(ck, Checkpoint)
    return ck


@FUZZ
@given(ckpt=checkpoints)
def test_checkpoints_round_trip_exactly(ckpt):
    back = decode_checkpoint(encode_checkpoint(ckpt))
    assert same(back.program_state, ckpt.program_state) and same(back.detector_state, ckpt.detector_state)
    assert back.program_params == ckpt.program_params and back.action_space == ckpt.action_space
    assert (back.world_id, back.kind, back.program, back.version, back.program_class) == (
        ckpt.world_id,
        ckpt.kind,
        ckpt.program,
        ckpt.version,
        ckpt.program_class,
    )
    assert back.sensors == ckpt.sensors


@FUZZ
@given(data=st.binary(max_size=512) | st.binary(max_size=256).map(lambda b: b"PK\x03\x04" + b))
def test_any_bytes_read_as_a_checkpoint_or_raise_checkpoint_error(data):
    read_or_refuse(data)


@FUZZ
@given(ckpt=checkpoints, data=st.data())
def test_mutated_checkpoint_files_read_or_raise_checkpoint_error(ckpt, data):
    raw = bytearray(encode_checkpoint(ckpt))
    for _ in range(data.draw(st.integers(1, 3))):
        pos = data.draw(st.integers(0, len(raw) - 1))
        if data.draw(st.booleans()):
            raw[pos] ^= 1 << data.draw(st.integers(0, 7))
        else:
            del raw[pos:]
            break
    read_or_refuse(bytes(raw))


@FUZZ
@given(
    ckpt=checkpoints,
    key=st.sampled_from(
        [
            "format",
            "format_version",
            "world_id",
            "kind",
            "sensors",
            "action_space",
            "version",
            "program_class",
            "program_params",
            "program_state",
            "detector_state",
        ]
    ),
    value=json_values,
    data=st.data(),
)
def test_hostile_checkpoint_metadata_reads_or_raises_checkpoint_error(ckpt, key, value, data):
    """Valid npz files whose JSON holds any value for any entry, or hostile nesting and array refs."""
    good = np.load(io.BytesIO(encode_checkpoint(ckpt)), allow_pickle=False)
    entries = {name: good[name] for name in good.files}
    meta = json.loads(entries["checkpoint.json"].tobytes())
    meta[key] = value
    text_ = json.dumps(meta)
    if data.draw(st.booleans()):  # nesting past json's recursion limit
        text_ = text_[:-1] + ',"deep":' + "[" * 5000 + "]" * 5000 + "}"
    entries["checkpoint.json"] = np.frombuffer(text_.encode(), np.uint8)
    if data.draw(st.booleans()):  # a wrong-typed or extra entry
        entries[data.draw(st.sampled_from(["checkpoint.json", "program_state.x"]))] = data.draw(arrays())
    read_or_refuse(_npz(entries))


def test_read_checkpoint_of_a_missing_file_or_a_directory_is_a_checkpoint_error(tmp_path):
    for path in (tmp_path / "none.ckpt.npz", tmp_path):
        with pytest.raises(CheckpointError):
            read_checkpoint(str(path))


# params ---------------------------------------------------------------------------------------------------


def _param_classes() -> list[type]:
    from sensorimotor.agent.programs.registry import PROGRAMS, program_params
    from sensorimotor.worlds.registry import WORLDS, world_params

    return sorted({program_params(n) for n in PROGRAMS} | {world_params(n) for n in WORLDS}, key=lambda c: c.__name__)


@pytest.mark.parametrize("cls", _param_classes(), ids=lambda c: c.__name__)
@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(data=st.data())
def test_every_declared_params_class_parses_any_strings_or_raises_param_error(cls, data):
    import dataclasses

    names = [f.name for f in dataclasses.fields(cls)]
    key = st.sampled_from(names) | text if names else text
    value = text | st.sampled_from(["1", "-1", "0.5", "1e309", "nan", "inf", "1,2", "none", "true", "(1,)", "9" * 400])
    values = data.draw(st.dictionaries(key, value, max_size=4))
    try:
        p = parse(cls, values)
    except ParamError:
        return
    assert isinstance(p, cls)
