import math

import numpy as np
import pytest

from sensorimotor.protocol import codec, errors
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.messages import (
    Action,
    ActionSpace,
    AgentEvent,
    AgentStatus,
    AttachConfig,
    Control,
    Embedding,
    EmbeddingScores,
    LinkStatus,
    Observation,
    SensorSpec,
    Truth,
    WorldEvent,
    WorldSpec,
)


def obs(**kw):
    base = dict(
        world_id="w",
        episode=3,
        step=17,
        t=2,
        tensors={"img": np.arange(12, dtype=np.float32).reshape(3, 4), "id": np.array([5], np.int32)},
        reward=0.5,
        done=True,
        start=4,
        timestamp=12.5,
        session="abc",
    )
    base.update(kw)
    return Observation(**base)


def test_observation_round_trip_keeps_values_dtypes_and_shapes():
    o = obs()
    back = codec.decode(Observation, codec.encode(o))
    assert (back.world_id, back.episode, back.step, back.t, back.reward, back.done, back.start, back.session) == (
        "w",
        3,
        17,
        2,
        0.5,
        True,
        4,
        "abc",
    )
    for k, a in o.tensors.items():
        assert back.tensors[k].dtype == a.dtype and back.tensors[k].shape == a.shape
        np.testing.assert_array_equal(back.tensors[k], a)
    assert not back.tensors["img"].flags.writeable  # decoded arrays are read-only views


@pytest.mark.parametrize(
    "msg",
    [
        WorldSpec(
            "w",
            "gridworld",
            (SensorSpec("state", "int32", (1,), 0, 80, "d"),),
            ActionSpace(n=4, names=("u",) * 4),
            0.0,
            1.0,
            "gridworld",
            81,
            {"size": "9"},
            "s1",
        ),
        WorldSpec(
            "r", "retina", (SensorSpec("f", "float32", (4096,)),), ActionSpace(low=(-1.0, -1.0), high=(1.0, 1.0))
        ),
        Action("w", 9, (1.0, -2.5), True, 3, 1.0),
        Control("w", "lesion", {"x": "0.1"}, 7, 2.0),
        Truth("w", "start_states", {"positions": np.random.default_rng(0).normal(size=(5, 2))}, 3, 1.0),
        Embedding(
            "a0", "w", 2, "policy_iteration 2", (0, 1, 2), np.eye(3)[:, :2], (3.0, 2.0, 0.1), 0.01, 99, 1.0, {"m": 1.5}
        ),
        Embedding("a0", "w", 1, "t", (0, 1), np.zeros((2, 2)), (1.0,), None),
        AgentEvent("a0", "w", "bad_input", "detail", 5, 1.0, {"count": 2.0}),
        AgentEvent("a0", "w", "bad_input", "detail", 5, 1.0, {"count": 2.0}, "malformed"),
        AgentEvent(
            "a0",
            "w",
            "attached",
            "",
            0,
            1.0,
            {},
            "new",
            AttachConfig(-3, "cusum", "retina", {"embed_every": "500", "rule": "basic"}),
        ),
        Embedding("a0", "w", 4, "relearned", (0, 1), np.zeros((2, 1)), (1.0,), 0.5, 10, 1.0, {}, 7, 0),
        Embedding("a0", "w", 4, "relearned", (0, 1), np.zeros((2, 1)), (1.0,), 0.5, 10, 1.0, {}, 7, 123456789),
        Embedding(
            "a0",
            "w",
            5,
            "policy_iteration",
            (0, 1, 2),
            np.eye(3)[:, :2],
            (1.0,),
            0.1,
            scores=EmbeddingScores(0.875, 0.9375, 0.125, 0.0625, 1, 3),
        ),
        WorldEvent("w", "action_refused", "bad_action", "step 3: out of range", 3, "s1", 2.0),
        AgentStatus(
            "a0",
            3.5,
            (LinkStatus("w", "gridworld", "gridworld", "attached", 10, 2, 1, 0.1, {"oversize": 1}, 0.02),),
            {"unattached": 3},
            4.0,
        ),
    ],
)
def test_round_trip_every_message(msg):
    back = codec.decode(type(msg), codec.encode(msg))
    for f in msg.__dataclass_fields__:
        a, b = getattr(msg, f), getattr(back, f)
        if isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        elif isinstance(a, dict) and a and isinstance(next(iter(a.values())), np.ndarray):
            for k in a:
                np.testing.assert_array_equal(a[k], b[k])
        else:
            assert a == b, f


def test_garbage_bytes_are_malformed():
    with pytest.raises(errors.MalformedMessage, match="not a valid protobuf"):
        codec.decode(Observation, b"\xff\xfe garbage \x00\x01")


def test_unknown_schema_version_is_refused_with_both_versions_named():
    p = pb.Observation(schema_version=7, world_id="w")
    with pytest.raises(errors.UnknownVersion, match="schema version 7.*version 1"):
        codec.decode(Observation, p.SerializeToString())
    with pytest.raises(errors.UnknownVersion, match="0 usually means"):
        codec.decode(Observation, b"")


def _raw_obs(dtype="float32", shape=(2, 2), data=b"\x00" * 16, reward=0.0):
    p = pb.Observation(schema_version=1, world_id="w", step=1, reward=reward)
    p.tensors.add(name="x", dtype=dtype, shape=list(shape), data=data)
    return p.SerializeToString()


def test_dtype_whitelist():
    with pytest.raises(errors.BadDtype, match="complex128"):
        codec.decode(Observation, _raw_obs(dtype="complex128"))
    with pytest.raises(errors.BadDtype):
        codec.encode(obs(tensors={"x": np.zeros(2, dtype=np.complex64)}))


def test_shape_and_bytes_must_agree():
    with pytest.raises(errors.ShapeMismatch, match=r"needs 16 bytes, got 12"):
        codec.decode(Observation, _raw_obs(data=b"\x00" * 12))


def test_oversize_claim_is_refused_before_allocation():
    # shape claims ~4e18 elements: refused from the header alone (no allocation, no overflow)
    with pytest.raises(errors.OversizeMessage, match="claims shape"):
        codec.decode(Observation, _raw_obs(shape=(2**31, 2**31), data=b""))
    with pytest.raises(errors.OversizeMessage, match="bytes, at most"):
        codec.decode(Observation, b"\x00" * (codec.MAX_MESSAGE_BYTES + 1))


def test_a_tensor_over_the_limit_is_refused_from_the_wire_format_before_parsing():
    """33 MiB of tensor data: refused by reading the field lengths (no copy into a message); a
    legal tensor of exactly the limit in a message as large still decodes."""
    import time

    n = codec.MAX_TENSOR_BYTES + (1 << 20)
    p = pb.Observation(schema_version=1, world_id="w", episode=3, step=5, reward=0.5)
    p.tensors.add(name="ok", dtype="uint8", shape=[4], data=bytes(4))
    p.tensors.add(name="big", dtype="uint8", shape=[n], data=bytes(n))
    data = p.SerializeToString()
    assert codec.oversize_field(data) > codec.MAX_TENSOR_BYTES
    t0 = time.perf_counter()
    with pytest.raises(errors.OversizeMessage, match="refused before parsing"):
        codec.decode(Observation, data)
    assert time.perf_counter() - t0 < 0.02  # parsing it takes ~55 ms
    ok = pb.Observation(schema_version=1, world_id="w", episode=1, step=1)
    ok.tensors.add(name="x", dtype="uint8", shape=[codec.MAX_TENSOR_BYTES], data=bytes(codec.MAX_TENSOR_BYTES))
    ok.tensors.add(name="y", dtype="uint8", shape=[1 << 20], data=bytes(1 << 20))
    raw = ok.SerializeToString()
    assert len(raw) > codec.MAX_TENSOR_BYTES and codec.oversize_field(raw) == 0
    assert codec.decode(Observation, raw).tensors["x"].nbytes == codec.MAX_TENSOR_BYTES
    assert codec.oversize_field(b"\xff" * 20) == 0  # not a varint: the parser decides


def test_too_many_tensors():
    p = pb.Observation(schema_version=1, world_id="w")
    for i in range(codec.MAX_TENSORS + 1):
        p.tensors.add(name=f"t{i}", dtype="uint8", shape=[1], data=b"\x00")
    with pytest.raises(errors.OversizeMessage, match="tensors, at most"):
        codec.decode(Observation, p.SerializeToString())


def test_non_finite_reward_and_tensor_values():
    with pytest.raises(errors.NonFiniteValue, match="reward"):
        codec.decode(Observation, _raw_obs(reward=math.nan))
    with pytest.raises(errors.NonFiniteValue, match="reward"):
        codec.encode(obs(reward=math.inf))
    bad = np.array([1.0, np.nan, 2.0, 3.0], dtype=np.float32).tobytes()
    with pytest.raises(errors.NonFiniteValue, match="NaN or inf"):
        codec.decode(Observation, _raw_obs(data=bad))
    with pytest.raises(errors.NonFiniteValue):
        codec.encode(Action("w", 1, (math.nan,)))


def test_duplicate_tensor_names_are_malformed():
    p = pb.Observation(schema_version=1, world_id="w")
    for _ in range(2):
        p.tensors.add(name="x", dtype="uint8", shape=[1], data=b"\x00")
    with pytest.raises(errors.MalformedMessage, match="twice"):
        codec.decode(Observation, p.SerializeToString())


def test_every_error_is_a_protocol_error_with_a_kind():
    kinds = {
        c.kind
        for c in (
            errors.MalformedMessage,
            errors.UnknownVersion,
            errors.BadDtype,
            errors.ShapeMismatch,
            errors.OversizeMessage,
            errors.NonFiniteValue,
            errors.SpecMismatch,
        )
    }
    assert len(kinds) == 7
    assert all(issubclass(c, errors.ProtocolError) for c in (errors.MalformedMessage, errors.SpecMismatch))


def test_generated_code_matches_schema_file():
    from pathlib import Path

    from google.protobuf import descriptor_pb2

    src = (Path(__file__).resolve().parents[1] / "protocol" / "schemas" / "sme_v1.proto").read_text()
    fd = descriptor_pb2.FileDescriptorProto()
    pb.DESCRIPTOR.CopyToProto(fd)
    for m in fd.message_type:
        assert f"message {m.name} {{" in src
        for f in m.field:
            assert f" {f.name} = {f.number};" in src, (m.name, f.name)


def test_embedding_scores_are_additive_and_non_finite_scores_are_refused():
    plain = Embedding("a0", "w", 1, "t", (0, 1), np.zeros((2, 2)), (1.0,), None)
    assert codec.decode(Embedding, codec.encode(plain)).scores is None  # an old writer: no scores
    scored = Embedding(
        "a0", "w", 1, "t", (0, 1), np.zeros((2, 2)), (1.0,), 0.0, scores=EmbeddingScores(1, 1, 0, 0, 5, 2)
    )
    p = pb.Embedding.FromString(codec.encode(scored))
    assert p.HasField("scores") and p.scores.n_neighbors == 5
    p.scores.continuity = math.nan
    with pytest.raises(errors.NonFiniteValue, match="score"):
        codec.decode(Embedding, p.SerializeToString())
