"""Test helper process for tests/test_churn.py: many light worlds from one process.

`churn`: N gridworlds, `--batch` at a time, each a WorldNode on its own client session (closing the
session is how a world vanishes: its liveliness token goes with it), `--steps` lockstep steps each.
`flood`: one gridworld whose observations are published as fast as the process can, for distinct
steps, without waiting for the agent's answers.

Run from the repository root: `python -m tests.churn_helper churn --connect tcp/127.0.0.1:PORT`.
"""

from __future__ import annotations

import argparse
import threading
import time
from dataclasses import replace

import numpy as np

from sensorimotor.protocol import codec, keys
from sensorimotor.protocol import sme_v1_pb2 as pb
from sensorimotor.protocol.bus import Bus, BusConfig
from sensorimotor.protocol.messages import Action, Observation, WorldSpec
from sensorimotor.worlds.gridworld import GridWorld
from sensorimotor.worlds.lockstep import Lockstep
from sensorimotor.worlds.node import WorldNode


def serve_one(endpoint: str, wid: str, steps: int) -> int:
    """Serve gridworld `wid` for `steps` lockstep steps on its own session, then vanish."""
    with Bus(BusConfig.for_role("world", endpoint), wait_limit=20) as bus:
        node = WorldNode(GridWorld(wid, seed=0), bus, wid, max_steps=steps, seconds=30.0, image_every=0)
        return node.run().steps


def churn(endpoint: str, n: int, batch: int, steps: int, prefix: str) -> None:
    """Worlds prefix0 .. prefix{n-1}, `batch` at a time; prints one line per batch."""
    for b0 in range(0, n, batch):
        done: list[int] = []
        threads = [
            threading.Thread(target=lambda i=i, done=done: done.append(serve_one(endpoint, f"{prefix}{i}", steps)))
            for i in range(b0, min(n, b0 + batch))
        ]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        print(f"batch {b0 // batch} done: steps {done}", flush=True)
    print("churn done", flush=True)


def flood(endpoint: str, wid: str, seconds: float, messages: int) -> None:
    """Publish distinct observation steps of gridworld `wid` without waiting for answers: for
    `seconds`, or until `messages` were sent (the same flood on a fast machine as on a slow one)."""
    world = GridWorld(wid, seed=0)
    session = "flood"
    spec = codec.encode(replace(world.spec(), world_id=wid, session=session))
    answered = [0]
    last_answer = [-1]

    def on_action(msg) -> None:  # noqa: ANN001 - a BusMessage
        answered[0] += 1
        last_answer[0] = codec.decode(Action, msg.payload).step

    with Bus(BusConfig.for_role("world", endpoint), wait_limit=20) as bus:
        bus.queryable(keys.world_spec(wid), lambda k, p: spec, codec.schema_name(WorldSpec))
        bus.subscribe(keys.world_act(wid), on_action)
        pub = bus.publisher(keys.world_obs(wid), codec.schema_name(Observation), block=False)
        bus.token(keys.alive_world(wid))
        time.sleep(1.0)  # let the agent attach
        # a cycle of valid observations, re-stamped with a new step each time: cheap enough to publish
        # many times faster than the agent answers
        lock = Lockstep(world, wid, session)
        rng = np.random.default_rng(0)
        cycle = []
        for _ in range(1000):
            p = pb.Observation()
            p.ParseFromString(codec.encode(lock.observation(time.time())))
            cycle.append(p)
            lock.advance(Action(wid, lock.step, (float(rng.integers(4)),)))
        sent, t0 = 0, time.monotonic()
        while time.monotonic() - t0 < seconds and sent < messages:
            p = cycle[sent % len(cycle)]
            p.step = sent
            pub.put(p.SerializeToString())
            sent += 1
        took = time.monotonic() - t0
        # then behave: publish the newest step and wait for its answer (resending, as a lockstep world
        # does), so the agent sees how far the world got and counts the steps it never answered
        p = cycle[sent % len(cycle)]
        p.step = sent
        data = p.SerializeToString()
        end = time.monotonic() + 90  # the agent first answers the backlog zenoh holds (slow under load)
        while last_answer[0] != sent and time.monotonic() < end:
            pub.put(data)
            time.sleep(0.5)
        sent += 1
        print(f"flood sent {sent} in {took:.1f} s, answered {answered[0]}, last answer {last_answer[0]}", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("mode", choices=["churn", "flood"])
    p.add_argument("--connect", required=True)
    p.add_argument("--n", type=int, default=100)
    p.add_argument("--batch", type=int, default=10)
    p.add_argument("--steps", type=int, default=50)
    p.add_argument("--prefix", default="c")
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--messages", type=int, default=4_000_000)
    a = p.parse_args()
    if a.mode == "churn":
        churn(a.connect, a.n, a.batch, a.steps, a.prefix)
    else:
        flood(a.connect, f"{a.prefix}flood", a.seconds, a.messages)


if __name__ == "__main__":
    main()
