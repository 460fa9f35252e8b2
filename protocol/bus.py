"""The message bus over Eclipse Zenoh: the only module of the project that imports zenoh.

Sessions are built from the flags zenoh's own examples use (`--mode`, `--connect`, `--listen`,
`--config`, `--no-multicast-scouting`). The embedded default needs no router and no config: the
agent daemon is a Zenoh *router* listening on tcp/127.0.0.1:7447 and every other process is a
*client* of it (a router does not forward between peers, so clients are what lets a recorder or a
viewer see world<->agent traffic). Worlds, recorders and viewers wait for the agent to appear
(`retry`); query tools fail fast with a hint. Clients reconnect by themselves when the agent
restarts. Multicast scouting is off and nothing listens beyond loopback.
"""

from __future__ import annotations

import argparse
import collections
import json
import logging
import re
import socket
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import zenoh

from sensorimotor.protocol import security
from sensorimotor.protocol.keys import DEFAULT_ENDPOINT, DEFAULT_SECURE_ENDPOINT

log = logging.getLogger("sme.bus")


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


class BusError(RuntimeError):
    """The bus could not be opened or used; the message says what to do."""


class BusMessage(NamedTuple):
    """One sample as the bus hands it to callbacks and inboxes.

    Attributes
    ----------
    key : str
        The key expression it was published on.
    payload : bytes
        The raw payload (decode it with `codec.decode`).
    encoding : str
        Zenoh's encoding string, e.g. ``application/protobuf;sme.v1.Observation``.
    kind : str
        ``put``, or ``delete`` (a liveliness token vanished).
    """

    key: str
    payload: bytes
    encoding: str
    kind: str = "put"  # "put" or "delete"


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


def _encoding_str(sample: Any) -> str:
    try:
        return str(sample.encoding)
    except Exception:  # pragma: no cover - defensive: foreign encodings
        return ""


def _message(sample: Any) -> BusMessage:
    kind = "delete" if sample.kind == zenoh.SampleKind.DELETE else "put"
    return BusMessage(str(sample.key_expr), sample.payload.to_bytes(), _encoding_str(sample), kind)


def _guard(callback: Callable[[BusMessage], None], what: str) -> Callable[[Any], None]:
    """Zenoh callbacks run on zenoh's threads: an exception must be logged, never lost silently."""

    def run(sample: Any) -> None:
        try:
            callback(_message(sample))
        except Exception:
            log.exception("callback for %s failed", what)

    return run


COLLECT_GRACE = 5.0  # seconds a query may outlast its own timeout before its replies are taken as they are


def _collect(start: Callable[[Any], Any], timeout: float) -> tuple[list[Any], bool]:
    """The replies of a zenoh query started by `start(handler)`, gathered by a callback.

    Not zenoh's default handler: that is a FIFO of 256 replies which the caller drains only once the
    query call has returned, and a session answers the part of a query it can from its own tables
    (a router: every liveliness token it knows; any session: its own tokens) inside that call, with
    its state locked. With more than 256 such replies the call waited forever for room, every
    other use of the session (puts included) waited for the lock, and the process stopped
    answering (issue 41: `sme bench fuzz` declares ~800 fake worlds). The callback only appends,
    on a thread of its own (indirect), so it never holds the session up; its `drop` says the query
    is over (all replies in, or `timeout` passed). Returns the replies and whether the query ended
    before its timeout (else replies may be missing).
    """
    got: list[Any] = []
    done = threading.Event()
    t0 = time.monotonic()
    start(zenoh.handlers.Callback(got.append, done.set))
    over = done.wait(timeout + COLLECT_GRACE)
    if not over:
        log.warning(
            "a query was not over %.1f s after its %.1f s timeout; using its %d replies",
            COLLECT_GRACE,
            timeout,
            len(got),
        )
    return list(got), over and time.monotonic() - t0 < timeout * 0.95


class Inbox:
    """A bounded queue filled by a subscriber: when full, the oldest message is dropped and counted."""

    def __init__(self, maxsize: int) -> None:
        if maxsize < 1:
            raise ValueError("maxsize must be >= 1")
        self.maxsize = maxsize
        self._q: collections.deque[BusMessage] = collections.deque()
        self._cv = threading.Condition()
        self.dropped = 0
        self._closed = False

    def push(self, msg: BusMessage) -> None:
        """Append `msg`, dropping (and counting in `dropped`) the oldest one when full."""
        with self._cv:
            if len(self._q) >= self.maxsize:
                self._q.popleft()
                self.dropped += 1
            self._q.append(msg)
            self._cv.notify()

    def get(self, timeout: float | None = None) -> BusMessage | None:
        """The oldest message, or None after `timeout` seconds (or once closed and empty)."""
        with self._cv:
            if not self._q and not self._closed:
                self._cv.wait(timeout)
            return self._q.popleft() if self._q else None

    def close(self) -> None:
        """Wake every waiting `get`; later gets return what is left, then None."""
        with self._cv:
            self._closed = True
            self._cv.notify_all()

    def __len__(self) -> int:
        return len(self._q)


class Publisher:
    """A declared publisher; its encoding (schema) was set at declaration."""

    def __init__(self, pub: Any) -> None:
        self._pub = pub
        self.put = pub.put  # bound once: this is the lockstep hot path


class Bus:
    """A Zenoh session with the few operations the project needs.

    Always use it as a context manager: a session with declared callbacks keeps the interpreter
    alive until it is closed. Callbacks run on zenoh's threads; an exception in one is logged.

    Parameters
    ----------
    config : BusConfig
        How to open the session.
    wait_limit : float or None, default=None
        With ``config.retry``, give up waiting for the router after this many seconds
        (None: wait until interrupted).

    Raises
    ------
    BusError
        If the session cannot be opened; the message hints at the fix.

    Examples
    --------
    >>> from sensorimotor.protocol import codec, keys, messages
    >>> from sensorimotor.protocol.bus import Bus, BusConfig
    >>> with Bus(BusConfig.for_role("tool")) as bus:  # doctest: +SKIP
    ...     (reply,) = bus.get(keys.world_spec("grid0"))
    ...     spec = codec.decode(messages.WorldSpec, reply.payload)
    """

    def __init__(self, config: BusConfig, wait_limit: float | None = None) -> None:
        self.config = config
        try:
            self._session = self._open(config, wait_limit)
        except zenoh.ZError as e:
            why = zenoh_words(e)
            if config.mode == "client":
                refused = refusal(config)
                if refused is not None:
                    raise BusError(f"{refused}. Fix the credentials, or use the ones the router accepts.") from None
                where = ", ".join(config.connect) or "(no --connect endpoint)"
                raise BusError(
                    f"no agent at {where} ({why}). Start one with `sme agent` (add --listen ENDPOINT for another "
                    f"address), or pass --connect ENDPOINT to reach the one that runs elsewhere."
                ) from None
            if config.mode == "router":
                where = ", ".join(config.listen) or "(no --listen endpoint)"
                raise BusError(
                    f"cannot listen on {where} ({why}). Is another agent (or `sme demo`) already listening there? "
                    "Stop it, or pass --listen ENDPOINT to pick another address."
                ) from None
            raise BusError(f"cannot open zenoh session ({config.describe()}): {why}") from None
        self._declared: list[Any] = []
        self._lock = threading.Lock()
        self._closed = False

    @staticmethod
    def _open(config: BusConfig, wait_limit: float | None) -> zenoh.Session:
        zc = config.zenoh_config()
        if not (config.retry and config.mode == "client"):
            return zenoh.open(zc)
        told = False
        deadline = None if wait_limit is None else time.monotonic() + wait_limit
        while True:
            try:
                return zenoh.open(zc)
            except zenoh.ZError:
                if deadline is not None and time.monotonic() >= deadline:
                    raise
                if not told:
                    refused = refusal(config)
                    if refused is not None:  # waiting does not fix credentials, but the router's may change
                        log.warning("%s; trying again (Ctrl-C gives up)", refused)
                    else:
                        log.warning(
                            "waiting for the agent at %s (start `sme agent`; Ctrl-C gives up)",
                            ", ".join(config.connect),
                        )
                    told = True
                time.sleep(0.5)

    # context manager ---------------------------------------------------------------------------
    def __enter__(self) -> Bus:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def close(self) -> None:
        """Close the session (and everything declared on it); closing twice is harmless."""
        with self._lock:
            if self._closed:
                return
            self._closed = True
        try:
            self._session.close()
        except Exception:  # pragma: no cover - closing twice or during interpreter shutdown
            log.debug("session close failed", exc_info=True)

    @property
    def closed(self) -> bool:
        """Whether `close` was called."""
        return self._closed

    @staticmethod
    def encoding(schema: str | None) -> Any:
        """The zenoh encoding of a protobuf message called `schema` (octet-stream for None)."""
        if schema is None:
            return zenoh.Encoding.APPLICATION_OCTET_STREAM
        return zenoh.Encoding.APPLICATION_PROTOBUF.with_schema(schema)

    # publish -----------------------------------------------------------------------------------
    def publisher(self, key: str, schema: str | None = None, *, express: bool = True, block: bool = True) -> Publisher:
        """Declare a publisher on `key`.

        Parameters
        ----------
        key : str
            The key expression (see `keys`).
        schema : str or None, default=None
            The protobuf full name of the messages (`codec.schema_name`), carried in the encoding.
        express : bool, default=True
            Send at once instead of batching (lower latency).
        block : bool, default=True
            True (reliable, congestion BLOCK) for lockstep traffic; False drops under congestion
            (for best-effort live views). A reader that stalls (a recorder, viewer or watcher frozen
            or too slow) holds BLOCK traffic up for at most ~1 s: the agent's router closes a link
            that cannot take a message for `BLOCKED_LINK_CLOSE_US` (zenoh's default: 5 s), readers
            have a 1 s lease and no shared memory (see `BusConfig.for_role`); the reader reconnects
            when it runs again and counts what it missed.

        Returns
        -------
        Publisher
            Its ``put(payload)`` sends one message.
        """
        cc = zenoh.CongestionControl.BLOCK if block else zenoh.CongestionControl.DROP
        pub = self._session.declare_publisher(
            key, express=express, congestion_control=cc, encoding=self.encoding(schema)
        )
        self._declared.append(pub)
        return Publisher(pub)

    def put(self, key: str, payload: bytes, schema: str | None = None) -> None:
        """Publish one message on `key` without declaring a publisher (for occasional messages).

        Parameters
        ----------
        key : str
            The key expression.
        payload : bytes
            The serialized message.
        schema : str or None, default=None
            The protobuf full name of the message, carried in the encoding.
        """
        self._session.put(key, payload, encoding=self.encoding(schema), express=True)

    # subscribe ---------------------------------------------------------------------------------
    def subscribe(self, key: str, callback: Callable[[BusMessage], None]) -> Any:
        """Call `callback` with every message published on `key`.

        Parameters
        ----------
        key : str
            A key expression (wildcards allowed, e.g. `keys.ALL_OBS`).
        callback : callable
            Called as ``callback(BusMessage)`` on a zenoh thread; an exception is logged.

        Returns
        -------
        object
            The zenoh subscriber (pass it to `undeclare` to stop).
        """
        sub = self._session.declare_subscriber(key, _guard(callback, key))
        self._declared.append(sub)
        return sub

    def inbox(self, key: str, maxsize: int = 1024) -> Inbox:
        """Subscribe to `key` into a bounded queue, for consumers that poll instead of reacting.

        Parameters
        ----------
        key : str
            A key expression (wildcards allowed).
        maxsize : int, default=1024
            Messages kept; beyond, the oldest are dropped and counted.

        Returns
        -------
        Inbox
        """
        box = Inbox(maxsize)
        self.subscribe(key, box.push)
        return box

    # query -------------------------------------------------------------------------------------
    def queryable(self, key: str, handler: Callable[[str, bytes | None], bytes], schema: str | None = None) -> Any:
        """Answer `get`s on `key` with `handler(key, payload)`.

        Parameters
        ----------
        key : str
            The key expression to answer on.
        handler : callable
            ``handler(key, payload) -> bytes``, where `payload` is the query's payload or None.
            An exception becomes an error reply (a LookupError is logged at debug level only:
            "nothing to answer" is expected).
        schema : str or None, default=None
            The protobuf full name of the replies.

        Returns
        -------
        object
            The zenoh queryable (pass it to `undeclare` to stop).
        """
        enc = self.encoding(schema)

        def on_query(query: Any) -> None:
            try:
                payload = query.payload.to_bytes() if query.payload is not None else None
                reply = handler(str(query.key_expr), payload)
                query.reply(query.key_expr, reply, encoding=enc)
            except Exception as e:
                (log.debug if isinstance(e, LookupError) else log.warning)("queryable %s: %s", key, e)
                try:
                    query.reply_err(str(e).encode())
                except Exception:  # pragma: no cover
                    pass

        q = self._session.declare_queryable(key, on_query)
        self._declared.append(q)
        return q

    def get(self, key: str, timeout: float = 2.0, payload: bytes | None = None) -> list[BusMessage]:
        """Query `key` and collect the replies.

        Parameters
        ----------
        key : str
            The key expression (wildcards gather one reply per matching queryable).
        timeout : float, default=2.0
            Seconds to wait for replies.
        payload : bytes or None, default=None
            Sent with the query.

        Returns
        -------
        list of BusMessage
            The replies (empty when nobody answered in time).

        Raises
        ------
        BusError
            If a queryable answered with an error and none answered with a value; the message
            carries the error's text. (A query that reaches one queryable along two routes can
            get a value along one and a timeout error along the other: the value counts.)
        """
        out = []
        error: str | None = None
        # every matching queryable answers (a wildcard gathers one reply per agent), none consolidated away
        replies = self._session.get(
            key,
            timeout=timeout,
            payload=payload,
            target=zenoh.QueryTarget.ALL,
            consolidation=zenoh.ConsolidationMode.NONE,
        )
        for reply in replies:
            if reply.ok is not None:
                out.append(_message(reply.ok))
            elif error is None:
                err = reply.err
                error = err.payload.to_bytes().decode(errors="replace") if err is not None else "empty reply"
        if error is not None and not out:
            raise BusError(f"query {key}: {error}")
        return out

    # liveliness --------------------------------------------------------------------------------
    def token(self, key: str) -> Any:
        """Declare a liveliness token on `key` (it vanishes when undeclared or the process dies).

        Parameters
        ----------
        key : str
            The token's key (`keys.alive_world`, `keys.alive_agent`).

        Returns
        -------
        object
            The zenoh token (pass it to `undeclare` to withdraw it).
        """
        tok = self._session.liveliness().declare_token(key)
        self._declared.append(tok)
        return tok

    def watch_alive(self, key: str, on_change: Callable[[str, bool], None], history: bool = True) -> Any:
        """Call `on_change(key, alive)` when a liveliness token matching `key` appears or vanishes.

        Parameters
        ----------
        key : str
            A key expression (wildcards allowed, e.g. `keys.ALL_ALIVE_WORLDS`).
        on_change : callable
            ``on_change(token_key, alive)`` on a zenoh thread.
        history : bool, default=True
            Also report the tokens alive already.

        Returns
        -------
        object
            The zenoh subscriber (pass it to `undeclare` to stop).
        """

        def cb(msg: BusMessage) -> None:
            on_change(msg.key, msg.kind == "put")

        sub = self._session.liveliness().declare_subscriber(key, _guard(cb, key), history=history)
        self._declared.append(sub)
        return sub

    def alive(self, key: str, timeout: float = 1.0, complete: bool = False) -> list[str]:
        """The keys of the liveliness tokens matching `key` alive now.

        Parameters
        ----------
        key : str
            A key expression (wildcards allowed).
        timeout : float, default=1.0
            Seconds to wait for the answer.
        complete : bool, default=False
            Raise BusError when some route answered with an error or the query ran out of time (the
            list may then lack tokens) instead of returning what came. Even a complete answer can
            lack a token under load (a reply lost on its way): a token's absence is weaker evidence
            than its presence.

        Returns
        -------
        list of str
        """
        out = []
        replies, in_time = _collect(lambda h: self._session.liveliness().get(key, h, timeout=timeout), timeout)
        if complete and not in_time:
            raise BusError(f"liveliness query {key}: no end of the answer within {timeout:g} s")
        for r in replies:
            if r.ok is not None:
                out.append(str(r.ok.key_expr))
            elif complete:
                raise BusError(f"liveliness query {key}: a route answered with an error")
        return list(dict.fromkeys(out))  # a client's own tokens are answered by itself and by its router

    def undeclare(self, entity: Any) -> None:
        """Undeclare a publisher (a `Publisher` or the zenoh one), subscriber, queryable or token made
        by this bus (no error if gone)."""
        if isinstance(entity, Publisher):
            entity = entity._pub
        try:
            entity.undeclare()
        except Exception:  # pragma: no cover - already gone with a closed session
            pass
        if entity in self._declared:
            self._declared.remove(entity)
