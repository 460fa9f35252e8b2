"""Over real zenoh on loopback: separate processes, free ports, no multicast."""

from __future__ import annotations

import json
import signal
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import (
    AgentEvent,
    AgentStatus,
    Control,
    EventKind,
    Observation,
    WorldEventKind,
)
from tests.conftest import Lines, wait_for
from tests.conftest import agent_status as status
from tests.conftest import world_link as link

pytestmark = pytest.mark.integration


def read_json_lines(proc, n, timeout):
    out, end = [], time.monotonic() + timeout
    while len(out) < n and time.monotonic() < end:
        line = proc.stdout.readline()
        if not line:
            if proc.poll() is not None:
                break
            continue
        out.append(json.loads(line))
    return out


def test_three_shells_embeddings_arrive_and_improve_and_world_restart_resumes(procs, endpoint):
    agent = procs.start("agent", "--listen", endpoint, "-q")
    world = procs.start("world", "gridworld", "--id", "g1", "--connect", endpoint, "-q")
    watch = procs.start("watch", "--json", "--no-events", "--count", "9", "--timeout", "90", "--connect", endpoint)
    rows = read_json_lines(watch, 9, 100)
    assert len(rows) == 9, rows
    for r in rows:
        assert {"world", "version", "trigger", "n_points", "dims", "eigenvalues", "procrustes_error"} <= set(r)
        assert r["world"] == "g1" and r["n_points"] == 81 and r["dims"] == 2
    assert [r["version"] for r in rows] == list(range(1, 10))
    errs = [r["procrustes_error"] for r in rows]
    assert errs[0] > 0.5 and min(errs[-2:]) < 0.05, errs

    # kill the world: the link pauses; start it again: the daemon re-attaches and carries on
    before = link(wait_for(lambda: status(endpoint)), "g1")
    world.kill()
    world.wait()
    assert wait_for(lambda: (ln := link(status(endpoint), "g1")) is not None and ln.state == "paused", 15)
    world2 = procs.start("world", "gridworld", "--id", "g1", "--connect", endpoint, "-q")
    after = wait_for(
        lambda: (
            (ln := link(status(endpoint), "g1")) is not None
            and ln.state == "attached"
            and ln.steps > before.steps + 500
            and ln
        ),
        30,
    )
    assert after and after.embedding_version >= before.embedding_version
    # the learned policy survived: the next embedding is already good
    watch2 = procs.start("watch", "--json", "--no-events", "--count", "1", "--timeout", "60", "--connect", endpoint)
    nxt = read_json_lines(watch2, 1, 70)
    assert nxt and nxt[0]["version"] > before.embedding_version and nxt[0]["procrustes_error"] < 0.05
    assert procs.stop(world2) == 0
    assert procs.stop(agent) == 0  # clean stop on SIGINT


def test_bad_input_is_counted_answered_and_harmless(procs, endpoint):
    agent = procs.start("agent", "--listen", endpoint, "-q")
    procs.start("world", "gridworld", "--id", "g2", "--connect", endpoint, "-q")
    assert wait_for(lambda: (ln := link(status(endpoint), "g2")) is not None and ln.steps > 200, 30)
    events: list[AgentEvent] = []
    with Bus(BusConfig.for_role("world", endpoint)) as bus:
        bus.subscribe(keys.agent_event("a0", "g2"), lambda m: events.append(codec.decode(AgentEvent, m.payload)))
        # a round trip through the router on this session: the router has taken the subscription
        # (declared before the query on the same link) when the reply comes back
        assert bus.get(keys.agent_status("a0"), timeout=10.0)
        key = keys.world_obs("g2")
        good = Observation("g2", 0, 10**9, 0, {"state": np.array([1], np.int32)}, 0.0, False, -1, 0.0, "x")
        wrong_shape = Observation("g2", 0, 10**9, 0, {"state": np.array([1, 2], np.int32)}, 0.0, False)
        p = pb.Observation(schema_version=1, world_id="g2", step=5, reward=float("nan"))
        nan_reward = p.SerializeToString()
        p = pb.Observation(schema_version=1, world_id="g2", step=5)
        p.tensors.add(name="state", dtype="int32", shape=[1 << 20, 1 << 20], data=b"")
        oversize = p.SerializeToString()
        p = pb.Observation(schema_version=99, world_id="g2", step=5)
        unknown = p.SerializeToString()

        def rejected() -> int:
            return sum(e.kind == "bad_input" for e in list(events))

        for i, payload in enumerate((b"\x07garbage\xff", codec.encode(wrong_shape), nan_reward, oversize, unknown)):
            bus.put(key, payload, "sme.v1.Observation")
            # one at a time: each its own event
            assert wait_for(lambda: rejected() >= i + 1, 30), (i, events)  # noqa: B023 (called at once)
        assert codec.encode(good)  # a valid message still encodes fine
    kinds = {e.reason for e in events if e.kind == "bad_input"}
    assert kinds == {"malformed", "spec_mismatch", "non_finite", "oversize", "unknown_version"}, events
    st = status(endpoint)
    ln = link(st, "g2")
    assert ln.rejected == {"malformed": 1, "spec_mismatch": 1, "non_finite": 1, "oversize": 1, "unknown_version": 1}
    steps = ln.steps
    assert wait_for(lambda: link(status(endpoint), "g2").steps > steps + 200, 20)  # still learning
    # the world reports a control it cannot apply; the agent passes it on, and garbage on the
    # world's event key is counted, not fatal
    with Bus(BusConfig.for_role("tool", endpoint)) as bus:
        bus.subscribe(keys.agent_event("a0", "g2"), lambda m: events.append(codec.decode(AgentEvent, m.payload)))
        time.sleep(0.5)
        bus.put(keys.world_ctl("g2"), codec.encode(Control("g2", "nosuch")), codec.schema_name(Control))
        bus.put(keys.world_event("g2"), b"\x07garbage", "sme.v1.WorldEvent")
        assert wait_for(
            lambda: any(e.kind == EventKind.WORLD_EVENT and e.reason == WorldEventKind.CONTROL_REFUSED for e in events),
            20,
        ), events
    assert wait_for(lambda: (status(endpoint) or AgentStatus("", 0)).counters.get("bad_world_event") == 1, 10)
    assert agent.poll() is None


def test_status_and_watch_fail_clearly_without_agent(procs, endpoint):
    st = procs.start("status", "--connect", endpoint)
    st.wait(20)
    err = st.stderr.read()
    # what to do, and no zenoh internals (its Rust source paths)
    assert st.returncode == 2 and f"no agent at {endpoint}" in err and "Start one with `sme agent`" in err, err
    assert ".rs:" not in err and ".cargo" not in err, err
    w = procs.start("watch", "--count", "1", "--timeout", "1", "--connect", endpoint)
    w.wait(20)
    assert w.returncode == 2 and "Start one with `sme agent`" in w.stderr.read()


def test_world_waits_for_agent_and_stops_on_sigterm(procs, endpoint):
    world = procs.start("world", "gridworld", "--id", "g3", "--connect", endpoint, "-q")
    err = Lines(world.stderr)
    assert wait_for(lambda: err.has("waiting for the agent") or world.poll() is not None, 60), err.lines
    assert world.poll() is None  # it is in its retry loop, no crash
    agent = procs.start("agent", "--listen", endpoint, "-q")
    assert wait_for(lambda: (ln := link(status(endpoint), "g3")) is not None and ln.steps > 100, 30)
    assert procs.stop(world, signal.SIGTERM) == 0
    assert procs.stop(agent, signal.SIGTERM) == 0


def test_daemon_checkpoint_resumes_after_kill(procs, endpoint, tmp_path):
    state = str(tmp_path / "state")
    agent = procs.start("agent", "--listen", endpoint, "--state-dir", state, "--checkpoint-every", "1", "-q")
    procs.start("world", "gridworld", "--id", "g4", "--connect", endpoint, "-q")
    assert wait_for(lambda: (ln := link(status(endpoint), "g4")) is not None and ln.embedding_version >= 9, 60)
    # a checkpoint written after that (so it holds version >= 9), then the kill
    seen = time.time_ns()
    assert wait_for(
        lambda: any(
            f.is_file() and not f.name.endswith(".tmp") and f.stat().st_mtime_ns > seen for f in Path(state).iterdir()
        ),
        60,
    )
    agent.kill()
    agent.wait()
    procs.start("agent", "--listen", endpoint, "--state-dir", state, "-q")
    restored = wait_for(lambda: link(status(endpoint), "g4"), 30)
    assert restored.embedding_version >= 9  # numbering carries on from the checkpoint
    ln = wait_for(
        lambda: (
            (ln := link(status(endpoint), "g4")) is not None
            and ln.embedding_version > restored.embedding_version
            and ln
        ),
        60,
    )
    assert ln and ln.last_procrustes_error < 0.05  # the first embedding after the restart is already good


def test_retina_reversal_live_detected_relearned_and_reembedded(procs, endpoint):
    """As a user would: agent, retina world, watch; `sme perturb reverse` mid-run; the agent notices
    by itself, relearns and publishes an embedding whose trigger says why."""
    procs.start("agent", "--listen", endpoint, "-q", "--program-param", "retina.embed_every=500")
    procs.start("world", "retina", "--id", "r1", "--param", "supersample=1", "--connect", endpoint, "-q")
    watch = procs.start("watch", "--json", "--timeout", "170", "--connect", endpoint)
    rows: list[dict] = []

    def follow():
        for line in watch.stdout:
            rows.append(json.loads(line))

    threading.Thread(target=follow, daemon=True).start()
    # learn for 2000 saccades (4 periodic embeddings), then reverse the up/down motor commands
    assert wait_for(lambda: sum(r.get("type") == "embedding" for r in rows) >= 4, 90), rows
    pert = procs.start("perturb", "reverse", "--world", "r1", "--connect", endpoint)
    assert pert.wait(20) == 0
    # the world's own report of the change carries the world step it was applied at
    assert wait_for(lambda: any(r.get("mark") == "change" for r in rows), 20), rows
    t_rev = next(r["step"] for r in rows if r.get("mark") == "change")
    assert wait_for(lambda: any(r.get("trigger") == "relearned" for r in rows), 120), [
        (r.get("kind"), r.get("trigger")) for r in rows
    ]
    drops = [r for r in rows if r.get("kind") == "drop_detected"]
    assert t_rev > 0 and len(drops) == 1 and drops[0]["step"] > t_rev
    assert drops[0]["step"] - t_rev <= 2 * 300  # within 300 saccades of the reversal: 2 steps per saccade
    relearned = next(r for r in rows if r.get("trigger") == "relearned")
    assert relearned["step"] > drops[0]["step"] and relearned["n_points"] > 3000
    kinds = [r.get("kind") for r in rows if r.get("type") == "event"]
    assert kinds.index("drop_detected") < kinds.index("relearning") < kinds.index("relearned")
