"""Small PyBullet helpers shared by the rendered worlds."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from collections.abc import Iterator
from typing import Any

import pybullet as p
from pybullet_utils.bullet_client import BulletClient

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


def direct_client() -> BulletClient:
    """A headless (DIRECT) PyBullet client, its start-up noise kept off stdout."""
    with stdout_to_stderr():
        return BulletClient(connection_mode=p.DIRECT)


def disconnect(client: Any) -> None:
    """Close a BulletClient, ignoring one that is already gone."""
    if client is not None:
        try:
            client.disconnect()
        except p.error:
            pass
