"""The world node steps its world where the answer arrives (the action subscriber's thread): each
answer moves it exactly one step, stale and duplicate answers are ignored, an unanswered
observation is resent, and a world that fails stops the node with its error on the caller's thread."""

from __future__ import annotations

import os
import threading
import time

import numpy as np

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import Action, Observation
from sensorimotor.worlds.bench import BenchWorld
from sensorimotor.worlds.node import WorldNode


class _Breaks(BenchWorld):
    def step(self, action: np.ndarray):
        if self.t >= 2:
            raise RuntimeError("simulator crashed")
        return super().step(action)


def _serve(world, endpoint: str, **kw):
    """Run a WorldNode on a router session in a thread; an 'agent' client session answers."""
    out: dict = {}
    ready = threading.Event()

    def run() -> None:
        with Bus(BusConfig.for_role("agent", endpoint)) as bus:
            node = WorldNode(world, bus, "w", image_every=0, **kw)
            out["node"] = node
            ready.set()
            try:
                out["stats"] = node.run()
            except Exception as e:  # noqa: BLE001 - the test inspects it
                out["error"] = e

    t = threading.Thread(target=run, daemon=True)
    t.start()
    assert ready.wait(30)
    return t, out


def node_resends(out: dict) -> int:
    node = out.get("node")
    return node.stats.resends if node is not None else 0


def test_each_answer_moves_one_step_and_stale_answers_are_ignored(endpoint):
    t, out = _serve(BenchWorld(obs_bytes=16), endpoint, resend=0.2)
    seen: list[int] = []
    got = threading.Event()
    with Bus(BusConfig.for_role("world", endpoint)) as bus:
        pub = bus.publisher(keys.world_act("w"), codec.schema_name(Action))

        def on_obs(m):
            seen.append(codec.decode(Observation, m.payload).step)
            got.set()

        bus.subscribe(keys.world_obs("w"), on_obs)
        assert got.wait(10)  # observation 0, or its resend (it was published before we subscribed)
        end = time.monotonic() + 10  # unanswered, it is resent (every 0.2 s): wait for one resend
        while node_resends(out) < 1 and time.monotonic() < end:
            time.sleep(0.02)
        for step in range(5):
            got.clear()
            pub.put(codec.encode(Action("w", step, (0.0,))))
            pub.put(codec.encode(Action("w", step, (0.0,))))  # a duplicate: ignored
            pub.put(codec.encode(Action("w", step + 7, (0.0,))))  # not the awaited step: ignored
            assert got.wait(10)
        node = out["node"]
        end = time.monotonic() + 10
        while node.stats.actions_received < 15 and time.monotonic() < end:
            time.sleep(0.05)
        node.stop()
        t.join(10)
    st = out["stats"]
    assert "error" not in out and st.steps == 5
    assert st.actions_received == 15 and st.actions_ignored == 10
    assert [s for s in seen if s > 0] == [1, 2, 3, 4, 5]  # each answered step published once
    assert st.resends >= 1 and min(seen) == 0


def test_a_failing_world_stops_the_node_with_its_error(endpoint):
    t, out = _serve(_Breaks(obs_bytes=16), endpoint, resend=0.2)
    with Bus(BusConfig.for_role("world", endpoint)) as bus:
        pub = bus.publisher(keys.world_act("w"), codec.schema_name(Action))
        time.sleep(0.5)
        for step in range(3):
            pub.put(codec.encode(Action("w", step, (0.0,))))
            time.sleep(0.2)
        t.join(10)
    assert not t.is_alive()
    assert isinstance(out.get("error"), RuntimeError) and "simulator crashed" in str(out["error"])
    assert out["node"].stats.steps == 2


def test_stop_from_another_thread_ends_run_promptly(endpoint):
    t, out = _serve(BenchWorld(obs_bytes=16), endpoint, resend=30.0)
    time.sleep(0.5)
    t0 = time.monotonic()
    out["node"].stop()
    t.join(10)
    assert not t.is_alive() and time.monotonic() - t0 < 5.0
    assert out["stats"].steps == 0


def test_seconds_bounds_a_world_nobody_answers(endpoint):
    t, out = _serve(BenchWorld(obs_bytes=16), endpoint, resend=0.1, seconds=1.0)
    t.join(10)
    assert not t.is_alive() and out["stats"].steps == 0 and out["stats"].resends >= 5


def test_a_measured_node_reports_its_cpu_per_step(endpoint):
    t, out = _serve(BenchWorld(obs_bytes=64), endpoint, measure=True, warmup=10, max_steps=300)
    with Bus(BusConfig.for_role("world", endpoint)) as bus:
        pub = bus.publisher(keys.world_act("w"), codec.schema_name(Action))
        bus.subscribe(
            keys.world_obs("w"),
            lambda m: pub.put(codec.encode(Action("w", codec.decode(Observation, m.payload).step, (0.0,)))),
        )
        t.join(30)
    summary = out["stats"].summary()
    assert out["stats"].steps == 300 and summary["steady_steps_per_s"] > 0
    # process_time counts every thread of this process (the answering client too): > 0 and bounded
    assert 0 < summary["cpu_us_per_step"] < 1e5
    assert 0 < summary["cpu_cores"] <= (os.cpu_count() or 1) + 0.01
