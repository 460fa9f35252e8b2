"""The generic program (ch. 6 recipe) learns worlds that no program was written for: a world
defined only here, with smooth sensor readings of an unseen position, and the gridworld's state ids."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sensorimotor.agent.attach import AgentConfig, attach
from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import ActionSpace, Control, EventKind, SensorSpec, Trigger, Truth, WorldSpec
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.base import StepResult, World
from sensorimotor.worlds.gridworld import GridWorld

MOVES = ((0, 1), (0, -1), (-1, 0), (1, 0))


class Beacons(World):
    """A walker on an n x n grid that senses only the strengths of 12 beacons (Gaussian in the
    distance to each), reward 1 on reaching the centre; `flip` reverses its moves."""

    kind = "beacons"

    def __init__(self, world_id: str = "b", seed: int = 0, n: int = 7, program: str = "generic") -> None:
        super().__init__(world_id, seed)
        self.n, self.program, self.flip = n, program, False
        self.beacons = np.random.default_rng(100 + seed).uniform(-1, n, size=(12, 2))
        self.cells = [(x, y) for y in range(n) for x in range(n)]
        self.goal = (n // 2, n // 2)
        self.pos = self.goal

    def spec(self) -> WorldSpec:
        return WorldSpec(
            self.world_id,
            self.kind,
            (SensorSpec("beacons", "float32", (12,), 0.0, 1.0),),
            ActionSpace(n=4),
            program=self.program,
            n_starts=len(self.cells),
        )

    def _obs(self, reward: float = 0.0, done: bool = False) -> StepResult:
        d = np.linalg.norm(self.beacons - np.asarray(self.pos, float), axis=1)
        return StepResult({"beacons": np.exp(-0.5 * (d / 2.5) ** 2).astype(np.float32)}, reward, done)

    def reset(self, seed=None, start=None) -> StepResult:
        self.pos = self.cells[self.pick_start(seed, start, len(self.cells))]
        self.t = 0
        return self._obs(done=self.pos == self.goal)

    def step(self, action) -> StepResult:
        dx, dy = MOVES[int(np.asarray(action).reshape(-1)[0])]
        if self.flip:
            dx, dy = -dx, -dy
        x, y = self.pos[0] + dx, self.pos[1] + dy
        if 0 <= x < self.n and 0 <= y < self.n:
            self.pos = (x, y)
        self.t += 1
        at_goal = self.pos == self.goal
        return self._obs(1.0 if at_goal else 0.0, at_goal or self.t >= 50)

    def perturb(self, control: Control) -> str:
        self.flip = not self.flip
        return "moves reversed"

    def truth(self) -> Truth:
        return Truth(self.world_id, "start_states", {"positions": np.array(self.cells, dtype=np.float64)})


def test_generic_program_embeds_a_world_it_has_never_seen():
    world = Beacons()
    program = make_program(world.spec(), 0, samples_per_iteration=150)
    assert isinstance(program, GenericProgram) and not program.tabular
    run = run_inprocess(world, program, 5_000)
    errors = [e for e in run.errors if e is not None]
    assert len(errors) >= 4, run.outputs  # worse policies than the accepted one are not published
    assert errors[0] > 0.3 and errors[-1] < 0.05, errors  # the map improves as the policy does
    # a sweep that repeats the accepted policy's traces is no new map: no version repeats the one before
    assert all(a != b for a, b in zip(errors, errors[1:], strict=False)), errors


def test_generic_program_on_state_ids_matches_the_gridworld_program():
    world = GridWorld("g", seed=0, size=7)
    spec = replace(world.spec(), program="generic")
    program = make_program(spec, 0)
    assert program.tabular
    run = run_inprocess(world, program, 8_000)
    errors = [e for e in run.errors if e is not None]
    assert errors and errors[-1] < 0.05, errors


def test_an_unknown_program_name_is_learned_by_the_generic_program():
    world = Beacons(program="my-robot-v3")
    out: list = []
    att = attach(world.spec(), AgentConfig(), lambda ch, m: out.append(m), truth=world.truth())
    assert att.link.program.name == "generic"
    assert any(e.kind == EventKind.PROGRAM_FALLBACK and e.reason == "my-robot-v3" for e in out)


def test_generic_program_detects_reversed_moves_and_relearns():
    world = Beacons()
    program = make_program(world.spec(), 0, samples_per_iteration=150)
    flip_at = 3_000

    def settled(r) -> bool:
        t = [e.trigger for e in r.embeddings]
        return Trigger.RELEARNED in t and len(t) >= t.index(Trigger.RELEARNED) + 3

    run = run_inprocess(
        world,
        program,
        20_000,
        detector=make_detector("cusum", **program.detector_params),
        perturb=lambda k: Control("b", "flip") if k == flip_at else None,
        stop_when=settled,
    )
    drops = run.events(EventKind.DROP_DETECTED)
    assert len(drops) == 1 and flip_at < drops[0].step <= flip_at + 300, [d.step for d in drops]
    before = [e for e in run.embeddings if e.step < flip_at]
    assert before[-1].procrustes_error < 0.05
    i = [e.trigger for e in run.embeddings].index(Trigger.RELEARNED)
    relearned = run.embeddings[i]
    assert relearned.drop_step == drops[0].step and run.events(EventKind.RELEARNED)
    assert relearned.procrustes_error < 0.1 and max(run.errors[i + 1 :], default=0.0) < 0.05, run.errors


class Jittery(Beacons):
    """Beacons whose every start state, once `jitter` is sent, fails its next episode once (the
    walker stuck in place): a world that is not bit-repeatable, tipping a trace off its goal."""

    def __init__(self) -> None:
        super().__init__()
        self.armed, self.failed, self.stuck = False, set(), False

    def reset(self, seed=None, start=None) -> StepResult:
        self.stuck = self.armed and start is not None and start >= 0 and start not in self.failed
        if self.stuck:
            self.failed.add(start)
        return super().reset(seed, start)

    def step(self, action) -> StepResult:
        if self.stuck:
            self.t += 1
            return self._obs(done=self.t >= 50)
        return super().step(action)

    def perturb(self, control: Control) -> str:
        self.armed = True
        return "every start fails once"


def _jitter_run(doubt: bool):
    world = Jittery()
    program = make_program(world.spec(), 0, samples_per_iteration=150)
    if not doubt:
        program._in_doubt = lambda start, trace, ok: False
    run = run_inprocess(
        world,
        program,
        6_000,
        detector=make_detector("cusum", **program.detector_params),
        perturb=lambda k: Control("b", "jitter") if k == 3_000 else None,
    )
    return world, run, program


def test_a_goal_missed_once_is_run_again_before_it_counts_as_a_drop():
    world, run, program = _jitter_run(doubt=True)
    assert len(world.failed) == world.n**2  # every start had its one stuck episode
    assert not run.events(EventKind.DROP_DETECTED)
    late = [e for e in run.embeddings if e.step > 3_000]
    # the sweeps that ran a start again repeat the accepted traces: they publish no new map
    assert program.retried_total >= 1
    assert all(e.metrics["goal_reached_fraction"] == 1.0 for e in late)
    _, blind, _ = _jitter_run(doubt=False)  # without the second run the same world reads as a drop
    assert blind.events(EventKind.DROP_DETECTED)


def test_a_check_sweep_that_repeats_the_last_published_traces_publishes_nothing():
    """A watched policy is swept again (a check) when a newer one is worse or outcomes alternate. A
    world that changed under it gives other traces, whose map is published once; the same traces
    again are no new map (MiniGrid's Dynamic-Obstacles published one map seven times in a row)."""
    world = GridWorld("g", seed=0, size=7)
    program = make_program(replace(world.spec(), program="generic"), 0)
    run_inprocess(world, program, 20_000, stop_when=lambda r: program._watching and program.phase == "explore")
    assert program._watching and program._accepted_traces is not None
    changed = [list(t) for t in program._accepted_traces]
    changed[0] = changed[0] + [changed[0][-1]]  # one start's way is longer now (still at the goal)
    published = []
    for _ in range(3):
        program._checking, program.phase = True, "embed"
        program._sweep.traces, program._sweep.reached = [list(t) for t in changed], list(program._accepted_reached)
        program._pending_embedding = None
        program.background.discard("embed")
        program._swept(0)
        program.drain()
        n = len(changed)
        program._embedded({"coordinates": np.zeros((n, 2)), "eigenvalues": np.ones(2)})  # the job's result
        published.append(sum(type(o).__name__ == "EmbeddingOutput" for o in program.drain()))
    assert published == [1, 0, 0], published
    # the accepted policy and its traces are unchanged: a check does not accept
    assert program._accepted_traces != changed and not program._checking
