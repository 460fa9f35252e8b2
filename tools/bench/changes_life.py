"""`sme bench changes --life N`: a life of N body changes in one run per world (plasticity kept?).

One seeded in-process run per world: the generic program learns; then N changes come one after the
other, each once the change before was relearned (a relearned version published; of a program that
then refines its map, the first version within 1.5x of the error before the first change) and the
detector warmed up again, or its budget ran out. Odd changes are drawn by the seed from the kinds that break
a learned policy and can be relearned (reverse, every action moved one place on or back); even ones
are `restore` (the body as it was: a change too, which the policy relearned for the other body
does not survive). Per change: detection delay, steps from the detection to the relearned map and its error; per run:
changes detected, the last change's steps to relearn over the first's, the process's RSS growth
from the first change to the end, and embedding versions that did not rise."""

from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, make_detector
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.protocol.messages import Control, Embedding, EventKind
from sensorimotor.tools.bench.changes import DEFAULT_WORLDS, Tap, select
from sensorimotor.tools.bench.changes_families import Family
from sensorimotor.tools.bench.procstat import proc_sample
from sensorimotor.tools.bench.zoo import ZooWorld
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.worlds.body_changes.layer import BodyChanges
from sensorimotor.worlds.registry import make_world

#: the worlds of a life by default: one per family of the scorecard's default worlds
LIFE_WORLDS = DEFAULT_WORLDS[:3]


@dataclass
class LifeChange:
    """One change of a life: what, when it came, when it was noticed and relearned (steps)."""

    kind: str
    params: dict[str, str]
    at: int
    rss_mb: float
    error_before: float | None = None
    detected: int | None = None
    relearned: int | None = None
    relearned_error: float | None = None

    @property
    def delay(self) -> int | None:
        return None if self.detected is None else self.detected - self.at

    @property
    def to_relearn(self) -> int | None:
        """Steps from the drop detected to the relearned map: how fast the agent relearns, apart from
        how long the change waited for a sweep to show it (`delay`, which depends on where in the
        program's cycle of exploring and sweeping the change came)."""
        return None if self.relearned is None or self.detected is None else self.relearned - self.detected


@dataclass(frozen=True)
class LifeBudget:
    """Steps: before the first change, the most each change may take, the least between changes."""

    before: int = 5_000
    per_change: int = 40_000
    gap: int = 500


def draw(rng: np.random.Generator, n_actions: int) -> tuple[str, dict[str, str]]:
    """A change that breaks a learned policy and can be relearned, drawn by `rng`: reverse, or every
    action moved one place on (rotate) or back (a policy that uses a few of many actions - MiniGrid's
    left, right, forward of seven - survives an exchange of two others, and no change would be seen)."""
    pick = int(rng.integers(3))
    if pick == 0:
        return "reverse", {}
    if pick == 1 or n_actions < 2:
        return "permute", {"order": "rotate"}
    return "permute", {"order": ",".join(str((i - 1) % n_actions) for i in range(n_actions))}


@dataclass
class _State:
    changes: list[LifeChange] = field(default_factory=list)
    pending_drop: bool = False


def life(z: ZooWorld, n: int, seed: int, budget: LifeBudget = LifeBudget(), quick: bool = False) -> dict[str, Any]:
    """One life of `n` changes on zoo world `z` (or a family of the project's own worlds: served as
    the scorecard serves it, first changed no sooner than its scorecard's first change, each change
    given as long as the scorecard gives it; `quick`: its quick budget's), seeded."""
    rng = np.random.default_rng(seed)
    refines = isinstance(z, Family) and z.refines
    if isinstance(z, Family):
        w = z.build(seed)
        fb = z.quick_budget if quick else z.budget
        budget = replace(budget, before=max(budget.before, fb.before), per_change=max(budget.per_change, fb.after))
    else:
        w = BodyChanges(make_world(z.world, None, seed, z.params))
    st = _State()
    versions: list[int] = []
    first_error: list[float] = []  # the map's error before the first change: the body every restore returns to
    with w:
        spec = w.spec()
        n_actions = spec.action_space.n or 1
        program = make_program(spec, seed, **z.program)
        params = dict(getattr(program, "detector_params", {}) or {})
        tap = Tap(make_detector(DEFAULT_DETECTOR, **params))
        warm = int(params.get("warmup", 100)) + 2 * spec.n_starts
        t0 = time.perf_counter()
        last_emb: list[Embedding] = []

        def relearned(e: Embedding, cur: LifeChange) -> bool:
            """The relearned map: the version that names the drop; of a program that names it in a
            rough map and then refines it (the roving eye), the first within 1.5x of the error before
            the life's first change (a renamed or restored body draws the same map: measured against
            the first, the bar does not creep up from one change to the next)."""
            if not refines:
                return e.drop_step is not None
            return e.procrustes_error is not None and bool(first_error) and e.procrustes_error <= 1.5 * first_error[0]

        def on_output(msg: Any) -> None:
            cur = st.changes[-1] if st.changes else None
            if isinstance(msg, Embedding):
                versions.append(msg.version)
                last_emb[:] = [msg]
                if cur is not None and cur.detected is not None and cur.relearned is None and relearned(msg, cur):
                    cur.relearned, cur.relearned_error = msg.step, msg.procrustes_error
            elif getattr(msg, "kind", None) == EventKind.DROP_DETECTED and cur is not None and cur.detected is None:
                cur.detected = msg.step

        def perturb(k: int) -> Control | None:
            cur = st.changes[-1] if st.changes else None
            if len(st.changes) >= n or k < budget.before or tap.since_reset < warm:
                return None
            if cur is not None and k < cur.at + budget.gap:
                return None
            if cur is not None and cur.relearned is None and k < cur.at + budget.per_change:
                return None
            i = len(st.changes)
            kind, prm = ("restore", {}) if i % 2 else draw(rng, n_actions)
            rss = proc_sample(os.getpid())
            before = None
            if last_emb and last_emb[0].procrustes_error is not None:
                before = float(last_emb[0].procrustes_error)
                first_error[:] = first_error or [before]
            st.changes.append(LifeChange(kind, prm, k, round(rss[0], 1) if rss else float("nan"), before))
            return Control(w.world_id, kind, prm)

        def done(r: Any) -> bool:
            if len(st.changes) < n:
                return False
            cur = st.changes[-1]
            return cur.relearned is not None or r.steps >= cur.at + budget.per_change

        run = run_inprocess(
            w,
            program,
            budget.before + (n + 1) * budget.per_change,
            detector=tap.detector,
            on_output=on_output,
            perturb=perturb,
            stop_when=done,
        )
        seconds = time.perf_counter() - t0
    end = proc_sample(os.getpid())
    ch = st.changes
    first, last = (ch[0].to_relearn, ch[-1].to_relearn) if ch else (None, None)
    rss0 = ch[0].rss_mb if ch else None
    rss1 = round(end[0], 1) if end else None
    return {
        "bench": "changes",
        "life": True,
        "world": z.label,
        "seed": seed,
        "changes": len(ch),
        "steps": run.steps,
        "seconds": round(seconds, 1),
        "detected": sum(c.detected is not None for c in ch),
        "relearned": sum(c.relearned is not None for c in ch),
        "first_steps_to_relearn": first,
        "last_steps_to_relearn": last,
        "last_over_first": None if not first or last is None else round(last / first, 3),
        "median_delay": None if not ch else _median([c.delay for c in ch]),
        "rss_first_change_mb": rss0,
        "rss_end_mb": rss1,
        "rss_growth": None if not rss0 or rss1 is None else round(rss1 / rss0 - 1.0, 4),
        "versions": len(versions),
        "versions_repeat": sum(b <= a for a, b in zip(versions, versions[1:], strict=False)),
        "per_change": [asdict(c) | {"delay": c.delay, "to_relearn": c.to_relearn} for c in ch],
    }


def _median(vals: list[int | None]) -> float | None:
    v = [x for x in vals if x is not None]
    return float(np.median(v)) if v else None


def main(n: int, only: list[str] | None, seeds: int, json_out: bool, quick: bool) -> int:
    """A life of `n` changes per world (the life's worlds by default) and seed."""
    worlds = select(only) if only else select(list(LIFE_WORLDS))
    budget = LifeBudget(2_000, 20_000, 500) if quick else LifeBudget()
    for z in worlds:
        for s in range(seeds):
            r = life(z, n, s, budget, quick)
            if json_out:
                print(json.dumps(r), flush=True)
            else:
                for i, c in enumerate(r["per_change"], 1):
                    print(
                        f"{r['world']} seed {s} change {i:2d} {c['kind']} {c['params']}: at {c['at']}, "
                        f"noticed after {c['delay']} steps, relearned {c['to_relearn']} steps after that "
                        f"(error {c['relearned_error']}), RSS {c['rss_mb']} MB"
                    )
                print(
                    f"{r['world']} seed {s}: {r['detected']}/{r['changes']} detected, {r['relearned']} relearned; "
                    f"last/first steps to relearn {r['last_over_first']}; RSS growth {r['rss_growth']}; "
                    f"versions not rising {r['versions_repeat']} of {r['versions']} ({r['seconds']} s)"
                )
            print(f"life: {r['world']} seed {s} done ({r['seconds']} s)", file=sys.stderr, flush=True)
    return 0


__all__ = ["LifeBudget", "LifeChange", "draw", "life", "main"]
