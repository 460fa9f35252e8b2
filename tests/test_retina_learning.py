"""Shortened, seeded versions of the chapter-4 experiments (the full ones: `sme reproduce retina`)."""

import numpy as np

from sensorimotor.protocol.messages import Trigger
from sensorimotor.tools.experiments import retina as R


def test_saccades_and_geometry_improve_with_training():
    c = R.learning(0, steps=3000, every=1000, supersample=1, n_eval=30)
    assert c.steps == [0, 1000, 2000, 3000]
    assert c.one[0] > 30 and c.one[-1] < 11  # px of the 128-px retina
    assert c.two[-1] < c.one[-1]  # a second saccade corrects the first
    assert c.geometry[-1] < 0.4 * c.geometry[0]  # E_geometry falls (Fig 4.2)
    assert c.activation[-1] > 2 * c.activation[0]


def test_reversal_is_detected_by_the_agent_relearned_and_reembedded():
    r = R.perturbation(0, "reverse", at=2000, steps=4200, supersample=1, embed_every=500)
    after = [d for d in r.drop_episodes if d >= 2000]
    assert len(r.drop_episodes) == 1 and after and after[0] - 2000 <= 300
    n = R.relearn_episodes(r.rewards, 2000)
    assert n is not None and n <= 2200
    triggers = [e.trigger for e in r.run.embeddings]
    assert Trigger.RELEARNED in triggers
    assert all(e.drop_step is not None for e in r.run.embeddings if e.trigger == Trigger.RELEARNED)
    last = r.run.embeddings[-1]
    assert last.procrustes_error < 0.35 and "e_geometry" in last.metrics


def test_lesion_robust_rule_ends_above_basic_rule():
    post = {}
    for rule in ("basic", "robust"):
        r = R.perturbation(
            0,
            "lesion",
            at=1000,
            steps=2500,
            rule=rule,
            detector=None,
            supersample=1,
            exploration="gaussian",
            every=500,  # greedy evaluations at 0, 500, ..., 2500: three after the lesion
            embed_every=10**9,
        )
        assert r.world.lesion.sum() > 50
        post[rule] = np.mean([a for s, a in zip(r.curve.steps, r.curve.activation, strict=True) if s > 1000])
    assert post["robust"] > post["basic"]
