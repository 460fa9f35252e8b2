"""Arms of 5 to 7 moving joints (worlds/arm.py with sampled starts) and the reach learner that
learns them (agent/learners/reach.py). Shortened: a 5-link planar arm written here (boxes render
fast), a smaller lattice and earlier sweeps; `sme bench zoo --defaults --world kuka --world xarm6`
runs the Kuka (7 joints) and the xArm6 (6) at the program's defaults."""

from __future__ import annotations

import numpy as np

from sensorimotor.agent.learners.reach import ReachLearner, ReachParams, medoid
from sensorimotor.agent.learners.registry import STATE_LEARNERS
from sensorimotor.agent.programs.generic import GenericProgram
from sensorimotor.agent.programs.generic_jobs import action_table
from sensorimotor.protocol.messages import ActionSpace
from sensorimotor.tools.experiments.arm import planar_urdf
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.arm import ArmWorld


def test_seven_joints_are_accepted_with_sampled_starts_and_a_reach_learner():
    with ArmWorld(seed=3, n_joints=7, image=16, goal_image=32) as w:
        spec = w.spec()
        assert spec.n_starts == 128 and spec.action_space.n == 14 and spec.params["starts"] == "sampled"
        assert [s.name for s in spec.sensors] == ["camera", "joints"]  # proprioception: on from 5 joints
        assert w.poses.shape == (128, 7) and len(np.unique(w.poses, axis=0)) == 128
        for j, g in enumerate(w._grid):  # every start is a lattice pose
            assert np.isin(w.poses[:, j], g).all()
        poses = w.poses.copy()
        program = GenericProgram(spec, seed=0)
        assert program.learner == "reach" and program.n_actions == 14 and "joints" in program.describe()
    with ArmWorld(seed=3, n_joints=7, image=16, goal_image=32) as again, ArmWorld(seed=4, n_joints=7) as other:
        assert np.array_equal(again.poses, poses) and not np.array_equal(other.poses, poses)
    # box moves of 7 joints: one move per joint and direction, not 3^7 combinations
    with ArmWorld(seed=0, n_joints=7, actions="box", starts=130, image=16, goal_image=32) as w:
        assert w.spec().n_starts == 130
        program = GenericProgram(w.spec(), seed=0)
        assert program.learner == "reach" and program.actions.shape == (14, 7)


def test_box_actions_of_eight_dimensions_are_coded_per_axis():
    from dataclasses import replace

    with ArmWorld(seed=0, n_joints=2, lattice=3, image=16, goal_image=32) as w:
        spec = replace(w.spec(), action_space=ActionSpace(low=(-1.0,) * 8, high=(2.0,) * 8))
    table = action_table(spec, 3, 0.5)
    assert table.shape == (16, 8)
    assert np.allclose(table[0], [1.25] + [0.5] * 7) and np.allclose(table[15], [0.5] * 7 + [-0.25])
    assert action_table(replace(spec, action_space=ActionSpace(low=(-1.0,) * 4, high=(1.0,) * 4)), 3).shape == (81, 4)


def test_reach_learner_moves_toward_the_medoid_of_the_goal_states_one_joint_after_another():
    learner = ReachLearner(3, 6, seed=0, params=ReachParams(ridge=0.0))
    assert STATE_LEARNERS["reach"].endswith(":ReachLearner")
    moves = np.eye(3).repeat(2, axis=0) * np.tile([0.1, -0.1], 3)[:, None]
    x = np.full(3, 0.5)
    for a in range(6):
        assert learner.observe(x, a, x + moves[a], "continue")  # each action's first try: plan now
    goals = np.array([[0.7, 0.5, 0.3], [0.7, 0.6, 0.3], [0.6, 0.5, 0.3], [0.2, 0.2, 0.2]])
    for g in goals:
        assert learner.observe(g - moves[0], 0, g, "goal")
    assert not learner.observe(goals[0] - moves[0], 0, goals[0], "goal")  # met before
    learner.install(ReachLearner.plan_job(**learner.job_args()))
    assert np.allclose(learner.W, moves, atol=1e-12)  # each action's mean move
    assert np.allclose(learner.target, [0.7, 0.5, 0.3]) and np.allclose(medoid(goals, learner.scale), learner.target)
    q = learner.q(np.array([0.5, 0.5, 0.5]))
    assert q.tolist() == [1.0, -1.0, -1.0, -1.0, -1.0, 1.0]  # joint 0 up or joint 2 down; joint 1 is there
    line = np.arange(4.0)[:, None]  # summed distances 6, 4, 4, 6
    assert medoid(line, np.ones(1)) == 1.0 and medoid(line, np.ones(1), np.array([2.0]), 0.1) == 2.0  # kept
    assert medoid(line, np.ones(1), np.array([0.0]), 0.1) == 1.0  # 6 > 1.1 x 4: the target moves
    frozen = learner.w.copy()
    copy = ReachLearner(3, 6, seed=1, params=ReachParams(ridge=0.0))
    copy.restore(learner.state())  # saved as explicit arrays and values
    assert np.array_equal(copy.w, frozen) and copy.act(x) == learner.act(x)
    assert not copy.observe(goals[1] - moves[0], 0, goals[1], "goal")  # the goal states met are kept
    learner.reset()
    assert learner.target is None and not np.any(learner.q(x))  # no goal known: every action alike
    assert np.array_equal(learner.q(x, frozen), q)  # a kept plan is followed as it was


def test_a_five_joint_arm_is_learned_from_sampled_starts(tmp_path):
    with ArmWorld(seed=0, urdf=planar_urdf(tmp_path, n=5), n_joints=5, lattice=5, bend=0.3, image=24) as w:
        spec = w.spec()
        assert spec.n_starts == 128 and spec.params["truth_dims"] == "5"
        program = GenericProgram(spec, seed=0, embed_every=1500, sarsa_warmup=300)
        run = run_inprocess(w, program, 6000, stop_when=lambda r: len(r.embeddings) >= 1)
        again = GenericProgram(spec, seed=0, embed_every=1500, sarsa_warmup=300)
    again.restore(program.state())  # a checkpoint keeps the learned moves, goal states and ranges
    assert isinstance(again.planner, ReachLearner) and isinstance(program.planner, ReachLearner)
    assert np.array_equal(again.planner.w, program.planner.w) and np.array_equal(again._lo, program._lo)
    assert len(again.planner.goals) == len(program.planner.goals) > 0
    assert program.learner == "reach"
    e = run.embeddings[0]
    assert e.metrics["goal_reached_fraction"] == 1.0  # (seed 0: 0.089 at step 2,843)
    assert e.procrustes_error is not None and e.procrustes_error < 0.15, e.procrustes_error
