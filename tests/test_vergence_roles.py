"""The mountain-car program finds which of its body's actions verge (agent/programs/vergence_roles.py):
by the views each ordered pair of actions gives from one start, and, live, after a `permute` that
left its vergence practice without reward."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.agent.programs.vergence_roles import VergenceRoleProbe
from sensorimotor.protocol.messages import Action, Control
from sensorimotor.tools.bench import changes as C
from sensorimotor.tools.bench.changes_families import family
from sensorimotor.worlds.lockstep import Lockstep

CAR = "Mountain car (ch. 8)"


def _probe(order: str | None, change: tuple[str, dict] | None = None) -> tuple[int, ...] | None:
    with family(CAR).build(0) as w:
        if order is not None:
            w.perturb(Control(w.world_id, "permute", {"order": order}))
        if change is not None:
            w.perturb(Control(w.world_id, change[0], change[1]))
        # the program's start: the first evaluation state (a fixed state where the car moves)
        lock, probe = Lockstep(w, w.world_id), VergenceRoleProbe(5, start=int(w.spec().params["n_positions"]))
        dec = probe.begin()
        steps = 0
        while dec is not None:
            obs = lock.observation()
            lock.advance(Action(w.world_id, obs.step, dec.values, dec.reset, dec.start, 0.0))
            dec = probe.step(lock.observation())
            steps += 1
        assert steps == 100  # 20 ordered pairs, 5 steps each
        return probe.roles()


@pytest.mark.parametrize(
    ("order", "roles"),
    [(None, (0, 1, 2, 3, 4)), ("rotate", (4, 0, 1, 2, 3)), ("0:1", (1, 0, 2, 3, 4)), ("1:3", (0, 3, 1, 2, 4))],
)
def test_the_probe_names_the_actions_that_converge_and_diverge(order, roles):
    # rotate: action i acts as i+1, so 4 converges and 0 diverges; the others drive, in their order
    # (1:3: 3 diverges, and 1 coasts: the probe tells the drives from vergence, not from each other)
    assert _probe(order) == roles


def test_a_body_that_cannot_converge_gets_no_roles():
    # lesion action 0: converge does nothing, so no pair turns the eyes and back
    assert _probe(None, ("lesion", {"what": "action", "index": "0"})) is None


def test_a_pair_cut_by_a_restart_or_an_episode_end_is_run_again():
    from sensorimotor.protocol.messages import Observation

    def obs(t: int, done: bool = False, v: float = 0.0) -> Observation:
        return Observation("w", 0, t, t, {"left": np.full(4, v)}, 0.0, done)

    p = VergenceRoleProbe(5, start=7)
    assert p.begin().start == 7
    assert p.step(obs(0)).values == (0.0,)  # the pair (0, 1): converge first
    again = p.step(obs(0))  # t = 0 within the pair: the world restarted
    assert again.reset and again.start == 7 and not p._scores
    p.step(obs(0))
    p.interrupted()
    assert p.step(obs(1, v=1.0)).reset  # a restart the program was told of
    assert p.step(obs(0)).values == (0.0,)
    assert p.step(obs(1, done=True)).reset  # the episode ended within the pair


def test_a_probe_state_round_trips_and_a_bad_one_is_refused():
    p = VergenceRoleProbe(5)
    p.begin()
    q = VergenceRoleProbe(5)
    q.restore(p.state())
    assert q.state() == p.state()
    with pytest.raises(ValueError, match="out of range"):
        q.restore(p.state() | {"i": 99})
    with pytest.raises(ValueError, match="lacks the views"):
        q.restore(p.state() | {"stage": 2})
    with pytest.raises(RuntimeError, match="not seen every pair"):
        q.roles()


def test_a_car_whose_actions_were_exchanged_finds_its_vergence_actions_and_draws_its_map_again():
    """`permute` (rotate): the actions the program verged with now diverge and drive. Noticed by its
    failures; the program probes which actions verge and relearns the map it had."""
    car = family(CAR)
    r = C.run_one(car, C.pick_changes(["permute"], car.changes)[0], 0, C.Budget(0, 700_000, 150_000, 0))
    assert r["applied"] and r["detected"] and r["harm"] >= 0.2, r
    assert r["error_at_1.5x"] is not None and r["error_at_1.5x"] <= 1.5 * r["error_before"], r
