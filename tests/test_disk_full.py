"""Disks and files: `sme record` to a bad path fails before connecting; a disk that fills while
recording ends the recorder with a clear "disk full" and a file that reads back; a checkpoint on a
full disk keeps the previous one and is logged, not fatal. Full disks are small tmpfs mounts (root
only; skipped with the reason otherwise)."""

from __future__ import annotations

import contextlib
import errno
import logging
import os
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from sensorimotor.agent.checkpoint import write_atomically
from sensorimotor.agent.daemon import AgentDaemon
from sensorimotor.agent.detectors import make_detector
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.programs.registry import make_program
from sensorimotor.tools.inprocess import run_inprocess
from sensorimotor.tools.mcap_io import read, recover
from sensorimotor.worlds.gridworld import GridWorld
from tests.conftest import ROOT, wait_for
from tests.conftest import agent_status as status
from tests.conftest import world_link as link


@contextlib.contextmanager
def tmpfs(path: Path, size: str, read_only: bool = False) -> Iterator[Path]:
    """A tmpfs of `size` mounted on `path` for the duration (unmounted also on failure); the test
    is skipped with the reason when mounting is not permitted."""
    path.mkdir(parents=True, exist_ok=True)
    if os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root")
    opts = f"size={size}" + (",ro" if read_only else "")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(path)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"mount -t tmpfs not permitted here: {r.stderr.strip()}")
    try:
        yield path
    finally:
        subprocess.run(["umount", "-l", str(path)], check=False)


def fill(folder: Path) -> None:
    """Write a filler file in `folder` until the disk is full."""
    with open(folder / "filler", "wb", buffering=0) as f:
        block = b"\0" * 4096
        while True:
            try:
                f.write(block)
            except OSError as e:
                assert e.errno == errno.ENOSPC
                return


def sme(*args: str, timeout: float = 60) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sensorimotor.tools.cli", *args],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


# sme record: a bad path ------------------------------------------------------------------------


def test_record_to_a_missing_directory_fails_before_connecting(tmp_path, endpoint):
    # nobody listens on `endpoint`: a recorder that connected first would wait for the bus instead
    target = tmp_path / "no" / "such" / "dir" / "rec.mcap"
    r = sme("record", str(target), "--connect", endpoint, "--seconds", "30", timeout=20)
    assert r.returncode == 2, r.stderr
    assert "cannot record to" in r.stderr and "does not exist" in r.stderr, r.stderr
    assert not target.parent.exists()


def test_record_to_a_directory_path_fails(tmp_path, endpoint):
    r = sme("record", str(tmp_path), "--connect", endpoint, timeout=20)
    assert r.returncode == 2 and "is a directory" in r.stderr, r.stderr


def test_record_to_a_read_only_directory_fails_before_connecting(tmp_path, endpoint):
    ro = tmp_path / "ro"
    if os.geteuid() == 0:  # root writes through permission bits: a read-only mount stops it
        ctx = tmpfs(ro, "1m", read_only=True)
    else:
        ro.mkdir()
        ro.chmod(0o555)
        ctx = contextlib.nullcontext(ro)
    with ctx:
        r = sme("record", str(ro / "rec.mcap"), "--connect", endpoint, "--seconds", "30", timeout=20)
        assert r.returncode == 2, r.stderr
        assert "cannot record to" in r.stderr and ("Read-only" in r.stderr or "Permission denied" in r.stderr)
        assert not (ro / "rec.mcap").exists()


# sme record: the disk fills ---------------------------------------------------------------------


@pytest.mark.integration
def test_a_disk_that_fills_while_recording_ends_the_recorder_clearly_and_the_file_reads_back(procs, endpoint, tmp_path):
    agent = procs.start("agent", "--listen", endpoint, "-q")
    world = procs.start("world", "bench", "--id", "b1", "--connect", endpoint, "-q")
    assert wait_for(lambda: (ln := link(status(endpoint), "b1")) is not None and ln.steps > 100, 60)
    with tmpfs(tmp_path / "small", "2m") as disk:
        rec = procs.start("record", str(disk / "rec.mcap"), "--connect", endpoint, "--chunk-kb", "64")
        try:
            rc = rec.wait(120)  # 16 KB observations of random floats fill 2 MB within seconds
        finally:
            procs.stop(rec)
        err = rec.stderr.read()
        assert rc == 1, err
        assert "disk full" in err and "rec.mcap" in err and "sme recover" in err, err
        assert "Traceback" not in err, err
        records = list(read(str(disk / "rec.mcap")))
        assert len(records) > 10 and any(r.topic.endswith("/obs") for r in records)
        n = recover(str(disk / "rec.mcap"), str(tmp_path / "recovered.mcap"))
    assert n == len(records) > 10
    assert [r.sequence for r in read(str(tmp_path / "recovered.mcap"))] == [r.sequence for r in records]
    assert agent.poll() is None and world.poll() is None  # the bus and the others go on


# checkpoints on a full disk ---------------------------------------------------------------------


def _daemon_with_link(state_dir: Path) -> tuple[AgentDaemon, WorldLink, GridWorld]:
    world = GridWorld("g1", seed=1)
    spec = world.spec()
    program = make_program(spec, 3)
    detector = make_detector("cusum", **program.detector_params)
    run_inprocess(world, program, 300, detector=detector)
    daemon = AgentDaemon(bus=None, seed=3, state_dir=str(state_dir), detector="cusum")
    lnk = WorldLink("a", spec, program, lambda *a: None, detector)
    lnk.version = 1
    daemon.links[spec.world_id] = lnk
    return daemon, lnk, world


def _check_full_disk_checkpoint(daemon: AgentDaemon, lnk: WorldLink, world, state_dir: Path, caplog) -> None:
    """With the previous checkpoint on disk and the disk full: checkpoint() logs, keeps the old file."""
    path = state_dir / "g1.ckpt.npz"
    old = path.read_bytes()
    run_inprocess(world, lnk.program, 200, detector=lnk.detector)  # learn on: a different checkpoint
    lnk.version = 2
    with caplog.at_level(logging.ERROR, logger="sme.agent"):
        daemon.checkpoint()  # does not raise
    assert any("checkpoint not written" in r.message and "No space left" in r.message for r in caplog.records)
    assert path.read_bytes() == old
    assert not (state_dir / "g1.ckpt.npz.tmp").exists()
    saved = daemon._load_checkpoint(lnk.spec)
    assert saved is not None and saved.version == 1


def test_checkpoint_on_a_full_tmpfs_keeps_the_previous_one(tmp_path, caplog):
    with tmpfs(tmp_path / "state", "1m") as state:
        daemon, lnk, world = _daemon_with_link(state)
        daemon.checkpoint()
        assert (state / "g1.ckpt.npz").exists()
        fill(state)
        _check_full_disk_checkpoint(daemon, lnk, world, state, caplog)
        os.unlink(state / "filler")  # room again: the next checkpoint is written
        daemon.checkpoint()
        assert daemon._load_checkpoint(lnk.spec).version == 2


def test_checkpoint_when_fsync_reports_enospc_keeps_the_previous_one(tmp_path, caplog, monkeypatch):
    daemon, lnk, world = _daemon_with_link(tmp_path)
    daemon.checkpoint()

    def no_space(fd: int) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr("sensorimotor.agent.checkpoint.os.fsync", no_space)
    _check_full_disk_checkpoint(daemon, lnk, world, tmp_path, caplog)


def test_write_atomically_removes_its_temporary_file_on_failure(tmp_path, monkeypatch):
    path = tmp_path / "x.bin"
    write_atomically(str(path), b"old")

    def no_space(fd: int) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr("sensorimotor.agent.checkpoint.os.fsync", no_space)
    with pytest.raises(OSError, match="No space left"):
        write_atomically(str(path), b"new")
    assert path.read_bytes() == b"old" and sorted(p.name for p in tmp_path.iterdir()) == ["x.bin"]
