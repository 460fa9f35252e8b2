"""Shared checkpoints: the newest copy per world, the share schedule after new embedding versions,
and the daemon parts built on them (share soon after a version, a takeover that says its copy is
older than the last published embedding and numbers after it)."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.attach import attach
from sensorimotor.agent.checkpoint import Checkpoint, encode_checkpoint
from sensorimotor.agent.checkpoint_store import SharedCheckpoints, ShareSchedule
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.messages import Embedding, EventKind, SharedCheckpoint
from sensorimotor.worlds.gridworld import GridWorld


def ckpt_bytes(world: str = "g1", saved_at: float = 1.0, version: int = 3, owner: str = "a") -> bytes:
    spec = GridWorld(world).spec()
    return encode_checkpoint(
        Checkpoint(
            world, spec.kind, spec.program, spec.sensors, spec.action_space, version, "GridworldProgram",
            saved_at=saved_at, owner=owner, epoch=2, program_state={"w": np.arange(3.0)},
        )
    )  # fmt: skip


def test_the_newest_copy_is_kept_and_bad_ones_are_refused_with_a_reason():
    s = SharedCheckpoints(max_bytes=1 << 20)
    assert s.offer("a", "g1", ckpt_bytes(saved_at=5.0, version=5)) is None
    assert s.offer("b", "g1", ckpt_bytes(saved_at=4.0, version=4, owner="b")) is None  # older: not kept
    copy = s.newest("g1")
    assert copy is not None and copy.owner == "a" and copy.checkpoint.version == 5
    assert copy.checkpoint.owner == "a" and copy.checkpoint.epoch == 2
    assert "not 'g2'" in (s.offer("a", "g2", ckpt_bytes("g1")) or "")
    assert "not a checkpoint" in (s.offer("a", "g1", b"garbage") or "")
    assert "more than" in (SharedCheckpoints(max_bytes=10).offer("a", "g1", ckpt_bytes()) or "")
    assert s.offer("me", "g1", ckpt_bytes(saved_at=9.0, owner="me"), exclude="me") is None
    assert s.newest("g1").checkpoint.saved_at == 5.0  # own state: not taken as a copy
    s.drop("g1")
    assert s.newest("g1") is None and s.worlds() == []


def test_published_versions_only_grow():
    s = SharedCheckpoints()
    s.published("g1", 4)
    s.published("g1", 2)
    assert s.last_published("g1") == 4 and s.last_published("g2") == 0


def test_share_schedule_shares_a_burst_once_and_its_last_version_later():
    s = ShareSchedule(2.0)
    assert s.take(0.0) == []
    s.new_version("g1", 0.0)
    s.new_version("g2", 0.0)
    assert s.take(0.0) == ["g1", "g2"]
    s.shared("g1", 0.0)
    s.shared("g2", 0.0)
    s.new_version("g1", 0.5)
    s.new_version("g1", 1.0)
    assert s.take(1.9) == []  # within the interval
    assert s.take(2.0) == ["g1"]  # the last version of the burst, once the interval passed
    s.forget("g1")
    assert s.take(10.0) == []


class _Pub:
    def __init__(self) -> None:
        self._pub = object()
        self.put = lambda data: None


class _Bus:
    """The little of Bus the daemon uses to publish and share, without zenoh."""

    closed = False

    def __init__(self) -> None:
        self.puts: list[tuple[str, bytes]] = []

    def publisher(self, key: str, schema: str | None = None) -> _Pub:
        return _Pub()

    def put(self, key: str, payload: bytes, schema: str | None = None) -> None:
        self.puts.append((key, payload))

    def undeclare(self, entity: object) -> None:
        pass

    def get(self, key: str, timeout: float = 2.0, payload: bytes | None = None) -> list:
        return []


def embedding(world: str, version: int) -> Embedding:
    return Embedding("a0", world, version, "periodic", (0, 1), np.zeros((2, 2)), (1.0, 0.5))


def test_a_new_embedding_version_is_shared_soon_and_at_most_once_per_interval():
    bus = _Bus()
    d = AgentDaemon(bus, owner_id="a", share_on_embedding=2.0)  # type: ignore[arg-type]
    d.book.owner("b", True)  # another owner alive: shares go out
    spec = GridWorld("g1").spec()
    d.links["g1"] = attach(spec, d.config, d.publish).link
    d._claims["g1"] = (object(), 0.0)
    d.publish("embedding", embedding("g1", 1))
    assert d.share_new_versions(now=100.0) == 1
    assert [k for k, _ in bus.puts] == [keys.agent_checkpoint("a", "g1")]
    d.publish("embedding", embedding("g1", 2))
    assert d.share_new_versions(now=101.0) == 0  # within 2 s of the last share
    assert d.share_new_versions(now=102.5) == 1 and d.counters["shared_on_embedding"] == 2
    # the copy it answers queries with is its own last share (the checkpoint file inside the
    # sme.v1.Checkpoint message that went on the bus)
    shared = codec.decode(SharedCheckpoint, bus.puts[-1][1])
    assert shared.world_id == "g1" and shared.owner == "a" and shared.format_version >= 1
    assert d._answer_checkpoint(keys.agent_checkpoint("a", "g1"), None) == shared.data
    assert d._answer_checkpoint(keys.agent_checkpoint("a", "g9"), None) == b""
    # nothing over the size bound goes on the bus
    small = AgentDaemon(_Bus(), owner_id="a", share_max_bytes=100)  # type: ignore[arg-type]
    small.book.owner("b", True)
    small.links["g1"] = attach(spec, small.config, small.publish).link
    small._claims["g1"] = (object(), 0.0)
    assert small.share() == 0 and small.counters["share_oversize"] == 1


def test_a_takeover_from_an_older_copy_says_so_and_numbers_after_the_last_published_version():
    events = []
    d = AgentDaemon(_Bus(), owner_id="b", on_output=lambda ch, m: events.append(m))  # type: ignore[arg-type]
    spec = GridWorld("g1").spec()
    owner_a = AgentDaemon(_Bus(), owner_id="a")  # type: ignore[arg-type]
    was = attach(spec, owner_a.config, owner_a.publish).link
    was.version = 3
    assert d.store.offer("a", "g1", owner_a._encoded_state("g1", was) or b"") is None
    d.store.published("g1", 5)  # a published v4 and v5 after the copy it shared
    restored = d._load_checkpoint(spec)
    assert restored is not None and restored.version == 3 and d.counters["taken_over"] == 1
    link = attach(spec, d.config, d.publish, restored=restored, last_published=d.store.last_published("g1")).link
    assert link.version == 5  # the next embedding is v6: no version number published twice
    att = [e for e in events if e.kind == EventKind.ATTACHED][-1]
    assert att.reason == "restored" and "older than the last published embedding v5" in att.detail
    assert att.values == {"checkpoint_version": 3.0, "last_published_version": 5.0}
    fresh = attach(spec, d.config, d.publish, last_published=7).link
    assert fresh.version == 7 and "versions go on from there" in events[-1].detail


def test_the_share_interval_is_a_command_line_option_the_workers_get_too(monkeypatch, capsys):
    """`sme agent --share-on-embedding S` sets the interval of the share after a new embedding
    version (default 2 s), for the agent and every worker; a bad value is a usage error."""
    from sensorimotor.tools.cli import build_parser, main
    from sensorimotor.tools.commands import agent as agent_cmd
    from sensorimotor.tools.common import free_port

    assert build_parser().parse_args(["agent"]).share_on_embedding == 2.0
    for bad in ("-1", "nan"):
        assert main(["agent", "--share-on-embedding", bad]) == 2
        assert "--share-on-embedding must be >= 0 seconds" in capsys.readouterr().err
    args = build_parser().parse_args(["agent", "--share-on-embedding", "0.5"])
    argv = agent_cmd._worker_argv(args, 1, "tcp/127.0.0.1:7447")
    assert argv[argv.index("--share-on-embedding") + 1] == "0.5"

    made: list[AgentDaemon] = []

    class Made(Exception):
        pass

    def capture(*a, **kw):
        made.append(AgentDaemon(*a, **kw))
        raise Made

    monkeypatch.setattr(agent_cmd, "AgentDaemon", capture)
    port = free_port()
    try:
        main(["agent", "--workers", "1", "--listen", f"tcp/127.0.0.1:{port}", "--share-on-embedding", "0.5", "-q"])
    except Made:
        pass
    assert made and made[0].schedule is not None and made[0].schedule.min_interval == 0.5
