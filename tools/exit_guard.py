"""The exit guard of an `sme agent` process: when the process is told to stop (SIGINT, SIGTERM) or,
for a worker, when the agent that started it is gone, it asks for a clean stop and ends the process
`grace` seconds later if the clean stop has not ended it by then.

A clean stop can hang where Python cannot interrupt it: a zenoh call on a session whose router
closed (a liveliness query and the link's removal deadlock inside zenoh 1.x) never returns, and a
signal handler only runs between Python bytecodes of the main thread. The guard watches from its
own thread - signals through `signal.set_wakeup_fd`, written by the C-level handler even while the
main thread is blocked, and the parent through `os.getppid()` - so a worker is gone within about
`grace` + one second of its agent's death in every state (connecting, reconnecting, idle,
learning). Before it ends the process it gives `last_words` (the daemon's checkpoint to its state
dir: files only, no bus) at most `last_words_timeout` seconds.
"""

from __future__ import annotations

import logging
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable

log = logging.getLogger("sme.agent")

POLL = 0.2  # seconds between two looks at the parent


def _names(signums: bytes) -> str:
    """The signal numbers read from the wakeup fd, as names (``SIGTERM``)."""
    out = []
    for n in signums:
        try:
            out.append(signal.Signals(n).name)
        except ValueError:
            out.append(str(n))
    return ", ".join(dict.fromkeys(out))


class ExitGuard:
    """Watch for a stop request and end the process `grace` seconds after it (see the module doc).

    Parameters
    ----------
    who : str
        The process's name in log lines (``worker a0.w1``).
    grace : float
        Seconds the clean stop gets before the process is ended.
    parent_pid : int, optional
        Stop when the process's parent is no longer this pid (a worker's agent).
    """

    def __init__(self, who: str, grace: float, parent_pid: int | None = None) -> None:
        self.who = who
        self.grace = grace
        self.parent_pid = parent_pid
        self.stop: Callable[[], None] = lambda: None  # asks for the clean stop (set once there is a daemon)
        self.last_words: Callable[[], object] = lambda: None
        self.last_words_timeout = 0.5
        self._rfd: int | None = None
        self._wfd: int | None = None
        self._old_wakeup_fd = -1
        self._fired = threading.Event()
        self._closed = threading.Event()

    def start(self) -> None:
        """Start watching the parent (if any); call `watch_signals` too once signal handlers are set."""
        threading.Thread(target=self._watch, name="exit-guard", daemon=True).start()

    def watch_signals(self) -> None:
        """Have the C-level signal handler wake the guard (main thread only, after the Python
        handlers for SIGINT/SIGTERM are installed: only signals with a Python handler write the fd)."""
        r, w = os.pipe()
        os.set_blocking(w, False)
        self._old_wakeup_fd = signal.set_wakeup_fd(w, warn_on_full_buffer=False)
        self._rfd, self._wfd = r, w

    def close(self) -> None:
        """Stop watching (the process stopped cleanly; a deadline already running still ends it):
        the previous wakeup fd is put back (main thread only)."""
        self._closed.set()
        if self._wfd is not None:
            signal.set_wakeup_fd(self._old_wakeup_fd)
            os.close(self._wfd)
            self._wfd = None

    def _watch(self) -> None:
        while not self._fired.is_set() and not self._closed.is_set():
            rfd = self._rfd
            if rfd is not None:
                try:
                    ready, _, _ = select.select([rfd], [], [], POLL)
                except (OSError, ValueError):  # closed meanwhile
                    return
                if ready and not self._closed.is_set():
                    signums = os.read(rfd, 64)
                    self.fire(f"{_names(signums) or 'a signal'} received", logging.INFO)  # asked to stop: a normal end
                    return
            else:
                time.sleep(POLL)
            if self.parent_pid is not None and os.getppid() != self.parent_pid:
                self.fire(f"its agent (pid {self.parent_pid}) is gone")
                return

    def fire(self, why: str, level: int = logging.WARNING) -> None:
        """Ask for the clean stop now and end the process `grace` seconds later (once); said at
        `level` (a signal asking to stop is a normal end, an agent gone is not)."""
        if self._fired.is_set():
            return
        self._fired.set()
        log.log(level, "%s: %s; stopping (ends within %g s)", self.who, why, self.grace)
        try:
            self.stop()
        except Exception:  # noqa: BLE001 - the deadline below still holds
            log.exception("%s: stop failed", self.who)
        threading.Thread(target=self._deadline, name="exit-deadline", daemon=True).start()

    def _deadline(self) -> None:
        time.sleep(self.grace)
        done = threading.Event()

        def words() -> None:
            try:
                self.last_words()
            except Exception:  # noqa: BLE001 - ending the process is what matters now
                log.exception("%s: last checkpoint failed", self.who)
            done.set()

        threading.Thread(target=words, name="exit-last-words", daemon=True).start()
        done.wait(self.last_words_timeout)
        log.warning("%s: the clean stop did not end within %g s: ending the process", self.who, self.grace)
        for h in logging.getLogger().handlers + log.handlers:
            try:
                h.flush()
            except Exception:  # noqa: BLE001, S110 - flushing is best effort before _exit
                pass
        sys.stderr.flush()
        os._exit(3)
