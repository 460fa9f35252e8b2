"""Learning off the act path (agent/programs/background.py): a job's result is swapped in exactly
`lag` acts after it started, the act waits only when the job outlasts that, the programs give the
same decisions and embeddings with jobs in threads as inline, and a checkpoint taken with a job in
flight restores to the same continuation."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.background import Background, function_name
from sensorimotor.agent.programs.base import Program
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld
from tests.test_checkpoint import Recorder, assert_same_outputs, assert_same_tree, lockstep

RELEASE = threading.Event()
STARTED = threading.Event()


def gated_sum(values: list[float]) -> float:
    """A job that runs until the test releases it."""
    STARTED.set()
    assert RELEASE.wait(30)
    return float(np.sum(values))


def test_only_module_level_functions_are_jobs():
    with pytest.raises(ValueError):
        function_name(lambda: 0)
    assert function_name(gated_sum).endswith(":gated_sum")


@pytest.mark.timeout(60)
def test_acts_before_the_due_one_never_wait_and_the_due_one_waits_for_a_late_job():
    RELEASE.clear()
    STARTED.clear()
    bg = Background(lag=4)
    bg.submit("sum", gated_sum, values=[1.0, 2.0])
    assert STARTED.wait(30)
    for _ in range(3):  # the job is held: these ticks return at once with nothing
        assert bg.tick() == [] and bg.pending("sum")
    assert bg.waits == 0
    threading.Timer(0.05, RELEASE.set).start()
    assert bg.tick() == [("sum", 3.0)]  # the 4th act waits for it: the design's only wait
    assert bg.waits == 1 and not bg.pending()
    with pytest.raises(RuntimeError):
        bg.submit("sum", gated_sum, values=[])
        bg.submit("sum", gated_sum, values=[])
    bg.cancel()


def test_a_finished_job_is_still_swapped_in_at_its_due_act_only():
    RELEASE.set()
    bg = Background(lag=5)
    bg.submit("sum", gated_sum, values=[4.0])
    bg.wait()  # finished long before it is due
    assert [bg.tick() for _ in range(4)] == [[]] * 4
    assert bg.tick() == [("sum", 4.0)] and bg.waits == 0


def _gridworld_run(inline: bool, steps: int) -> tuple[list, list]:
    Program.inline_background = inline
    try:
        w = GridWorld(seed=1)
        p = make_program(w.spec(), 1, samples_per_iteration=200, learn_lag=150)
        run = run_inprocess(w, p, steps)
    finally:
        Program.inline_background = False
    return run.embeddings, run.events("policy_iteration")


def test_gridworld_in_threads_equals_inline_and_learns():
    threaded, it_a = _gridworld_run(False, 5000)
    inline, it_b = _gridworld_run(True, 5000)
    assert len(threaded) >= 4 and len(threaded) == len(inline)
    for a, b in zip(threaded, inline, strict=True):
        assert (a.version, a.step, a.iteration, a.metrics) == (b.version, b.step, b.iteration, b.metrics)
        assert a.coordinates.tobytes() == b.coordinates.tobytes()
    assert [(e.step, e.values) for e in it_a] == [(e.step, e.values) for e in it_b]
    # the policy iteration's result arrives `learn_lag` acts after it started, the embedding after
    # the sweep that follows: the first embedding is poorer than the last
    errs = [e.procrustes_error for e in threaded]
    assert errs[-1] < errs[0]


def test_checkpoint_with_a_job_in_flight_restores_the_same_continuation(tmp_path):
    params = {"samples_per_iteration": 200, "learn_lag": 150}
    world = GridWorld(seed=0)
    spec = world.spec()
    program = make_program(spec, 3, **params)
    assert program.background is not None
    first = run_inprocess(
        world, program, 3000, stop_when=lambda r: r.steps > 500 and program.background.pending("lspi")
    )
    assert program.background.pending("lspi")  # the checkpoint is taken mid-job
    daemon = AgentDaemon(bus=None, seed=3, state_dir=str(tmp_path), program_params={"gridworld": params})
    original = Recorder()
    link = WorldLink("a", spec, program, original)
    link.version = len(first.embeddings)
    daemon.links[spec.world_id] = link
    daemon.checkpoint()
    assert os.listdir(tmp_path) == [f"{spec.world_id}.ckpt.npz"]
    saved = daemon._load_checkpoint(spec)
    assert saved is not None
    twin_program = saved.program
    assert twin_program.background is not None and twin_program.background.pending("lspi")
    assert_same_tree(twin_program.state(), program.state())
    restored = Recorder()
    twin = WorldLink("a", spec, twin_program, restored)
    twin.version = saved.version
    lockstep(world, 1500, [link, twin])
    assert assert_same_outputs(original, restored) >= 1
    assert_same_tree(twin_program.state(), program.state())


def test_bench_gap_refuses_unknown_modes_and_bad_bounds(capsys):
    import argparse

    from sensorimotor.tools.bench.gap import main_args

    def args(**kw):
        base = {"seconds": 1.0, "modes": "inline", "retina_embed_every": 50, "warmup": 0, "json": True}
        return argparse.Namespace(**{**base, **kw})

    assert main_args(args(modes="fast")) == 2
    assert "unknown mode" in capsys.readouterr().err
    assert main_args(args(seconds=0.0)) == 2


def test_observations_fed_again_give_the_same_embeddings_as_offline_replay_does():
    """What `sme replay --offline` does - the recorded observations through a fresh link - gives the
    live run's embeddings byte for byte, though the live jobs ran in threads and these run inline."""
    world = GridWorld(seed=2)
    spec = world.spec()
    params = {"samples_per_iteration": 200, "learn_lag": 120}
    seen: list = []
    live = run_inprocess(world, make_program(spec, 2, **params), 4000, on_step=lambda k, obs: seen.append(obs))
    Program.inline_background = True
    try:
        again = Recorder()
        link = WorldLink("offline", spec, make_program(spec, 2, **params), again)
        link.truth = world.truth()
        for obs in seen:
            link.answer(obs)
    finally:
        Program.inline_background = False
    replayed = [o for o in again.outputs if hasattr(o, "coordinates")]
    assert len(live.embeddings) >= 3 and len(replayed) == len(live.embeddings)
    for a, b in zip(live.embeddings, replayed, strict=True):
        assert (a.version, a.step, a.procrustes_error) == (b.version, b.step, b.procrustes_error)
        assert a.coordinates.tobytes() == b.coordinates.tobytes()
