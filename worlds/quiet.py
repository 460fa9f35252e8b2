"""C code's output on file descriptor 1 kept off a command's stdout (PyBullet prints `argv[0]=...`
when a client connects, panda-gym's included)."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator

_FD_LOCK = threading.Lock()


@contextlib.contextmanager
def stdout_to_stderr() -> Iterator[None]:
    """Send what C code writes to file descriptor 1 to file descriptor 2 meanwhile.

    PyBullet's C code prints `argv[0]=...` on stdout when a client connects; a command's stdout is
    for its own output (`sme demo`'s progress, JSON lines), so that noise goes to stderr. Where
    there is no real stdout (a test's captured stream) nothing is redirected."""
    try:
        out, err = sys.__stdout__.fileno(), sys.__stderr__.fileno()  # type: ignore[union-attr]
    except (AttributeError, OSError, ValueError):
        yield
        return
    with _FD_LOCK:
        sys.stdout.flush()
        saved = os.dup(out)
        try:
            os.dup2(err, out)
            yield
        finally:
            os.dup2(saved, out)
            os.close(saved)
