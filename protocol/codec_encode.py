"""Encoders: each message dataclass of `messages` to its `sme.v1` protobuf message, validated as a
decode would be (so a bad message fails at the sender)."""

from __future__ import annotations

import math

import numpy as np

from sensorimotor.protocol import errors, limits
from sensorimotor.protocol import messages as m
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.codec_tensors import MAX_TENSOR_BYTES, _finite, _limited, _tensor_to_pb, _tensors_to_pb


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
