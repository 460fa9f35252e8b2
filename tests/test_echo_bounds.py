"""Say only what happened, bound what is echoed: events and logs clip what they copy from their
input, workers get every bus option of their agent, bad arguments are usage errors (exit 2)."""

from __future__ import annotations

import subprocess
import sys

from sensorimotor.protocol import codec
from sensorimotor.protocol.messages import MAX_ECHO, AgentEvent, WorldEvent, clip
from sensorimotor.tools.agent_cmd import _worker_argv
from sensorimotor.tools.cli import build_parser


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
