"""The agent daemon's state: what its parts (publishing, checkpoints, leases, attaching, the
ownership tick, the main loop) share, set up once from a checked `DaemonConfig`.

Each part is a layer of `AgentDaemon` in its own module (`daemon_publish`, `daemon_restore`,
`daemon_share`, `daemon_inbox`, `daemon_status`, `daemon_leases`, `daemon_attach`, `daemon_own`),
built on this one and on the layers below it, so each module reads on its own and imports only
what it stands on.
"""

from __future__ import annotations

import logging
import os
import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from sensorimotor.agent.attach import AgentConfig
from sensorimotor.agent.checkpoint_store import SharedCheckpoints, ShareSchedule
from sensorimotor.agent.daemon_config import DaemonConfig
from sensorimotor.agent.lease import LeaseClient
from sensorimotor.agent.link import WorldLink
from sensorimotor.agent.ownership import OwnerBook
from sensorimotor.agent.rate_limit import TokenBucket
from sensorimotor.protocol.bus import Bus
from sensorimotor.protocol.messages import AgentStatus, WorldEvent

log = logging.getLogger("sme.agent")

#: the daemon's counters, reported by `sme status` (the links' own counters come beside them)
COUNTERS = (
    "unattached",
    "attach_failed",
    "bad_truth",
    "bad_world_event",
    "released",  # links of worlds gone longer than link_ttl, released from memory
    "dropped",  # observations dropped unanswered (flood); here those of released links
    "others",  # observations of worlds another owner claims (not answered here)
    "claimed",  # claims declared
    "lost",  # claims withdrawn for a lower claimant
    "shed",  # worlds handed off to balance the load
    "shared",  # checkpoints shared on the bus
    "taken_over",  # links restored from another owner's shared checkpoint
    "shared_on_embedding",  # of the shared, those made soon after a new embedding version
    "share_oversize",  # checkpoints not shared: over share_max_bytes
    "lease_granted",  # leases the worlds granted this owner
    "lease_refused",  # lease requests refused (another live owner holds the world)
    "lease_lost",  # worlds that applied another owner's actions: stopped answering them
    "unfenced",  # attaches to worlds without a lease queryable (answered with epoch 0)
    "bad_checkpoint",  # checkpoints (shared or in the state dir) refused and set aside
    "liveliness_mended",  # tokens whose appearance or disappearance zenoh did not report (TokenAudit)
)


class DaemonState:
    """The daemon's shared state (see the module docstring); `config` must be checked already."""

    WARN_RATE = 5.0  # log lines per second about refused input, at most (see `_warn`)

    def __init__(self, bus: Bus, config: DaemonConfig) -> None:
        assert config.owner_id is not None and config.program_params is not None, "a checked DaemonConfig"
        self.settings = config
        self.detector = config.detector
        self.bus = bus
        self.threaded_links = config.threaded_links
        self.agent_id = config.agent_id
        self.owner_id: str = config.owner_id
        self.claim_settle = config.claim_settle
        self.claim_delay = config.claim_delay
        self.share_every = config.share_every
        self.book = OwnerBook()
        self._claims: dict[str, tuple[Any, float]] = {}  # world -> (claim token, monotonic time declared)
        self._avoid: dict[str, float] = {}  # world -> monotonic time until which it is not claimed again
        self.store = SharedCheckpoints(config.share_max_bytes)  # the newest copy of each world another owner shared
        self._own_shared: dict[str, tuple[float, bytes]] = {}  # world -> (saved_at, bytes) this owner last shared
        self.schedule = ShareSchedule(config.share_on_embedding) if config.share_on_embedding is not None else None
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
        self.workers = config.workers
        self.all_obs = config.all_obs
        self._obs_subs: dict[str, list[Any]] = {}  # without all_obs: world -> its obs/truth/event subscribers
        self._worker_status: dict[str, AgentStatus] = {}
        self.seed = config.seed
        self.state_dir = config.state_dir
        self.checkpoint_every = config.checkpoint_every
        self.program_params: dict[str, dict[str, Any]] = config.program_params
        self.config = AgentConfig(self.agent_id, config.seed, config.detector, self.program_params)
        self.on_output: Callable[[str, Any], None] | None = config.on_output
        self.links: dict[str, WorldLink] = {}
        self.counters: dict[str, int] = dict.fromkeys(COUNTERS, 0)
        self.link_ttl = config.link_ttl
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
        if config.state_dir:
            os.makedirs(config.state_dir, exist_ok=True)

    def _lease_get(self, key: str, payload: bytes, timeout: float) -> list[bytes]:
        """The lease client's query: the payloads of the replies to `key` (see `agent.lease`)."""
        return [r.payload for r in self.bus.get(key, timeout=timeout, payload=payload)]

    def _warn(self, fmt: str, *args: Any) -> None:
        """Log a warning about refused input, rate-limited (`WARN_RATE`); the next line that gets
        through says how many were left out. The counters count every item."""
        if self._warnings.take():
            n = self._warnings.suppressed()
            log.warning(fmt + (f" ({n} similar warnings not logged)" if n else ""), *args)
