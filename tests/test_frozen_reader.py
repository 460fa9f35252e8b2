"""No reader can stop a world: a `sme record` frozen with SIGSTOP for 20 s beside a full-speed
lockstep `bench` world (default size) leaves the world at >= 80 % of its step rate, and the
recorder, once resumed, reports the observation steps it lost.

The freeze costs a bounded stall (the socket buffers fill, then the agent's router waits
`BLOCKED_LINK_CLOSE_US` before it closes the link): about 2 s on a loaded 2-core machine. The
window is long enough that the test measures that bound, not the load: over 10 s the same stall
read as 0.72-0.79 of the rate before."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time

import pytest
from conftest import Lines, wait_for

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig, BusError
from sensorimotor.protocol.messages import AgentStatus
from sensorimotor.tools.commands.record import observation_step
from sensorimotor.tools.mcap_io import read

pytestmark = pytest.mark.skipif(not hasattr(signal, "SIGSTOP"), reason="needs SIGSTOP")


def _steps(bus: Bus) -> int | None:
    """The bench link's step count from the agent's status (a query lost on a busy machine is retried)."""
    for _ in range(3):
        try:
            r = bus.get(keys.agent_status("a0"), timeout=3.0)
        except BusError:
            continue
        if r:
            st = codec.decode(AgentStatus, r[0].payload)
            return next((ln.steps for ln in st.links if ln.world_id == "bench"), None)
    return None


def _rate(bus: Bus, seconds: float) -> float:
    """The bench world's steps per second over `seconds` (from the agent's status)."""
    a, t0 = _steps(bus), time.perf_counter()
    time.sleep(seconds)
    b, t1 = _steps(bus), time.perf_counter()
    assert a is not None and b is not None, "the bench link vanished from the agent's status"
    return (b - a) / (t1 - t0)


def test_observation_step_is_read_without_decoding() -> None:
    import numpy as np

    from sensorimotor.protocol.messages import Observation

    data = codec.encode(Observation("w1", 7, 2**40 + 3, 0, {"x": np.zeros(4, np.float32)}, 0.5))
    assert observation_step(data) == 2**40 + 3
    assert observation_step(data, "w1") == 2**40 + 3
    assert observation_step(data, "w2") is None  # another world's: not counted
    first = codec.encode(Observation("w1", 0, 0, 0, {"x": np.zeros(4, np.float32)}, 0.0))
    assert observation_step(first, "w1") == 0  # proto3 leaves step 0 out
    assert observation_step(b"\xff\xff") is None  # not an observation: not counted
    assert observation_step(b"") is None


@pytest.mark.integration
@pytest.mark.alone
def test_a_frozen_recorder_does_not_slow_the_world(procs, endpoint, tmp_path) -> None:
    agent = procs.start("agent", "--listen", endpoint, "--workers", "1", "-q", stdout=subprocess.DEVNULL)
    world = procs.start("world", "bench", "--connect", endpoint, "-q", stdout=subprocess.DEVNULL)
    rec = procs.start("record", str(tmp_path / "r.mcap"), "--connect", endpoint, stdout=subprocess.DEVNULL)
    rec_err = Lines(rec.stderr)
    try:
        with Bus(BusConfig(mode="client", connect=(endpoint,), retry=True), wait_limit=60) as bus:
            assert wait_for(lambda: (_steps(bus) or 0) > 2000, 60), "the bench world did not run"
            assert wait_for(lambda: rec_err.has("recording"), 20)
            before = _rate(bus, 4.0)
            os.kill(rec.pid, signal.SIGSTOP)
            try:
                during = _rate(bus, 20.0)
            finally:
                os.kill(rec.pid, signal.SIGCONT)
            time.sleep(2.0)  # the recorder takes messages again and sees the gap
            after = _rate(bus, 2.0)
    finally:
        procs.stop(rec)
    assert agent.poll() is None and world.poll() is None
    assert during >= 0.8 * before, f"frozen recorder: {during:.0f} steps/s against {before:.0f} before"
    assert after > 0.5 * before
    summary = "".join(rec_err.lines)
    m = re.search(r"lost (\d+) observation steps", summary)
    assert m, summary[-2000:]
    # what it reports lost is exactly what is missing from the file: the gaps in the world's steps
    steps = [
        observation_step(r.data, "bench") for r in read(str(tmp_path / "r.mcap")) if r.topic == keys.world_obs("bench")
    ]
    gaps = sum(b - a - 1 for a, b in zip(steps, steps[1:], strict=False) if b > a + 1)
    assert int(m.group(1)) == gaps
