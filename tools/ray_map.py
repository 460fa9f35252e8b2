"""Run the reproduce jobs on a Ray cluster (`sme reproduce ... --cluster ADDRESS`): one Ray task
per job, results in job order, so `results.json` holds the same numbers as the process pool (every
job is seeded by its arguments). Ray is an optional extra (`pip install 'sensorimotor-embedding[cluster]'`);
the package must be importable on every node of the cluster (the same install, or a Ray runtime_env)."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import Any

from sensorimotor.tools.common import require

log = logging.getLogger("sme.reproduce")


def ray_map(fn: Callable[..., Any], jobs: list[tuple[Any, ...]], address: str) -> list[Any]:
    """``[fn(*job) for job in jobs]``, each call a Ray task on the cluster at `address`.

    Parameters
    ----------
    fn : callable
        A top-level (importable) function: Ray ships it by reference to the workers.
    jobs : list of tuple
        The argument tuples, one task each.
    address : str
        The cluster (``HOST:PORT`` of its head, ``ray://HOST:10001`` for Ray Client, or ``auto``).
        If this process is already connected to a Ray instance, that one is used.

    Returns
    -------
    list
        The results, in job order.
    """
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no usage report leaves the machine
    ray = require("ray", package="ray", extra="cluster")
    if not ray.is_initialized():
        ray.init(address=address, log_to_driver=False, logging_level=logging.WARNING)
        log.info("connected to the Ray cluster at %s: %s", address, ray.cluster_resources())
    task = ray.remote(num_cpus=1)(fn)
    return list(ray.get([task.remote(*job) for job in jobs]))
