"""The locked-down bus: which credential each role presents, and the router's access-control rules.

A secure directory (made by `sme secure init DIR`) holds a private CA and one key + certificate per
role, each with its own common name. The agent's router listens on `tls/...` with mutual TLS (a
client must present a certificate signed by that CA) and Zenoh access control matches each client
by its certificate's common name. Nothing here imports zenoh: `protocol.bus` turns the plain
dictionaries below into session configuration.

Roles and their files (`DIR/<role>.pem` certificate, `DIR/<role>.key` private key):

- ``agent``: the daemon's router (server certificate) and the agent when it connects as a client.
- ``world``: `sme world`, `sme replay` (it plays worlds back).
- ``tool``: `sme record`, `watch`, `status`, `view`: read-only.
- ``perturb``: `sme perturb`: may only put controls (and hear the worlds' answers to them).
"""

from __future__ import annotations

import ipaddress
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sensorimotor.protocol.keys import PREFIX

CREDENTIALS = ("agent", "world", "tool", "perturb")
CA_FILE = "ca.pem"
CA_KEY_FILE = "ca.key"


def common_name(role: str) -> str:
    """The certificate common name of a credential role (what the router's ACL matches)."""
    if role not in CREDENTIALS:
        raise ValueError(f"unknown credential {role!r}; one of {CREDENTIALS}")
    return f"sme-{role}"


@dataclass(frozen=True)
class Credential:
    """The files one role presents on a secure bus.

    Attributes
    ----------
    role : str
        One of `CREDENTIALS`.
    ca : str
        The CA certificate that signs every certificate of the bus (trust anchor).
    cert, key : str
        This role's certificate and private key (PEM).
    """

    role: str
    ca: str
    cert: str
    key: str


def credential(secure_dir: str | os.PathLike[str], role: str) -> Credential:
    """The files of `role` in `secure_dir`; ValueError naming what is missing.

    Parameters
    ----------
    secure_dir : path
        A directory made by `sme secure init`.
    role : str
        The credential role (`agent`, `world`, `tool`, `perturb`).
    """
    common_name(role)
    d = Path(secure_dir)
    cred = Credential(role, str(d / CA_FILE), str(d / f"{role}.pem"), str(d / f"{role}.key"))
    missing = [p for p in (cred.ca, cred.cert, cred.key) if not os.path.isfile(p)]
    if missing:
        raise ValueError(
            f"--secure {secure_dir}: missing {', '.join(missing)} (the {role!r} credential); "
            f"create the directory with `sme secure init {secure_dir}`"
        )
    return cred


def _rule(rid: str, messages: list[str], flow: str, keys: list[str]) -> dict[str, Any]:
    return {"id": rid, "messages": messages, "flows": [flow], "permission": "allow", "key_exprs": keys}


W = f"{PREFIX}/world/*"
ALL = f"{PREFIX}/**"
DECLARATIONS = ["declare_subscriber", "declare_queryable", "declare_liveliness_subscriber"]
READ = ["declare_subscriber", "query", "declare_liveliness_subscriber", "liveliness_query"]
RECEIVE = ["put", "delete", "reply", "liveliness_token"]

# What each role may send to the router (ingress) beyond reading, and what it may receive (egress).
WORLD_PUTS = [f"{W}/obs", f"{W}/truth", f"{W}/event", f"{W}/image/*"]
WORLD_SERVES = [f"{W}/spec", f"{W}/truth", f"{W}/lease"]
WORLD_READS = [f"{W}/act", f"{W}/ctl"]
AGENT_PUTS = [
    f"{W}/act",
    f"{PREFIX}/agent/*/embedding/*",
    f"{PREFIX}/agent/*/event/*",
    f"{PREFIX}/agent/*/checkpoint/*",
]
AGENT_TOKENS = [f"{PREFIX}/alive/agent/*", f"{PREFIX}/alive/owner/*", f"{PREFIX}/alive/claim/*/*"]
AGENT_SERVES = [f"{PREFIX}/agent/*/status", f"{PREFIX}/agent/*/checkpoint/*"]
PERTURB_PUTS = [f"{W}/ctl"]


def acl_rules() -> dict[str, Any]:
    """The router's `access_control` section: deny by default, allow per role (certificate CN).

    Ingress (client -> router) decides what a role may *send*; egress (router -> client) what it
    may *receive*. Declarations (subscriber, queryable, liveliness subscriber) may be forwarded to
    every role: they carry key names, no data, and clients need them to route.
    """
    rules = [
        # every role: see others' declarations (needed for routing), query the agent's status
        _rule("any-egress-declarations", DECLARATIONS, "egress", [ALL]),
        # world
        _rule("world-puts", ["put", "delete"], "ingress", WORLD_PUTS),
        _rule("world-serves", ["declare_queryable", "reply"], "ingress", WORLD_SERVES),
        _rule("world-token", ["liveliness_token"], "ingress", [f"{PREFIX}/alive/world/*"]),
        _rule("world-subscribes", ["declare_subscriber"], "ingress", WORLD_READS),
        _rule("world-receives", ["put", "delete"], "egress", WORLD_READS),
        _rule("world-is-queried", ["query"], "egress", WORLD_SERVES),
        # the world follows the owners' tokens: a vanished lease holder's lease is free at once
        _rule(
            "world-watches-owners",
            ["declare_liveliness_subscriber", "liveliness_query"],
            "ingress",
            [f"{PREFIX}/alive/owner/*"],
        ),
        _rule("world-sees-owners", ["liveliness_token", "reply"], "egress", [f"{PREFIX}/alive/owner/*"]),
        # agent (as a client or a peer router): reads everything, publishes its own outputs
        _rule("agent-reads", READ, "ingress", [ALL]),
        _rule("agent-receives", RECEIVE + ["query"], "egress", [ALL]),
        _rule("agent-puts", ["put", "delete"], "ingress", AGENT_PUTS),
        _rule("agent-serves", ["declare_queryable", "reply"], "ingress", AGENT_SERVES),
        _rule("agent-token", ["liveliness_token"], "ingress", AGENT_TOKENS),
        # tool: read-only
        _rule("tool-reads", READ, "ingress", [ALL]),
        _rule("tool-receives", RECEIVE, "egress", [ALL]),
        # perturb: put controls; may check that the world is alive
        _rule("perturb-puts", ["put"], "ingress", PERTURB_PUTS),
        _rule("perturb-checks", ["liveliness_query", "query"], "ingress", [f"{PREFIX}/alive/world/*", f"{W}/spec"]),
        _rule("perturb-receives", ["liveliness_token", "reply"], "egress", [f"{PREFIX}/alive/world/*", f"{W}/spec"]),
        # ... and hear the world's answer (control_applied / control_refused)
        _rule("perturb-subscribes", ["declare_subscriber"], "ingress", [f"{W}/event"]),
        _rule("perturb-hears", ["put"], "egress", [f"{W}/event"]),
    ]
    subjects = [{"id": role, "cert_common_names": [common_name(role)]} for role in CREDENTIALS]
    policies = [
        {"id": "p-any", "rules": ["any-egress-declarations"], "subjects": list(CREDENTIALS)},
        {
            "id": "p-world",
            "rules": [r["id"] for r in rules if r["id"].startswith("world-")],
            "subjects": ["world"],
        },
        {
            "id": "p-agent",
            "rules": [r["id"] for r in rules if r["id"].startswith("agent-")],
            "subjects": ["agent"],
        },
        {"id": "p-tool", "rules": [r["id"] for r in rules if r["id"].startswith("tool-")], "subjects": ["tool"]},
        {
            "id": "p-perturb",
            "rules": [r["id"] for r in rules if r["id"].startswith("perturb-")],
            "subjects": ["perturb"],
        },
    ]
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def is_loopback_endpoint(endpoint: str) -> bool:
    """True when a zenoh endpoint (`proto/host:port[#...]`) names a loopback address or localhost."""
    addr = endpoint.split("/", 1)[-1].split("#", 1)[0]
    host = addr.rsplit(":", 1)[0].strip("[]")
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


EXPOSED_WARNING = (
    "the agent listens on {ends} beyond loopback WITHOUT --secure: anyone who can reach that "
    "address can steer every world (publish actions), read every embedding, observation and event, "
    "inject perturbations (controls) and impersonate worlds or the agent. Use `sme secure init DIR` "
    "and `--secure DIR` (mutual TLS + access control), or keep the default loopback endpoint."
)


def exposure_warning(mode: str, listen: tuple[str, ...], secure: bool) -> str | None:
    """The warning for a router listening beyond loopback without `--secure`, else None."""
    if secure or mode != "router":
        return None
    exposed = [e for e in listen if not is_loopback_endpoint(e)]
    return EXPOSED_WARNING.format(ends=", ".join(exposed)) if exposed else None
