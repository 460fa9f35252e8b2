import numpy as np
import pytest

from sensorimotor.agent.detectors import CUSUM, DETECTORS, BernoulliCUSUM, MovingAverageDrop, PageHinkley, make_detector


def stream(seed, pre=3000, post=500, drop=2.0, sd=1.0, level=0.0):
    rng = np.random.default_rng(seed)
    x = rng.normal(level, sd, pre + post)
    x[pre:] -= drop * sd
    return x


def first_alarm(det, x):
    for i, v in enumerate(x):
        if det.update(v):
            return i
    return None


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_detects_a_two_sigma_drop_quickly_and_rarely_before(name):
    delays, false_alarms = [], 0
    for seed in range(20):
        x = stream(seed)
        d = make_detector(name)
        alarms = [i for i, v in enumerate(x) if d.update(v)]
        false_alarms += sum(i < 3000 for i in alarms)
        after = [i for i in alarms if i >= 3000]
        assert after, seed
        delays.append(after[0] - 3000)
    assert false_alarms <= 3  # 60k in-control steps; every detector is tuned to <= ~0.35 per 10k
    assert np.median(delays) <= 12


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_scale_and_level_invariant(name):
    # standardised: the same stream scaled by 50 and shifted by 100 gives the same alarm step
    x = stream(7)
    assert first_alarm(make_detector(name), x) == first_alarm(make_detector(name), 50 * x + 100)


@pytest.mark.parametrize("name", sorted(DETECTORS))
def test_increases_never_alarm(name):
    x = stream(3, drop=-3.0)  # a rise, not a drop
    assert first_alarm(make_detector(name), x) is None


def test_cusum_false_alarm_rate_meets_target():
    fa = 0
    for seed in range(20):
        d = CUSUM()
        fa += sum(d.update(v) for v in np.random.default_rng(100 + seed).normal(size=10_000))
    assert fa / 20 <= 0.6  # target 0.3 per 10k, with room for 20-seed sampling noise


def test_detector_resets_and_detects_a_second_drop():
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.normal(0, 1, 2000), rng.normal(-3, 1, 2000), rng.normal(-6, 1, 500)])
    d = CUSUM()
    alarms = [i for i, v in enumerate(x) if d.update(v)]
    assert len(alarms) == 2 and 2000 <= alarms[0] < 2020 and 4000 <= alarms[1] < 4020


def test_statistic_and_reference_are_exposed():
    d = MovingAverageDrop()
    assert np.isnan(d.reference)
    for v in stream(1)[:3000]:
        d.update(v)
    assert abs(d.reference) < 0.2 and d.statistic < d.drop
    p = PageHinkley()
    for v in stream(1)[:500]:
        p.update(v)
    assert p.statistic >= 0


def test_bad_values_and_names():
    with pytest.raises(ValueError, match="finite"):
        CUSUM().update(float("nan"))
    with pytest.raises(ValueError, match="unknown detector"):
        make_detector("magic")
    with pytest.raises(ValueError):
        CUSUM(h=0)


def test_field_scores_of_the_bench_count_delay_misses_and_false_alarms():
    pytest.importorskip("river")
    from sensorimotor.tools.bench.detectors import WorldStream, field_rows, field_table, score_stream

    rng = np.random.default_rng(0)
    big = [WorldStream("w", "drop", s, stream(s, pre=2000, post=300, drop=4.0), 2000, {}, "step") for s in range(3)]
    flat = rng.normal(0.0, 1.0, 1000)
    none = [WorldStream("w", "flat", 0, flat, None, {}, "step")]
    rows = {(r.perturbation, r.detector): r for r in field_rows(big + none)}
    cusum = rows[("drop", "cusum")]
    assert cusum.seeds == 3 and cusum.missed_ratio == 0.0 and cusum.unit == "step"
    # the mean time to detect is the mean of the per-stream delays of the first alarm after the change
    delays = [score_stream(lambda: make_detector("cusum"), s.values, 2000)[1] for s in big]
    assert all(d is not None and d < 20 for d in delays)
    assert cusum.mean_time_to_detect == pytest.approx(np.mean(delays))
    assert cusum.drop_sd == pytest.approx(4.0, abs=0.3)
    assert {d for _, d in rows} >= {"cusum", "river.ADWIN", "river.PageHinkley(down)", "river.KSWIN"}
    flat_row = rows[("flat", "cusum")]  # no change: only false alarms, over the whole stream
    d = make_detector("cusum")  # a fresh detector per stream
    alarms = sum(bool(d.update(v)) for v in flat)
    assert flat_row.missed_ratio is None and flat_row.mean_time_to_detect is None
    assert flat_row.false_alarms_per_10k == pytest.approx(round(alarms / 0.1, 2))
    assert "| w | drop | cusum |" in field_table(list(rows.values()))


def test_world_stream_of_the_gridworld_has_no_change_and_bench_cli_writes_the_table(tmp_path, capsys):
    pytest.importorskip("river")
    from sensorimotor.tools.bench.detectors import WORLD_BENCHES, world_stream
    from sensorimotor.tools.cli import main

    st = world_stream("gridworld", WORLD_BENCHES["gridworld"].perturbations[0], 0, quick=True)
    assert st.change is None and st.values.size > 100 and np.all((st.values >= 0) & (st.values <= 1))
    out = tmp_path / "field.md"
    args = ["bench", "detectors", "--quick", "--seeds", "2", "--worlds", "gridworld", "--world-seeds", "1"]
    assert main([*args, "--out", str(out)]) == 0
    text = out.read_text()
    assert "| gridworld | none (accepts none) | cusum | n/a | n/a |" in text
    assert main(["bench", "detectors", "--worlds", "nowhere"]) == 2
    assert "unknown world(s) nowhere" in capsys.readouterr().err


def _episode_lengths(seed, n=5000, after=200):
    """A driver's training episodes as the mountain car reports them, -(car steps) / 400, -1 for a
    failed one: most near 100 steps, a 6 % tail of slow ones (200-399) and 3 % that fail; after `n`
    a body change makes 60 % fail."""
    rng = np.random.default_rng(seed)
    steps = np.where(rng.random(n) < 0.06, rng.uniform(200, 399, n), rng.normal(100, 30, n))
    steps = np.where(rng.random(n) < 0.03, 400.0, steps)
    post = np.where(rng.random(after) < 0.6, 400.0, rng.normal(100, 30, after))
    return -np.clip(np.concatenate([steps, post]), 1, 400) / 400, n


def test_the_cusum_of_failures_ignores_a_skewed_streams_tail_and_still_sees_a_run_of_failures():
    from sensorimotor.agent.programs.mountaincar import MountainCarProgram

    params = MountainCarProgram.detector_params
    assert isinstance(make_detector("cusum", **params), BernoulliCUSUM)
    fa = {"z-score": 0, "failures": 0}
    for seed in range(10):
        x, n = _episode_lengths(seed)
        for name, make in (
            ("z-score", lambda: CUSUM(warmup=20, rate=0.05)),
            ("failures", lambda: make_detector("cusum", **params)),
        ):
            d = make()
            alarms = [i for i, v in enumerate(x) if d.update(v)]
            fa[name] += sum(i < n for i in alarms)
            if name == "failures":
                after = [i - n for i in alarms if i >= n]
                assert after and after[0] <= 12, (seed, after)  # 4-9 episodes with these seeds
    assert fa["failures"] <= 2 and fa["failures"] * 10 < fa["z-score"], fa


def test_a_body_that_fails_almost_always_is_not_flagged_again_and_again():
    """Once the reference itself fails nearly always, a failure adds almost nothing: the detector
    does not keep calling for relearning a body that cannot do better."""
    for rate in (0.8, 0.9, 1.0):
        x = np.where(np.random.default_rng(3).random(2000) < rate, -1.0, -0.3)
        d = BernoulliCUSUM(failure=-1.0)
        assert sum(d.update(v) for v in x) == 0, rate


def test_bernoulli_cusum_is_the_log_likelihood_ratio_of_failures_and_saves_its_state():
    d = BernoulliCUSUM(failure=0.0, shift=0.3, h=8.0, warmup=4, p0_rate=0.02)
    for v in [1.0] * 6:  # 4 join the reference (lag 2), 2 wait: p0 = 0, floored at 0.02
        assert not d.update(v)
    assert d.reference == 0.0 and d.statistic == 0.0
    d.update(0.0)
    assert d.statistic == pytest.approx(np.log(0.32 / 0.02))
    saved = d.state()
    e = BernoulliCUSUM(failure=0.0, shift=0.3, h=8.0, warmup=4, p0_rate=0.02)
    e.restore(saved)
    assert e.update(0.0) is d.update(0.0) is False and e.statistic == pytest.approx(2 * np.log(16))
    assert e.update(0.0) is d.update(0.0) is True  # 3 * log(16) = 8.3 > 8
    assert e.statistic == d.statistic == 0.0
    with pytest.raises(ValueError):
        BernoulliCUSUM(shift=1.5)


def test_the_cars_detector_on_its_recorded_streams_has_no_false_alarm_and_misses_no_harmful_change():
    """The scorecard's mountain car streams, kept in docs/results (10 unperturbed seeds, the new
    baseline and permute on seeds 0-5, the live changes of `sme reproduce mountaincar` and an early
    one): the figures docs/body-changes.md quotes."""
    from pathlib import Path

    from sensorimotor.agent.programs.mountaincar import MountainCarProgram
    from sensorimotor.tools.bench.score_streams import load, score_streams

    path = Path(__file__).parent.parent / "docs/results/bench-changes-mountaincar/streams.jsonl.gz"
    streams = load(str(path))
    ours = score_streams(streams, "cusum", dict(MountainCarProgram.detector_params))
    z = score_streams(streams, "cusum", {"warmup": 20, "rate": 0.05})
    assert ours.samples == z.samples == 24_626 and ours.false_alarms == 0 and z.false_alarms == 41
    harmful = {k: v for k, v in ours.delays.items() if k not in ("gain x2", "reverse")}
    assert sum(len(v) for v in harmful.values()) == 15
    assert all(d is not None and d <= 17 for v in harmful.values() for d in v), harmful
