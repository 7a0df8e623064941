"""Least-recently-used caches kept in plain ``OrderedDict`` s (the GT's routes, joined
borders, candidate lanelets, border parts and line samples, and the meter's matches)."""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Callable, Hashable
from typing import TypeVar

K = TypeVar("K", bound=Hashable)
V = TypeVar("V")


def lru_get(cache: OrderedDict[K, V], key: K, make: Callable[[], V], size: int | None) -> V:
    """``cache[key]``, made by ``make()`` (never None) when missing, and marked used last;
    beyond ``size`` entries the least recently used is dropped (``size`` None: unbounded,
    nothing reordered)."""
    found = cache.get(key)
    if found is None:
        found = cache[key] = make()
        if size is not None and len(cache) > size:
            cache.popitem(last=False)
    elif size is not None:
        cache.move_to_end(key)
    return found
