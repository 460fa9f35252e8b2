"""PyBullet's start-up lines kept out of a command's output: its C code prints ``pybullet build time:
...`` on import and ``argv[0]=`` when a client connects (panda-gym's included), on file
descriptors 1 and 2, where Python cannot catch them. They say nothing to a user."""

from __future__ import annotations

import contextlib
import ctypes
import os
import re
import sys
import tempfile
import threading
from collections.abc import Iterator

_FD_LOCK = threading.Lock()
_INSIDE = threading.local()  # this thread holds the descriptors already (a nested call)
#: PyBullet's start-up lines: dropped; every other line written meanwhile is passed on
NOISE = re.compile(rb"^(pybullet build time: .*|argv\[\d+\]=.*)$")


def _flush_c_stdio() -> None:
    try:
        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):
        pass


@contextlib.contextmanager
def pybullet_quiet() -> Iterator[None]:
    """Hold what is written to file descriptors 1 and 2 meanwhile, then pass it on to the same
    descriptor without PyBullet's start-up lines (`NOISE`). Where there is no real stdout (a test's
    captured stream) nothing is held."""
    try:
        fds = (sys.__stdout__.fileno(), sys.__stderr__.fileno())  # type: ignore[union-attr]
    except (AttributeError, OSError, ValueError):
        yield
        return
    if getattr(_INSIDE, "held", False):  # e.g. a user's module that makes a world while it is imported
        yield
        return
    with _FD_LOCK:
        _INSIDE.held = True
        try:
            with _held(fds):
                yield
        finally:
            _INSIDE.held = False


@contextlib.contextmanager
def _held(fds: tuple[int, ...]) -> Iterator[None]:
    for f in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            f.flush()
    _flush_c_stdio()
    held = []
    for fd in fds:
        tmp = tempfile.TemporaryFile()
        held.append((fd, os.dup(fd), tmp))
        os.dup2(tmp.fileno(), fd)
    try:
        yield
    finally:
        for f in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                f.flush()
        _flush_c_stdio()
        for fd, saved, tmp in held:
            os.dup2(saved, fd)
            os.close(saved)
            tmp.seek(0)
            kept = b"".join(ln for ln in tmp.read().splitlines(keepends=True) if not NOISE.match(ln.rstrip(b"\r\n")))
            tmp.close()
            while kept:
                kept = kept[os.write(fd, kept) :]
