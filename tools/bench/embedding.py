"""`sme bench embedding`: traces to coordinates, our pipeline against scikit-learn's ClassicalMDS,
MDS (SMACOF) and Isomap, side by side in one process, on synthetic traces with known positions.

continuous: n start points uniform in [-1, 1]^2, each trace walks straight to the goal at the
origin in steps of at most sqrt(2)/99 (so L <= 100, d = 2). discrete: n distinct cells within
Manhattan distance 50 of the goal, traces move horizontally then vertically (L <= 100), edit
distance with substitution cost 2. Each row: method, kind, n, seconds, peak_mb (tracemalloc peak
above the inputs), procrustes_error against the true positions. scikit-learn gets the distance
matrix we computed, so its rows time the distances-to-coordinates part only; ours are given both ways.
"""

from __future__ import annotations

import argparse
import json
import time
import tracemalloc
from collections.abc import Callable
from typing import Any

import numpy as np

from sensorimotor.agent.embedding import (
    classical_mds,
    landmark_trace_embedding,
    procrustes_error,
    trace_distances,
)
from sensorimotor.tools.common import require


def continuous_traces(n: int, L: int = 100, seed: int = 0) -> tuple[list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1, 1, (n, 2))
    s = np.sqrt(2) / (L - 1)
    traces = []
    for p in P:
        dist = np.linalg.norm(p)
        k = max(1, int(np.ceil(dist / s)))
        steps = np.repeat((-p / k)[None, :], k, axis=0)
        traces.append(steps)
    return traces, P


def discrete_traces(n: int, radius: int = 50, seed: int = 0) -> tuple[list[list[int]], np.ndarray]:
    rng = np.random.default_rng(seed)
    cells = [
        (x, y) for x in range(-radius, radius + 1) for y in range(-radius, radius + 1) if abs(x) + abs(y) <= radius
    ]
    pick = rng.choice(len(cells), size=min(n, len(cells)), replace=False)
    P = np.array([cells[i] for i in pick], dtype=np.float64)
    traces = [[3 if x < 0 else 2] * int(abs(x)) + [0 if y < 0 else 1] * int(abs(y)) for x, y in P]
    return traces, P


def measure(fn: Callable[[], Any]) -> tuple[Any, float, float]:
    tracemalloc.start()
    tracemalloc.reset_peak()
    base = tracemalloc.get_traced_memory()[0]
    t0 = time.perf_counter()
    out = fn()
    sec = time.perf_counter() - t0
    peak = tracemalloc.get_traced_memory()[1] - base
    tracemalloc.stop()
    return out, sec, peak / 1e6


def row(method: str, kind: str, n: int, sec: float, mb: float, err: float | None, **extra: Any) -> dict:
    return {
        "bench": "embedding",
        "method": method,
        "kind": kind,
        "n": n,
        "seconds": round(sec, 4),
        "peak_mb": round(mb, 1),
        "procrustes_error": None if err is None else round(float(err), 6),
        **extra,
    }


def run(sizes: list[int], landmark_n: int, smacof_max: int, exact_landmark: bool, kinds: list[str]) -> list[dict]:
    manifold = require("sklearn.manifold", package="scikit-learn")
    MDS, ClassicalMDS, Isomap = manifold.MDS, manifold.ClassicalMDS, manifold.Isomap

    rows: list[dict] = []
    trace_distances(continuous_traces(50)[0])  # compile the kernels outside the measurements
    for kind in kinds:
        for n in sizes:
            traces, P = continuous_traces(n) if kind == "continuous" else discrete_traces(n)
            opts = {"kind": "continuous"} if kind == "continuous" else {"kind": "edit", "substitution_cost": 2}

            def ours_all():
                D = trace_distances(traces, dtype=np.float32, **opts)
                return classical_mds(D, 2, method="topk", overwrite=True)

            res, sec, mb = measure(ours_all)
            rows.append(
                row(
                    "ours: traces -> coordinates (float32, top-k)",
                    kind,
                    n,
                    sec,
                    mb,
                    procrustes_error(P, res.coordinates),
                )
            )
            D, dsec, dmb = measure(lambda: trace_distances(traces, dtype=np.float32, **opts))
            rows.append(row("ours: trace distances only", kind, n, dsec, dmb, None))
            D64 = D.astype(np.float64)
            res, msec, mmb = measure(lambda: classical_mds(D.copy(), 2, method="topk", overwrite=True))
            rows.append(
                row(
                    "ours: classical MDS from distances (top-k)",
                    kind,
                    n,
                    msec,
                    mmb,
                    procrustes_error(P, res.coordinates),
                )
            )
            sk, ssec, smb = measure(lambda: ClassicalMDS(n_components=2, metric="precomputed").fit_transform(D64))
            rows.append(
                row(
                    "sklearn ClassicalMDS from distances",
                    kind,
                    n,
                    ssec,
                    smb,
                    procrustes_error(P, sk),
                    ratio_vs_ours=round(ssec / msec, 1),
                )
            )
            iso, isec, imb = measure(
                lambda: Isomap(n_components=2, n_neighbors=10, metric="precomputed").fit_transform(D64)
            )
            rows.append(
                row(
                    "sklearn Isomap from distances",
                    kind,
                    n,
                    isec,
                    imb,
                    procrustes_error(P, iso),
                    ratio_vs_ours=round(isec / msec, 1),
                )
            )
            if n <= smacof_max:
                sm, msec2, mmb2 = measure(
                    lambda: MDS(
                        n_components=2, metric="precomputed", n_init=1, init="random", random_state=0, max_iter=300
                    ).fit_transform(D64)
                )
                rows.append(
                    row(
                        "sklearn MDS (SMACOF) from distances",
                        kind,
                        n,
                        msec2,
                        mmb2,
                        procrustes_error(P, sm),
                        ratio_vs_ours=round(msec2 / msec, 1),
                    )
                )
            D = D64 = None  # free the n x n matrices before the next size
        if landmark_n and kind == "continuous":
            traces, P = continuous_traces(landmark_n, seed=1)
            res, sec, mb = measure(lambda: landmark_trace_embedding(traces, 2, n_landmarks=300))
            extra: dict[str, Any] = {"landmarks": int(res.landmarks.size)}
            if exact_landmark:
                D = trace_distances(traces, dtype=np.float32)
                exact = classical_mds(D, 2, method="topk", overwrite=True).coordinates
                del D
                extra["disparity_vs_exact"] = round(procrustes_error(exact, res.coordinates), 6)
            rows.append(
                row(
                    "ours: landmark MDS, traces -> coordinates",
                    kind,
                    landmark_n,
                    sec,
                    mb,
                    procrustes_error(P, res.coordinates),
                    **extra,
                )
            )
    return rows


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "embedding",
        help="trace distances + MDS vs scikit-learn",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--quick", action="store_true", help="a smoke run: n = 300, 1000; landmarks at 5000")
    p.add_argument("--sizes", default="1000,2000,5000", help="exact sizes (default 1000,2000,5000)")
    p.add_argument("--landmark-n", type=int, default=20000, help="landmark MDS size (default 20000; 0 skips)")
    p.add_argument("--smacof-max", type=int, default=2000, help="largest n given to SMACOF (slow)")
    p.add_argument(
        "--no-exact-landmark",
        action="store_true",
        help="skip the exact embedding of the landmark set (its disparity check costs ~1.6 GB at 20k)",
    )
    p.add_argument("--kinds", default="continuous,discrete", help="continuous, discrete or both")
    p.add_argument("--json", action="store_true", help="one JSON object per line")
    p.set_defaults(func=main_args)


def main_args(args: argparse.Namespace) -> int:
    sizes = [300, 1000] if args.quick else [int(s) for s in args.sizes.split(",") if s]
    landmark_n = 5000 if args.quick and args.landmark_n == 20000 else args.landmark_n
    rows = run(
        sizes,
        landmark_n,
        min(args.smacof_max, 1000) if args.quick else args.smacof_max,
        not args.no_exact_landmark,
        [k.strip() for k in args.kinds.split(",")],
    )
    for r in rows:
        if args.json:
            print(json.dumps(r), flush=True)
        else:
            extra = "".join(f"  {k}={r[k]}" for k in ("ratio_vs_ours", "disparity_vs_exact", "landmarks") if k in r)
            err = "-" if r["procrustes_error"] is None else f"{r['procrustes_error']:.4f}"
            print(
                f"{r['kind']:<10} n={r['n']:<6} {r['method']:<46} {r['seconds']:>8.3f} s {r['peak_mb']:>8.1f} MB  "
                f"procrustes {err}{extra}",
                flush=True,
            )
    return 0
