"""Issue 41, state and identity: a checkpoint value beyond the wire's limit or a checkpoint of
another world is never restored; `sme status` never hides an agent and flags an id answered by two
processes."""

from __future__ import annotations

import dataclasses
import json
import logging
import os
import subprocess
import sys
import time

import numpy as np
import pytest
from conftest import ROOT
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from sensorimotor.agent.checkpoint import (
    MAX_VERSION,
    Checkpoint,
    CheckpointError,
    decode_checkpoint,
    encode_checkpoint,
    read_checkpoint,
    write_checkpoint,
)
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol import codec, keys, limits
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.errors import OutOfRange
from sensorimotor.protocol.messages import AgentEvent, AgentStatus, Embedding, LinkStatus
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld


class _EventBus:
    """Stands in for the bus: keeps the events the daemon puts."""

    closed = False

    def __init__(self) -> None:
        self.events: list[AgentEvent] = []

    def put(self, key: str, payload: bytes, schema: str | None = None) -> None:  # noqa: ARG002
        self.events.append(codec.decode(AgentEvent, payload))


def _saved_grid(tmp_path, **over) -> tuple[GridWorld, str]:
    """A learned gridworld link checkpointed in `tmp_path`, then rewritten with `over` replaced."""
    world = GridWorld(seed=0)
    program = make_program(world.spec(), 0)
    run_inprocess(world, program, 200)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))  # type: ignore[arg-type]
    daemon.links[world.world_id] = WorldLink("a0", world.spec(), program, lambda *a: None, None)
    assert daemon.checkpoint() == {world.world_id}
    path = str(tmp_path / f"{world.world_id}.ckpt.npz")
    if over:
        write_checkpoint(path, dataclasses.replace(read_checkpoint(path), **over))
    return world, path


# 1. values beyond the wire's limits ----------------------------------------------------------------


@pytest.mark.parametrize(
    "over, why",
    [
        (dict(version=2**32 + 5), "version"),
        (dict(version=limits.EMBEDDING_VERSION_MAX), "version"),  # fits, but the next version would not
        (dict(epoch=2**64 + 5), "epoch"),
        (dict(epoch=-1), "epoch"),
    ],
)
def test_a_checkpoint_beyond_the_wire_limits_is_set_aside(tmp_path, caplog, over, why) -> None:
    world, path = _saved_grid(tmp_path)
    ck = read_checkpoint(path)
    data = encode_checkpoint(dataclasses.replace(ck, **over))
    with pytest.raises(CheckpointError, match=why):
        decode_checkpoint(data)
    with open(path, "wb") as f:
        f.write(data)
    bus = _EventBus()
    daemon = AgentDaemon(bus, state_dir=str(tmp_path))  # type: ignore[arg-type]
    with caplog.at_level(logging.WARNING, logger="sme.agent"):
        assert daemon._load_checkpoint(world.spec()) is None
    assert daemon.counters["bad_checkpoint"] == 1
    assert [e.reason for e in bus.events] == ["bad_checkpoint"] and why in bus.events[0].detail
    assert [f for f in os.listdir(tmp_path) if ".ckpt.npz.bad-" in f]
    codec.encode(daemon.status())  # the agent's status always encodes


def test_the_highest_version_the_wire_takes_is_restored_and_the_next_one_fits(tmp_path) -> None:
    world, _ = _saved_grid(tmp_path, version=MAX_VERSION)
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))  # type: ignore[arg-type]
    restored = daemon._load_checkpoint(world.spec())
    assert restored is not None and restored.version == MAX_VERSION
    codec.encode(Embedding("a0", world.world_id, MAX_VERSION + 1, "initial", (), np.zeros((0, 2)), (), None))


def test_a_version_mark_beyond_the_wire_is_ignored(tmp_path) -> None:
    (tmp_path / "g1.version").write_text(f"{2**32 + 5}\n")
    daemon = AgentDaemon(bus=None, state_dir=str(tmp_path))  # type: ignore[arg-type]
    assert daemon._version_floor("g1") == 0


def test_the_codec_names_the_field_beyond_its_limit() -> None:
    with pytest.raises(OutOfRange, match="Embedding.version"):
        codec.encode(Embedding("a0", "g1", 2**32 + 5, "initial", (), np.zeros((0, 2)), (), None))
    link = LinkStatus("g1", "gridworld", "gridworld", "attached", embedding_version=2**32 + 5)
    with pytest.raises(OutOfRange, match="embedding_version"):
        codec.encode(AgentStatus("a0", 1.0, (link,), {}, time.time()))


FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _near(limit: int) -> st.SearchStrategy[int]:
    """Integers at and around 0 and `limit`, and far beyond both."""
    return st.one_of(
        st.integers(-3, 3),
        st.integers(limit - 3, limit + 3),
        st.integers(-(2**70), 2**70),
    )


def _base() -> Checkpoint:
    from sensorimotor.protocol.messages import ActionSpace, SensorSpec

    return Checkpoint(
        world_id="g1",
        kind="gridworld",
        program="gridworld",
        sensors=(SensorSpec("state", "int32", (1,), 0, 80),),
        action_space=ActionSpace(n=4),
        version=3,
        program_class="GridworldProgram",
        program_state={"w": np.arange(6, dtype=np.float64)},
        saved_at=time.time() - 10,
        steps=10,
    )


@FUZZ
@given(
    version=_near(limits.EMBEDDING_VERSION_MAX),
    epoch=_near(limits.EPOCH_MAX),
    steps=_near(2**53),
)
def test_checkpoint_fields_at_and_beyond_their_limits(version, epoch, steps) -> None:
    """Property: a checkpoint decodes only when every counter fits the wire (with room for the
    next embedding version); then everything it restores encodes on the wire."""
    data = encode_checkpoint(dataclasses.replace(_base(), version=version, epoch=epoch, steps=steps))
    fits = 0 <= version < limits.EMBEDDING_VERSION_MAX and 0 <= epoch <= limits.EPOCH_MAX and 0 <= steps < 2**53
    try:
        ck = decode_checkpoint(data)
    except CheckpointError as e:
        assert not fits, f"refused a checkpoint within the limits: {e}"
        return
    assert fits
    codec.encode(Embedding("a0", ck.world_id, ck.version + 1, "initial", (), np.zeros((0, 2)), (), None))
    link = LinkStatus("g1", "gridworld", "gridworld", "attached", steps=ck.steps, embedding_version=ck.version)
    codec.encode(AgentStatus("a0", 1.0, (link,), {}, time.time()))


# 2. a checkpoint is restored only for the world it names ---------------------------------------------


def test_a_checkpoint_of_another_world_is_not_restored(tmp_path, caplog) -> None:
    world, path = _saved_grid(tmp_path, world_id="zz")
    bus = _EventBus()
    daemon = AgentDaemon(bus, state_dir=str(tmp_path))  # type: ignore[arg-type]
    with caplog.at_level(logging.WARNING, logger="sme.agent"):
        assert daemon._load_checkpoint(world.spec()) is None
    assert "'zz'" in caplog.text and "starting fresh" in caplog.text
    assert [e.reason for e in bus.events] == ["bad_checkpoint"] and "'zz'" in bus.events[0].detail
    assert daemon.counters["bad_checkpoint"] == 1
    assert not os.path.exists(path) and [f for f in os.listdir(tmp_path) if ".ckpt.npz.other-world-" in f]


# 1, 3. `sme status` never hides an agent, and flags an id two processes answer ----------------------


def _status(agent: str, uptime: float) -> bytes:
    return codec.encode(AgentStatus(agent, uptime, (), {"links": 0}, time.time()))


def _sme_status(ep: str, *more: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "status", "--connect", ep, "--timeout", "1.5", *more],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_status_lists_an_agent_that_does_not_answer_and_exits_non_zero(endpoint) -> None:
    def broken(key: str, payload: bytes | None) -> bytes:  # noqa: ARG001 - an agent whose status cannot be encoded
        raise ValueError("Value out of range: 4294967302")

    with Bus(BusConfig.for_role("agent", endpoint)) as bus:
        bus.queryable(keys.agent_status("good"), lambda k, p: _status("good", 5.0))
        bus.token(keys.alive_agent("good"))
        bus.queryable(keys.agent_status("a0"), broken)
        bus.token(keys.alive_agent("a0"))
        bus.token(keys.alive_agent("mute"))  # alive, no status queryable at all
        out = _sme_status(endpoint)
        assert out.returncode == 1, out
        assert "agent good: up" in out.stdout
        assert "agent a0: NOT ANSWERING" in out.stdout and "agent mute: NOT ANSWERING" in out.stdout
        js = _sme_status(endpoint, "--json")
        assert js.returncode == 1
        got = json.loads(js.stdout)
        assert [a["agent"] for a in got["agents"]] == ["good"]
        assert sorted(a["agent"] for a in got["not_answering"]) == ["a0", "mute"]
        one = _sme_status(endpoint, "--agent", "a0")
        assert one.returncode == 1 and "not answering" in one.stderr and "Traceback" not in one.stderr


def test_status_flags_an_id_answered_by_two_processes(endpoint) -> None:
    with Bus(BusConfig.for_role("agent", endpoint)) as bus, Bus(BusConfig.for_role("tool", endpoint)) as other:
        bus.queryable(keys.agent_status("a0"), lambda k, p: _status("a0", 50.0))
        other.queryable(keys.agent_status("a0"), lambda k, p: _status("a0", 5.0))
        bus.token(keys.alive_agent("a0"))
        out = _sme_status(endpoint)
        assert out.returncode == 1, out
        assert "agent id 'a0' is answered by 2 processes" in out.stdout
        got = json.loads(_sme_status(endpoint, "--json").stdout)
        assert got["duplicates"] == {"a0": 2}


def test_an_embedding_version_with_no_room_for_the_next_is_not_followed() -> None:
    """A version heard on the bus that a link would number after (last_published) must leave room
    for the next one: 2^32-1 from a hostile publisher would make every later publish fail."""
    from sensorimotor.protocol.bus import BusMessage

    d = AgentDaemon(bus=None)  # type: ignore[arg-type]
    for version in (7, limits.EMBEDDING_VERSION_MAX):
        emb = Embedding("x", "g1", version, "initial", (), np.zeros((0, 2)), (), None)
        d._on_embedding(BusMessage(keys.agent_embedding("x", "g1"), codec.encode(emb), ""))
    assert d.store.last_published("g1") == 7


@pytest.mark.integration
def test_an_agent_given_a_checkpoint_beyond_the_wire_starts_fresh_publishes_and_answers(
    procs, endpoint, tmp_path
) -> None:
    """The trial of the issue: a state dir whose checkpoint says embedding version 2^32+5 made every
    publish fail and the agent vanish from `sme status`; now it is set aside and the world learns."""
    from conftest import Lines, agent_status, wait_for, world_link

    world, path = _saved_grid(tmp_path, version=2**32 + 5)
    agent = procs.start("agent", "--listen", endpoint, "--workers", "1", "--state-dir", str(tmp_path))
    logs = Lines(agent.stderr)
    procs.start("world", "gridworld", "--id", world.world_id, "--connect", endpoint, "-q")

    def learned():
        ln = world_link(agent_status(endpoint), world.world_id)
        return ln is not None and ln.embedding_version >= 1 and ln

    ln = wait_for(learned, 90, every=0.5)
    assert ln and ln.embedding_version < 100, ln
    assert agent_status(endpoint).counters["bad_checkpoint"] == 1
    out = _sme_status(endpoint)
    assert out.returncode == 0 and f"{world.world_id}" in out.stdout, out
    assert [f for f in os.listdir(tmp_path) if ".ckpt.npz.bad-" in f]
    assert wait_for(lambda: logs.has("set aside"), 10), logs.lines
    assert not logs.has("Traceback") and not logs.has("Value out of range"), logs.lines
