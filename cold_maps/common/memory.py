"""Freed heap memory handed back to the system.

glibc's ``malloc`` keeps the memory a long run frees between its temporary arrays in its
heap, and most of it stays resident: on a 10 000-frame ``cold-eval`` drive the heap held
about 94 MB free (against 141 MB in use) after 1 000 frames. :func:`release_free_heap`
hands the free pages back (``malloc_trim(0)``); where the C library has no ``malloc_trim``
(not glibc) it does nothing.
"""

from __future__ import annotations

import ctypes
import functools
import sys
from typing import Any


@functools.cache
def _malloc_trim() -> Any:
    """glibc's ``malloc_trim``, or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        trim = ctypes.CDLL(None).malloc_trim
    except (OSError, AttributeError):
        return None
    trim.argtypes = [ctypes.c_size_t]
    trim.restype = ctypes.c_int
    return trim


def release_free_heap() -> None:
    """Hands the heap's free pages back to the system (glibc; elsewhere nothing)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
