"""`sme bench fuzz` as a test: 2000 hostile messages on every key the agent listens to, beside a
good gridworld, over real zenoh on loopback (separate processes, free port, no multicast)."""

from __future__ import annotations

import pytest

from sensorimotor.tools.bench.fuzz import COUNTERS, run

pytestmark = pytest.mark.integration


def test_fuzz_2000_messages_all_counted_no_crash_good_world_learns():
    # two worker processes whatever the cores here: with workers, truth and events of a world answered
    # by another worker were counted twice and broken worlds made an owner hand a healthy one off
    r = run(2000, seed=1, rate=1000.0, workers=2)
    assert r.crashes == 0 and r.agent_alive, r
    assert r.sent == 2000
    # every message counted exactly once, by the counter its category was built for
    assert r.counted == r.sent, r
    assert {c: r.counters[c] for c in COUNTERS} == {c: r.expected[c] for c in COUNTERS}, r
    assert r.rejected_kinds == {k.split(".", 1)[1]: v for k, v in r.expected.items() if k.startswith("rejected.")}
    assert set(r.categories) == {
        "obs_bytes", "obs_version", "obs_dtype", "obs_shape", "obs_oversize", "obs_nonfinite", "obs_spec",
        "obs_wrong_world", "obs_duplicate", "truth_bad", "event_bad", "unattached", "attach",
    }  # fmt: skip
    assert r.good_world["alive"] and r.good_world["state"] == "attached"
    assert r.good_world_procrustes < 0.05, r
    assert r.handoffs == 0, r  # the fake and broken worlds never moved the good one
    # what the ratio was paid with: every group's cores in both windows, read from /proc
    for window in ("baseline", "fuzz"):
        used = r.cpu[window]
        assert used["agent"] > 0 and used["world"] > 0, r.cpu
        assert 0 < used["machine_busy"] <= 1, r.cpu
    assert r.cpu["fuzz"]["bench"] > r.cpu["baseline"]["bench"] >= 0, r.cpu  # it publishes only during the fuzz


def test_fuzz_refuses_unknown_categories_before_starting_anything():
    with pytest.raises(ValueError, match="unknown categories.*choose from obs_bytes"):
        run(10, categories=("obs_bytes", "nonsense"))
