"""The world link on its own: detection, relearning hooks, resends, stale and bad observations."""

import numpy as np

from sensorimotor.agent.detectors import CUSUM
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.base import Decision, Program
from sensorimotor.protocol import codec
from sensorimotor.protocol.messages import ActionSpace, Observation, SensorSpec, WorldSpec

SPEC = WorldSpec("w", "toy", (SensorSpec("x", "float32", (2,)),), ActionSpace(n=2), program="toy")


class Toy(Program):
    name = "toy"

    def __init__(self, spec, seed=0):
        super().__init__(spec, seed)
        self.seen, self.drops = [], []

    def act(self, obs):
        self.seen.append(obs.step)
        return Decision((0.0,))

    def performance(self, obs):
        return obs.reward

    def on_drop(self, step):
        self.drops.append(step)


def make():
    out = []
    prog = Toy(SPEC)
    link = WorldLink("a0", SPEC, prog, lambda ch, m: out.append((ch, m)), CUSUM())
    return link, prog, out


def obs(k, reward=0.0, x=(0.0, 0.0)):
    return Observation("w", 0, k, k, {"x": np.array(x, np.float32)}, reward)


def test_program_relearns_only_when_the_detector_fires():
    link, prog, out = make()
    rng = np.random.default_rng(0)
    rewards = np.r_[rng.normal(10, 1, 1000), rng.normal(6, 1, 200)]
    for k, r in enumerate(rewards):
        link.answer(obs(k, float(r)))
    assert len(prog.drops) == 1 and 1000 <= prog.drops[0] < 1020
    events = [m for ch, m in out if ch == "event"]
    assert [e.kind for e in events] == ["drop_detected"] and events[0].step == prog.drops[0]


def test_resend_is_answered_again_but_learned_once_and_stale_is_ignored():
    link, prog, out = make()
    link.handle(codec.encode(obs(0)))
    link.handle(codec.encode(obs(1)))
    link.handle(codec.encode(obs(1)))  # the world resent step 1
    link.handle(codec.encode(obs(0)))  # stale
    acts = [m for ch, m in out if ch == "act"]
    assert [a.step for a in acts] == [0, 1, 1] and prog.seen == [0, 1]
    assert link.counters.duplicates == 1 and link.counters.stale == 1


def test_bad_observations_are_counted_and_evented_and_learning_goes_on():
    link, prog, out = make()
    link.handle(b"\x00\xffnot protobuf")
    link.handle(codec.encode(Observation("w", 0, 5, 0, {"x": np.zeros(3, np.float32)})))  # wrong shape
    link.handle(codec.encode(Observation("other", 0, 6, 0, {"x": np.zeros(2, np.float32)})))  # wrong world
    link.handle(codec.encode(obs(7)))
    assert link.counters.rejected == {"malformed": 1, "spec_mismatch": 2}
    assert prog.seen == [7]
    kinds = [m.kind for ch, m in out if ch == "event"]
    assert kinds.count("bad_input") == 3


def test_a_failing_program_does_not_kill_the_link():
    link, prog, out = make()
    prog.act = lambda o: 1 / 0
    a = link.answer(obs(0))
    assert a.reset and any(m.kind == "program_error" for ch, m in out if ch == "event")
