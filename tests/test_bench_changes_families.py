"""`sme bench changes` on the project's own worlds (tools/bench/changes_families.py): each family's
changes are ones its world takes, and a family runs through the scorecard's machinery (a short
seeded run on the gridworld)."""

from __future__ import annotations

import pytest

from sensorimotor.protocol.messages import Control
from sensorimotor.tools.bench import changes as C
from sensorimotor.tools.bench.changes_families import FAMILIES, family

pytest.importorskip("river", reason="ADWIN and Page-Hinkley come from river: pip install -e '.[experiments]'")


@pytest.mark.parametrize("fam", FAMILIES, ids=lambda f: f.world)
def test_every_change_of_a_family_is_one_its_world_takes(fam):
    with fam.build(0) as w:
        assert {c.kind for c in fam.changes} <= set(w.perturbations())
        for ch in fam.changes:  # each applied (and said how), then undone
            assert w.perturb(Control(w.world_id, ch.kind, dict(ch.params)))
            w.perturb(Control(w.world_id, "restore", {}))


def test_a_family_is_selected_by_name_with_its_own_changes():
    (g,) = C.select(["Gridworld"])
    assert g is family("Gridworld 9x9 (generic program)") and g.build(0).spec().program == "generic"
    picked = C.pick_changes(["reverse", "gain x2"], family("Retina").changes)
    assert [c.label for c in picked] == ["reverse up/down (own)", "gain x2"]


def test_a_reversed_gridworld_is_noticed_within_a_sweep_before_adwin_and_relearned():
    g = family("Gridworld 9x9 (generic program)")
    r = C.run_one(g, C.pick_changes(["reverse"], g.changes)[0], 0, C.Budget(1_000, 8_000, 4_000, 0))
    assert r["applied"] and r["false_alarms"] == 0 and r["harm"] >= 0.9 and r["n_starts"] == 81
    assert r["detected"] and r["ours_delay_sweeps"] <= 2 and r["ours_delay_samples"] == r["delay_samples_live"]
    assert r["adwin_delay_samples"] > r["ours_delay_samples"]
    assert r["error_at_1.5x"] is not None and r["error_at_1.5x"] <= 1.5 * r["error_before"]


def test_the_mountain_cars_harm_counts_episodes_that_reached_the_goal_before_giving_up():
    car = family("Mountain car (ch. 8)")
    # -(car steps) / 400 per training episode; -1: gave up at 400 car steps without the goal
    assert car.harm([-0.3, -1.0, -0.5, -0.2], [-1.0, -1.0, -0.4, -1.0]) == pytest.approx(1 - 0.25 / 0.75)
    assert family("Retina").harm([0.5, 0.5], [0.25, 0.25]) == 0.5 and car.harm([-1.0], [-1.0]) is None


def test_a_gridworld_that_lost_a_motor_is_relearned_to_the_map_its_body_can_draw():
    """`lesion action 0`: 36 of the 81 starts can no longer reach the goal, so no policy reaches
    `watch_after` of them; once its model is complete the plan is the best the body allows, and
    that policy's map is published as the relearned one (the changed body's own, as from scratch)
    and watched."""
    g = family("Gridworld 9x9 (generic program)")
    r = C.run_one(g, C.pick_changes(["lesion action 0"], g.changes)[0], 0, C.Budget(1_000, 8_000, 12_000, 0))
    assert r["applied"] and r["detected"] and 0.4 < r["harm"] < 0.6, r
    assert r["steps_to_relearned"] is not None and r["fresh_error"] is not None, r
    assert r["relearned_error"] <= 1.5 * max(r["fresh_error"], r["error_before"]), r


def test_an_arm_whose_actions_act_late_is_relearned_over_lspi_with_the_last_action_in_the_state():
    """`delay 1` on the arm seen by its camera (LSPI over PCA + RBF features): outcomes alternate
    while relearning, so the state becomes the frame with the action sent last (one block of
    features per last action) and the delayed body is mapped as before."""
    g = family("Arm Kuka iiwa, 2 joints (sme world arm)")
    r = C.run_one(g, C.pick_changes(["delay 1"], g.changes)[0], 2, C.Budget(5_000, 20_000, 15_000, 0))
    assert r["applied"] and r["detected"] and r["harm"] >= 0.5, r
    assert r["error_at_1.5x"] is not None and r["error_at_1.5x"] <= 1.5 * r["error_before"], r
