"""Every Zenoh key expression of the project, in one place (see DESIGN.md, "The loop").

Keys are built from ids checked by `check_id`, so that an id can never widen a subscription
(`*`, `**`) or add a level to a key.

Examples
--------
>>> from sensorimotor.protocol import keys
>>> keys.world_obs("grid0")
'sme/v1/world/grid0/obs'
>>> keys.world_of("sme/v1/agent/a0/embedding/grid0")
'grid0'
"""

from __future__ import annotations

import re

PREFIX = "sme/v1"
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_SECURE_ENDPOINT = "tls/127.0.0.1:7447"  # with --secure DIR: mutual TLS + access control
DEFAULT_AGENT_ID = "a0"

_ID = re.compile(r"[A-Za-z0-9_.-]{1,64}")


def is_id(value: object) -> bool:
    """Whether `value` is a valid id (1-64 characters from A-Z a-z 0-9 _ . -)."""
    return isinstance(value, str) and _ID.fullmatch(value) is not None


def check_id(value: str, what: str = "id") -> str:
    """Ids become key-expression chunks: refuse anything that could widen or break a key."""
    if not isinstance(value, str) or not _ID.fullmatch(value):  # fullmatch: "$" would let "g1\n" in
        raise ValueError(f"invalid {what} {value!r}: use 1-64 characters from A-Z a-z 0-9 _ . -")
    return value


def world_obs(world: str) -> str:
    """Key of a world's observations (Observation messages, one per step)."""
    return f"{PREFIX}/world/{world}/obs"


def world_act(world: str) -> str:
    """Key of the actions that answer a world's observations (Action messages)."""
    return f"{PREFIX}/world/{world}/act"


def world_ctl(world: str) -> str:
    """Key of a world's perturbations (Control messages, applied between steps)."""
    return f"{PREFIX}/world/{world}/ctl"


def world_truth(world: str) -> str:
    """Queryable key of a world's ground truth (Truth; for evaluation only)."""
    return f"{PREFIX}/world/{world}/truth"


def world_spec(world: str) -> str:
    """Queryable key of a world's spec (WorldSpec: sensors, action space, program)."""
    return f"{PREFIX}/world/{world}/spec"


def world_event(world: str) -> str:
    """Key of WorldEvent messages: what the world reports about itself (e.g. a refused action)."""
    return f"{PREFIX}/world/{world}/event"


def world_lease(world: str) -> str:
    """Key of a world's lease queryable: owners ask it for the lease (LeaseRequest -> Lease)."""
    return f"{PREFIX}/world/{world}/lease"


def world_image(world: str, camera: str) -> str:
    """Key of a world's camera frames as foxglove.RawImage, for standard viewers."""
    return f"{PREFIX}/world/{world}/image/{camera}"


def alive_world(world: str) -> str:
    """Liveliness-token key of a serving world."""
    return f"{PREFIX}/alive/world/{world}"


def alive_agent(agent: str) -> str:
    """Liveliness-token key of a running agent daemon."""
    return f"{PREFIX}/alive/agent/{agent}"


def alive_owner(owner: str) -> str:
    """Liveliness-token key of a session that may own worlds (an agent daemon or one of its workers)."""
    return f"{PREFIX}/alive/owner/{owner}"


def alive_claim(world: str, owner: str) -> str:
    """Liveliness-token key of owner `owner`'s claim on world `world` (see protocol/README.md, "Owners")."""
    return f"{PREFIX}/alive/claim/{world}/{owner}"


def agent_checkpoint(owner: str, world: str) -> str:
    """Key of the checkpoints (.npz bytes, see agent/checkpoint.py) owner `owner` shares of world `world`."""
    return f"{PREFIX}/agent/{owner}/checkpoint/{world}"


def agent_embedding(agent: str, world: str) -> str:
    """Key of the Embedding messages agent `agent` learns from world `world`."""
    return f"{PREFIX}/agent/{agent}/embedding/{world}"


def agent_event(agent: str, world: str) -> str:
    """Key of the AgentEvent messages (drops, pauses, ...) of agent `agent` about world `world`."""
    return f"{PREFIX}/agent/{agent}/event/{world}"


def agent_status(agent: str) -> str:
    """Key of an agent daemon's AgentStatus messages."""
    return f"{PREFIX}/agent/{agent}/status"


ALL = f"{PREFIX}/**"
ALL_OBS = f"{PREFIX}/world/*/obs"
ALL_ALIVE_WORLDS = f"{PREFIX}/alive/world/*"
ALL_ALIVE_OWNERS = f"{PREFIX}/alive/owner/*"
ALL_ALIVE_AGENTS = f"{PREFIX}/alive/agent/*"
ALL_CLAIMS = f"{PREFIX}/alive/claim/*/*"
ALL_CHECKPOINTS = f"{PREFIX}/agent/*/checkpoint/*"
ALL_STATUS = f"{PREFIX}/agent/*/status"
ALL_EMBEDDINGS = f"{PREFIX}/agent/*/embedding/*"
ALL_EVENTS = f"{PREFIX}/agent/*/event/*"
ALL_WORLD_EVENTS = f"{PREFIX}/world/*/event"


def last_chunk(key: str) -> str:
    """The last ``/``-separated chunk of `key`."""
    return str(key).rsplit("/", 1)[-1]


def world_of(key: str) -> str:
    """The world id in a key under ``sme/v1/world/{id}/...`` or ``.../embedding|event/{id}``."""
    parts = str(key).split("/")
    if len(parts) >= 4 and parts[2] == "world":
        return parts[3]
    return parts[-1]
