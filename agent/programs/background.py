"""Learning off the act path: a program's slow learning work (policy iteration, a sweep's
embedding, MDS, relearning) runs as a background job and its result is swapped in later, while
`act` keeps answering from the current policy.

Reproducibility is kept by construction, not by recording anything:

- a job is a pure function of a snapshot: a module-level function (named "module:qualname") and
  keyword arguments that are copies of the program's values when the job starts;
- a job started during the program's c-th `act` is swapped in at the start of act number
  c + `lag` exactly - the program's own act count, which depends only on the observation stream.
  If the job is not finished by then, that act waits for it (the only wait there is).

So a seeded run takes the same decisions and emits the same embeddings whether the job ran in a
thread, a process or inline, whatever the machine's load: in-process runs, `reproduce`, and
`sme replay --offline` all agree with the live agent. The cost of not recording the swap step is
the bounded wait: `act` blocks only when a job takes longer than `lag` steps of wall time.

Jobs run on a thread pool shared by the process. Their work is numpy/scipy/rapidfuzz (BLAS,
LAPACK, sparse products and edit distances release the GIL); the pure-Python glue left in a job
takes the GIL for up to the interpreter's switch interval at a time, which is lowered from 5 ms to
0.5 ms for the process once the pool exists (measured: a thread sleeping 0.5 ms at a time beside a
gridworld LSPI + MDS job woke late by up to 21 ms at 5 ms, up to 5.4 ms at 0.5 ms; C calls that keep
the GIL, e.g. building arrays from lists, make the rest). A process pool would remove that too, at
the price of copying each snapshot to another process; `sme bench gap` measures what is left. BLAS is limited to one thread for the whole process once a
program uses background jobs: a multi-threaded OpenBLAS on a busy machine made a 324 x 324 solve
take 0.4-1.2 s instead of 2-7 ms (spinning threads fighting for the cores, the act thread among
them), and one thread count for every job keeps float results the same from run to run.

A job in flight is part of the program's saved state (`state()`/`restore()`): its function, its
arguments and its due act, so a restored program resubmits it and swaps it in at the same act.
"""

from __future__ import annotations

import importlib
import os
import sys
import threading
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

_POOL: ThreadPoolExecutor | None = None
_POOL_LOCK = threading.Lock()
# the interpreter's GIL switch interval once jobs run in threads (the default is 5 ms)
SWITCH_INTERVAL = 0.0005
_BLAS_LIMITED = False


def _limit_blas() -> None:
    """One BLAS thread for the process (once; see the module docstring)."""
    global _BLAS_LIMITED
    with _POOL_LOCK:
        if not _BLAS_LIMITED:
            from threadpoolctl import threadpool_limits

            threadpool_limits(1, user_api="blas")
            _BLAS_LIMITED = True


def _pool() -> ThreadPoolExecutor:
    """The process's shared job pool (made on first use; one worker per core, at least two)."""
    global _POOL
    with _POOL_LOCK:
        if _POOL is None:
            sys.setswitchinterval(min(sys.getswitchinterval(), SWITCH_INTERVAL))
            _POOL = ThreadPoolExecutor(max_workers=max(2, os.cpu_count() or 1), thread_name_prefix="sme-learn")
        return _POOL


def function_name(fn: Callable[..., Any]) -> str:
    """ "module:qualname" of a module-level function (what a saved job names)."""
    name = f"{fn.__module__}:{fn.__qualname__}"
    if "<" in fn.__qualname__ or resolve(name) is not fn:
        raise ValueError(f"a background job must be a module-level function, not {name}")
    return name


def resolve(name: str) -> Callable[..., Any]:
    """The function a "module:qualname" names (ValueError if there is none)."""
    module, _, qual = name.partition(":")
    try:
        obj: Any = importlib.import_module(module)
        for part in qual.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as e:
        raise ValueError(f"no background job function {name!r}") from e
    if not callable(obj):
        raise ValueError(f"{name!r} is not a function")
    return obj


@dataclass
class _Job:
    fn: str
    args: dict[str, Any]
    due: int
    future: Future | None = None
    result: Any = None
    done: bool = False


class Background:
    """A program's background jobs, each swapped in exactly `lag` acts after it started.

    Parameters
    ----------
    lag : int
        Acts between a job's start and the act that swaps its result in (>= 1).
    inline : bool, default False
        Run each job at once, on the caller's thread (same results, no thread; for tests and
        comparisons).

    Examples
    --------
    In a program (`Program.use_background` makes one)::

        for name, result in self.background.tick():  # first thing in every act
            ...swap `result` in...
        self.background.submit("lspi", solve_lspi, samples=..., w=...)
    """

    def __init__(self, lag: int, inline: bool = False) -> None:
        if lag < 1:
            raise ValueError("lag must be >= 1")
        self.lag = lag
        self.inline = inline
        _limit_blas()
        self.clock = 0  # acts so far (ticks)
        # ticks that had to wait for a job (its work took longer than `lag` acts): a measurement of
        # this run's machine, not state (not saved)
        self.waits = 0
        self._jobs: dict[str, _Job] = {}

    def tick(self) -> list[tuple[str, Any]]:
        """Advance one act; return (name, result) of every job due now, in submission order,
        waiting for any that has not finished (a job's exception is raised here)."""
        self.clock += 1
        due = [name for name, job in self._jobs.items() if job.due <= self.clock]
        out = []
        for name in due:
            job = self._jobs.pop(name)
            if not job.done:
                assert job.future is not None
                if not job.future.done():
                    self.waits += 1
                job.result = job.future.result()
            out.append((name, job.result))
        return out

    def submit(self, name: str, fn: Callable[..., Any], **args: Any) -> None:
        """Start job `name`: `fn(**args)` (a module-level function of copies of the program's
        values, which it must not change: they are the job's saved state), due `lag` acts from
        now. One job per name at a time."""
        if name in self._jobs:
            raise RuntimeError(f"background job {name!r} is already running")
        self._start(name, _Job(function_name(fn), args, self.clock + self.lag))

    def _start(self, name: str, job: _Job) -> None:
        fn = resolve(job.fn)
        if self.inline:
            job.result, job.done = fn(**job.args), True
        else:
            job.future = _pool().submit(fn, **job.args)
        self._jobs[name] = job

    def pending(self, name: str | None = None) -> bool:
        """Whether job `name` (any job, if None) is in flight."""
        return bool(self._jobs) if name is None else name in self._jobs

    def wait(self) -> None:
        """Block until every job in flight has finished (they still swap in at their due act)."""
        for job in self._jobs.values():
            if job.future is not None:
                job.future.exception()

    def discard(self, name: str) -> None:
        """Forget job `name` if it is in flight (its result is never swapped in)."""
        job = self._jobs.pop(name, None)
        if job is not None and job.future is not None:
            job.future.cancel()

    def cancel(self) -> None:
        """Forget every job in flight (their results are never swapped in)."""
        for job in self._jobs.values():
            if job.future is not None:
                job.future.cancel()
        self._jobs = {}

    def state(self) -> dict[str, Any]:
        """The act clock and each job in flight (function, arguments, due act); `lag` and `inline`
        are configuration. Arguments are stored as given: the snapshot convention's leaves."""
        return {
            "clock": self.clock,
            "jobs": {name: {"fn": j.fn, "args": j.args, "due": j.due} for name, j in self._jobs.items()},
        }

    def restore(self, state: dict[str, Any]) -> None:
        """Continue from a `state()` snapshot: jobs in flight are started again from their saved
        arguments (pure functions: the same results) and swap in at the same acts."""
        self.cancel()
        self.clock = int(state["clock"])
        for name, j in sorted(state["jobs"].items(), key=lambda kv: int(kv[1]["due"])):
            self._start(name, _Job(str(j["fn"]), dict(j["args"]), int(j["due"])))
