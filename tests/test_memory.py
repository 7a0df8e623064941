"""Freed heap memory is handed back to the system (glibc's malloc_trim)."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from cold_maps.common.memory import _malloc_trim, release_free_heap


def _rss_bytes() -> int:
    with open("/proc/self/statm") as stream:
        return int(stream.read().split()[1]) * 4096


@pytest.mark.skipif(not sys.platform.startswith("linux") or _malloc_trim() is None, reason="needs glibc's malloc_trim")
def test_freed_heap_pages_leave_the_resident_set() -> None:
    blocks = [np.ones(8000) for _ in range(4000)]  # 64 kB each: on the heap, below the mmap threshold
    kept = blocks[-1]
    del blocks  # all but the last one freed: the heap's top stays in use, so nothing is trimmed by itself
    before = _rss_bytes()
    release_free_heap()
    assert before - _rss_bytes() > 0.5 * 4000 * 64_000
    assert kept.sum() == 8000.0
