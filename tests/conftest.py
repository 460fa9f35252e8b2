"""Shared fixtures: free loopback ports and `sme` subprocesses that every test stops."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO, Any

# One BLAS thread, for this process and the `sme` processes tests start (they inherit the
# environment): the tests' linear algebra is small (LSPI solves of a few hundred features), where
# BLAS threads only contend with the other test processes; on a busy 2-core machine a 256x256 solve
# took 0.16 s threaded against 3 ms on one thread.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import pytest  # noqa: E402
from threadpoolctl import threadpool_limits  # noqa: E402

from sensorimotor.tools.common import free_port  # noqa: E402

threadpool_limits(1, user_api="blas")  # numpy may already be loaded: limit it in place too

ROOT = Path(__file__).resolve().parents[1]

# The longest files (seconds of their slowest tests on CI's 2 cores), run first. The default run
# deals whole files to two xdist workers in collection order (pyproject: `--dist loadfile
# --no-loadscope-reorder`): long files started last would leave one worker running alone at the end.
LONGEST_FIRST = (
    "test_gym_bus.py",  # ~180: learned over the bus (panda 79)
    "test_first_hour.py",  # ~100: the retina demo at its default length (61)
    "test_objectpose.py",  # 24 on CI, its shared fixture 130 under load
    "test_mountaincar_visual.py",  # 47
    "test_recording.py",  # 45
    "test_partition.py",  # 44
    "test_versions_after_kill.py",  # 39
    "test_fuzz_bus.py",  # 36
    "test_churn.py",  # 34
    "test_frozen_reader.py",  # 33
    "test_many_hosts.py",  # 29
    "test_secure_bus.py",  # 25
    "test_owners.py",  # 25
    "test_bench_scale.py",  # 24
    "test_soak.py",  # 20
)


@pytest.fixture(autouse=True)
def _alone_when_marked(request: pytest.FixtureRequest):
    """Under xdist, a test marked `alone` (its figures depend on the machine's load: exact counts
    under a flood, rates) runs while the other worker waits: it holds the session's lock file
    exclusively, every other test holds it shared. Without xdist nothing is locked."""
    uid = os.environ.get("PYTEST_XDIST_TESTRUNUID")
    if uid is None:
        yield
        return
    import fcntl

    with open(_lock_path(uid), "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX if request.node.get_closest_marker("alone") else fcntl.LOCK_SH)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


_OWN_UID = pytest.StashKey[str]()


def _lock_path(uid: str) -> Path:
    import tempfile

    return Path(tempfile.gettempdir()) / f"sme-pytest-{uid}.lock"


def pytest_configure(config: pytest.Config) -> None:
    """The xdist controller names the run (as xdist would, a fresh uuid) so that it knows the lock
    file its workers share, and removes it at the end (`pytest_unconfigure`)."""
    if not hasattr(config, "workerinput") and hasattr(config.option, "testrunuid") and not config.option.testrunuid:
        import uuid

        config.option.testrunuid = config.stash[_OWN_UID] = uuid.uuid4().hex


def pytest_unconfigure(config: pytest.Config) -> None:
    uid = config.stash.get(_OWN_UID, None)  # only the run's own name: one given by --testrunuid may be shared
    if uid:
        _lock_path(uid).unlink(missing_ok=True)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """Put the files of LONGEST_FIRST first, in its order; the rest keep theirs (a stable sort)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))


@pytest.fixture
def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


class Procs:
    """Start `sme ...` subprocesses; all are stopped (SIGINT, then SIGKILL) at teardown."""

    def __init__(self) -> None:
        self.procs: list[subprocess.Popen] = []

    def start(self, *args: str, stdout=subprocess.PIPE, stderr=subprocess.PIPE) -> subprocess.Popen:
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        p = subprocess.Popen(
            [sys.executable, "-m", "sensorimotor.tools.cli", *args],
            cwd=ROOT,
            stdout=stdout,
            stderr=stderr,
            text=True,
            env=env,
        )
        self.procs.append(p)
        return p

    def stop(self, p: subprocess.Popen, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        if p.poll() is None:
            p.send_signal(sig)
            try:
                p.wait(timeout)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        return p.returncode

    def stop_all(self) -> None:
        for p in self.procs:
            self.stop(p)
            for f in (p.stdout, p.stderr):
                if f:
                    f.close()


@pytest.fixture
def procs():
    ps = Procs()
    yield ps
    ps.stop_all()


def wait_for(pred, timeout: float = 20.0, every: float = 0.1):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = pred()
        if v:
            return v
        time.sleep(every)
    return pred()


class Lines:
    """The lines of a process's text stream, read on a background thread as they come, so that a
    test can wait for one (a readiness line) instead of sleeping. Do not read the stream elsewhere."""

    def __init__(self, stream: IO[str]) -> None:
        self.lines: list[str] = []
        threading.Thread(target=self._read, args=(stream,), daemon=True).start()

    def _read(self, stream: IO[str]) -> None:
        try:
            for line in stream:
                self.lines.append(line)
        except (ValueError, OSError):  # closed at teardown
            pass

    def has(self, text: str) -> bool:
        return any(text in line for line in list(self.lines))


def agent_status(ep: str, agent: str = "a0") -> Any:
    """The daemon's AgentStatus, or None while no agent answers on `ep`."""
    from sensorimotor.protocol import codec, keys
    from sensorimotor.protocol.bus import Bus, BusConfig, BusError
    from sensorimotor.protocol.messages import AgentStatus

    try:
        with Bus(BusConfig.for_role("tool", ep)) as bus:
            r = bus.get(keys.agent_status(agent), timeout=2.0)
            return codec.decode(AgentStatus, r[0].payload) if r else None
    except BusError:
        return None  # the agent is not up (yet)


def world_link(st: Any, wid: str) -> Any:
    """The status of world `wid`'s link in an AgentStatus (None if absent)."""
    if st is None:
        return None
    return next((ln for ln in st.links if ln.world_id == wid), None)


def install_entry_point(tmp_path: Path, monkeypatch: Any, dist: str, group: str, line: str) -> None:
    """Make `tmp_path` an installed distribution `dist` (a .dist-info beside its modules) declaring
    `line` (``name = module:Class``) in entry-point group `group`, on sys.path for this test."""
    import importlib

    info = tmp_path / f"{dist.replace('-', '_')}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist}\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text(f"[{group}]\n{line}\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    importlib.invalidate_caches()
