"""protocol.heap.trim: freed heap pages go back to the OS (the recorder's flat RSS depends on it)."""

import sys
import threading

import pytest

from sensorimotor.protocol import heap


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096 / 2**20


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/statm; malloc_trim is glibc's")
def test_trim_gives_freed_heap_back_to_the_os() -> None:
    """Blocks freed between survivors stay resident until trimmed: what a recorder's payloads did."""
    kept: list[bytearray] = []

    def churn() -> None:
        blocks = [bytearray(32 * 1024) for _ in range(6000)]  # ~190 MB below glibc's mmap threshold
        kept.extend(blocks[::200])  # survivors pin the arena: glibc cannot shrink it by itself
        blocks.clear()

    t = threading.Thread(target=churn)  # another thread: another arena, as with Zenoh's callbacks
    t.start()
    t.join()
    before = rss_mb()
    assert heap.trim()
    assert rss_mb() < before - 100
