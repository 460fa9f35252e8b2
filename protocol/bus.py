"""The message bus over Eclipse Zenoh: with `protocol.bus_config`, the only code that imports zenoh.

Sessions are built from the flags zenoh's own examples use (`--mode`, `--connect`, `--listen`,
`--config`, `--no-multicast-scouting`). The embedded default needs no router and no config: the
agent daemon is a Zenoh *router* listening on tcp/127.0.0.1:7447 and every other process is a
*client* of it (a router does not forward between peers, so clients are what lets a recorder or a
viewer see world<->agent traffic). Worlds, recorders and viewers wait for the agent to appear
(`retry`); query tools fail fast with a hint. Clients reconnect by themselves when the agent
restarts. Multicast scouting is off and nothing listens beyond loopback.

The session's settings and command-line flags live in `protocol.bus_config`, its plain types
(`BusError`, `BusMessage`, `Inbox`, `Publisher`) in `protocol.bus_types`; all are importable from
here as before.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from typing import Any

import zenoh

from sensorimotor.protocol.bus_config import (
    BLOCKED_LINK_CLOSE_US,
    READER_LEASE_MS,
    BusConfig,
    add_bus_arguments,
    bus_config_from_args,
    check_key_expr,
    refusal,
    zenoh_words,
)
from sensorimotor.protocol.bus_types import BusError, BusMessage, Inbox, Publisher

log = logging.getLogger("sme.bus")

__all__ = [
    "BLOCKED_LINK_CLOSE_US",
    "READER_LEASE_MS",
    "Bus",
    "BusConfig",
    "BusError",
    "BusMessage",
    "Inbox",
    "Publisher",
    "add_bus_arguments",
    "bus_config_from_args",
    "check_key_expr",
    "refusal",
    "zenoh_words",
]


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
