"""The /proc readers behind the benchmarks' CPU figures."""

from __future__ import annotations

import os
import subprocess
import sys
import time

from sensorimotor.tools.bench.procstat import (
    busy_fraction,
    children,
    cores_used,
    cpu_ticks,
    machine_cpu,
    proc_sample,
)


def test_a_spinning_child_is_found_and_its_cpu_counted():
    spin = subprocess.Popen([sys.executable, "-c", "import time\nt = time.time()\nwhile time.time() - t < 30: pass"])
    try:
        assert spin.pid in children(os.getpid())
        groups = {"spin": [spin.pid], "none": []}
        before, m0, t0 = cpu_ticks(groups), machine_cpu(), time.perf_counter()
        time.sleep(1.0)
        used = cores_used(before, cpu_ticks(groups), time.perf_counter() - t0)
        assert 0.2 < used["spin"] <= 1.05, used  # one busy thread: at most one core
        assert used["none"] == 0
        busy = busy_fraction(m0, machine_cpu())
        assert busy is not None and 0 < busy <= 1
    finally:
        spin.kill()
        spin.wait()
    assert proc_sample(spin.pid) is None  # gone: None, not an error
    assert cpu_ticks({"gone": [spin.pid]}) == {"gone": 0}


def test_degenerate_readings_give_none_or_nothing():
    assert busy_fraction(None, (1.0, 2.0)) is None
    assert busy_fraction((5.0, 10.0), (5.0, 10.0)) is None
    assert cores_used({"a": 1}, {"a": 2}, 0.0) == {}
    rss, ticks = proc_sample(os.getpid())
    assert rss > 1 and ticks >= 0
