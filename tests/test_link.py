"""The world link on its own: detection, relearning hooks, resends, stale and bad observations."""

import threading

import numpy as np

from sensorimotor.agent.detectors import CUSUM
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.base import Decision, EmbeddingOutput, EventOutput, Program
from sensorimotor.protocol import codec
from sensorimotor.protocol.messages import (
    ActionSpace,
    EventKind,
    Observation,
    SensorSpec,
    Trigger,
    Truth,
    WorldSpec,
)

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


class Mapper(Toy):
    """Emits an embedding of 400 points and then an event at act 1."""

    def act(self, obs):
        if obs.step == 1:
            rng = np.random.default_rng(0)
            self.emit(
                EmbeddingOutput(Trigger.POLICY_ITERATION, tuple(range(400)), rng.normal(size=(400, 2)), (1.0, 1.0), 1)
            )
            self.emit(EventOutput(EventKind.RELEARNED, "after the embedding", 1))
        return Decision((0.0,))


def test_outputs_in_background_are_published_off_the_act_path_in_order_and_flushed_by_stop():
    out = []
    link = WorldLink(
        "a0", SPEC, Mapper(SPEC), lambda ch, m: out.append((ch, m, threading.current_thread().name)), CUSUM()
    )
    link.truth = Truth("w", "toy", {"positions": np.random.default_rng(1).normal(size=(400, 2))})
    link.outputs_in_background()
    link.answer(obs(0))
    link.answer(obs(1))
    assert link.version == 1  # counted at once, published by the output thread
    link.stop()  # waits for what is queued
    kinds = [(ch, getattr(m, "kind", None)) for ch, m, _ in out if ch != "act"]
    assert kinds == [("embedding", None), ("event", EventKind.RELEARNED)], kinds
    emb = next(m for ch, m, _ in out if ch == "embedding")
    assert emb.version == 1 and emb.scores is not None and 0 <= emb.scores.trustworthiness <= 1
    threads = {ch: t for ch, _, t in out}
    assert threads["act"] == threading.current_thread().name
    assert threads["embedding"].startswith("out-w") and threads["event"].startswith("out-w"), threads
    # without it (in-process runs, replay): everything on the caller's thread, as before
    out2 = []
    link2 = WorldLink("a0", SPEC, Mapper(SPEC), lambda ch, m: out2.append(threading.current_thread().name), CUSUM())
    link2.answer(obs(0))
    link2.answer(obs(1))
    assert set(out2) == {threading.current_thread().name}
