"""How a bus session is opened: `BusConfig` (mode, endpoints, credential; the embedded defaults
per role; its `zenoh.Config`), the zenoh example flags every command takes (`add_bus_arguments`,
`bus_config_from_args`), and the words a refused or failed session is explained with.

With `protocol.bus` the only module that imports zenoh (for `zenoh.Config` and key-expression checks).
"""

from __future__ import annotations

import argparse
import json
import re
import socket
from dataclasses import dataclass, replace

import zenoh

from sensorimotor.protocol import security
from sensorimotor.protocol.bus_types import BusError
from sensorimotor.protocol.keys import DEFAULT_ENDPOINT, DEFAULT_SECURE_ENDPOINT


def zenoh_words(e: BaseException) -> str:
    """A zenoh error's message for people: without the Rust source location zenoh appends
    (`at /root/.cargo/.../orchestrator.rs:447.`), which says nothing to a user."""
    text = re.sub(r"\s+at\s+\S+\.rs:\d+\.?", "", str(e)).strip().rstrip(".!")
    if text.startswith("Unable to connect to any of"):
        return "nothing answered there"
    return text or type(e).__name__


def _listening(endpoint: str, timeout: float = 0.5) -> bool:
    """Whether something accepts a TCP connection at a tcp/ or tls/ `endpoint` (False otherwise)."""
    proto, _, rest = endpoint.partition("/")
    if proto not in ("tcp", "tls"):
        return False
    host, _, port = re.split(r"[?#]", rest, maxsplit=1)[0].rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            return True
    except (OSError, ValueError):
        return False


def refusal(config: BusConfig) -> str | None:
    """Why a client session was not opened when a router does listen at one of its endpoints: it
    refused the session's handshake, i.e. its authentication (None: nothing listens there)."""
    where = [ep for ep in config.connect if _listening(ep)]
    if not where:
        return None
    text = ""
    if config.config_file:
        try:
            with open(config.config_file, encoding="utf-8", errors="replace") as f:
                text = f.read(1_000_000)
        except OSError:
            pass
    if "usrpwd" in text:
        how = (
            f"the user and password of transport/auth/usrpwd in {config.config_file} are not in the router's "
            "dictionary file"
        )
    elif config.secure_dir:
        how = f"the router does not accept the certificate of {config.secure_dir}"
    else:
        how = "the router requires authentication (user/password or TLS) this session does not offer"
    return f"the router at {where[0]} refused this session: authentication refused ({how})"


READER_LEASE_MS = 1000  # see BusConfig.for_role
BLOCKED_LINK_CLOSE_US = 1_000_000  # see BusConfig.zenoh_config


@dataclass(frozen=True)
class BusConfig:
    """How to open a session: mode, endpoints, and (with `secure_dir`) the credential to present.

    `credential` is the role whose certificate this session presents on a secure bus (`agent`,
    `world`, `tool`, `perturb`; see `protocol.security`); `secure_dir` the directory made by
    `sme secure init`. A secure router listens with mutual TLS and enforces the access-control rules
    of `security.acl_rules()`; a secure client presents its certificate.
    """

    mode: str = "client"
    connect: tuple[str, ...] = (DEFAULT_ENDPOINT,)
    listen: tuple[str, ...] = ()
    config_file: str | None = None
    multicast_scouting: bool = False
    lease_ms: int | None = None
    retry: bool = False  # client: wait for the router to appear instead of failing
    credential: str = "tool"
    secure_dir: str | None = None
    # False for readers (record, watch, view): a reader that stalls must not hold the publishers'
    # shared-memory buffers (their pool runs dry and the world's observations fall back to slow copies)
    shared_memory: bool = True

    ROLES = ("agent", "world", "reader", "tool", "perturb")

    @classmethod
    def for_role(cls, role: str, endpoint: str | None = None, secure_dir: str | None = None) -> BusConfig:
        """Embedded defaults per role.

        Parameters
        ----------
        role : str
            ``agent``: router listening on `endpoint` (agent credential); ``world``: client that waits
            for the agent (world credential; also `sme replay`); ``reader``: client that waits, tool
            credential (record, watch, view); ``tool``: client that fails fast, tool credential
            (status); ``perturb``: client that fails fast, perturb credential.
        endpoint : str, optional
            Default `tcp/127.0.0.1:7447`, or `tls/127.0.0.1:7447` with `secure_dir`.
        secure_dir : str, optional
            Credentials from `sme secure init`: the session uses TLS with this role's certificate.
        """
        ep = endpoint or (DEFAULT_SECURE_ENDPOINT if secure_dir else DEFAULT_ENDPOINT)
        if role == "agent":
            return cls(mode="router", connect=(), listen=(ep,), credential="agent", secure_dir=secure_dir)
        clients = {
            "world": (True, "world"),
            "reader": (True, "tool"),
            "tool": (False, "tool"),
            "perturb": (False, "perturb"),
        }
        if role in clients:
            retry, cred = clients[role]
            return cls(
                mode="client",
                connect=(ep,),
                listen=(),
                retry=retry,
                credential=cred,
                secure_dir=secure_dir,
                shared_memory=role != "reader",
                # a reader frozen or too slow to read its link holds up every BLOCK message routed to
                # it; the router closes its link after this lease, the reader reconnects when it runs
                # again and counts what it missed
                lease_ms=READER_LEASE_MS if role == "reader" else None,
            )
        raise ValueError(f"unknown bus role {role!r}; one of {cls.ROLES}")

    def check_secure(self) -> security.Credential | None:
        """The credential files of a secure session (BusError if missing or if an endpoint is not tls/)."""
        if not self.secure_dir:
            return None
        plain = [e for e in (*self.connect, *self.listen) if not e.startswith("tls/")]
        if plain:
            raise BusError(
                f"--secure needs tls/ endpoints (e.g. {DEFAULT_SECURE_ENDPOINT}), not {', '.join(plain)}: "
                "anything else would bypass mutual TLS"
            )
        try:
            return security.credential(self.secure_dir, self.credential)
        except ValueError as e:
            raise BusError(str(e)) from None

    def zenoh_config(self) -> zenoh.Config:
        """This configuration as a `zenoh.Config` (BusError for an unknown mode)."""
        if self.mode not in ("router", "peer", "client"):
            raise BusError(f"--mode must be router, peer or client, not {self.mode!r}")
        cfg = zenoh.Config.from_file(self.config_file) if self.config_file else zenoh.Config()
        cfg.insert_json5("mode", json.dumps(self.mode))
        cfg.insert_json5("connect/endpoints", json.dumps(list(self.connect)))
        cfg.insert_json5("listen/endpoints", json.dumps(list(self.listen)))
        cfg.insert_json5("scouting/multicast/enabled", json.dumps(self.multicast_scouting))
        cfg.insert_json5("scouting/gossip/enabled", "false" if self.mode != "router" else "true")
        if self.lease_ms:
            cfg.insert_json5("transport/link/tx/lease", str(int(self.lease_ms)))
        if not self.shared_memory:
            cfg.insert_json5("transport/shared_memory/enabled", "false")
        if self.mode == "router" and not self.config_file:
            # a link that cannot take a lockstep (BLOCK) message for this long is closed, so that a
            # frozen reader stops the routing of the world's messages for at most this long (zenoh's
            # default is 5 s); a live agent or worker drains its link in microseconds
            cfg.insert_json5(
                "transport/link/tx/queue/congestion_control/block/wait_before_close", str(BLOCKED_LINK_CLOSE_US)
            )
        cred = self.check_secure()
        if cred is not None:
            tls = {
                "root_ca_certificate": cred.ca,
                "enable_mtls": True,
                "connect_certificate": cred.cert,
                "connect_private_key": cred.key,
                "verify_name_on_connect": True,
            }
            if self.listen:
                tls.update(listen_certificate=cred.cert, listen_private_key=cred.key)
            for k, v in tls.items():
                cfg.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
            if self.mode != "client":  # routers and peers accept connections: they enforce the rules
                cfg.insert_json5("access_control", json.dumps(security.acl_rules()))
        return cfg

    def describe(self) -> str:
        """One line for logs and --help, e.g. ``client connecting to tcp/127.0.0.1:7447``."""
        ends = ",".join(self.listen if self.mode == "router" else self.connect) or "-"
        wait = " (waits for it)" if self.retry and self.mode == "client" else ""
        sec = f", mutual TLS as {security.common_name(self.credential)}" if self.secure_dir else ""
        return f"{self.mode} {'listening on' if self.mode == 'router' else 'connecting to'} {ends}{wait}{sec}"

    def exposure_warning(self) -> str | None:
        """A warning when this is a router listening beyond loopback without `--secure`."""
        return security.exposure_warning(self.mode, self.listen, bool(self.secure_dir))


def add_bus_arguments(parser: argparse.ArgumentParser, role: str) -> None:
    """Add the zenoh example flags to `parser`, with this role's embedded default explained in --help.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The command's parser; the flags go in a ``zenoh`` argument group.
    role : {"agent", "world", "tool"}
        Whose defaults to show (see `BusConfig.for_role`).
    """
    d = BusConfig.for_role(role)
    g = parser.add_argument_group(
        "zenoh", f"bus session (default for this command: {d.describe()}; no multicast, loopback only)"
    )
    g.add_argument(
        "--mode", choices=["router", "peer", "client"], default=None, help=f"zenoh session mode (default: {d.mode})"
    )
    g.add_argument(
        "-e",
        "--connect",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to connect to, repeatable (default: %s)" % (",".join(d.connect) or "none"),
    )
    g.add_argument(
        "-l",
        "--listen",
        action="append",
        default=None,
        metavar="ENDPOINT",
        help="endpoint to listen on, repeatable (default: %s)" % (",".join(d.listen) or "none"),
    )
    g.add_argument(
        "-c",
        "--config",
        default=None,
        metavar="FILE",
        help="zenoh JSON5 configuration file; the flags above override it",
    )
    g.add_argument(
        "--no-multicast-scouting",
        action="store_true",
        help="disable multicast scouting (already the default; accepted for zenoh compatibility)",
    )
    g.add_argument(
        "--multicast-scouting",
        action="store_true",
        help="enable multicast scouting (off by default: it reaches beyond this machine)",
    )
    cred = d.credential
    what = "listens with mutual TLS and enforces access control" if role == "agent" else "presents"
    g.add_argument(
        "--secure",
        default=None,
        metavar="DIR",
        help=f"locked-down bus with the credentials of `sme secure init DIR`: this command {what} "
        f"(certificate {cred}.pem, common name {security.common_name(cred)}); endpoints must be tls/ "
        f"(default {DEFAULT_SECURE_ENDPOINT})",
    )


def bus_config_from_args(args: argparse.Namespace, role: str) -> BusConfig:
    """The session of a command of `role` from its parsed bus arguments (see `add_bus_arguments`)."""
    cfg = BusConfig.for_role(role, secure_dir=getattr(args, "secure", None))
    if args.mode:
        cfg = replace(cfg, mode=args.mode)
    if args.connect is not None:
        cfg = replace(cfg, connect=tuple(args.connect))
    if args.listen is not None:
        cfg = replace(cfg, listen=tuple(args.listen))
    if args.config:
        cfg = replace(cfg, config_file=args.config)
    if cfg.mode != "client":
        cfg = replace(cfg, retry=False)
    elif args.listen is None:
        cfg = replace(cfg, listen=())  # a client listens on nothing unless told (not the role's router default)
    return replace(cfg, multicast_scouting=bool(args.multicast_scouting and not args.no_multicast_scouting))


def check_key_expr(expr: str) -> str:
    """`expr` if it is a valid zenoh key expression, else ValueError saying why (for command-line
    arguments: a usage error, not a traceback from the subscriber)."""
    try:
        zenoh.KeyExpr(expr)
    except Exception as e:  # noqa: BLE001 - zenoh raises its own ZError
        why = str(e).split(" at /", 1)[0]  # zenoh appends its source location
        raise ValueError(f"not a valid key expression: {expr!r} ({why})") from None
    return expr
