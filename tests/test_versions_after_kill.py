"""Embedding versions never go back or repeat, kill -9 included: twelve `kill -9` restarts of an
agent with --state-dir (checkpoints every 30 s, so each restart resumes from an older state), and no
version number of the world is published twice."""

from __future__ import annotations

import signal
import subprocess
import threading
from collections import Counter

import pytest
from conftest import wait_for

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import Embedding


@pytest.mark.integration
def test_twelve_kill_9_restarts_never_reuse_a_version(procs, endpoint, tmp_path) -> None:
    seen: Counter[int] = Counter()
    lock = threading.Lock()

    def on_embedding(msg) -> None:
        v = codec.decode(Embedding, msg.payload).version
        with lock:
            seen[v] += 1

    state = str(tmp_path / "state")
    agent_args = ("agent", "--mode", "client", "--connect", endpoint, "--workers", "1", "--state-dir", state, "-q")
    fast = ("--program-param", "gridworld.samples_per_iteration=100")
    # the test is the router, so that it hears every agent incarnation
    with Bus(BusConfig(mode="router", connect=(), listen=(endpoint,))) as bus:
        bus.subscribe(keys.agent_embedding("a0", "g1"), on_embedding)
        procs.start("world", "gridworld", "--id", "g1", "--connect", endpoint, "-q", stdout=subprocess.DEVNULL)
        for _ in range(12):
            with lock:
                top = max(seen, default=0)
            agent = procs.start(*agent_args, *fast, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            assert wait_for(lambda top=top: max(seen, default=0) >= top + 2, 60), "no new embedding"
            agent.send_signal(signal.SIGKILL)
            agent.wait(10)
    with lock:
        twice = {v: n for v, n in seen.items() if n > 1}
        assert not twice, f"versions published more than once: {twice}"
        assert len(seen) >= 24
