"""The model learner (agent/learners/tabular_model.py): value iteration on counts, optimistic
exploration, saved state; and the generic program choosing it for worlds of states it never saw."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.agent.learners.tabular_model import TabularModel, plan_tabular_job
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.registry import make_world
from tests.conftest import install_entry_point


def _chain(n: int) -> TabularModel:
    """States 0..n-1 on a line, action 1 steps right (the last step reaches the goal), action 0 stays."""
    m = TabularModel(n, 2, gamma=0.9, seed=0)
    for s in range(n):
        m.learn_one(s, 0, s, "continue")
        if s == n - 1:
            m.learn_one(s, 1, None, "goal")
        else:
            m.learn_one(s, 1, s + 1, "continue")
    return m


def test_values_are_the_discounted_chance_of_the_goal():
    m = _chain(5)
    m.install(plan_tabular_job(**m.job_args()))
    steps = np.arange(5, 0, -1)  # steps to the goal by going right
    np.testing.assert_allclose(m.q[:, 1], 0.9 ** (steps - 1), rtol=1e-6)
    assert (m.q.argmax(axis=1) == 1).all()


def test_stochastic_outcomes_are_weighed_by_their_counts():
    m = TabularModel(2, 1, gamma=0.5, seed=0)
    for _ in range(3):
        m.learn_one(0, 0, None, "goal")
    m.learn_one(0, 0, None, "failure")
    m.install(plan_tabular_job(**m.job_args()))
    assert m.q[0, 0] == pytest.approx(0.75)


def test_untried_actions_are_optimistic_only_while_exploring():
    m = TabularModel(3, 2, seed=0)
    m.learn_one(0, 0, 1, "continue")
    m.install(plan_tabular_job(**m.job_args()))
    assert m.q_explore[0, 1] == 1.0 and m.q[0, 1] == 0.0
    assert m.act(0) == 1  # the untried action first


def test_exploration_tries_every_action_of_a_grid_quickly():
    """A 10 x 10 open grid with four moves: every (state, action) is tried within a few times their
    number of steps (random actions need far more)."""
    n, rng = 10, np.random.default_rng(0)
    m = TabularModel(n * n, 4, seed=0)
    moves = [(0, 1), (1, 0), (0, -1), (-1, 0)]
    s, steps = 0, 0
    while (m.tried == 0).any():
        a = m.act(s)
        r, c = divmod(s, n)
        r2, c2 = min(n - 1, max(0, r + moves[a][0])), min(n - 1, max(0, c + moves[a][1]))
        s2 = r2 * n + c2
        m.learn_one(s, a, s2, "continue")
        s, steps = s2, steps + 1
        assert steps < 3 * n * n * 4, "exploration stalls"
    assert rng is not None and steps < 3 * m.tried.size


def test_saved_state_continues_the_same_way():
    m = _chain(6)
    m.learn_one(2, 0, 2, "continue")
    saved = m.state()
    other = TabularModel(6, 2, gamma=0.9, seed=99)
    other.restore(saved)
    assert [m.act(s) for s in range(6)] == [other.act(s) for s in range(6)]
    a, b = plan_tabular_job(**m.job_args()), plan_tabular_job(**other.job_args())
    np.testing.assert_array_equal(a["q"], b["q"])


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="gamma"):
        TabularModel(3, 2, gamma=1.0)
    with pytest.raises(ValueError, match="outcome"):
        TabularModel(3, 2).learn_one(0, 0, 1, "maybe")


def test_a_random_ten_by_ten_lake_is_learned_at_the_defaults():
    """Gymnasium's random 10 x 10 map (seed 0, not slippery): the generic program picks the model
    learner, reaches the goal from every start and embeds the lake (LSPI over random samples did
    not reach the goal there)."""
    from gymnasium.envs.toy_text.frozen_lake import generate_random_map

    desc = generate_random_map(size=10, p=0.8, seed=0)
    with make_world("gym:FrozenLake-v1", None, 0, {"desc": desc, "is_slippery": "false"}) as w:
        program = make_program(w.spec(), 0)
        assert program.learner == "model"
        run = run_inprocess(w, program, 30_000)
    embs = [e for e in run.embeddings if e.procrustes_error is not None]
    assert embs and embs[-1].metrics["goal_reached_fraction"] == 1.0
    assert embs[-1].procrustes_error < 0.1, [e.procrustes_error for e in embs]
    errors = [e.procrustes_error for e in embs]
    assert all(a != b for a, b in zip(errors, errors[1:], strict=False)), errors  # no map republished


def test_a_minigrid_layout_drawn_at_reset_is_the_seeds_one():
    """LavaGap and SimpleCrossing draw their layout at every reset: the world serves the seed's
    layout each time, so the start states stay free cells and their truth stays true."""
    pytest.importorskip("minigrid")
    for env in ("MiniGrid-LavaGapS7-v0", "MiniGrid-SimpleCrossingS9N1-v0"):
        with make_world(f"gym:{env}", None, 0, {}) as w:
            w.reset()
            grid = w.u.grid.encode().copy()
            for start in (-1, 0, 3):
                w.reset(start=start if start >= 0 else None)
                assert np.array_equal(w.u.grid.encode(), grid), env


def test_a_minigrid_room_wider_than_the_view_is_served_whole():
    """The egocentric 7 x 7 view shows the middle cells of a 16 x 16 room alike; the whole grid
    (`view=auto`) makes each cell and heading its own observation."""
    pytest.importorskip("minigrid")
    with make_world("gym:MiniGrid-Empty-16x16-v0", None, 0, {}) as w:
        assert {s.name: s.shape for s in w.spec().sensors}["image"][:2] == (16, 16)
        seen = {w.reset(start=k).tensors["image"].tobytes() for k in range(w.spec().n_starts)}
        assert len(seen) == w.spec().n_starts
    with make_world("gym:MiniGrid-Empty-16x16-v0", None, 0, {"view": "agent"}) as w:
        seen = {w.reset(start=k).tensors["image"].tobytes() for k in range(w.spec().n_starts)}
        assert len(seen) < w.spec().n_starts  # aliased


LEARNER_PACKAGE = '''
import numpy as np


def plan(q):
    return {"q": q}


class OptimisticQ:
    """One-step Q-learning with optimistic initial values: a learner from outside this project."""

    plan_job = staticmethod(plan)

    def __init__(self, n_states, n_actions, seed=0):
        self.n_actions = n_actions
        self.rng = np.random.default_rng(seed)
        self.q = np.ones((n_states, n_actions))
        self.steps = 0

    def act(self, s):
        q = self.q[s]
        return int(self.rng.choice(np.flatnonzero(q >= q.max() - 1e-12)))

    def learn_one(self, s, a, s_next, outcome):
        target = 1.0 if outcome == "goal" else 0.0 if outcome == "failure" else 0.9 * self.q[s_next].max()
        self.q[s, a] += 0.5 * (target - self.q[s, a])
        self.steps += 1
        return False

    def job_args(self):
        return {"q": self.q.copy()}

    def install(self, result):
        pass

    def complete(self):
        return self.steps > 2000

    def set_stochastic(self, stochastic):
        pass

    def reset(self):
        self.q[:] = 1.0

    def state(self):
        return {"q": self.q.copy(), "steps": self.steps}

    def restore(self, state):
        self.q, self.steps = np.asarray(state["q"]), int(state["steps"])
'''


def test_a_learner_from_an_installed_package_is_chosen_by_name(tmp_path, monkeypatch):
    """A table learner that a package declares in the `sensorimotor.learners` entry-point group is
    chosen with `generic.learner=NAME` and learns the gridworld; an unknown name is refused with
    the valid ones."""
    import sys
    from dataclasses import replace

    from sensorimotor.agent.programs.registry import check_program_params
    from sensorimotor.protocol.errors import SpecMismatch
    from sensorimotor.worlds.gridworld import GridWorld

    pkg = tmp_path / "my_learners"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "q.py").write_text(LEARNER_PACKAGE)
    install_entry_point(
        tmp_path, monkeypatch, "my-learners", "sensorimotor.learners", "optimistic-q = my_learners.q:OptimisticQ"
    )
    try:
        assert check_program_params({"generic": {"learner": "optimistic-q"}}) == {
            "generic": {"learner": "optimistic-q"}
        }
        world = GridWorld("g", seed=0, size=7)
        spec = replace(world.spec(), program="generic")
        program = make_program(spec, 0, learner="optimistic-q")
        assert type(program.model).__name__ == "OptimisticQ" and "OptimisticQ" in program.describe()
        run = run_inprocess(world, program, 8_000)
        errors = [e for e in run.errors if e is not None]
        assert errors and errors[-1] < 0.05, errors
        with pytest.raises(SpecMismatch, match="optimistic-q"):  # the valid names include the outside one
            make_program(spec, 0, learner="no-such-learner")
    finally:
        sys.modules.pop("my_learners.q", None)
        sys.modules.pop("my_learners", None)


def test_the_estimator_is_chosen_by_how_much_a_start_repeats_its_most_common_trace():
    """`estimator=auto`: where a start's samples are mostly one trace (a move goes where meant 9
    times in 10) the mode trace is embedded; on slippery ice, where every sample is another trace,
    the mean traces are."""
    from sensorimotor.agent.programs.generic_jobs import embed_job, mode_share

    rng = np.random.default_rng(0)
    mostly = [[[0, 0, 1]] * 7 + [[0, 1, 1, 1]] for _ in range(5)]
    assert mode_share(mostly) == pytest.approx(7 / 8)
    scattered = [[list(rng.integers(0, 4, 6)) for _ in range(8)] for _ in range(5)]
    assert mode_share(scattered) < 0.5
    for traces, like in ((mostly, "mode"), (scattered, "mean_trace")):
        reached = [[True] * 8 for _ in traces]
        auto = embed_job(traces, None, 2, estimator="auto", n_actions=4, reached=reached)
        chosen = embed_job(traces, None, 2, estimator=like, n_actions=4, reached=reached)
        np.testing.assert_allclose(auto["coordinates"], chosen["coordinates"])


def test_a_near_deterministic_lake_is_embedded_from_its_mode_traces():
    """FrozenLake 4x4 where a move goes where meant 9 times in 10: stochastic, yet each start mostly
    repeats one trace; at the defaults the map is the mode traces' (mean traces gave 0.62 here)."""
    with make_world("gym:FrozenLake-v1", None, 0, {"success_rate": "0.9"}) as w:
        program = make_program(w.spec(), 0)
        run = run_inprocess(w, program, 12_000, stop_when=lambda r: bool(r.embeddings))
    assert program.stochastic and program.estimator == "auto"
    assert run.embeddings and run.embeddings[0].procrustes_error < 0.15, run.errors


def test_walls_make_a_map_of_ways_not_of_places():
    """tools/experiments/geodesic_ceiling: in an open room the shortest ways are the places (MDS of
    them is near the cells); round LavaGap's wall they are not."""
    pytest.importorskip("minigrid")
    from sensorimotor.tools.experiments.geodesic_ceiling import geodesic_error

    with make_world("gym:MiniGrid-Empty-8x8-v0", None, 0, {}) as w:
        assert geodesic_error(w) < 0.05
    with make_world("gym:MiniGrid-LavaGapS7-v0", None, 0, {}) as w:
        assert geodesic_error(w) > 0.15


def test_reversed_moves_are_a_detected_drop_and_the_model_relearns():
    """The model learner at the defaults on FrozenLake 4x4 (not slippery): moves reversed at step
    10,000 (the test swaps each move with its opposite) are one detected drop within 500 steps, the
    model is dropped and learned again, and the relearned map is as good as the first."""
    from sensorimotor.agent.detectors import make_detector
    from sensorimotor.protocol.messages import EventKind

    with make_world("gym:FrozenLake-v1", None, 0, {"is_slippery": "false"}) as w:
        program = make_program(w.spec(), 0)
        now, step = [0], w.step

        def maybe_reversed(action, step=step):
            if now[0] >= 10_000:
                action = np.asarray([(int(np.asarray(action).reshape(-1)[0]) + 2) % 4])
            return step(action)

        w.step = maybe_reversed  # type: ignore[method-assign]
        detector = make_detector("cusum", **program.detector_params)
        run = run_inprocess(w, program, 30_000, detector=detector, on_step=lambda k, obs: now.__setitem__(0, k))
    drops = [e.step for e in run.events(EventKind.DROP_DETECTED)]
    assert len(drops) == 1 and 10_000 < drops[0] <= 10_500, drops
    relearned = [e for e in run.embeddings if e.trigger == "relearned"]
    assert relearned and relearned[0].drop_step == drops[0] and relearned[0].procrustes_error < 0.1
    assert program.learner == "model"
