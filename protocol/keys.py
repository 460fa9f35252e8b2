"""Every Zenoh key expression of the project, in one place (see DESIGN.md, "The loop")."""

from __future__ import annotations

import re

PREFIX = "sme/v1"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_SECURE_ENDPOINT = "tls/127.0.0.1:7447"  # with --secure DIR: mutual TLS + access control
DEFAULT_AGENT_ID = "a0"

_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")


def check_id(value: str, what: str = "id") -> str:
    """Ids become key-expression chunks: refuse anything that could widen or break a key."""
    if not isinstance(value, str) or not _ID.fullmatch(value):  # fullmatch: "$" would let "g1\n" in
        raise ValueError(f"invalid {what} {value!r}: use 1-64 characters from A-Z a-z 0-9 _ . -")
    return value


def world_obs(world: str) -> str:
    return f"{PREFIX}/world/{world}/obs"


def world_act(world: str) -> str:
    return f"{PREFIX}/world/{world}/act"


def world_ctl(world: str) -> str:
    return f"{PREFIX}/world/{world}/ctl"


def world_truth(world: str) -> str:
    return f"{PREFIX}/world/{world}/truth"


def world_spec(world: str) -> str:
    return f"{PREFIX}/world/{world}/spec"


def world_event(world: str) -> str:
    """WorldEvent messages: what the world reports about itself (e.g. a refused action)."""
    return f"{PREFIX}/world/{world}/event"


def world_image(world: str, camera: str) -> str:
    """Camera frames as foxglove.RawImage, for standard viewers."""
    return f"{PREFIX}/world/{world}/image/{camera}"


def alive_world(world: str) -> str:
    return f"{PREFIX}/alive/world/{world}"


def alive_agent(agent: str) -> str:
    return f"{PREFIX}/alive/agent/{agent}"


def agent_embedding(agent: str, world: str) -> str:
    return f"{PREFIX}/agent/{agent}/embedding/{world}"


def agent_event(agent: str, world: str) -> str:
    return f"{PREFIX}/agent/{agent}/event/{world}"


def agent_status(agent: str) -> str:
    return f"{PREFIX}/agent/{agent}/status"


ALL = f"{PREFIX}/**"
ALL_OBS = f"{PREFIX}/world/*/obs"
ALL_ALIVE_WORLDS = f"{PREFIX}/alive/world/*"
ALL_EMBEDDINGS = f"{PREFIX}/agent/*/embedding/*"
ALL_EVENTS = f"{PREFIX}/agent/*/event/*"
ALL_WORLD_EVENTS = f"{PREFIX}/world/*/event"


def last_chunk(key: str) -> str:
    return str(key).rsplit("/", 1)[-1]


def world_of(key: str) -> str:
    """The world id in a key under sme/v1/world/{id}/... or .../embedding|event/{id}."""
    parts = str(key).split("/")
    if len(parts) >= 4 and parts[2] == "world":
        return parts[3]
    return parts[-1]
