"""Decoders: each `sme.v1` protobuf message to its dataclass of `messages`, every field checked
(ids, ranges, finite numbers, tensors) with a typed `ProtocolError` that says what was wrong."""

from __future__ import annotations

import math

from sensorimotor.protocol import errors, keys
from sensorimotor.protocol import messages as m
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.codec_tensors import (
    DTYPES,
    MAX_DIMS,
    MAX_TENSOR_BYTES,
    MAX_TENSORS,
    _finite,
    _not_nan,
    _tensor_from_pb,
    _tensors_from_pb,
)


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
