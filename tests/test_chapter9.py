"""Chapter 9 (beyond the dissertation): slippery gridworld and the probabilistic estimators,
option discovery, policy maps (schema, program output, mountain car clusters vs true outcomes)."""

import collections

import numpy as np
import pytest

from sensorimotor.agent.embedding.options import discover_options, random_options, segments
from sensorimotor.agent.embedding.policy_map import policy_map
from sensorimotor.agent.embedding.probabilistic import (
    mean_pair_distances,
    mode_distances,
    mode_trace,
    sample_until_settled,
)
from sensorimotor.agent.learners.smdp_q import OptionQLearner
from sensorimotor.agent.programs.gridworld import GridworldProgram
from sensorimotor.protocol import codec, errors
from sensorimotor.protocol.messages import Embedding, Trigger
from sensorimotor.tools.experiments import chapter9 as C9
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.gridworld import GridWorld

# --- slip and the probabilistic estimators (9.4) -----------------------------------------------


def _moves(w: GridWorld, a: int, n: int) -> collections.Counter:
    c: collections.Counter = collections.Counter()
    for _ in range(n):
        w.reset(start=w.index[(4, 4)])
        w.step(np.array([a]))
        c[(w.pos[0] - 4, w.pos[1] - 4)] += 1
    return c


def test_slip_default_is_deterministic_and_slip_goes_sideways_at_its_rate():
    w = GridWorld(seed=0, goal=(0, 0))
    assert _moves(w, 3, 200) == {(1, 0): 200}  # right, always
    assert "slip" not in w.spec().params  # the default world's spec is unchanged
    c = _moves(GridWorld(seed=1, goal=(0, 0), slip=0.2), 3, 4000)
    assert set(c) == {(1, 0), (0, 1), (0, -1)}  # right, or sideways: never backwards
    assert c[(1, 0)] / 4000 == pytest.approx(0.8, abs=0.02)
    assert c[(0, 1)] / 4000 == pytest.approx(0.1, abs=0.015)
    assert GridWorld(seed=1, slip=0.2).spec().params["slip"] == "0.2"


def test_mode_trace_and_mean_pair_distances():
    assert mode_trace([[0, 1], [0, 1, 1], [0, 1], [2]]) == (0, 1)
    assert mode_trace([[0, 0, 0], [1]]) == (1,)  # tie: the shorter
    with pytest.raises(ValueError):
        mode_trace([])
    samples = [[[0, 0], [0, 0]], [[1, 1], [1]], [[0, 1], [0, 1]]]
    D = mean_pair_distances(samples)
    # indel distances: [0,0]-[1,1] = 4, [0,0]-[1] = 3 -> mean 3.5
    assert D[0, 1] == pytest.approx(3.5) and D[1, 0] == pytest.approx(3.5)
    assert np.all(np.diag(D) == 0)
    # debiased: start 1's spread is d([1,1],[1]) = 1, so 3.5 - (0 + 1) / 2 = 3.0
    assert mean_pair_distances(samples, debias=True)[0, 1] == pytest.approx(3.0)
    assert mode_distances(samples)[0, 2] == 2.0


def test_sampling_stops_when_the_estimate_settles_and_not_for_deterministic_noise():
    rng = np.random.default_rng(0)
    fixed = sample_until_settled(lambda i: [i % 3] * (i + 1), 6, mode_distances, batch=2, tol=0.01)
    assert fixed.settled and fixed.n_samples == 6 and fixed.changes == (0.0, 0.0)  # 3 rounds of 2
    noisy = sample_until_settled(
        lambda i: [0] * (i + int(rng.integers(0, 4))), 6, mean_pair_distances, batch=2, tol=1e-6, max_samples=8
    )
    assert not noisy.settled and noisy.n_samples == 8


def test_probabilistic_estimators_recover_the_slippery_gridworld_plain_does_not():
    r = C9.probabilistic_gridworld(seed=0, slip=0.2, size=7, max_samples=24)
    assert r.plain > 0.08  # one sampled trace per start: slips scramble the map
    assert min(r.mode, r.mean) <= 0.05
    assert r.mean < r.plain / 3 and r.mode < r.plain / 2
    assert 8 <= r.samples_mean <= 24


# --- option discovery (9.6) ----------------------------------------------------------------------


def test_segments_and_discovered_options_are_the_cluster_modes():
    assert segments([[1, 2, 3, 4, 5, 6, 7], [1, 2]], 3) == [(1, 2, 3), (4, 5, 6)]
    traces = [[0] * 10 + [3] * 10, [3] * 15, [0] * 20, [0, 3] * 10]
    found = discover_options(traces, n_options=3, seed=0)
    assert set(found.options) == {(0,) * 5, (3,) * 5, (0, 3, 0, 3, 0)}
    assert len(found.labels) == len(found.segments) == 15
    opts = random_options(4, 3, seed=1)
    assert len(opts) == 3 and all(len(o) == 5 and max(o) < 4 for o in opts)
    with pytest.raises(ValueError):
        OptionQLearner(5, 4, [(0, 7)])


def test_discovered_options_reach_the_level_faster_than_none_and_random():
    r = C9.options_job(seed=0, budget=25_000, size=11)
    none, rand, disc = (r[k]["steps_to_level"] for k in ("none", "random", "discovered"))
    assert disc is not None and none is not None
    assert disc <= 0.8 * none
    assert rand is None or rand > disc
    assert len(r["discovered_options"]) == len(r["random_options"]) >= 2


# --- policy maps (9.6) -----------------------------------------------------------------------------


def test_embedding_labels_round_trip_and_are_checked():
    e = Embedding("a0", "w", 3, Trigger.POLICY_MAP, (0, 1, 2), np.zeros((3, 2)), (1.0,), labels=(0, 2, 1))
    assert codec.decode(Embedding, codec.encode(e)).labels == (0, 2, 1)
    assert codec.decode(Embedding, codec.encode(Embedding("a0", "w", 1, "t", (0,), np.zeros((1, 2)), ()))).labels == ()
    bad = Embedding("a0", "w", 3, Trigger.POLICY_MAP, (0, 1, 2), np.zeros((3, 2)), (1.0,), labels=(0, 1))
    with pytest.raises(errors.ProtocolError):
        codec.decode(Embedding, codec.encode(bad))


def test_gridworld_program_emits_a_policy_map_with_labels():
    w = GridWorld(seed=0, size=7)
    p = GridworldProgram(w.spec(), seed=0, policy_map=3)
    run = run_inprocess(w, p, 3000)
    maps = [e for e in run.embeddings if e.trigger == Trigger.POLICY_MAP]
    plain = [e for e in run.embeddings if e.trigger == Trigger.POLICY_ITERATION]
    assert maps and len(maps) == len(plain)
    m = maps[-1]
    assert len(m.labels) == 49 and set(m.labels) == {0, 1, 2} and m.metrics["clusters"] == 3.0
    assert not plain[-1].labels


def test_policy_map_of_the_mountain_car_separates_failures_direct_climbs_and_rocking():
    agent = C9.train_mountaincar(0, 30_000)
    traces, outcomes = C9.mountaincar_traces(agent, 400, 1)
    counts = collections.Counter(outcomes)
    assert all(counts[o] >= 40 for o in C9.OUTCOMES), counts  # the seeded policy shows all three
    pm = policy_map(traces, n_clusters=5, seed=0)
    out = np.array(outcomes)
    majority = {}
    for c in range(pm.n_clusters):
        m = collections.Counter(out[pm.labels == c].tolist())
        o, n = m.most_common(1)[0]
        if n / sum(m.values()) >= 0.6:
            majority.setdefault(o, []).append(c)
    assert set(majority) == set(C9.OUTCOMES), majority  # a mostly-failing, a direct and a rocking cluster


def test_mountaincar_thrust_noise_defaults_to_the_deterministic_dynamics():
    from sensorimotor.worlds.mountaincar import MountainCarWorldParams
    from sensorimotor.worlds.mountaincar_dynamics import MountainCarParams, step

    assert MountainCarWorldParams().thrust_noise == 0.0
    prm = MountainCarParams()
    assert step(-0.5, 0.01, 1, prm) == step(-0.5, 0.01, 1, prm, 0.0)
    x1, v1, _ = step(-0.5, 0.01, 1, prm, 0.5)
    x0, v0, _ = step(-0.5, 0.01, 1, prm)
    assert v1 - v0 == pytest.approx(0.5 * prm.p)  # noise is extra thrust in units of the push


def test_view_draws_a_policy_map_coloured_by_cluster():
    from sensorimotor.protocol import keys
    from sensorimotor.tools.commands.view import PALETTE, RerunLogger

    class FakeRR:
        def __init__(self):
            self.logged = []

        def set_time(self, *a, **k):
            pass

        def Points2D(self, pts, colors=None, radii=None):  # noqa: N802 (rerun's name)
            return {"pts": pts, "colors": colors}

        def Scalars(self, v):  # noqa: N802
            return v

        def TextLog(self, text, level=None):  # noqa: N802
            return text

        def log(self, path, what):
            self.logged.append((path, what))

    rr = FakeRR()
    e = Embedding("a0", "w", 3, Trigger.POLICY_MAP, (0, 1, 2), np.eye(3)[:, :2], (1.0,), labels=(0, 2, 2))
    RerunLogger(rr).handle(keys.agent_embedding("a0", "w"), codec.encode(e), 1.0)
    (path, pts) = next((p, w) for p, w in rr.logged if p.endswith("policy_map"))
    assert path == "w/policy_map"
    assert (pts["colors"] == PALETTE[[0, 2, 2]]).all()


def test_gridworld_program_samples_until_settled_in_a_slippery_world():
    w = GridWorld(seed=0, size=7, slip=0.2)
    p = GridworldProgram(w.spec(), seed=0, estimator="mode", samples_per_iteration=1500, max_samples=24)
    run = run_inprocess(w, p, 30_000, stop_when=lambda r: len(r.embeddings) >= 3)
    last = run.embeddings[-1]
    assert last.procrustes_error is not None and last.procrustes_error < 0.05, run.errors
    assert 2 < last.metrics["samples_per_start"] <= 24  # the agent chose how many samples
    restored = GridworldProgram(w.spec(), seed=0, estimator="mode", samples_per_iteration=1500, max_samples=24)
    restored.restore(p.state())  # the sampling state survives a checkpoint
    assert restored.params.estimator == "mode"
