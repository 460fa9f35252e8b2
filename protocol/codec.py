"""Validating codec between the dataclasses in `messages` and Protocol Buffers bytes.

Every decode checks, before anything large is allocated: total size, schema version, tensor count,
dtype whitelist, shape/bytes agreement, per-tensor size, and finiteness of rewards and float
tensors. Each failure raises a typed `ProtocolError` whose message says what was wrong.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
from google.protobuf.message import DecodeError

from sensorimotor.protocol import errors, keys, limits
from sensorimotor.protocol import messages as m
from sensorimotor.protocol import sme_v1_pb2 as pb

MAX_MESSAGE_BYTES = 64 * 1024 * 1024
MAX_TENSORS = 64
MAX_TENSOR_BYTES = 32 * 1024 * 1024
MAX_DIMS = 8

DTYPES: dict[str, np.dtype] = {
    name: np.dtype(name).newbyteorder("<")
    for name in ("uint8", "int8", "uint16", "int16", "int32", "int64", "float32", "float64", "bool")
}

_DTYPE_NAMES: dict[np.dtype, str] = {}


def dtype_name(dt: np.dtype) -> str:
    """``dt.name``, memoised: numpy computes the name in Python each time (~5 us, on the hot path)."""
    name = _DTYPE_NAMES.get(dt)
    if name is None:
        name = _DTYPE_NAMES[dt] = dt.name
    return name


SCHEMA_NAMES = {
    m.WorldSpec: "sme.v1.WorldSpec",
    m.Observation: "sme.v1.Observation",
    m.Action: "sme.v1.Action",
    m.Control: "sme.v1.Control",
    m.Truth: "sme.v1.Truth",
    m.Embedding: "sme.v1.Embedding",
    m.AgentEvent: "sme.v1.AgentEvent",
    m.WorldEvent: "sme.v1.WorldEvent",
    m.AgentStatus: "sme.v1.AgentStatus",
    m.LeaseRequest: "sme.v1.LeaseRequest",
    m.Lease: "sme.v1.Lease",
    m.SharedCheckpoint: "sme.v1.Checkpoint",
}


def _not_nan(value: float, what: str) -> float:
    if math.isnan(value):
        raise errors.NonFiniteValue(f"{what} is NaN; a bound may be infinite, never NaN")
    return value


def _finite(value: float, what: str) -> float:
    if not math.isfinite(value):
        raise errors.NonFiniteValue(f"{what} is {value!r}; only finite numbers are accepted")
    return value


def _limited(value: int, limit: int, what: str) -> int:
    """`value` if its wire field (`protocol.limits`) can carry it; OutOfRange naming the field otherwise."""
    if not limits.within(value, limit):
        raise errors.OutOfRange(f"{what} {value!r} is out of the wire's range 0 .. {limit}")
    return value


def _tensor_to_pb(name: str, array: np.ndarray, out: pb.Tensor) -> None:
    a = np.asarray(array)
    dt = dtype_name(a.dtype)
    if dt not in DTYPES:
        raise errors.BadDtype(f"tensor {name!r}: dtype {dt} is not one of {sorted(DTYPES)}")
    if a.ndim > MAX_DIMS:
        raise errors.ShapeMismatch(f"tensor {name!r}: {a.ndim} dimensions, at most {MAX_DIMS}")
    if a.nbytes > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(f"tensor {name!r}: {a.nbytes} bytes, at most {MAX_TENSOR_BYTES}")
    out.name = name
    out.dtype = dt
    out.shape.extend(a.shape)
    out.data = np.ascontiguousarray(a, dtype=DTYPES[dt]).tobytes()


def _tensor_from_pb(t: pb.Tensor, where: str) -> np.ndarray:
    name = t.name or "?"
    dt = DTYPES.get(t.dtype)
    if dt is None:
        raise errors.BadDtype(f"{where}: tensor {name!r} has dtype {t.dtype!r}; allowed: {sorted(DTYPES)}")
    shape = tuple(t.shape)
    if len(shape) > MAX_DIMS:
        raise errors.ShapeMismatch(f"{where}: tensor {name!r} has {len(shape)} dimensions, at most {MAX_DIMS}")
    claimed = math.prod(shape) * dt.itemsize  # Python ints: a huge claim cannot overflow
    if claimed > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(
            f"{where}: tensor {name!r} claims shape {list(shape)} = {claimed} bytes, at most {MAX_TENSOR_BYTES}"
        )
    data = t.data  # each access copies the bytes out of the message
    if claimed != len(data):
        raise errors.ShapeMismatch(
            f"{where}: tensor {name!r} shape {list(shape)} x {dt.name} needs {claimed} bytes, got {len(data)}"
        )
    a = np.frombuffer(data, dtype=dt).reshape(shape)
    if dt.kind == "f" and a.size and not np.isfinite(a).all():
        raise errors.NonFiniteValue(f"{where}: tensor {name!r} contains NaN or inf")
    return a


def _tensors_from_pb(ts: Any, where: str) -> dict[str, np.ndarray]:
    if len(ts) > MAX_TENSORS:
        raise errors.OversizeMessage(f"{where}: {len(ts)} tensors, at most {MAX_TENSORS}")
    out: dict[str, np.ndarray] = {}
    for t in ts:
        if t.name in out:
            raise errors.MalformedMessage(f"{where}: tensor name {t.name!r} appears twice")
        out[t.name] = _tensor_from_pb(t, where)
    return out


def _tensors_to_pb(tensors: dict[str, np.ndarray], field: Any) -> None:
    if len(tensors) > MAX_TENSORS:
        raise errors.OversizeMessage(f"{len(tensors)} tensors, at most {MAX_TENSORS}")
    for name, a in tensors.items():
        _tensor_to_pb(name, a, field.add())


# --- encoders ---------------------------------------------------------------------------------


def _enc_spec(x: m.WorldSpec) -> pb.WorldSpec:
    p = pb.WorldSpec(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        kind=x.kind,
        reward_min=x.reward_min,
        reward_max=x.reward_max,
        program=x.program,
        n_starts=x.n_starts,
        session=x.session,
        goal="" if x.goal == m.GoalRule.REWARD else str(x.goal),
    )
    for s in x.sensors:
        p.sensors.add(
            name=s.name, dtype=s.dtype, shape=list(s.shape), low=s.low, high=s.high, description=s.description
        )
    a = x.action_space
    p.action_space.discrete_n = a.n
    p.action_space.low.extend(a.low)
    p.action_space.high.extend(a.high)
    p.action_space.names.extend(a.names)
    p.params.update(x.params)
    return p


def _enc_obs(x: m.Observation) -> pb.Observation:
    _finite(float(x.reward), "observation reward")
    p = pb.Observation(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        episode=x.episode,
        step=x.step,
        t=x.t,
        timestamp=x.timestamp,
        reward=x.reward,
        done=x.done,
        start=x.start,
        session=x.session,
        truncated=x.truncated,
        success=x.success,
    )
    _tensors_to_pb(x.tensors, p.tensors)
    return p


def _enc_act(x: m.Action) -> pb.Action:
    for v in x.values:
        _finite(float(v), "action value")
    return pb.Action(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        step=x.step,
        values=[float(v) for v in x.values],
        reset=x.reset,
        start=x.start,
        timestamp=x.timestamp,
        owner=x.owner,
        epoch=x.epoch,
    )


def _enc_ctl(x: m.Control) -> pb.Control:
    p = pb.Control(schema_version=m.SCHEMA_VERSION, world_id=x.world_id, kind=x.kind, id=x.id, timestamp=x.timestamp)
    p.params.update({k: str(v) for k, v in x.params.items()})
    return p


def _enc_truth(x: m.Truth) -> pb.Truth:
    p = pb.Truth(schema_version=m.SCHEMA_VERSION, world_id=x.world_id, kind=x.kind, step=x.step, timestamp=x.timestamp)
    _tensors_to_pb(x.tensors, p.tensors)
    return p


def _enc_emb(x: m.Embedding) -> pb.Embedding:
    p = pb.Embedding(
        schema_version=m.SCHEMA_VERSION,
        agent_id=x.agent_id,
        world_id=x.world_id,
        version=_limited(x.version, limits.EMBEDDING_VERSION_MAX, "Embedding.version"),
        trigger=x.trigger,
        ids=list(x.ids),
        eigenvalues=[float(e) for e in x.eigenvalues],
        has_procrustes=x.procrustes_error is not None,
        procrustes_error=float(x.procrustes_error) if x.procrustes_error is not None else 0.0,
        step=x.step,
        timestamp=x.timestamp,
        iteration=x.iteration,
        labels=[int(v) for v in x.labels],
    )
    if x.drop_step is not None:
        p.drop_step = x.drop_step
    if x.scores is not None:
        sc = x.scores
        p.scores.trustworthiness = float(sc.trustworthiness)
        p.scores.continuity = float(sc.continuity)
        p.scores.metric_dissimilarity = float(sc.metric_dissimilarity)
        p.scores.topological_dissimilarity = float(sc.topological_dissimilarity)
        p.scores.n_neighbors = int(sc.n_neighbors)
        p.scores.n_points = int(sc.n_points)
    _tensor_to_pb("coordinates", np.asarray(x.coordinates, dtype=np.float64), p.coordinates)
    p.metrics.update({k: float(v) for k, v in x.metrics.items()})
    return p


def _enc_event(x: m.AgentEvent) -> pb.AgentEvent:
    p = pb.AgentEvent(
        schema_version=m.SCHEMA_VERSION,
        agent_id=x.agent_id,
        world_id=x.world_id,
        kind=x.kind,
        detail=m.clip(x.detail),
        step=x.step,
        timestamp=x.timestamp,
        reason=m.clip(x.reason, 100),
    )
    p.values.update({k: float(v) for k, v in x.values.items()})
    if x.config is not None:
        c = x.config
        p.config.seed, p.config.detector, p.config.program = c.seed, c.detector, c.program
        p.config.program_params.update({k: str(v) for k, v in c.program_params.items()})
    return p


def _enc_world_event(x: m.WorldEvent) -> pb.WorldEvent:
    return pb.WorldEvent(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        session=x.session,
        kind=x.kind,
        reason=m.clip(x.reason, 100),
        detail=m.clip(x.detail),
        step=x.step,
        timestamp=x.timestamp,
        control_id=x.control_id,
        owner=x.owner,
        epoch=x.epoch,
        holder=x.holder,
        holder_epoch=x.holder_epoch,
    )


def _enc_lease_request(x: m.LeaseRequest) -> pb.LeaseRequest:
    return pb.LeaseRequest(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        owner=x.owner,
        epoch=x.epoch,
        release=x.release,
        request_id=x.request_id,
    )


def _enc_lease(x: m.Lease) -> pb.Lease:
    if math.isnan(x.ttl) or x.ttl < 0:
        raise errors.NonFiniteValue(f"Lease ttl is {x.ttl!r}; a number >= 0 (inf: never) is expected")
    return pb.Lease(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        session=x.session,
        holder=x.holder,
        epoch=x.epoch,
        granted=x.granted,
        reason=x.reason,
        ttl=x.ttl,
        timestamp=x.timestamp,
    )


def _enc_checkpoint(x: m.SharedCheckpoint) -> pb.Checkpoint:
    if len(x.data) > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(f"Checkpoint: {len(x.data)} bytes of data, at most {MAX_TENSOR_BYTES}")
    return pb.Checkpoint(
        schema_version=m.SCHEMA_VERSION,
        world_id=x.world_id,
        owner=x.owner,
        epoch=x.epoch,
        format_version=x.format_version,
        embedding_version=x.embedding_version,
        saved_at=_finite(x.saved_at, "Checkpoint.saved_at"),
        data=x.data,
    )


def _enc_status(x: m.AgentStatus) -> pb.AgentStatus:
    p = pb.AgentStatus(schema_version=m.SCHEMA_VERSION, agent_id=x.agent_id, uptime=x.uptime, timestamp=x.timestamp)
    for ln in x.links:
        q = p.links.add(
            world_id=ln.world_id,
            kind=ln.kind,
            program=ln.program,
            state=ln.state,
            steps=ln.steps,
            episodes=ln.episodes,
            embedding_version=_limited(
                ln.embedding_version, limits.EMBEDDING_VERSION_MAX, f"LinkStatus {ln.world_id!r} embedding_version"
            ),
            reward_mean=ln.reward_mean,
            last_procrustes_error=ln.last_procrustes_error,
            detector_statistic=ln.detector_statistic,
            drops=ln.drops,
            dropped=ln.dropped,
        )
        q.rejected.update(ln.rejected)
    p.counters.update(x.counters)
    return p


# --- decoders ---------------------------------------------------------------------------------


def _dec_spec(p: pb.WorldSpec) -> m.WorldSpec:
    # A spec promises what every observation will look like: refuse one that no valid observation
    # could meet (more sensors than an observation may carry, a shape over the tensor limits), with
    # NaN bounds, or with an action box that is not finite, instead of building a program from it.
    # Sensor and reward bounds may be infinite (an unbounded sensor, Gymnasium's default reward range).
    if len(p.sensors) > MAX_TENSORS:
        raise errors.OversizeMessage(f"WorldSpec: {len(p.sensors)} sensors, at most {MAX_TENSORS}")
    sensors: list[m.SensorSpec] = []
    for s in p.sensors:
        dt = DTYPES.get(s.dtype)
        if dt is None:
            raise errors.BadDtype(f"WorldSpec sensor {s.name!r} has dtype {s.dtype!r}; allowed: {sorted(DTYPES)}")
        if any(x.name == s.name for x in sensors):
            raise errors.MalformedMessage(f"WorldSpec: sensor name {s.name!r} appears twice")
        if len(s.shape) > MAX_DIMS:
            raise errors.ShapeMismatch(f"WorldSpec sensor {s.name!r} has {len(s.shape)} dimensions, at most {MAX_DIMS}")
        if math.prod(s.shape) * dt.itemsize > MAX_TENSOR_BYTES:
            raise errors.OversizeMessage(
                f"WorldSpec sensor {s.name!r} shape {list(s.shape)} is over {MAX_TENSOR_BYTES} bytes"
            )
        where = f"WorldSpec sensor {s.name!r}"
        sensors.append(
            m.SensorSpec(
                s.name,
                s.dtype,
                tuple(s.shape),
                _not_nan(s.low, f"{where} low"),
                _not_nan(s.high, f"{where} high"),
                s.description,
            )
        )
    a = p.action_space
    if a.discrete_n == 0 and (len(a.low) == 0 or len(a.low) != len(a.high)):
        raise errors.MalformedMessage("WorldSpec action_space: neither discrete_n > 0 nor matching low/high bounds")
    if max(len(a.low), len(a.high), len(a.names)) > MAX_TENSORS:
        raise errors.OversizeMessage(f"WorldSpec action_space: more than {MAX_TENSORS} dimensions or names")
    for v in a.low:
        _finite(v, "WorldSpec action_space low")
    for v in a.high:
        _finite(v, "WorldSpec action_space high")
    for lo, hi in zip(a.low, a.high, strict=False):
        if lo > hi:
            raise errors.MalformedMessage(f"WorldSpec action_space: low {lo} > high {hi}")
    _not_nan(p.reward_min, "WorldSpec reward_min")
    _not_nan(p.reward_max, "WorldSpec reward_max")
    goal = p.goal or m.GoalRule.REWARD
    if goal not in tuple(m.GoalRule):
        raise errors.MalformedMessage(
            f"WorldSpec goal {p.goal[:40]!r} is not one of {', '.join(r.value for r in m.GoalRule)}"
        )
    return m.WorldSpec(
        world_id=p.world_id,
        kind=p.kind,
        sensors=tuple(sensors),
        action_space=m.ActionSpace(a.discrete_n, tuple(a.low), tuple(a.high), tuple(a.names)),
        reward_min=p.reward_min,
        reward_max=p.reward_max,
        program=p.program,
        n_starts=p.n_starts,
        params=dict(p.params),
        session=p.session,
        goal=m.GoalRule(goal),
    )


def _dec_obs(p: pb.Observation) -> m.Observation:
    where = f"Observation(world={p.world_id!r}, step={p.step})"
    return m.Observation(
        world_id=p.world_id,
        episode=p.episode,
        step=p.step,
        t=p.t,
        tensors=_tensors_from_pb(p.tensors, where),
        reward=_finite(p.reward, f"{where} reward"),
        done=p.done,
        start=p.start,
        timestamp=p.timestamp,
        session=p.session,
        truncated=p.truncated,
        success=p.success,
    )


def _dec_act(p: pb.Action) -> m.Action:
    if len(p.values) > MAX_TENSORS:
        raise errors.OversizeMessage(f"Action has {len(p.values)} values, at most {MAX_TENSORS}")
    vals = tuple(_finite(v, f"Action(step={p.step}) value") for v in p.values)
    _lease_id(p.owner, "Action owner", empty=True)
    return m.Action(p.world_id, p.step, vals, p.reset, p.start, p.timestamp, p.owner, p.epoch)


def _dec_ctl(p: pb.Control) -> m.Control:
    return m.Control(p.world_id, p.kind, dict(p.params), p.id, p.timestamp)


def _dec_truth(p: pb.Truth) -> m.Truth:
    return m.Truth(p.world_id, p.kind, _tensors_from_pb(p.tensors, "Truth"), p.step, p.timestamp)


def _dec_emb(p: pb.Embedding) -> m.Embedding:
    coords = _tensor_from_pb(p.coordinates, "Embedding")
    if p.labels and len(p.labels) != (coords.shape[0] if coords.ndim else 0):
        raise errors.ShapeMismatch(f"Embedding: {len(p.labels)} labels for {coords.shape[0]} rows")
    return m.Embedding(
        agent_id=p.agent_id,
        world_id=p.world_id,
        version=p.version,
        trigger=p.trigger,
        ids=tuple(p.ids),
        coordinates=coords,
        eigenvalues=tuple(p.eigenvalues),
        procrustes_error=p.procrustes_error if p.has_procrustes else None,
        step=p.step,
        timestamp=p.timestamp,
        metrics=dict(p.metrics),
        iteration=p.iteration,
        drop_step=p.drop_step if p.HasField("drop_step") else None,
        labels=tuple(p.labels),
        scores=_dec_scores(p.scores) if p.HasField("scores") else None,
    )


def _dec_scores(s: pb.Embedding.Scores) -> m.EmbeddingScores:
    values = (s.trustworthiness, s.continuity, s.metric_dissimilarity, s.topological_dissimilarity)
    if not all(math.isfinite(v) for v in values):
        raise errors.NonFiniteValue("Embedding: a score is NaN or inf")
    return m.EmbeddingScores(*values, n_neighbors=s.n_neighbors, n_points=s.n_points)


def _dec_event(p: pb.AgentEvent) -> m.AgentEvent:
    config = None
    if p.HasField("config"):
        c = p.config
        config = m.AttachConfig(c.seed, c.detector, c.program, dict(c.program_params))
    return m.AgentEvent(p.agent_id, p.world_id, p.kind, p.detail, p.step, p.timestamp, dict(p.values), p.reason, config)


def _dec_world_event(p: pb.WorldEvent) -> m.WorldEvent:
    return m.WorldEvent(
        p.world_id,
        p.kind,
        p.reason,
        p.detail,
        p.step,
        p.session,
        p.timestamp,
        p.owner,
        p.epoch,
        p.holder,
        p.holder_epoch,
        p.control_id,
    )


# Lease messages name owners and worlds: ids (see keys.check_id) or empty where the contract allows it.
def _lease_id(value: str, what: str, empty: bool = False) -> str:
    if (empty and value == "") or keys.is_id(value):
        return value
    raise errors.MalformedMessage(f"{what} {value[:80]!r} is not an id (1-64 of A-Z a-z 0-9 _ . -)")


def _dec_lease_request(p: pb.LeaseRequest) -> m.LeaseRequest:
    if len(p.request_id) > 64:
        raise errors.MalformedMessage(f"LeaseRequest request_id is {len(p.request_id)} characters, at most 64")
    return m.LeaseRequest(
        _lease_id(p.world_id, "LeaseRequest world_id"),
        _lease_id(p.owner, "LeaseRequest owner"),
        p.epoch,
        p.release,
        p.request_id,
    )


def _dec_lease(p: pb.Lease) -> m.Lease:
    if math.isnan(p.ttl) or p.ttl < 0:
        raise errors.NonFiniteValue(f"Lease ttl is {p.ttl!r}; a number >= 0 (inf: never) is expected")
    return m.Lease(
        _lease_id(p.world_id, "Lease world_id"),
        p.session,
        _lease_id(p.holder, "Lease holder", empty=True),
        p.epoch,
        p.granted,
        p.reason,
        p.ttl,
        p.timestamp,
    )


def _dec_checkpoint(p: pb.Checkpoint) -> m.SharedCheckpoint:
    if len(p.data) > MAX_TENSOR_BYTES:
        raise errors.OversizeMessage(f"Checkpoint: {len(p.data)} bytes of data, at most {MAX_TENSOR_BYTES}")
    return m.SharedCheckpoint(
        p.world_id,
        p.data,
        p.owner,
        p.epoch,
        p.format_version,
        p.embedding_version,
        _finite(p.saved_at, "Checkpoint.saved_at"),
    )


def _dec_status(p: pb.AgentStatus) -> m.AgentStatus:
    links = tuple(
        m.LinkStatus(
            ln.world_id,
            ln.kind,
            ln.program,
            ln.state,
            ln.steps,
            ln.episodes,
            ln.embedding_version,
            ln.reward_mean,
            dict(ln.rejected),
            ln.last_procrustes_error,
            ln.detector_statistic,
            ln.drops,
            ln.dropped,
        )
        for ln in p.links
    )
    return m.AgentStatus(p.agent_id, p.uptime, links, dict(p.counters), p.timestamp)


_CODECS: dict[type, tuple[type, Callable[[Any], Any], Callable[[Any], Any]]] = {
    m.WorldSpec: (pb.WorldSpec, _enc_spec, _dec_spec),
    m.Observation: (pb.Observation, _enc_obs, _dec_obs),
    m.Action: (pb.Action, _enc_act, _dec_act),
    m.Control: (pb.Control, _enc_ctl, _dec_ctl),
    m.Truth: (pb.Truth, _enc_truth, _dec_truth),
    m.Embedding: (pb.Embedding, _enc_emb, _dec_emb),
    m.AgentEvent: (pb.AgentEvent, _enc_event, _dec_event),
    m.WorldEvent: (pb.WorldEvent, _enc_world_event, _dec_world_event),
    m.AgentStatus: (pb.AgentStatus, _enc_status, _dec_status),
    m.LeaseRequest: (pb.LeaseRequest, _enc_lease_request, _dec_lease_request),
    m.Lease: (pb.Lease, _enc_lease, _dec_lease),
    m.SharedCheckpoint: (pb.Checkpoint, _enc_checkpoint, _dec_checkpoint),
}


def encode(msg: Any) -> bytes:
    """Serialise one of the message dataclasses to Protocol Buffers bytes.

    The message is validated like a decode would be (dtypes, shapes, sizes, finite numbers), so
    a bad message fails at the sender, with the sender's stack trace.

    Parameters
    ----------
    msg : WorldSpec, Observation, Action, Control, Truth, Embedding, AgentEvent, WorldEvent or AgentStatus
        The message (an instance of one of the `messages` dataclasses).

    Returns
    -------
    bytes
        The serialized ``sme.v1`` message.

    Raises
    ------
    TypeError
        If `msg` is not a protocol message.
    ProtocolError
        If the message breaks the contract (`BadDtype`, `ShapeMismatch`, `OversizeMessage`,
        `NonFiniteValue`, ...).

    Examples
    --------
    >>> from sensorimotor.protocol import codec, messages
    >>> data = codec.encode(messages.Action("grid0", step=3, values=(1.0,)))
    >>> codec.decode(messages.Action, data).step
    3
    """
    try:
        _, enc, _ = _CODECS[type(msg)]
    except KeyError:
        raise TypeError(f"not a protocol message: {type(msg).__name__}") from None
    try:
        data = enc(msg).SerializeToString()
    except errors.ProtocolError:
        raise
    except ValueError as e:  # protobuf's "Value out of range: N" for an integer beyond its field
        raise errors.OutOfRange(f"{type(msg).__name__}: {e} (see protocol.limits)") from None
    if len(data) > MAX_MESSAGE_BYTES:
        raise errors.OversizeMessage(f"{type(msg).__name__}: {len(data)} bytes, at most {MAX_MESSAGE_BYTES}")
    return data


_FIELD_SLACK = 64 * 1024  # a tensor's name, dtype and shape beside its at most MAX_TENSOR_BYTES of data
_SCAN_FIELDS = 256  # top-level fields looked at before parsing (beyond: the parser decides)


def _varint(data: bytes | bytearray | memoryview, i: int) -> tuple[int, int] | None:
    """The protobuf varint at `i` and the index after it (None: truncated or over 10 bytes)."""
    value = shift = 0
    for j in range(i, min(i + 10, len(data))):
        b = data[j]
        value |= (b & 0x7F) << shift
        if b < 0x80:
            return value, j + 1
        shift += 7
    return None


def oversize_field(data: bytes | bytearray | memoryview) -> int:
    """The length of the first top-level field of `data` (a serialized message) longer than any
    field of an sme message can be (MAX_TENSOR_BYTES plus a tensor's header), 0 if none is among
    the first fields. Read from the wire format without parsing, so that a 33 MiB tensor is refused
    without being copied into a message first (~55 ms of a bus thread per message otherwise)."""
    i, n = 0, len(data)
    for _ in range(_SCAN_FIELDS):
        if i >= n:
            return 0
        key = _varint(data, i)
        if key is None:
            return 0
        wire, i = key[0] & 7, key[1]
        if wire == 0:
            v = _varint(data, i)
            if v is None:
                return 0
            i = v[1]
        elif wire == 1:
            i += 8
        elif wire == 5:
            i += 4
        elif wire == 2:
            ln = _varint(data, i)
            if ln is None:
                return 0
            if ln[0] > MAX_TENSOR_BYTES + _FIELD_SLACK:
                return ln[0]
            i = ln[1] + ln[0]
        else:  # groups or garbage: the parser says what is wrong
            return 0
    return 0


def decode(cls: type, payload: bytes | bytearray | memoryview) -> Any:
    """Parse and validate bytes as message class `cls`.

    Every check (total size, schema version, tensor count, dtype, shape against bytes, finite
    numbers) runs before anything large is allocated, so hostile bytes cannot exhaust memory.

    Parameters
    ----------
    cls : type
        The expected message class (one of the `messages` dataclasses).
    payload : bytes, bytearray or memoryview
        The serialized message, as received.

    Returns
    -------
    object
        An instance of `cls`.

    Raises
    ------
    KeyError
        If `cls` is not a protocol message class.
    ProtocolError
        If the bytes are not a valid `cls` message (`MalformedMessage`, `UnknownVersion`,
        `OversizeMessage`, `BadDtype`, `ShapeMismatch`, `NonFiniteValue`).
    """
    pbcls, _, dec = _CODECS[cls]
    name = cls.__name__
    if len(payload) > MAX_MESSAGE_BYTES:
        raise errors.OversizeMessage(f"{name}: {len(payload)} bytes, at most {MAX_MESSAGE_BYTES}")
    if len(payload) > MAX_TENSOR_BYTES:  # only a message this large can hold a field over the limit
        big = oversize_field(payload)
        if big:
            raise errors.OversizeMessage(
                f"{name}: a field of {big} bytes, at most {MAX_TENSOR_BYTES} per tensor (refused before parsing)"
            )
    p = pbcls()
    try:
        p.ParseFromString(bytes(payload))
    except (DecodeError, RuntimeError, ValueError) as e:
        raise errors.MalformedMessage(f"{name}: not a valid protobuf message ({e})") from None
    if p.schema_version != m.SCHEMA_VERSION:
        raise errors.UnknownVersion(
            f"{name}: schema version {p.schema_version}, this build speaks version {m.SCHEMA_VERSION}"
            + (" (0 usually means the bytes are not an sme message)" if p.schema_version == 0 else "")
        )
    return dec(p)


def schema_name(cls: type) -> str:
    """The protobuf full name of message class `cls` (e.g. ``sme.v1.Observation``), as bus
    encodings and MCAP schemas carry it."""
    return SCHEMA_NAMES[cls]


def descriptor_set(full_name: str) -> bytes:
    """The serialized FileDescriptorSet (with dependencies) defining message `full_name`, as MCAP
    protobuf schema records need. Knows sme.v1.* and foxglove.RawImage."""
    from google.protobuf import descriptor_pb2, descriptor_pool

    from sensorimotor.protocol import images  # noqa: F401  (registers foxglove.RawImage in the default pool)

    try:
        desc = descriptor_pool.Default().FindMessageTypeByName(full_name)
    except KeyError:
        raise KeyError(f"unknown protobuf message {full_name!r}") from None
    fds = descriptor_pb2.FileDescriptorSet()
    seen: set[str] = set()

    def add(fd) -> None:
        if fd.name in seen:
            return
        seen.add(fd.name)
        for dep in fd.dependencies:
            add(dep)
        fd.CopyToProto(fds.file.add())

    add(desc.file)
    return fds.SerializeToString()
