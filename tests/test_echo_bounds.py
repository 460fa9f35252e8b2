"""Say only what happened, bound what is echoed: events and logs clip what they copy from their
input, workers get every bus option of their agent, bad arguments are usage errors (exit 2)."""

from __future__ import annotations

import subprocess
import sys

from sensorimotor.protocol import codec
from sensorimotor.protocol.messages import MAX_ECHO, AgentEvent, WorldEvent, clip
from sensorimotor.tools.cli import build_parser
from sensorimotor.tools.commands.agent import _worker_argv


def test_clip_keeps_short_text_and_cuts_long_text() -> None:
    assert clip("short") == "short"
    cut = clip("x" * 1_000_000)
    assert cut.startswith("x" * MAX_ECHO) and len(cut) < MAX_ECHO + 100 and "999000 more characters" in cut


def test_events_do_not_carry_a_megabyte_of_their_input() -> None:
    big = "p" * (1 << 20)  # e.g. a refused control with 1 MB of params: the error message quotes them
    ev = codec.encode(WorldEvent("w1", "control_refused", big, f"bad params {big}"))
    ag = codec.encode(AgentEvent("a0", "w1", "bad_input", f"refused {big}", 0, 1.0, reason=big))
    assert len(ev) < 2 * MAX_ECHO and len(ag) < 2 * MAX_ECHO
    assert codec.decode(WorldEvent, ev).detail.startswith("bad params ppp")


def test_workers_inherit_the_bus_options_of_their_agent(tmp_path) -> None:
    cfg = tmp_path / "zenoh.json5"
    cfg.write_text("{}")
    args = build_parser().parse_args(["agent", "--config", str(cfg), "--secure", str(tmp_path)])
    argv = _worker_argv(args, 1, "tcp/127.0.0.1:7447")
    assert argv[argv.index("--config") + 1] == str(cfg)
    assert argv[argv.index("--secure") + 1] == str(tmp_path)
    assert argv[argv.index("--connect") + 1] == "tcp/127.0.0.1:7447" and "client" in argv


def test_an_invalid_record_key_expression_is_a_usage_error(tmp_path) -> None:
    p = subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", "record", str(tmp_path / "x.mcap"), "--keys", "a//b"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert p.returncode == 2 and "Traceback" not in p.stderr and "--keys" in p.stderr


def test_a_refused_control_of_a_megabyte_gives_a_bounded_event_and_log(caplog) -> None:
    from sensorimotor.protocol.messages import Control
    from sensorimotor.worlds.node import WorldNode
    from sensorimotor.worlds.registry import make_world

    class Bus:
        puts: list[bytes] = []

        def put(self, key: str, payload: bytes, schema: str | None = None) -> None:  # noqa: ARG002
            self.puts.append(payload)

    bus = Bus()
    node = WorldNode(make_world("rovingeye", seed=0), bus)  # type: ignore[arg-type]
    big = "p" * (1 << 20)  # the world's error quotes the bad value: a megabyte, unclipped
    node._controls.append(Control(node.world_id, "gain", {"gain": big}, id=7))
    with caplog.at_level("INFO"):
        node._apply_controls(1)
    events = [codec.decode(WorldEvent, p) for p in bus.puts]
    assert [e.kind for e in events] == ["control_refused"] and events[0].control_id == 7
    assert "gain='ppp" in events[0].detail and "(1048576 characters)" in events[0].detail
    assert all(len(p) < 2 * MAX_ECHO for p in bus.puts)
    assert caplog.records and all(len(r.getMessage()) < 2 * MAX_ECHO for r in caplog.records)


def test_a_release_says_checkpointed_only_when_the_file_is_there(tmp_path, caplog) -> None:
    """A world handed to another owner just before it vanished is not checkpointed here (its state
    is the new owner's): the release must not say "checkpointed to" a file that does not exist."""
    import time

    from sensorimotor.agent.attach import attach
    from sensorimotor.agent.daemon import AgentDaemon
    from sensorimotor.worlds.bench import BenchWorld

    class Bus:
        closed = False

        def publisher(self, key: str, schema: str | None = None) -> object:  # noqa: ARG002
            return type("P", (), {"put": lambda self, data: None, "_pub": None})()

        def undeclare(self, entity: object) -> None:
            pass

    d = AgentDaemon(Bus(), state_dir=str(tmp_path), link_ttl=5.0)  # type: ignore[arg-type]
    spec = BenchWorld("b1", params=None, obs_bytes=16).spec()
    d.links["b1"] = attach(spec, d.config, d.publish).link
    d._elsewhere.add("b1")  # another owner answered it since
    d._detach("b1")
    with caplog.at_level("INFO", logger="sme.agent"):
        assert d.release_expired(now=time.monotonic() + 6) == ["b1"]
    assert not (tmp_path / "b1.ckpt.npz").exists()
    assert "checkpointed to" not in caplog.text and "not checkpointed here" in caplog.text
