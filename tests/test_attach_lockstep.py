"""The one attach path and the one lockstep driver, and the failure loops they close: a world
that cannot apply an action, a program that keeps failing."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sensorimotor.agent.attach import AgentConfig, Restored, attach, same_body
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.base import Decision, Program
from sensorimotor.protocol.messages import (
    Action,
    ActionSpace,
    AgentEvent,
    EventKind,
    Observation,
    SensorSpec,
    WorldEvent,
    WorldEventKind,
    WorldSpec,
)
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.gridworld import GridWorld
from sensorimotor.worlds.lockstep import Lockstep


class Picky(World):
    """Accepts actions 0 and 1 only; episodes last 5 steps."""

    kind = "picky"

    def spec(self) -> WorldSpec:
        return WorldSpec(
            self.world_id, self.kind, (SensorSpec("x", "float32", (1,)),), ActionSpace(n=2), program="echo", n_starts=3
        )

    def reset(self, seed=None, start=None) -> StepResult:
        self.s = self.pick_start(seed, start, 3)
        self.t = 0
        return StepResult({"x": np.array([self.s], np.float32)})

    def step(self, action) -> StepResult:
        a = int(np.asarray(action).reshape(-1)[0])
        if a not in (0, 1):
            raise ValueError(f"action {a} is not 0 or 1")
        self.t += 1
        return StepResult({"x": np.array([self.s + self.t], np.float32)}, 0.0, self.t >= 5)


class Sometimes(Program):
    """Answers 7 (which Picky refuses) at every third step, else 0."""

    name = "sometimes"

    def act(self, obs: Observation) -> Decision:
        return Decision((7.0,) if obs.step % 3 == 2 else (0.0,))


class Broken(Program):
    name = "broken"

    def act(self, obs: Observation) -> Decision:
        raise RuntimeError("bug")


def test_lockstep_numbers_steps_episodes_and_starts():
    lock = Lockstep(Picky("p"), "p", "s0")
    o = lock.observation()
    assert (o.step, o.episode, o.t, o.start, o.session) == (0, 0, 0, -1, "s0")
    for k in range(5):
        assert lock.advance(Action("p", k, (1.0,))) is None
    o = lock.observation()
    assert (o.step, o.t, o.done) == (5, 5, True)
    lock.advance(Action("p", 5, (0.0,)))  # done: the world resets whatever the answer
    o = lock.observation()
    assert (o.step, o.episode, o.t, o.start) == (6, 1, 0, -1)
    lock.advance(Action("p", 6, (), reset=True, start=2))
    o = lock.observation()
    assert (o.episode, o.t, o.start, float(o.tensors["x"][0])) == (2, 0, 2, 2.0)


def test_a_refused_action_is_reported_once_and_the_world_moves_on():
    lock = Lockstep(Picky("p"), "p", "s0")
    ev = lock.advance(Action("p", 0, (9.0,)))
    assert isinstance(ev, WorldEvent) and ev.kind == WorldEventKind.ACTION_REFUSED and ev.reason == "bad_action"
    assert ev.step == 0 and "not 0 or 1" in ev.detail
    o = lock.observation()
    assert (o.step, o.episode, o.t) == (1, 1, 0)  # a new question, not the same one again
    ev = lock.advance(Action("p", 1, (), reset=True, start=99))
    assert ev is not None and ev.reason == "bad_reset" and lock.observation().start == -1


def test_in_process_run_counts_refusals_and_keeps_going():
    run = run_inprocess(Picky("p"), Sometimes(Picky("p").spec()), 30)
    refused = [o for o in run.outputs if isinstance(o, WorldEvent)]
    assert run.steps == 30 and len(refused) >= 5
    assert all(o.kind == WorldEventKind.ACTION_REFUSED for o in refused)
    seen = [e for e in run.events(EventKind.WORLD_EVENT)]
    assert seen and all(e.reason == WorldEventKind.ACTION_REFUSED for e in seen)


def test_failing_program_is_rate_limited_then_paused():
    out: list = []
    spec = Picky("p").spec()
    link = WorldLink("a0", spec, Broken(spec), lambda ch, m: out.append((ch, m)))
    answered = [link.answer(Observation("p", 0, k, 0, {"x": np.zeros(1, np.float32)})) for k in range(100)]
    errors = [m for ch, m in out if ch == "event" and m.kind == EventKind.PROGRAM_ERROR]
    paused = [m for ch, m in out if ch == "event" and m.kind == EventKind.PAUSED]
    assert link.counters.program_errors == WorldLink.MAX_PROGRAM_FAILURES
    assert 1 <= len(errors) <= WorldLink.EVENT_RATE + 1 and errors[0].reason == "RuntimeError"
    assert len(paused) == 1 and paused[0].reason == "program_errors" and link.state == "paused"
    assert all(a is None for a in answered[WorldLink.MAX_PROGRAM_FAILURES - 1 :])
    link.resume(spec)  # the world came back
    assert link.state == "attached"


def test_failing_program_ends_an_in_process_run():
    spec = Picky("p").spec()
    run = run_inprocess(Picky("p"), Broken(spec), 1000)
    assert run.steps == WorldLink.MAX_PROGRAM_FAILURES - 1
    assert run.events(EventKind.PAUSED)


def test_attach_new_resumed_and_restored():
    out: list[AgentEvent] = []
    world = GridWorld("g", seed=0, size=5)
    spec = world.spec()
    config = AgentConfig("a0", seed=3, detector="page_hinkley")
    att = attach(spec, config, lambda ch, m: out.append(m), truth=world.truth())
    assert att.how == "new" and att.link.program.seed == 3 and att.link.detector.name == "page_hinkley"
    ev = out[-1]
    assert ev.kind == EventKind.ATTACHED and ev.reason == "new"
    assert (ev.config.seed, ev.config.detector, ev.config.program) == (3, "page_hinkley", "gridworld")

    again = attach(replace(spec, session="other"), config, lambda ch, m: out.append(m), previous=att.link)
    assert again.how == "resumed" and again.link is att.link and out[-1].kind == EventKind.RESUMED

    other = replace(spec, sensors=(SensorSpec("state", "int32", (2,)),))
    assert not same_body(spec, other)
    fresh = attach(other, config, lambda ch, m: out.append(m), previous=att.link)
    assert fresh.how == "new" and fresh.link is not att.link

    restored = attach(
        spec, config, lambda ch, m: out.append(m), restored=Restored(att.link.program, 7, att.link.detector)
    )
    assert restored.how == "restored" and restored.link.version == 7 and restored.link.program is att.link.program


def test_same_body_includes_the_program():
    spec = GridWorld("g", size=5).spec()
    assert same_body(spec, replace(spec, world_id="h", session="x", params={}))
    assert not same_body(spec, replace(spec, program="echo"))


def test_an_unknown_program_falls_back_to_the_generic_one_and_says_so():
    out: list = []
    spec = replace(Picky("p").spec(), program="nosuch")
    att = attach(spec, AgentConfig(), lambda ch, m: out.append(m))
    assert att.link.program.name == "generic"
    fallback = [e for e in out if e.kind == EventKind.PROGRAM_FALLBACK]
    assert len(fallback) == 1 and fallback[0].reason == "nosuch"
    assert [e.config.program for e in out if e.kind == EventKind.ATTACHED] == ["generic"]
