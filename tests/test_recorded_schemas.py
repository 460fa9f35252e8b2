"""Every recorded channel is self-describing: shared checkpoints travel as `sme.v1.Checkpoint`, so an
MCAP of a two-agent session has a protobuf schema on every channel (read with the `mcap` reader)."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest
from conftest import Lines, wait_for

from sensorimotor.agent.checkpoint import FORMAT_VERSION, decode_checkpoint
from sensorimotor.protocol import codec
from sensorimotor.protocol.errors import OversizeMessage
from sensorimotor.protocol.messages import SharedCheckpoint
from sensorimotor.tools.common import free_port


def test_shared_checkpoint_round_trips_and_is_bounded() -> None:
    msg = SharedCheckpoint(
        "g1", b"PK\x03\x04data", owner="a.w1", epoch=3, format_version=1, embedding_version=7, saved_at=5.5
    )
    assert codec.decode(SharedCheckpoint, codec.encode(msg)) == msg
    assert codec.schema_name(SharedCheckpoint) == "sme.v1.Checkpoint"
    with pytest.raises(OversizeMessage):
        codec.encode(SharedCheckpoint("g1", bytes(codec.MAX_TENSOR_BYTES + 1)))


@pytest.mark.integration
def test_an_mcap_of_two_agents_has_a_schema_on_every_channel(procs, tmp_path) -> None:
    from mcap.reader import make_reader

    e1, e2 = f"tcp/127.0.0.1:{free_port()}", f"tcp/127.0.0.1:{free_port()}"
    fast = ("--workers", "1", "--checkpoint-every", "1", "-q")
    path = tmp_path / "two.mcap"
    procs.start("agent", "--id", "a", "--listen", e1, *fast, stdout=subprocess.DEVNULL)
    procs.start("agent", "--id", "b", "--listen", e2, "--connect", e1, *fast, stdout=subprocess.DEVNULL)
    rec = procs.start("record", str(path), "--connect", e1, stdout=subprocess.DEVNULL)
    rec_err = Lines(rec.stderr)
    assert wait_for(lambda: rec_err.has("sme record: recording"), 60)
    for w in ("g1", "g2"):
        procs.start("world", "gridworld", "--id", w, "--connect", e1, "--connect", e2, "-q", stdout=subprocess.DEVNULL)

    def recorded_a_while() -> bool:  # a progress line every 5 s; the agents share every 1 s
        return len([ln for ln in rec_err.lines if "messages written" in ln]) >= 2

    assert wait_for(recorded_a_while, 60)
    assert procs.stop(rec) == 0
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        channels = summary.channels
        schemas = summary.schemas
        topics = {c.topic: c.schema_id for c in channels.values()}
        assert any("/checkpoint/" in t for t in topics), sorted(topics)
        bare = sorted(t for t, sid in topics.items() if sid == 0 or sid not in schemas)
        assert not bare, f"channels without a schema: {bare}"
        assert {schemas[sid].name for t, sid in topics.items() if "/checkpoint/" in t} == {"sme.v1.Checkpoint"}
        f.seek(0)
        checkpoints = [m for _, c, m in make_reader(f).iter_messages() if "/checkpoint/" in c.topic]
    shared = codec.decode(SharedCheckpoint, checkpoints[-1].data)
    assert shared.owner in ("a", "b") and shared.format_version == FORMAT_VERSION and shared.saved_at > 0
    inner = decode_checkpoint(shared.data)
    assert inner.world_id == shared.world_id and np.isfinite(inner.saved_at)
