"""The agent daemon: discovers worlds by liveliness, attaches one link per world, runs each
world's developmental program, answers a status queryable, checkpoints, stops cleanly.

A world that vanishes pauses its link; when it returns (same id) the link resumes with everything
the program learned. With `state_dir`, each link's program is checkpointed atomically and picked up
again by a daemon started later. A world gone longer than `link_ttl` seconds has its link
checkpointed (with `state_dir`) and released from memory, so worlds that come and go do not pile up
links; if it returns, it is attached again through the normal path (restored from its checkpoint,
or fresh without a state dir).

One owner per world (see `agent.ownership` and protocol/README.md, "Owners"): the daemon answers a
world only while it holds the world's claim token and no lower owner id claims it too; several
daemons (or the workers of one, `owner_id`) share the worlds of a bus by count. Each owner shares
its worlds' checkpoints on the bus (`sme/v1/agent/{owner}/checkpoint/{world}`); every daemon keeps
the newest copy of the others', so the survivor of a dead owner resumes its worlds from there.
"""

from __future__ import annotations

import logging
import os
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from sensorimotor.agent.attach import AgentConfig, Restored, attach, program_name, same_body
from sensorimotor.agent.checkpoint import (
    FORMAT_VERSION,
    MAX_VERSION,
    Checkpoint,
    CheckpointError,
    check_shapes,
    encode_checkpoint,
    read_checkpoint,
    set_aside_checkpoint,
    write_atomically,
)
from sensorimotor.agent.checkpoint_store import MAX_SHARED_BYTES, SharedCheckpoints, ShareSchedule
from sensorimotor.agent.detectors import DEFAULT_DETECTOR, make_detector
from sensorimotor.agent.lease import LeaseClient, Outcome, lost_by
from sensorimotor.agent.link import WorldLink, check_truth
from sensorimotor.agent.ownership import OwnerBook, TokenAudit, claim_key, plan
from sensorimotor.agent.programs.registry import PROGRAMS, check_program_params, make_program
from sensorimotor.agent.rate_limit import TokenBucket
from sensorimotor.protocol import codec, keys
from sensorimotor.protocol.bus import Bus, BusError, BusMessage
from sensorimotor.protocol.errors import ProtocolError, SpecMismatch
from sensorimotor.protocol.messages import (
    EXTERNAL_PROGRAM,
    Action,
    AgentEvent,
    AgentStatus,
    Embedding,
    EventKind,
    SharedCheckpoint,
    Truth,
    WorldEvent,
    WorldEventKind,
    WorldSpec,
    clip,
)
from sensorimotor.protocol.params import as_strings, parse

log = logging.getLogger("sme.agent")


def _import_programs() -> None:
    """Import every program's module now, beside the first worlds, not inside a later attach: the
    first world of a kind would otherwise hold the process (its GIL) for the import, ~1.5 s for the
    generic program's scipy.stats and filterpy, while its lockstep worlds wait for their answers."""
    for kind in PROGRAMS.values():
        try:
            kind.program_class()
        except Exception as e:  # noqa: BLE001 - a broken optional dependency: the attach reports it
            log.debug("program module %s not imported: %s", kind.module, e)


class DuplicateAgent(Exception):
    """Another agent (or worker) with this owner id is alive on the bus (the message says which)."""


class _Unrestorable(Exception):
    """A checkpoint whose state this agent's program cannot take (the message says why)."""


class AgentDaemon:
    """The agent daemon: discovers worlds on the bus, attaches a `WorldLink` to each, checkpoints.

    Parameters
    ----------
    bus : Bus
        The message bus (Zenoh session or an in-process stand-in).
    agent_id : str, default keys.DEFAULT_AGENT_ID
        The agent's id in key expressions.
    seed : int, default 0
        Seed of every program's generator.
    state_dir : str, optional
        Directory of the checkpoints (`<world>.ckpt.npz`); without it nothing is saved or loaded.
    checkpoint_every : float, default 30.0
        Seconds between checkpoints while `run` loops.
    program_params : dict, optional
        `{program: {key: value}}` hyperparameters, validated at once.
    on_output : callable, optional
        Also called with `(channel, message)` for every embedding and event published.
    threaded_links : bool, default False
        Run each link on its own thread instead of in the bus callback.
    detector : str, default DEFAULT_DETECTOR
        The drop detector of every link (see `agent.detectors.DETECTORS`).
    link_ttl : float or None, default 600.0
        Seconds after which the link of a world gone is released (None: never).
    owner_id : str, optional
        The id this daemon claims worlds and answers status under (default: `agent_id`); the
        workers of `sme agent --workers N` are owners ``AGENT.wK`` publishing as agent AGENT.
    claim_settle : float, default 0.3
        Seconds a claim is held before the daemon answers the world (a lower claimant seen in that
        time wins); longer than the bus takes to carry a liveliness token between owners.
    claim_delay : float, default 0.3
        Seconds a world must be unclaimed before this daemon claims it (times 1 + its rank among
        the least-loaded owners; 0 for a world it has a paused link for).
    share_every : float or None, default None
        Seconds between checkpoints shared on the bus while another owner is alive (default:
        `checkpoint_every`; None there too: never).
    share_on_embedding : float or None, default 2.0
        Also share a world's checkpoint soon after each new embedding version, at most once per
        this many seconds per world (None: only periodically); see `agent.checkpoint_store`.
    share_max_bytes : int, default MAX_SHARED_BYTES
        Checkpoints larger than this are not shared on the bus (nor accepted from it).
    all_obs : bool, default True
        Subscribe to every world's observations, truth and events (those of worlds it does not answer are
        counted); False: only to the worlds it claims (the workers, so that N workers do not each receive all).
    workers : tuple of str, default ()
        The owner ids of this daemon's worker processes (`sme agent --workers N`): its status adds
        their links and counters, so `sme status --agent ID` shows the whole agent.

    Examples
    --------
    ::

        with AgentDaemon(bus, state_dir="state") as daemon:  # start() ... close()
            daemon.run(seconds=60)
    """

    def __init__(
        self,
        bus: Bus,
        agent_id: str = keys.DEFAULT_AGENT_ID,
        seed: int = 0,
        state_dir: str | None = None,
        checkpoint_every: float = 30.0,
        program_params: dict[str, dict[str, Any]] | None = None,
        on_output: Callable[[str, Any], None] | None = None,
        threaded_links: bool = False,
        detector: str = DEFAULT_DETECTOR,
        link_ttl: float | None = 600.0,
        owner_id: str | None = None,
        claim_settle: float = 0.3,
        claim_delay: float = 0.3,
        share_every: float | None = None,
        workers: tuple[str, ...] = (),
        all_obs: bool = True,
        share_on_embedding: float | None = 2.0,
        share_max_bytes: int = MAX_SHARED_BYTES,
    ) -> None:
        make_detector(detector)  # fail early on an unknown name
        self.detector = detector
        self.bus = bus
        self.threaded_links = threaded_links
        self.agent_id = keys.check_id(agent_id, "agent id")
        self.owner_id = keys.check_id(owner_id or agent_id, "owner id")
        self.claim_settle = claim_settle
        self.claim_delay = claim_delay
        self.share_every = checkpoint_every if share_every is None else share_every
        self.book = OwnerBook()
        self._claims: dict[str, tuple[Any, float]] = {}  # world -> (claim token, monotonic time declared)
        self._avoid: dict[str, float] = {}  # world -> monotonic time until which it is not claimed again
        self.store = SharedCheckpoints(share_max_bytes)  # the newest copy of each world another owner shared
        self._own_shared: dict[str, tuple[float, bytes]] = {}  # world -> (saved_at, bytes) this owner last shared
        self.schedule = ShareSchedule(share_on_embedding) if share_on_embedding is not None else None
        self.leases = LeaseClient(self._lease_get, self.owner_id)
        self._oversize_told: set[str] = set()  # worlds whose checkpoint was too big to share (logged once)
        self._waiting: dict[str, float] = {}  # world -> monotonic time its lease was last refused (asked again)
        self._lost: queue.Queue[tuple[str, WorldEvent]] = queue.Queue()  # lease_lost events, for the run loop
        self._stopped_at: dict[str, float] = {}  # world -> time.time() this daemon last stopped answering it
        self._last_shed = 0.0
        self._bad_ids: set[str] = set()  # world tokens whose id is not a valid id
        self._failed: set[str] = set()  # claimed worlds whose attach failed (until they vanish)
        self._retry_spec: dict[str, float] = {}  # failed for no spec reply (transient?): tried again from then
        self._retried: set[str] = set()  # worlds tried again after no spec reply (their failure was counted)
        self._elsewhere: set[str] = set()  # worlds another owner claimed after this one (a hint: see _newer_elsewhere)
        self._held: dict[str, tuple[int, float]] = {}  # world -> (lease epoch, time granted) last held here
        self._other: dict[str, tuple[str, int, float]] = {}  # world -> (owner, epoch, when) seen elsewhere
        self.workers = tuple(workers)
        self.all_obs = all_obs
        self._obs_subs: dict[str, list[Any]] = {}  # without all_obs: world -> its obs/truth/event subscribers
        self._worker_status: dict[str, AgentStatus] = {}
        self.seed = seed
        self.state_dir = state_dir
        self.checkpoint_every = checkpoint_every
        self.program_params = check_program_params(program_params)  # fail early, typed values only
        self.config = AgentConfig(self.agent_id, seed, detector, self.program_params)
        self.on_output = on_output
        self.links: dict[str, WorldLink] = {}
        self.counters: dict[str, int] = {
            "unattached": 0,
            "attach_failed": 0,
            "bad_truth": 0,
            "bad_world_event": 0,
            "released": 0,  # links of worlds gone longer than link_ttl, released from memory
            "dropped": 0,  # observations dropped unanswered (flood); here those of released links
            "others": 0,  # observations of worlds another owner claims (not answered here)
            "claimed": 0,  # claims declared
            "lost": 0,  # claims withdrawn for a lower claimant
            "shed": 0,  # worlds handed off to balance the load
            "shared": 0,  # checkpoints shared on the bus
            "taken_over": 0,  # links restored from another owner's shared checkpoint
            "shared_on_embedding": 0,  # of the shared, those made soon after a new embedding version
            "share_oversize": 0,  # checkpoints not shared: over share_max_bytes
            "lease_granted": 0,  # leases the worlds granted this owner
            "lease_refused": 0,  # lease requests refused (another live owner holds the world)
            "lease_lost": 0,  # worlds that applied another owner's actions: stopped answering them
            "unfenced": 0,  # attaches to worlds without a lease queryable (answered with epoch 0)
            "bad_checkpoint": 0,  # checkpoints (shared or in the state dir) refused and set aside
            "liveliness_mended": 0,  # tokens whose appearance or disappearance zenoh did not report (TokenAudit)
        }
        if link_ttl is not None and link_ttl <= 0:
            raise ValueError(f"link_ttl must be > 0 seconds (or None: never release), not {link_ttl}")
        self.link_ttl = link_ttl
        self._gone: dict[str, float] = {}  # world id -> time.monotonic() when its token vanished
        self._changes: queue.Queue[tuple[str, bool]] = queue.Queue()
        self._stop = threading.Event()
        self._started = time.time()
        self._started_mono = time.monotonic()
        self._pubs: dict[str, Any] = {}
        self._versions: dict[str, int] = {}  # world -> embedding version high-water mark written
        self._lock = threading.Lock()
        self._ckpt_lock = threading.Lock()
        self._unique_checked = False
        # log lines about refused input (bad truths, world events, checkpoints; worlds that cannot be
        # attached): a few per second at most, every item still counted (hostile input comes at bus speed)
        self._warnings = TokenBucket(self.WARN_RATE)
        if state_dir:
            os.makedirs(state_dir, exist_ok=True)

    WARN_RATE = 5.0  # log lines per second about refused input, at most (see `_warn`)

    def _warn(self, fmt: str, *args: Any) -> None:
        """Log a warning about refused input, rate-limited (`WARN_RATE`); the next line that gets
        through says how many were left out. The counters count every item."""
        if self._warnings.take():
            n = self._warnings.suppressed()
            log.warning(fmt + (f" ({n} similar warnings not logged)" if n else ""), *args)

    # publishing --------------------------------------------------------------------------------
    def _publisher(self, key: str, schema: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            with self._lock:
                pub = self._pubs.get(key) or self.bus.publisher(key, schema)
                self._pubs[key] = pub
        return pub

    def _forget_publishers(self, wid: str) -> None:
        """Undeclare the publishers declared for world `wid` (its link was released)."""
        for key in (
            keys.world_act(wid),
            keys.agent_embedding(self.agent_id, wid),
            keys.agent_event(self.agent_id, wid),
            keys.agent_checkpoint(self.owner_id, wid),
        ):
            with self._lock:
                pub = self._pubs.pop(key, None)
            if pub is not None:
                self.bus.undeclare(pub)

    def publish(self, channel: str, msg: Any) -> None:
        """Publish a link's message on its channel's key (and pass embeddings and events to `on_output`)."""
        wid = msg.world_id
        if channel == "act":
            key = keys.world_act(wid)
        elif channel == "embedding":
            key = keys.agent_embedding(self.agent_id, wid)
            self._persist_version(wid, msg.version)  # before it is published: never reused after a kill
        else:
            key = keys.agent_event(self.agent_id, wid)
        try:
            self._publisher(key, codec.schema_name(type(msg))).put(codec.encode(msg))
        except Exception:
            if not self.bus.closed:
                log.exception("publishing on %s failed", key)
        if channel == "embedding":
            self.store.published(wid, msg.version)
            if self.schedule is not None:
                self.schedule.new_version(wid, time.monotonic())
        if self.on_output is not None and channel != "act":
            self.on_output(channel, msg)

    # embedding versions: a high-water mark per world in the state dir, written before each version is
    # published, so that a link restored from an older checkpoint (a kill -9 since) goes on above it
    def _version_path(self, wid: str) -> str:
        return os.path.join(str(self.state_dir), f"{wid}.version")

    def _persist_version(self, wid: str, version: int) -> None:
        if not self.state_dir or version <= self._versions.get(wid, -1):
            return
        try:
            write_atomically(self._version_path(wid), f"{version}\n".encode())
            self._versions[wid] = version
        except OSError as e:  # a full disk: the version is still published; a restart may reuse it
            log.error("world %s: embedding version high-water mark not written (%s)", wid, e)

    def _version_floor(self, wid: str) -> int:
        """The highest embedding version this state dir has seen published for `wid` (0: none)."""
        if not self.state_dir:
            return 0
        try:
            with open(self._version_path(wid), "rb") as f:
                text = f.read(32).decode("ascii").strip()
            value = int(text)
        except (OSError, ValueError, UnicodeDecodeError):
            return 0
        if not 0 <= value <= MAX_VERSION:
            log.warning(
                "world %s: embedding version high-water mark %s in %s is beyond the wire's range (0 .. %d); ignored",
                wid,
                clip(text, 40),
                self._version_path(wid),
                MAX_VERSION,
            )
            return 0
        return value

    def event(self, world_id: str, kind: str, detail: str, reason: str = "") -> None:
        """Publish an event about a world that has no link (yet), without declaring a publisher for it
        (a flood of worlds that cannot be attached must not leave one declared publisher each)."""
        msg = AgentEvent(self.agent_id, world_id, kind, detail, 0, time.time(), reason=reason)
        key = keys.agent_event(self.agent_id, world_id)
        try:
            self.bus.put(key, codec.encode(msg), codec.schema_name(AgentEvent))
        except Exception as e:  # noqa: BLE001 - an event is never worth stopping for
            if not getattr(self.bus, "closed", False):
                log.warning("publishing on %s failed: %s", key, e)
        if self.on_output is not None:
            self.on_output("event", msg)

    # bus callbacks (zenoh threads) -----------------------------------------------------------------
    # Observations are answered right in the subscriber callback by default: the lockstep world is
    # waiting for exactly this answer, and a queue hop costs ~70 us of a ~400 us round trip. With
    # threaded_links each link runs on its own thread behind a bounded inbox, so one world's slow
    # embedding cannot delay another world's messages.
    def _on_obs(self, msg: BusMessage) -> None:
        wid = keys.world_of(msg.key)
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            if self.threaded_links:
                link.inbox.push(msg)
            else:
                link.handle(msg.payload)
            return
        if wid not in self._claims and self.book.claimed_by_other(wid, self.owner_id):
            self.counters["others"] += 1
        else:
            self.counters["unattached"] += 1

    def _on_alive(self, key: str, alive: bool) -> None:
        wid = keys.last_chunk(key)
        self.book.world(wid, alive)
        self._changes.put((wid, alive))

    def _on_owner(self, key: str, alive: bool) -> None:
        self.book.owner(keys.last_chunk(key), alive)

    def _on_claim(self, key: str, alive: bool) -> None:
        self.book.claim(key, alive)

    def _on_checkpoint(self, msg: BusMessage) -> None:
        """Keep the newest checkpoint another owner shares of each world (decoded: it is checked now)."""
        parts = msg.key.split("/")
        owner, wid = parts[-3], parts[-1]
        if owner == self.owner_id:
            return
        try:
            shared = codec.decode(SharedCheckpoint, msg.payload)
        except ProtocolError as e:
            self.counters["bad_checkpoint"] += 1
            self._warn("checkpoint shared by %s for world %s refused: %s", owner[:64], wid[:64], clip(str(e)))
            return
        if shared.world_id != wid:
            self.counters["bad_checkpoint"] += 1
            self._warn(
                "checkpoint shared by %s on world %s's key is for world %s: refused",
                owner[:64],
                wid[:64],
                clip(shared.world_id),
            )
            return
        why = self.store.offer(owner, wid, shared.data)
        if why is None:
            self._note_lease_elsewhere(wid, owner, shared.epoch, shared.saved_at)
        if why is not None:
            self.counters["bad_checkpoint"] += 1
            self._warn("checkpoint shared by %s for world %s refused: %s", owner[:64], wid[:64], why)

    def _on_embedding(self, msg: BusMessage) -> None:
        """Note the embedding version any agent published (a takeover says when its copy is older)."""
        try:
            emb = codec.decode(Embedding, msg.payload)
        except ProtocolError:
            return  # not ours to judge: watchers report bad embeddings
        if emb.world_id == keys.last_chunk(msg.key) and emb.version <= MAX_VERSION:
            # (a version with no room for the next one on the wire cannot be followed: not taken)
            self.store.published(emb.world_id, emb.version)

    def _answer_checkpoint(self, key: str, payload: bytes | None) -> bytes:
        """The checkpoint queryable: the newest copy this owner holds of the world asked (its own
        last share or another owner's), so a new owner resumes from the newest copy any agent
        holds; empty when it holds none."""
        wid = keys.last_chunk(key)
        copy = self.store.newest(wid)
        own = self._own_shared.get(wid)
        if own is not None and (copy is None or own[0] >= copy.checkpoint.saved_at):
            return own[1]
        return copy.data if copy is not None else b""

    # truth and world events for a world without a link are counted as `unattached`, like its
    # observations (`others` when another owner answers it); a refused one as bad_truth /
    # bad_world_event (the link keeps its truth)
    def _taker(self, wid: str) -> WorldLink | None:
        """The link that takes world `wid`'s truth and events here, or None after counting the message:
        `others` when another owner answers the world (that owner takes and counts it; a paused link
        left here from before a hand-off does not count it a second time), else `unattached`."""
        link = self.links.get(wid)
        elsewhere = wid not in self._claims and self.book.claimed_by_other(wid, self.owner_id)
        if link is not None and (link.state == "attached" or not elsewhere):
            return link
        self.counters["others" if elsewhere else "unattached"] += 1
        return None

    def _on_truth(self, msg: BusMessage) -> None:
        link = self._taker(keys.world_of(msg.key))
        if link is None:
            return
        try:
            truth = codec.decode(Truth, msg.payload)
            check_truth(truth, link.world_id)
        except ProtocolError as e:
            self.counters["bad_truth"] += 1
            self._warn("world %s: bad truth message: %s", link.world_id, e)
            return
        link.truth = truth

    def _on_world_event(self, msg: BusMessage) -> None:
        link = self._taker(keys.world_of(msg.key))
        if link is None:
            return
        try:
            ev = codec.decode(WorldEvent, msg.payload)
            if ev.world_id != link.world_id:
                raise SpecMismatch(f"world event for world {ev.world_id!r} arrived on {link.world_id!r}'s key")
        except ProtocolError as e:
            self.counters["bad_world_event"] += 1
            self._warn("world %s: bad world event: %s", link.world_id, e)
            return
        if ev.kind == WorldEventKind.LEASE_LOST:
            if link.state == "attached" and lost_by(ev, self.owner_id, link.epoch):
                with link.lock:  # stop at once; the run loop withdraws the claim and says so
                    link.pause()
                self._lost.put((link.world_id, ev))
            return  # addressed to another owner (or an old epoch of ours): nothing to do here
        link.world_event(ev)

    def _status(self, key: str, payload: bytes | None) -> bytes:
        return codec.encode(self.status())

    def status(self) -> AgentStatus:
        """The agent's status: uptime, every link's status and the daemon's counters."""
        links = tuple(link.status() for link in list(self.links.values()))
        counters = dict(self.counters)
        counters["dropped"] += sum(ln.dropped for ln in links)
        counters["links"] = len(links)
        counters["owned"] = len(self._claims)
        if self.workers:
            mine = {ln.world_id for ln in links if ln.state == "attached"}
            extra = []
            for st in list(self._worker_status.values()):
                extra += [ln for ln in st.links if ln.world_id not in mine and ln.state == "attached"]
                for k, v in st.counters.items():
                    counters[k] = counters.get(k, 0) + v
            seen = {ln.world_id for ln in extra} | mine
            links = tuple(ln for ln in links if ln.state == "attached" or ln.world_id not in seen) + tuple(extra)
            counters["links"] = len(links)
            counters["workers"] = len(self._worker_status) + 1  # the processes that answer, this one included
        return AgentStatus(self.owner_id, time.time() - self._started, links, counters, time.time())

    def _poll_workers(self) -> None:
        """Keep the workers' latest statuses (for `status`), every 0.5 s until stopped."""
        while not self._stop.wait(0.5):
            for w in self.workers:
                try:
                    replies = self.bus.get(keys.agent_status(w), timeout=1.0)
                    if replies:
                        self._worker_status[w] = codec.decode(AgentStatus, replies[0].payload)
                    else:
                        self._worker_status.pop(w, None)
                except (BusError, ProtocolError):
                    self._worker_status.pop(w, None)
                except Exception:  # noqa: BLE001 - a closed session at shutdown
                    return

    # attach / pause ----------------------------------------------------------------------------
    def _fetch(self, key: str, cls: type, tries: int = 3) -> Any:
        """The first reply to a query on `key` decoded as `cls` (None: no reply in `tries` tries).
        A reply that does not decode raises at once (asking again gets the same bytes); no reply or
        an error reply (a timeout on one of two routes) is asked again."""
        last: Exception | None = None
        for _ in range(tries):
            try:
                replies = self.bus.get(key, timeout=1.0)
            except BusError as e:
                last = e
            else:
                if replies:
                    return codec.decode(cls, replies[0].payload)
            if self._stop.is_set():
                break
        if last is not None:
            raise last
        return None

    @staticmethod
    def _checkpoint_path(state_dir: str, wid: str) -> str:
        return os.path.join(state_dir, f"{wid}.ckpt.npz")

    def _load_checkpoint(self, spec: WorldSpec, newer_than: float | None = None) -> Restored | None:
        """The saved link for this world, or None to start fresh: the program rebuilt from its
        class params and restored, its embedding version, and the drop detector restored (None: a
        fresh one). A file that cannot be read or restored is set aside
        as NAME.bad-<UTC time>, one learned on another body (kind, program, sensors, actions) as
        NAME.other-body-<UTC time>: its state cannot serve this world, and left in place it would
        be overwritten by the next checkpoint. Pickles (the old NAME.pkl) are never loaded.

        A checkpoint another owner shared on the bus is used instead when it is newer than the file
        (or there is no file); with `newer_than` (a time.time()), only one saved after it is used."""
        copy = self._newest_copy(spec.world_id, ask=newer_than is None)
        shared = copy.checkpoint if copy is not None else None
        if shared is not None and newer_than is not None and shared.saved_at <= newer_than:
            shared = None
        if shared is not None and not shared.same_body(spec):
            log.warning("world %s: the checkpoint shared on the bus is for another body; not used", spec.world_id)
            shared = None
        local = self._load_file(spec) if newer_than is None else None
        if shared is not None and (local is None or shared.saved_at > local[1]):
            try:
                restored = self._restore(spec, shared, "shared checkpoint")
            except _Unrestorable as e:
                self.counters["bad_checkpoint"] += 1
                log.warning("world %s: the checkpoint shared on the bus %s; set aside", spec.world_id, e)
                self.event(
                    spec.world_id,
                    EventKind.BAD_INPUT,
                    clip(f"checkpoint shared on the bus set aside: it {e}"),
                    "bad_checkpoint",
                )
                self.store.drop(spec.world_id)
            else:
                self.counters["taken_over"] += 1
                log.info(
                    "world %s: resuming from the checkpoint %s shared on the bus (embedding v%d, %d steps, %.1f s old)",
                    spec.world_id,
                    shared.owner or (copy.owner if copy is not None else "?"),
                    shared.version,
                    shared.steps,
                    time.time() - shared.saved_at,
                )
                return restored
        return local[0] if local is not None else None

    def _newest_copy(self, wid: str, ask: bool) -> Any:
        """The newest shared copy of world `wid` this owner holds; with `ask`, first ask every
        other owner for the copy it holds (a takeover resumes from the newest copy any agent holds,
        also one shared before this owner was listening)."""
        if ask and self.book.view().owners - {self.owner_id}:
            try:
                replies = self.bus.get(f"{keys.PREFIX}/agent/*/checkpoint/{wid}", timeout=1.0)
            except (BusError, ValueError) as e:
                log.debug("world %s: asking for checkpoints failed: %s", wid, e)
                replies = []
            except Exception as e:  # noqa: BLE001 - a closing session: use what is held
                log.debug("world %s: asking for checkpoints failed: %s", wid, e)
                replies = []
            for r in replies:
                if r.payload:
                    why = self.store.offer("?", wid, r.payload, exclude=self.owner_id)
                    if why is not None:
                        log.warning("world %s: a checkpoint another owner holds was refused: %s", wid, why)
        return self.store.newest(wid)

    def _restore(self, spec: WorldSpec, saved: Checkpoint, what: str) -> Restored:
        """The program (and detector) rebuilt from checkpoint `saved`; _Unrestorable says why not."""
        if saved.world_id != spec.world_id:
            raise _Unrestorable(f"is for world {saved.world_id!r}, not {spec.world_id!r}")
        try:
            program = make_program(spec, self.seed, **saved.program_params)
            if type(program).__name__ != saved.program_class:
                raise ValueError(f"it holds a {saved.program_class}, this world gets a {type(program).__name__}")
            wanted = as_strings(parse(type(program.params), self.program_params.get(program_name(spec), {})))
            if wanted != saved.program_params:
                log.warning(
                    "%s of world %s was made with program params %s, not %s: keeping its own (the learned "
                    "state belongs to them)",
                    what,
                    spec.world_id,
                    saved.program_params,
                    wanted,
                )
            detector = None
            if saved.detector_state is not None and saved.detector_state.get("name") == self.detector:
                detector = make_detector(self.detector, **program.detector_params)
            # arrays of the shapes this world's program keeps, before anything is restored from them
            check_shapes(saved.program_state, program.state(), "program_state")
            if detector is not None and saved.detector_state is not None:
                check_shapes(saved.detector_state, detector.state(), "detector_state")
            program.restore(saved.program_state)
            if detector is not None and saved.detector_state is not None:
                detector.restore(saved.detector_state)
        except CheckpointError as e:
            raise _Unrestorable(f"does not fit this world's program: {e}") from None
        except (ValueError, KeyError, TypeError, IndexError, AttributeError, ProtocolError) as e:
            raise _Unrestorable(f"cannot be restored ({type(e).__name__}: {e})") from None
        return Restored(program, saved.version, detector, saved.steps)

    def _load_file(self, spec: WorldSpec) -> tuple[Restored, float] | None:
        """The state dir's checkpoint of this world and when it was saved, or None (see _load_checkpoint)."""
        state_dir = self.state_dir
        if not state_dir:
            return None
        path = self._checkpoint_path(state_dir, spec.world_id)
        if os.path.exists(os.path.join(state_dir, f"{spec.world_id}.pkl")):
            log.warning(
                "world %s: ignoring the old pickle checkpoint %s.pkl (pickles are never loaded)",
                spec.world_id,
                spec.world_id,
            )
        if not os.path.exists(path):
            return None

        def set_aside(why: str, reason: str) -> None:
            self.counters["bad_checkpoint"] += 1
            self.event(
                spec.world_id, EventKind.BAD_INPUT, clip(f"checkpoint {path} set aside: {reason}"), "bad_checkpoint"
            )
            try:
                aside = set_aside_checkpoint(path, why)
            except OSError as e:
                log.warning("checkpoint %s: %s; starting fresh (could not set it aside: %s)", path, reason, e)
            else:
                log.warning("checkpoint %s: %s; set aside as %s, starting fresh", path, reason, aside)

        try:
            saved = read_checkpoint(path)
        except CheckpointError as e:
            set_aside("bad", f"unreadable ({e})")
            return None
        if saved.world_id != spec.world_id:  # a file copied or renamed from another world's
            set_aside(
                "other-world",
                f"saved for world {saved.world_id!r}, not {spec.world_id!r} (a checkpoint is restored only for the "
                "world it names)",
            )
            return None
        if not saved.same_body(spec):
            set_aside(
                "other-body",
                f"learned on a different world body ({saved.kind}, program "
                f"{saved.program or saved.kind!r}) than world {spec.world_id} ({spec.kind})",
            )
            return None
        try:
            restored = self._restore(spec, saved, f"checkpoint {path}")
        except _Unrestorable as e:
            set_aside("bad", str(e))
            return None
        return restored, saved.saved_at

    # whose state is newest: by lease epoch, not by who claimed last ----------------------------------
    def _note_lease_elsewhere(self, wid: str, owner: str, epoch: int, when: float) -> None:
        """Another owner held world `wid`'s lease at `epoch` at time `when` (a lease refusal or
        lease_lost naming it, a checkpoint it shared)."""
        if not owner or owner == self.owner_id or epoch <= 0 or wid not in self.links:
            return  # (only worlds with a link here: the others' worlds would pile up in memory)
        old = self._other.get(wid)
        if old is None or when > old[2]:
            self._other[wid] = (owner, epoch, when)

    def _newer_elsewhere(self, wid: str) -> str | None:
        """Why another owner holds a newer learned state of world `wid` than this owner's link
        (None: this owner's is the newest it knows of, so a release checkpoints it).

        Leases decide, not claims: a claim can be withdrawn before its owner answers a single step
        (the world vanished, a lower owner won), so a world claimed elsewhere after this owner
        answered it still has its newest state here unless another owner is seen holding its lease
        after this owner's grant, or wrote the state dir's checkpoint after this owner stopped. A
        world without leases (epoch 0) falls back to the claims (`_elsewhere`)."""
        held = self._held.get(wid)
        other = self._other.get(wid)
        if other is not None and (held is None or other[2] > held[1]):
            mine = f"this owner's epoch {held[0]}" if held is not None else "this owner held none"
            return f"owner {other[0][:64]} held its lease (epoch {other[1]}) after this owner did ({mine})"
        if held is None and wid in self._elsewhere:
            return "another owner answered it since (the world grants no leases: its state is that owner's)"
        if self.state_dir and wid in self._elsewhere:
            path = self._checkpoint_path(self.state_dir, wid)
            try:
                on_disk = read_checkpoint(path) if os.path.exists(path) else None
            except CheckpointError:
                on_disk = None
            stopped = self._stopped_at.get(wid, float("inf"))
            if on_disk is not None and on_disk.owner not in ("", self.owner_id) and on_disk.saved_at > stopped:
                return f"owner {on_disk.owner[:64]} wrote {path} after this owner stopped answering it"
        return None

    def checkpoint(self, only: str | None = None) -> set[str]:
        """Write every link's learned state (or only world `only`'s) to STATE_DIR/<world>.ckpt.npz
        (atomically, no pickle). A write that fails (e.g. a full disk) is logged and leaves the
        previous checkpoint in place. Returns the ids of the worlds written."""
        written: set[str] = set()
        state_dir = self.state_dir
        if not state_dir:
            return written
        with self._ckpt_lock:  # one writer at a time (a worker's exit deadline may write beside close())
            self._checkpoint_links(state_dir, only, written)
        return written

    def _checkpoint_links(self, state_dir: str, only: str | None, written: set[str]) -> None:
        for wid, link in list(self.links.items()):
            if only is not None and wid != only:
                continue
            if link.state != "attached" and self._newer_elsewhere(wid) is not None:
                continue  # another owner holds a newer state of it: its file is theirs to write
            path = self._checkpoint_path(state_dir, wid)
            data = self._encoded_state(wid, link)
            if data is None:
                continue
            try:
                write_atomically(path, data)
                written.add(wid)
            except OSError as e:  # e.g. a full disk: the previous checkpoint stays, learning goes on
                log.error("world %s: checkpoint not written (%s); the previous one is kept", wid, e)

    def _encoded_state(self, wid: str, link: WorldLink) -> bytes | None:
        """Link `link`'s learned state as checkpoint bytes (None, logged, if it cannot be encoded)."""
        encoded = self._encoded_snapshot(wid, link)
        return None if encoded is None else encoded[1]

    def _encoded_snapshot(self, wid: str, link: WorldLink) -> tuple[float, bytes] | None:
        """Link `link`'s learned state as (saved_at, checkpoint bytes); None, logged, if it cannot be encoded."""
        with link.lock:  # a consistent snapshot (copies): it is written while the link runs on
            program, spec = link.program, link.spec
            ckpt = Checkpoint(
                world_id=wid,
                kind=spec.kind,
                program=spec.program,
                sensors=tuple(spec.sensors),
                action_space=spec.action_space,
                version=link.version,
                program_class=type(program).__name__,
                program_params=as_strings(program.params),
                program_state=program.state(),
                detector_state=link.detector.state() if link.detector is not None else None,
                saved_at=time.time(),
                steps=link.learned_steps,
                owner=self.owner_id,
                # the lease the state was learned under (a released link holds none any more)
                epoch=link.epoch or self._held.get(wid, (0, 0.0))[0],
            )
        try:
            return ckpt.saved_at, encode_checkpoint(ckpt)
        except ValueError:  # a program whose state is not arrays and plain values: a bug, not fatal
            log.exception("world %s: checkpoint not written", wid)
            return None

    def share(self, only: str | None = None, worlds: list[str] | None = None) -> int:
        """Put the learned state of every world this daemon answers (or only `only`, or only those
        in `worlds` that are attached) on the bus, for the other owners to resume from if this one
        dies; nothing while no other owner is alive. A checkpoint over `share_max_bytes` is not
        shared (counted `share_oversize`, logged). Returns how many were shared."""
        if not (self.book.view().owners - {self.owner_id}):
            return 0
        n = 0
        for wid, link in list(self.links.items()):
            if (only is not None and wid != only) or (worlds is not None and wid not in worlds):
                continue
            if wid not in self._claims or (only is None and link.state != "attached"):
                continue
            encoded = self._encoded_snapshot(wid, link)
            if encoded is None:
                continue
            if self.schedule is not None:
                self.schedule.shared(wid, time.monotonic())
            if len(encoded[1]) > self.store.max_bytes:
                if wid not in self._oversize_told:
                    self._oversize_told.add(wid)
                    log.warning(
                        "world %s: checkpoint of %d bytes is over the %d shared on the bus: not shared "
                        "(a takeover would start from an older copy or fresh)",
                        wid,
                        len(encoded[1]),
                        self.store.max_bytes,
                    )
                self.counters["share_oversize"] += 1
                continue
            shared = SharedCheckpoint(
                wid,
                encoded[1],
                owner=self.owner_id,
                epoch=link.epoch,
                format_version=FORMAT_VERSION,
                embedding_version=link.version,
                saved_at=encoded[0],
            )
            try:
                self.bus.put(
                    keys.agent_checkpoint(self.owner_id, wid),
                    codec.encode(shared),
                    codec.schema_name(SharedCheckpoint),
                )
                self._own_shared[wid] = encoded
                n += 1
            except Exception as e:  # noqa: BLE001 - a closing bus: the next share will do
                log.warning("world %s: checkpoint not shared: %s", wid, e)
        self.counters["shared"] += n
        return n

    def share_new_versions(self, now: float | None = None) -> int:
        """Share the worlds that published a new embedding version since their last share, each at
        most once per `share_on_embedding` seconds (see `ShareSchedule`). Returns how many were shared."""
        if self.schedule is None:
            return 0
        due = self.schedule.take(time.monotonic() if now is None else now)
        if not due:
            return 0
        n = self.share(worlds=due)
        for w in due:  # not answered here any more, or no other owner to share with: not due again
            self.schedule.shared(w, time.monotonic() if now is None else now)
        self.counters["shared_on_embedding"] += n
        return n

    # ownership ---------------------------------------------------------------------------------
    def _claim(self, wid: str) -> None:
        tok = self.bus.token(claim_key(wid, self.owner_id))
        self._claims[wid] = (tok, time.monotonic())
        self.counters["claimed"] += 1
        log.info("owner %s claims world %s", self.owner_id, wid)

    def _stop_answering(self, wid: str, why: str) -> None:
        link = self.links.get(wid)
        if link is not None and link.state == "attached":
            with link.lock:  # an answer in flight goes out before the claim is withdrawn
                link.pause()
            link.event(EventKind.PAUSED, f"no longer answered by {self.owner_id}: {why}", reason="released")
        self._stopped_at[wid] = time.time()

    def _release(self, wid: str, why: str) -> None:
        """Stop answering world `wid` (first), give its lease back (if it is still there), then
        withdraw the claim."""
        self._stop_answering(wid, why)
        link = self.links.get(wid)
        if link is not None and link.epoch > 0:
            if wid in self.book.view().worlds and self.leases.release(wid, link.epoch):
                log.info("owner %s gave world %s's lease (epoch %d) back", self.owner_id, wid, link.epoch)
            link.set_lease(self.owner_id, 0)
        self._waiting.pop(wid, None)
        if self.schedule is not None:
            self.schedule.forget(wid)
        held = self._claims.pop(wid, None)
        self._failed.discard(wid)
        self._retry_spec.pop(wid, None)
        self._retried.discard(wid)
        for sub in self._obs_subs.pop(wid, ()):
            self.bus.undeclare(sub)
        if held is not None:
            self.bus.undeclare(held[0])
            log.info("owner %s releases world %s: %s", self.owner_id, wid, why)

    # leases (see agent.lease) ---------------------------------------------------------------------
    LEASE_RETRY = 0.5  # seconds between two lease requests to a world whose lease another owner holds
    SPEC_RETRY = 5.0  # seconds after which a claimed world whose spec query went unanswered is tried again

    def _lease_get(self, key: str, payload: bytes, timeout: float) -> list[bytes]:
        return [r.payload for r in self.bus.get(key, timeout=timeout, payload=payload)]

    def _take_lease(self, wid: str) -> Outcome | None:
        """Ask world `wid` for its lease: the outcome when granted, or for a world without leases
        (answered unfenced, epoch 0); None when another owner holds it (this owner waits, reports it
        once, and asks again every LEASE_RETRY seconds)."""
        out = self.leases.acquire(wid)
        if out.granted:
            self.counters["lease_granted"] += 1
            if self._waiting.pop(wid, None) is not None:
                log.info("world %s: lease granted to %s (epoch %d) after waiting", wid, self.owner_id, out.epoch)
            return out
        if out.unfenced:
            self.counters["unfenced"] += 1
            self._warn(
                "world %s answers no lease request (a world written before leases): answered unfenced, "
                "only the claim protocol keeps a second owner away",
                wid,
            )
            return out
        self.counters["lease_refused"] += 1
        self._note_lease_elsewhere(wid, out.holder, out.epoch, time.time())
        first = wid not in self._waiting
        self._waiting[wid] = time.monotonic()
        if first:
            what = f"held by {out.holder} (epoch {out.epoch})" if out.holder else f"not granted ({out.reason})"
            log.info("world %s: lease %s; %s waits and asks again", wid, what, self.owner_id)
            self.event(
                wid,
                EventKind.LEASE_REFUSED,
                f"the world's lease is {what}; {self.owner_id} does not answer it and asks again",
                out.reason or "held",
            )
        return None

    def _handle_lost(self) -> None:
        """The worlds whose lease this owner lost (their lease_lost events, seen on a bus thread,
        paused the link at once): say so, and withdraw the claim; a world whose lease went to
        another owner is not claimed again for a while, one whose lease is free (the world restarted
        or nobody holds it) is claimed again at once."""
        while True:
            try:
                wid, ev = self._lost.get_nowait()
            except queue.Empty:
                return
            link = self.links.get(wid)
            if link is None or link.epoch != ev.epoch:
                continue  # already handled, or a newer lease since
            self.counters["lease_lost"] += 1
            if ev.holder:
                detail = (
                    f"world {wid} applies the actions of owner {ev.holder} (lease epoch {ev.holder_epoch}), not "
                    f"those of {self.owner_id} (epoch {ev.epoch}): {self.owner_id} stopped answering it"
                )
            else:
                detail = f"world {wid} has no lease holder now (it restarted or the lease was freed): asking again"
            log.warning("%s", detail)
            link.event(
                EventKind.LEASE_LOST,
                detail,
                ev.step,
                {"epoch": float(ev.epoch), "holder_epoch": float(ev.holder_epoch)},
                reason="held" if ev.holder else "free",
            )
            link.set_lease(self.owner_id, 0)  # nothing to give back
            self._note_lease_elsewhere(wid, ev.holder, ev.holder_epoch, time.time())
            self._release(wid, f"lease lost to {ev.holder or 'nobody'}")
            if ev.holder:
                self._elsewhere.add(wid)
                self._avoid[wid] = time.monotonic() + 5.0

    def own(self) -> None:
        """One ownership tick: withdraw lost claims, hand one world off if overloaded, claim a free
        world if least loaded, and attach the worlds whose claim has settled."""
        now = time.monotonic()
        view = self.book.view()
        me = self.owner_id
        for w in view.worlds:
            c = view.claims.get(w)
            if w in self._claims or (c is not None and (len(c) > 1 or me not in c)):  # claimed by another
                self.book.unclaimed_since.pop(w, None)
            else:
                self.book.unclaimed_since.setdefault(w, now)
        for w in list(self.book.unclaimed_since):
            if w not in view.worlds:
                del self.book.unclaimed_since[w]
        for w, until in list(self._avoid.items()):
            if until <= now:
                del self._avoid[w]
        known = frozenset(w for w, ln in self.links.items() if ln.state != "attached")
        p = plan(
            self.owner_id,
            view,
            self._claims,
            {w: now - t for w, t in self.book.unclaimed_since.items()},
            known=known,
            avoid=frozenset(self._avoid) | frozenset(self._bad_ids),
            failed=frozenset(self._failed),
            claim_delay=self.claim_delay,
            may_shed=now - self._last_shed >= 2.0 and now - self._started_mono >= 2.0,
        )
        for w in self.links:
            if view.claimants(w) and self.owner_id not in view.claimants(w):
                self._elsewhere.add(w)  # another owner answers it now
        for w, why in p.release.items():
            if "wins" in why:
                self.counters["lost"] += 1
                self._elsewhere.add(w)
                link = self.links.get(w)
                if link is not None and link.state == "attached":  # the winner resumes from here
                    self._stop_answering(w, why)
                    self.share(only=w)
            self._release(w, why)
        if p.shed is not None:
            self._last_shed = now
            self._stop_answering(p.shed, "handed off to balance the load")
            self.share(only=p.shed)
            self._release(p.shed, "handed off to balance the load")
            self._elsewhere.add(p.shed)
            self._avoid[p.shed] = now + 5.0
            self.counters["shed"] += 1
        for w in p.claim:
            try:
                keys.check_id(w, "world id")
            except ValueError as e:  # a token no world id can have: never claimed, reported once (lowest owner)
                self._bad_ids.add(w)
                if self.owner_id == min(view.owners | {self.owner_id}):
                    self._attach_failed(w, "no_spec", e)
                continue
            self._claim(w)
        for w, (_, since) in list(self._claims.items()):
            if now - since < self.claim_settle:
                continue
            link = self.links.get(w)
            if link is not None and link.state == "attached":
                continue
            if w in self._failed and now >= self._retry_spec.get(w, float("inf")):
                self._failed.discard(w)  # no spec reply last time (a route being rebuilt?): once more
                self._retry_spec.pop(w, None)
                self._retried.add(w)  # a second failure is not counted or reported again
            if w in self._failed or any(o < self.owner_id for o in self.book.claimants(w)):
                continue  # tried once this appearance / withdrawn at the next tick
            if now - self._waiting.get(w, float("-inf")) < self.LEASE_RETRY:
                continue  # its lease is held by another owner: ask again in a moment
            self._attach(w)
            link = self.links.get(w)
            if w in self._waiting:
                continue  # the world's lease is held elsewhere: keep the claim and ask again
            if link is None or link.state != "attached":
                # keep the claim: the world is reported once (attach_failed), not by every owner in turn;
                # it is tried again when it reappears
                self._failed.add(w)

    def _attach(self, wid: str) -> None:
        self._gone.pop(wid, None)
        try:
            keys.check_id(wid, "world id")
            spec = self._fetch(keys.world_spec(wid), WorldSpec)
            if spec is None:
                raise BusError("no reply to the spec query")
            if spec.world_id != wid:
                raise SpecMismatch(f"the spec of world {wid!r} is for world {spec.world_id!r}")
        except ProtocolError as e:
            self._attach_failed(wid, "bad_spec", e)
            return
        except (ValueError, BusError) as e:
            if isinstance(e, BusError):
                self._retry_spec[wid] = time.monotonic() + self.SPEC_RETRY
            self._attach_failed(wid, "no_spec", e)
            return
        if spec.program == EXTERNAL_PROGRAM:  # an outside controller answers it (a Gymnasium BusEnv)
            log.info("world %s is driven by an outside controller (program %r): not attached", wid, spec.program)
            self.event(wid, EventKind.ATTACH_FAILED, "the world is driven by an outside controller", "external")
            return
        fresh: Any = None
        known = self.links.get(wid)
        if known is None or not same_body(known.spec, spec):
            # the program first: a world no program fits (a broken or fake one) fails here, before a
            # lease, truth or checkpoint query is sent for it (building one costs < 0.1 s once imported)
            try:
                fresh = make_program(spec, self.seed, **self.program_params.get(program_name(spec), {}))
            except Exception as e:  # noqa: BLE001 - SpecMismatch, KeyError, MemoryError (a huge state space), ...
                self._attach_failed(wid, "no_program", e)
                return
        lease = self._take_lease(wid)
        if lease is None:
            return  # held by another live owner: the claim stays, own() asks again
        epoch = lease.epoch if lease.granted else 0
        granted_at = time.time()
        try:
            truth = self._fetch(keys.world_truth(wid), Truth, tries=1)
        except (BusError, ProtocolError):
            truth = None
        previous = self.links.get(wid)
        if previous is not None:
            previous.set_lease(self.owner_id, epoch)  # before it answers again
        if previous is not None and same_body(previous.spec, spec):
            # resume it, unless another owner answered the world since (its shared state is newer)
            restored = self._load_checkpoint(spec, newer_than=self._stopped_at.get(wid, time.time()))
            if restored is not None:
                previous.stop()
                previous = None
        else:
            restored = self._load_checkpoint(spec)
        if truth is not None:
            try:
                check_truth(truth, wid)
            except ProtocolError as e:
                log.warning("world %s: truth not used: %s", wid, e)
                truth = None
        last = self.store.last_published(wid)
        try:
            att = attach(
                spec,
                self.config,
                self.publish,
                truth=truth,
                previous=previous,
                restored=restored,
                last_published=last,
                program=fresh,
                detector=None if fresh is None else make_detector(self.detector, **fresh.detector_params),
            )
        except Exception as e:  # noqa: BLE001 - no program fits this spec (KeyError, MemoryError, ...); the daemon goes on
            self.leases.release(wid, epoch)
            self._attach_failed(wid, "no_program", e)
            return
        att.link.set_lease(self.owner_id, epoch)
        att.link.outputs_in_background()  # an embedding's scores must not hold up other worlds' answers
        if previous is not None and att.link is not previous:
            previous.stop()
        floor = self._version_floor(wid)
        if att.link.version < floor:
            log.info("world %s: embedding versions go on from v%d (published before a restart)", wid, floor)
            att.link.version = floor
        self.links[wid] = att.link
        self._elsewhere.discard(wid)
        if epoch:
            self._held[wid] = (epoch, granted_at)
        if not self.all_obs and wid not in self._obs_subs:
            # only now: a claimed world that cannot be attached (a fake one) costs no subscriber
            # declarations, which every session on the bus would have to route; the lockstep world
            # resends its observation until it is answered
            self._obs_subs[wid] = [
                self.bus.subscribe(keys.world_obs(wid), self._on_obs),
                self.bus.subscribe(keys.world_truth(wid), self._on_truth),
                self.bus.subscribe(keys.world_event(wid), self._on_world_event),
            ]
        if self.threaded_links:
            att.link.start()
        log.info(
            "world %s %s (%s, program %s, %d steps learned, embedding v%d)",
            wid,
            att.how,
            spec.kind,
            att.link.program.name,
            att.link.learned_steps,
            att.link.version,
        )

    def _attach_failed(self, wid: str, reason: str, e: Exception) -> None:
        if wid in self._retried:  # this appearance of the world was counted and reported already
            log.debug("world %s: still cannot attach: %s", wid, clip(str(e)))
            return
        self.counters["attach_failed"] += 1
        self._warn("world %s: cannot attach: %s", wid, clip(str(e)))
        self.event(wid, EventKind.ATTACH_FAILED, str(e), reason)

    def _detach(self, wid: str) -> None:
        link = self.links.get(wid)
        if link is not None:
            self._gone[wid] = time.monotonic()
        if link is not None and link.state == "attached":
            link.pause()
            log.info("world %s disappeared: link paused at step %d", wid, link.counters.steps)
            link.event(EventKind.PAUSED, "world vanished; waiting for it to return", reason="world_gone")

    def release_expired(self, now: float | None = None) -> list[str]:
        """Release the links of worlds gone longer than `link_ttl`: checkpoint each (with a state
        dir) and drop it from `links`. A link whose checkpoint cannot be written is kept (and tried
        again at the next sweep): releasing it would lose what it learned. Returns the released ids."""
        if self.link_ttl is None:
            return []
        now = time.monotonic() if now is None else now
        released = []
        for wid, since in list(self._gone.items()):
            link = self.links.get(wid)
            if link is None:
                self._gone.pop(wid, None)
                continue
            if now - since < self.link_ttl or link.state == "attached":
                continue
            elsewhere = self._newer_elsewhere(wid)
            if self.state_dir and elsewhere is None and wid not in self.checkpoint(only=wid):
                log.warning("world %s: gone %.0f s but its checkpoint failed; link kept", wid, now - since)
                continue
            if self._gone.pop(wid, None) is None or self.links.get(wid) is not link:
                continue  # it came back meanwhile
            del self.links[wid]
            link.stop()
            self._forget_publishers(wid)
            self.counters["released"] += 1
            self.counters["dropped"] += link.dropped
            released.append(wid)
            held = self._held.pop(wid, None)
            self._other.pop(wid, None)
            if self.state_dir and elsewhere is not None:
                log.info(
                    "world %s gone %.0f s (link ttl %g s): link released, not checkpointed here (%s)",
                    wid,
                    now - since,
                    self.link_ttl,
                    elsewhere,
                )
            elif self.state_dir and os.path.exists(self._checkpoint_path(self.state_dir, wid)):
                log.info(
                    "world %s gone %.0f s (link ttl %g s): checkpointed to %s (%d steps learned; %s) and "
                    "released; it is restored from there if it returns",
                    wid,
                    now - since,
                    self.link_ttl,
                    self._checkpoint_path(self.state_dir, wid),
                    link.learned_steps,
                    f"the newest state: lease epoch {held[0]} was the last seen" if held else "no lease",
                )
            else:
                log.info(
                    "world %s gone %.0f s (link ttl %g s): link released; no --state-dir, so it starts fresh "
                    "if it returns",
                    wid,
                    now - since,
                    self.link_ttl,
                )
        return released

    # main loop ---------------------------------------------------------------------------------
    UNIQUE_ID_TIMEOUT = 1.0  # seconds the liveliness query for another agent with this id waits

    def check_unique(self) -> None:
        """Raise DuplicateAgent when an agent with this owner id is alive on the bus already (its
        liveliness token is there): two processes with one id would both answer its status and
        fight over its worlds' claims under one name."""
        if self._unique_checked:
            return
        self._unique_checked = True
        key = keys.alive_agent(self.owner_id)
        try:
            alive = self.bus.alive(key, timeout=self.UNIQUE_ID_TIMEOUT)
        except Exception as e:  # noqa: BLE001 - no answer is no proof of a duplicate: start
            log.debug("liveliness query %s failed: %s", key, e)
            return
        if alive:
            raise DuplicateAgent(
                f"an agent with id {self.owner_id!r} is already running on this bus (its liveliness token {key} "
                "is alive); give this one another --id, or stop that one first (the token of an agent that "
                "died without closing its connection stays until the zenoh lease expires, 10 s by default)"
            )

    def start(self) -> None:
        """Refuse an id already alive on the bus (DuplicateAgent), then declare the status
        queryable and liveliness token, subscribe, and watch for worlds."""
        self.check_unique()
        self.bus.queryable(keys.agent_status(self.owner_id), self._status, codec.schema_name(AgentStatus))
        if self.all_obs:
            self.bus.subscribe(keys.ALL_OBS, self._on_obs)
            self.bus.subscribe(f"{keys.PREFIX}/world/*/truth", self._on_truth)
            self.bus.subscribe(keys.ALL_WORLD_EVENTS, self._on_world_event)
        self.bus.subscribe(keys.ALL_CHECKPOINTS, self._on_checkpoint)
        self.bus.subscribe(keys.ALL_EMBEDDINGS, self._on_embedding)
        self.bus.queryable(f"{keys.PREFIX}/agent/{self.owner_id}/checkpoint/*", self._answer_checkpoint)
        self.bus.token(keys.alive_agent(self.owner_id))
        self.bus.token(keys.alive_owner(self.owner_id))
        self.bus.watch_alive(keys.ALL_ALIVE_OWNERS, self._on_owner, history=True)
        self.bus.watch_alive(keys.ALL_CLAIMS, self._on_claim, history=True)
        self.bus.watch_alive(keys.ALL_ALIVE_WORLDS, self._on_alive, history=True)
        if self.workers:
            threading.Thread(target=self._poll_workers, name="poll-workers", daemon=True).start()
        threading.Thread(target=_import_programs, name="import-programs", daemon=True).start()
        threading.Thread(target=self._audit_liveliness, name="liveliness-audit", daemon=True).start()

    AUDIT_EVERY = 0.5  # seconds between two comparisons of the owner book with a liveliness query

    def _audit_liveliness(self) -> None:
        """Compare the owner book with liveliness queries every AUDIT_EVERY seconds and book what the
        events missed (`TokenAudit`: a world that reconnected through another router can stay booked
        as gone); a world's missed event also goes to the main loop, as zenoh's would have."""
        audit = TokenAudit()
        exprs = (keys.ALL_ALIVE_WORLDS, keys.ALL_ALIVE_OWNERS, keys.ALL_CLAIMS)
        steps: dict[str, int] = {}
        # a router answers from its own tables; a client (a worker) through its link to one, whose
        # answers go empty while the link is re-made under load: a client books only what the audit
        # finds alive (a missed appearance leaves a world nobody claims; a false disappearance
        # would pause a live world and hand it off; a missed disappearance only keeps a claim)
        router = getattr(getattr(self.bus, "config", None), "mode", "router") == "router"
        while not self._stop.wait(self.AUDIT_EVERY):
            held = self.book.tokens()  # before the queries: an event meanwhile shows as touched
            sure = self._surely_alive(steps)
            for expr in exprs:
                booked = held[expr]
                try:
                    alive = self.bus.alive(expr, timeout=1.0, complete=True)
                except Exception as e:  # noqa: BLE001 - a closing session or a route's error: next time
                    log.debug("liveliness audit of %s skipped: %s", expr, e)
                    continue
                if booked and not alive:
                    # no evidence: zenoh 1.x sometimes answers a liveliness query with nothing at all on a
                    # session that watches the same tokens (~1 query in 5 here, whatever the reply handler);
                    # taken as evidence, a few such answers in a row unbooked every world at once
                    continue
                # under load an answer can lack replies (issue 41: hundreds of fake worlds mended as gone
                # and back, a healthy world paused): one that lacks a token surely alive is not used
                lacking = sure[expr] - set(alive)
                if expr == keys.ALL_CLAIMS:
                    lacking &= self._own_claims()  # not withdrawn while the query ran
                if lacking:
                    log.debug("liveliness audit of %s skipped: the answer lacks %d live tokens", expr, len(lacking))
                    continue
                for key, is_alive, since in audit.check(expr, booked, alive, time.monotonic(), self.book.touched):
                    if not is_alive and (not router or self._answers_alive(key)):
                        continue  # a client (see `router`), or absent from the list but present when asked alone
                    if not self.book.mend(expr, key, is_alive, since):
                        continue
                    self.counters["liveliness_mended"] += 1
                    log.info("liveliness token %s is %s, but zenoh never said so", key, "alive" if is_alive else "gone")
                    if expr == keys.ALL_ALIVE_WORLDS:
                        self._changes.put((keys.last_chunk(key), is_alive))

    def _surely_alive(self, steps: dict[str, int]) -> dict[str, set[str]]:
        """Tokens a complete liveliness answer lists, per audited expression: this owner's own token
        and claims, and the worlds whose links here answered an observation since the last call
        (`steps`: each link's steps then, updated)."""
        worlds = set()
        for wid, link in list(self.links.items()):
            n = link.counters.steps
            if link.state == "attached" and steps.get(wid, n) != n:
                worlds.add(keys.alive_world(wid))
            steps[wid] = n
        return {
            keys.ALL_ALIVE_WORLDS: worlds,
            keys.ALL_ALIVE_OWNERS: {keys.alive_owner(self.owner_id)},
            keys.ALL_CLAIMS: self._own_claims(),
        }

    def _own_claims(self) -> set[str]:
        """This owner's claim tokens declared at least a second ago (the bus has them all by then)."""
        now = time.monotonic()
        return {keys.alive_claim(w, self.owner_id) for w, (_, t) in list(self._claims.items()) if now - t >= 1.0}

    def _answers_alive(self, key: str) -> bool:
        """Whether a liveliness query for token `key` alone finds it (True when in doubt)."""
        try:
            return bool(self.bus.alive(key, timeout=1.0, complete=True))
        except Exception:  # noqa: BLE001 - a closing session or a route's error
            return True

    TICK = 0.1  # seconds between two ownership ticks when no world appeared or vanished
    MIN_TICK = 0.02  # when some did or the last tick claimed one: at most one per MIN_TICK (a tick is O(worlds))

    def run(self, seconds: float | None = None) -> None:
        """Process attach/detach until stop() or `seconds` elapse."""
        t0 = time.monotonic()
        last_ckpt = last_sweep = last_share = t0
        last_tick = float("-inf")
        busy = False  # the last tick claimed a world (more may wait: the next tick comes at MIN_TICK)
        sweep_every = min(1.0, self.link_ttl / 2) if self.link_ttl is not None else None
        while not self._stop.is_set():
            if seconds is not None and time.monotonic() - t0 >= seconds:
                break
            try:
                changes = [self._changes.get(timeout=self.MIN_TICK if busy else self.TICK)]
            except queue.Empty:
                changes = []
            while True:  # every change queued so far, then one tick for all of them
                try:
                    changes.append(self._changes.get_nowait())
                except queue.Empty:
                    break
            for wid, alive in changes:
                if not alive:
                    self._detach(wid)
            if time.monotonic() - last_tick < (self.MIN_TICK if changes or busy else self.TICK):
                continue  # a burst of worlds appearing or vanishing is one tick, not one each
            last_tick = time.monotonic()
            try:
                self._handle_lost()
                claims = self.counters["claimed"]
                self.own()
                busy = self.counters["claimed"] > claims  # one claim per tick: the next one soon
                self.share_new_versions()
            except Exception:  # noqa: BLE001 - one bad tick must not stop the daemon
                if self.bus.closed:
                    break
                log.exception("ownership tick failed")
            if self.share_every is not None and time.monotonic() - last_share >= self.share_every:
                self.share()
                last_share = time.monotonic()
            if sweep_every is not None and time.monotonic() - last_sweep >= sweep_every:
                self.release_expired()
                last_sweep = time.monotonic()
            if self.state_dir and time.monotonic() - last_ckpt >= self.checkpoint_every:
                self.checkpoint()
                last_ckpt = time.monotonic()

    def stop(self) -> None:
        """Make `run` return."""
        self._stop.set()

    def close(self) -> None:
        """Stop, stop every link, withdraw every claim and write a final checkpoint."""
        self._stop.set()
        try:
            self.share()  # the others resume from here
        except Exception as e:  # noqa: BLE001 - a closing bus: stopping goes on
            log.warning("final share failed: %s", e)
        for wid in list(self._claims):
            self._release(wid, "agent stopping")
        for link in list(self.links.values()):
            link.stop()
        try:
            self.checkpoint()
        except OSError as e:
            log.warning("final checkpoint failed: %s", e)

    def __enter__(self) -> AgentDaemon:
        self.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


__all__ = ["AgentDaemon", "Action", "Embedding"]
