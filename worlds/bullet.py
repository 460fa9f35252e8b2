"""Small PyBullet helpers shared by the rendered worlds."""

from __future__ import annotations

from typing import Any

import pybullet as p


def disconnect(client: Any) -> None:
    """Close a BulletClient, ignoring one that is already gone."""
    if client is not None:
        try:
            client.disconnect()
        except p.error:
            pass
