"""Small PyBullet helpers shared by the rendered worlds."""

from __future__ import annotations

from typing import Any

import pybullet as p
from pybullet_utils.bullet_client import BulletClient

from sensorimotor.worlds.quiet import pybullet_quiet


def direct_client() -> BulletClient:
    """A headless (DIRECT) PyBullet client, without its start-up line (``argv[0]=``)."""
    with pybullet_quiet():
        return BulletClient(connection_mode=p.DIRECT)


def disconnect(client: Any) -> None:
    """Close a BulletClient, ignoring one that is already gone."""
    if client is not None:
        try:
            client.disconnect()
        except p.error:
            pass
