"""`python -m sensorimotor.tools.experiments.repeatable`: the same moves from the same start, twice,
tell a bit-repeatable world from one that is not."""

from __future__ import annotations

import json

import pytest

from sensorimotor.tools.experiments.repeatable import check, cli
from tests.test_generic_program import Beacons, Jittery


def test_a_deterministic_world_repeats_every_start_to_the_bit():
    rows = check(Beacons(), seed=0, moves=30, every=3)
    assert len(rows) == -(-Beacons().spec().n_starts // 3)
    assert all(r.first_step is None and r.max_difference == 0.0 for r in rows), rows


def test_a_world_that_sticks_once_per_start_is_found_at_its_first_step():
    w = Jittery()
    w.armed = True  # every start's next episode is stuck in place once
    rows = check(w, seed=0, moves=30, every=3, between=0)  # so each start's first run is its stuck one
    moved = [r for r in rows if r.steps != (0, 0)]  # the goal cell ends its episode at the reset
    assert len(moved) == len(rows) - 1 and all(r.first_step is not None and r.max_difference > 0 for r in moved), rows
    assert sum(r.first_step == 1 for r in moved) >= len(moved) - 3, rows  # unless the first move hits a wall


def test_the_command_on_gymnasium_worlds_slippery_or_not(capsys):
    assert cli(["gym:FrozenLake-v1", "--param", "map_name=8x8", "--param", "is_slippery=false", "--json"]) == 0
    firm = json.loads(capsys.readouterr().out)
    assert firm["starts_checked"] >= 10 and firm["starts_not_repeated"] == 0, firm
    assert cli(["gym:FrozenLake-v1", "--json"]) == 0  # slippery: a move succeeds one time in three
    slippery = json.loads(capsys.readouterr().out)
    assert slippery["starts_not_repeated"] >= slippery["starts_checked"] // 2, slippery
    assert cli(["gym:FrozenLake-v1", "--moves", "0"]) == 2
    assert "moves >= 1" in capsys.readouterr().err


def test_a_world_without_starts_is_refused():
    class NoStarts(Beacons):
        def spec(self):
            from dataclasses import replace

            return replace(super().spec(), n_starts=0)

    with pytest.raises(ValueError, match="no start states"):
        check(NoStarts())
