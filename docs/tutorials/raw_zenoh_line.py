"""Your first world, from the wire contract alone: raw Zenoh and the protobuf classes.

No code of this project serves it: only `zenoh` (eclipse-zenoh) and the message classes protoc
generates from ``protocol/schemas/sme_v1.proto`` (here the copy the package ships,
``sensorimotor.protocol.sme_v1_pb2``; in another language, generate your own). It follows the
wire contract step by step: a spec and a truth queryable, a liveliness token, then the lockstep
loop (publish observation k, wait for the action that answers k, resend every 0.5 s).

A walker on a line of 11 cells senses 6 smooth bumps of its position; actions 0/1 move left/right;
reward 1 on reaching the middle cell. With ``sme agent`` running::

    python raw_zenoh_line.py            # serves world "line" until Ctrl-C
"""

from __future__ import annotations

import argparse
import json
import secrets
import signal
import threading
import time

import numpy as np
import zenoh

from sensorimotor.protocol import sme_v1_pb2 as pb

N = 11  # cells on a line; the goal is the middle one


class LineWorld:
    """A walker on a line of N cells that senses 6 smooth bumps of its position; actions 0/1 move
    left/right; reward 1 on reaching the middle cell. Served per the wire contract, in lockstep."""

    def __init__(self, endpoint: str, world_id: str, program: str) -> None:
        self.wid, self.program = world_id, program
        self.session_id = secrets.token_hex(4)
        conf = zenoh.Config()
        conf.insert_json5("mode", '"client"')
        conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
        conf.insert_json5("scouting/multicast/enabled", "false")
        deadline = time.monotonic() + 30
        while True:  # a client cannot open while the agent's router is down: retry (the wire contract)
            try:
                self.z = zenoh.open(conf)
                break
            except zenoh.ZError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)
        self.actions: dict[int, pb.Action] = {}
        self.cv = threading.Condition()
        self.stop = threading.Event()
        self.rng = np.random.default_rng(0)

    def spec(self) -> bytes:
        s = pb.WorldSpec(
            schema_version=1,
            world_id=self.wid,
            kind="line",
            program=self.program,
            n_starts=N,
            reward_min=0.0,
            reward_max=1.0,
            session=self.session_id,
        )
        s.sensors.add(name="bumps", dtype="float32", shape=[6], low=0.0, high=1.0)
        s.action_space.discrete_n = 2
        return s.SerializeToString()

    def truth(self) -> bytes:
        t = pb.Truth(schema_version=1, world_id=self.wid, kind="start_states")
        pos = np.arange(N, dtype="<f8").reshape(N, 1)
        t.tensors.add(name="positions", dtype="float64", shape=[N, 1], data=pos.tobytes())
        return t.SerializeToString()

    def obs(self, step: int, episode: int, t: int, x: int, reward: float, done: bool, start: int) -> bytes:
        bumps = np.exp(-0.5 * ((x - np.linspace(0, N - 1, 6)) / 2.0) ** 2).astype("<f4")
        o = pb.Observation(
            schema_version=1,
            world_id=self.wid,
            episode=episode,
            step=step,
            t=t,
            timestamp=time.time(),
            reward=reward,
            done=done,
            start=start,
            session=self.session_id,
        )
        o.tensors.add(name="bumps", dtype="float32", shape=[6], data=bumps.tobytes())
        return o.SerializeToString()

    def on_action(self, sample: zenoh.Sample) -> None:
        a = pb.Action()
        a.ParseFromString(sample.payload.to_bytes())
        with self.cv:
            self.actions[a.step] = a
            self.cv.notify_all()

    def run(self) -> None:
        base = f"sme/v1/world/{self.wid}"
        spec, truth = self.spec(), self.truth()
        qs = [
            self.z.declare_queryable(f"{base}/spec", lambda q: q.reply(q.key_expr, spec)),
            self.z.declare_queryable(f"{base}/truth", lambda q: q.reply(q.key_expr, truth)),
        ]
        sub = self.z.declare_subscriber(f"{base}/act", self.on_action)
        pub = self.z.declare_publisher(f"{base}/obs")
        token = self.z.liveliness().declare_token(f"sme/v1/alive/world/{self.wid}")
        step, episode, t, start = 0, 0, 0, -1
        x = int(self.rng.integers(N))
        reward, done = 0.0, x == N // 2
        while not self.stop.is_set():
            data = self.obs(step, episode, t, x, reward, done, start)
            pub.put(data)
            with self.cv:  # wait for the answer to this step, resending every 0.5 s
                while step not in self.actions and not self.stop.is_set():
                    if not self.cv.wait(0.5):
                        pub.put(data)
                act = self.actions.pop(step, None)
            if act is None:
                break
            if done or act.reset:
                start = act.start if 0 <= act.start < N else -1
                x = start if start >= 0 else int(self.rng.integers(N))
                episode, t, reward, done = episode + 1, 0, 0.0, x == N // 2
            else:
                x = min(max(x + (1 if int(act.values[0]) == 1 else -1), 0), N - 1)
                t += 1
                reward = 1.0 if x == N // 2 else 0.0
                done = reward > 0 or t >= 30
            step += 1
        token.undeclare()
        sub.undeclare()
        for q in qs:
            q.undeclare()

    def close(self) -> None:
        self.stop.set()
        with self.cv:
            self.cv.notify_all()


def main() -> None:
    p = argparse.ArgumentParser(description="a line world over raw zenoh")
    p.add_argument("--connect", default="tcp/127.0.0.1:7447", help="the agent's router (default: sme agent's)")
    p.add_argument("--id", default="line", help="world id on the bus")
    args = p.parse_args()
    world = LineWorld(args.connect, args.id, "generic")
    signal.signal(signal.SIGINT, lambda *a: world.close())
    signal.signal(signal.SIGTERM, lambda *a: world.close())
    try:
        world.run()
    finally:
        world.z.close()  # a zenoh session with callbacks keeps the interpreter alive until closed


if __name__ == "__main__":
    main()
