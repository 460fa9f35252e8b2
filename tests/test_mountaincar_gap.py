"""The split of the mountain car's gap to the true-state agent, state by state."""

import json

import numpy as np
import pytest

from sensorimotor.tools.experiments import mountaincar_gap as G


def test_the_three_parts_add_up_to_the_gap_and_each_state_counts_once():
    rng = np.random.default_rng(0)
    states = np.c_[rng.uniform(-2, 1.9, 50), rng.uniform(-0.07, 0.07, 50)]
    true = rng.integers(20, 200, size=(3, 50))
    emb = true + rng.integers(0, 40, size=(3, 50))
    emb[1, 7] = 1000  # a hold in one of the three evaluations
    emb[2, 9] = 450
    g = G.split_gap(4, emb, true, states)
    assert g.seed == 4 and g.hold_states == 2
    assert g.embedding == pytest.approx(emb.mean()) and g.true_state == pytest.approx(true.mean())
    assert g.holds + g.fast_starts + g.rest == pytest.approx(g.gap)
    fast = np.abs(states[:, 1]) >= 0.03
    fast[[7, 9]] = False
    assert g.fast_states == int(fast.sum())
    d = emb.mean(0) - true.mean(0)
    assert g.holds == pytest.approx((d[7] + d[9]) / 50)


def test_the_split_refuses_agents_evaluated_on_other_states():
    with pytest.raises(ValueError, match="evaluations x states"):
        G.split_gap(0, np.ones((3, 5)), np.ones((3, 4)), np.zeros((5, 2)))


def test_a_short_run_writes_the_table_and_every_states_steps(tmp_path, capsys):
    out = tmp_path / "gap.json"
    (g,) = G.cli(["--seeds", "0", "--train", "10000", "--n-eval", "8", "--workers", "1", "--out", str(out)])
    doc = json.loads(out.read_text())
    assert doc["gaps"][0]["seed"] == 0 and len(doc["states"]) == 8
    assert [len(p) for p in doc["per_state"]["visual 0"]] == [8] and [len(p) for p in doc["per_state"]["true 0"]] == [8]
    assert g.embedding == pytest.approx(np.mean(doc["per_state"]["visual 0"][-1]))
    assert all(1 <= n <= 1000 for n in doc["per_state"]["visual 0"][0] + doc["per_state"]["true 0"][0])
    assert "| mean |" in capsys.readouterr().out
    with pytest.raises(ValueError, match="at least one evaluation interval"):
        G.main([0], train=5_000)
