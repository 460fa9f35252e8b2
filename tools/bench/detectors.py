"""`sme bench detectors`: detection delay and false alarms of the reward-drop detectors, with
river's ADWIN and PageHinkley as peers, on (a) synthetic Gaussian streams with a 2-sigma drop and
(b) the retina lesion and reversal runs, as the agent sees them (log of the post-saccade activation). The default detector is the
one that meets "median delay <= 10 steps at <= 0.3 false alarms per 10k steps" on (a)."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from typing import Any, Protocol

import numpy as np

from sensorimotor.agent.detectors import DEFAULT_DETECTOR, DETECTORS
from sensorimotor.tools.common import require


class _Detector(Protocol):
    """What the benchmark needs of a detector: one observation in, an alarm flag out."""

    def update(self, x: float) -> bool: ...


class _River:
    """river detectors behind our interface (update -> flag)."""

    def __init__(self, make: Callable[[], Any], name: str) -> None:
        # river's detectors are untyped here (its `drift_detected` is a property of each class)
        self._d: Any = make()
        self.name = name

    def update(self, x: float) -> bool:
        self._d.update(x)
        return bool(self._d.drift_detected)


def candidates() -> dict[str, Callable[[], _Detector]]:
    drift = require("river.drift", package="river")

    out: dict[str, Callable[[], _Detector]] = {name: cls for name, cls in DETECTORS.items()}
    out["river.ADWIN"] = lambda: _River(drift.ADWIN, "river.ADWIN")
    out["river.PageHinkley(down)"] = lambda: _River(lambda: drift.PageHinkley(mode="down"), "river.PageHinkley")
    return out


def score_stream(make: Callable[[], _Detector], x: np.ndarray, change: int) -> tuple[int, int | None]:
    """(false alarms before `change`, delay of the first alarm at or after it)."""
    d = make()
    fa, delay = 0, None
    for i, v in enumerate(x):
        if d.update(float(v)):
            if i < change:
                fa += 1
            elif delay is None:
                delay = i - change
                break
    return fa, delay


def synthetic(seeds: int = 100, pre: int = 20000, post: int = 2000, drop: float = 2.0) -> list[dict]:
    rows = []
    for name, make in candidates().items():
        fas, delays = 0, []
        for s in range(seeds):
            rng = np.random.default_rng(s)
            x = rng.normal(0.0, 1.0, pre + post)
            x[pre:] -= drop
            fa, d = score_stream(make, x, pre)
            fas += fa
            delays.append(np.inf if d is None else d)
        rows.append(
            {
                "bench": "detectors",
                "streams": "synthetic",
                "detector": name,
                "seeds": seeds,
                "median_delay": float(np.median(delays)),
                "missed": int(np.isinf(delays).sum()),
                "false_alarms_per_10k": round(fas / (seeds * pre / 10_000), 3),
            }
        )
    return rows


def retina_streams(seeds: int, steps: int) -> list[tuple[str, np.ndarray, int]]:
    from sensorimotor.tools.experiments import retina as R

    out = []
    for s in range(seeds):
        for kind, at in (("lesion", steps // 3), ("reverse", steps // 2)):
            params = {"u": 4, "v": 4, "radius": 5} if kind == "lesion" else None
            r = R.perturbation(
                s, kind, at=at, steps=steps, detector=None, supersample=1, params=params, embed_every=10**9
            )
            # the signal the agent's detector watches: the retina program's performance, log(1 + activation)
            out.append((f"{kind} seed {s}", np.log1p(np.asarray(r.rewards)), at))
    return out


def on_streams(streams: list[tuple[str, np.ndarray, int]]) -> list[dict]:
    rows = []
    for name, make in candidates().items():
        fas, pre_total, delays = 0, 0, []
        for _, x, at in streams:
            fa, d = score_stream(make, x, at)
            fas += fa
            pre_total += at
            delays.append(np.inf if d is None else d)
        rows.append(
            {
                "bench": "detectors",
                "streams": "retina lesion+reversal",
                "detector": name,
                "runs": len(streams),
                "delays": [None if np.isinf(d) else int(d) for d in delays],
                "false_alarms_per_10k": round(fas / (pre_total / 10_000), 3),
            }
        )
    return rows


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("detectors", help="reward-drop detectors: delay and false alarms", description=__doc__)
    p.add_argument("--seeds", type=int, default=100, help="synthetic streams (default 100)")
    p.add_argument("--retina-seeds", type=int, default=2, help="retina runs per perturbation (default 2; 0 skips)")
    p.add_argument("--retina-steps", type=int, default=6000, help="saccades per retina run (default 6000)")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    rows = synthetic(args.seeds)
    if args.retina_seeds > 0:
        rows += on_streams(retina_streams(args.retina_seeds, args.retina_steps))
    for r in rows:
        if args.json:
            print(json.dumps(r))
        elif r["streams"] == "synthetic":
            print(
                f"{r['streams']:<24} {r['detector']:<24} median delay {r['median_delay']:>6} steps  missed "
                f"{r['missed']:>3}  false alarms/10k {r['false_alarms_per_10k']}"
            )
        else:
            print(
                f"{r['streams']:<24} {r['detector']:<24} delays {r['delays']}  false alarms/10k "
                f"{r['false_alarms_per_10k']}"
            )
    ok = next(r for r in rows if r["detector"] == DEFAULT_DETECTOR and r["streams"] == "synthetic")
    meets = ok["median_delay"] <= 10 and ok["false_alarms_per_10k"] <= 0.3
    msg = f"default detector {DEFAULT_DETECTOR}: {'meets' if meets else 'does NOT meet'} median delay <= 10 at <= 0.3 false alarms/10k"
    print(json.dumps({"bench": "detectors", "default": DEFAULT_DETECTOR, "meets_target": meets}) if args.json else msg)
    return 0
