"""What every `sme reproduce` chapter shares: the seeded job pool (local processes, a Ray cluster, a
cache of finished jobs for `--resume`), mean ± standard error and 95 % CI, the table cell format and
the line plot. Chapters (one file each in this package) and the `reproduce` command both import it."""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import sys
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from sensorimotor.tools.common import require


def mean_se(x: list[float] | np.ndarray) -> tuple[float, float]:
    a = np.asarray(x, dtype=np.float64)
    return float(a.mean()), float(a.std(ddof=1) / np.sqrt(a.size)) if a.size > 1 else 0.0


def fmt(ms: tuple[float, float], digits: int = 2) -> str:
    return f"{ms[0]:.{digits}f} ± {ms[1]:.{digits}f}"


def known(x: float | None) -> float:
    """A Procrustes error that must exist (the world publishes its ground truth)."""
    if x is None:
        raise ValueError("an embedding has no Procrustes error: the world gave no ground truth")
    return float(x)


#: (set by `--cluster` for one command; see `use_cluster`)
_CLUSTER: list[str | None] = [None]


@contextlib.contextmanager
def use_cluster(address: str | None) -> Iterator[None]:
    """Within the block, every chapter's jobs run on the Ray cluster at `address` (None: the local
    process pool)."""
    before = _CLUSTER[0]
    _CLUSTER[0] = address
    try:
        yield
    finally:
        _CLUSTER[0] = before


#: where `pool_map` keeps each finished job's result (a folder, and whether to reuse what is there);
#: set by `sme reproduce all` for each chapter (see `job_cache`)
_JOBS: list[tuple[str, bool] | None] = [None]


@contextlib.contextmanager
def job_cache(folder: str, reuse: bool) -> Iterator[None]:
    """Within the block, `pool_map` saves each job's result in `folder` as it finishes and, when
    `reuse`, takes the results already there instead of running those jobs again: a chapter cut
    short (hours of mountain car) goes on from its last finished job under `--resume`."""
    before = _JOBS[0]
    _JOBS[0] = (folder, reuse)
    try:
        yield
    finally:
        _JOBS[0] = before


def _job_path(folder: str, fn: Callable, job: tuple) -> str:
    import hashlib

    key = hashlib.sha1(f"{fn.__module__}.{fn.__qualname__}{job!r}".encode()).hexdigest()[:20]
    return os.path.join(folder, f"{fn.__name__}-{key}.pkl")


def _save_job(path: str, result: Any) -> None:
    import pickle

    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path + ".tmp", "wb") as f:
        pickle.dump(result, f)
    os.replace(path + ".tmp", path)  # a run killed while writing leaves no half a result


def pool_map(fn: Callable, jobs: list[tuple], workers: int) -> list[Any]:
    """``[fn(*job) for job in jobs]`` in job order: on the Ray cluster of `use_cluster`, else in
    `workers` spawned processes (in this process when 1). Jobs are seeded by their arguments, so
    every way gives the same results. Under `job_cache`, finished jobs are kept (and reused)."""
    import pickle

    results: list[Any] = [None] * len(jobs)
    cache = _JOBS[0]
    paths = [_job_path(cache[0], fn, j) for j in jobs] if cache else []
    todo = list(range(len(jobs)))
    if cache and cache[1]:
        for i in list(todo):
            try:
                with open(paths[i], "rb") as f:
                    results[i] = pickle.load(f)
                todo.remove(i)
            except (OSError, pickle.UnpicklingError, EOFError):
                pass
        if len(todo) < len(jobs):
            print(
                f"    {len(jobs) - len(todo)}/{len(jobs)} jobs kept from the earlier run", file=sys.stderr, flush=True
            )

    def finished(i: int, r: Any) -> None:
        results[i] = r
        if cache:
            _save_job(paths[i], r)
        progress.done()

    progress = _Progress(len(todo))
    if not todo:
        return results
    if _CLUSTER[0] is not None:
        from sensorimotor.tools.ray_map import ray_map

        for i, r in zip(todo, ray_map(fn, [jobs[i] for i in todo], _CLUSTER[0]), strict=True):
            finished(i, r)
        return results
    if workers <= 1:
        for i in todo:
            finished(i, fn(*jobs[i]))
        return results
    with mp.get_context("spawn").Pool(workers) as pool:
        # one job at a time (chunksize 1): a chunk of several long jobs left one core idle at the end
        # of a chapter; results come back as they finish (for the progress) and are put in job order
        for i, r in pool.imap_unordered(_indexed, [(fn, i, jobs[i]) for i in todo], chunksize=1):
            finished(i, r)
    return results


def _indexed(task: tuple[Callable, int, tuple]) -> tuple[int, Any]:
    fn, i, job = task
    return i, fn(*job)


class _Progress:
    """A line on stderr as a chapter's jobs finish (at most one per 20 s, and the last): a long run is
    seen to move, with the time to go at the pace so far."""

    def __init__(self, total: int, every: float = 20.0) -> None:
        self.total, self.every, self.n = total, every, 0
        self.t0 = self.last = time.time()

    def done(self) -> None:
        self.n += 1
        now = time.time()
        if now - self.last < self.every and self.n < self.total:
            return
        self.last = now
        spent = now - self.t0
        left = spent / self.n * (self.total - self.n)
        print(
            f"    {self.n}/{self.total} jobs done, {spent:.0f} s, about {left:.0f} s to go", file=sys.stderr, flush=True
        )


# --- chapters ------------------------------------------------------------------------------------


def plot(
    out: str, name: str, title: str, xlabel: str, ylabel: str, series, logy: bool = False, vline: float | None = None
) -> None:
    matplotlib = require("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.4, 4.0))
    for label, x, y in series:
        ax.plot(x, y, label=label, lw=1.2)
    if vline is not None:
        ax.axvline(vline, color="k", ls="--", lw=0.8)
    if logy:
        ax.set_yscale("log")
    ax.set(title=title, xlabel=xlabel, ylabel=ylabel)
    if len(series) <= 12:
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(out, name), dpi=110)
    plt.close(fig)


def ci95(x: list[float]) -> tuple[float, float]:
    from scipy import stats

    a = np.asarray(x, dtype=np.float64)
    if a.size < 2:
        return float(a.mean()), 0.0
    return float(a.mean()), float(stats.t.ppf(0.975, a.size - 1) * a.std(ddof=1) / np.sqrt(a.size))
