"""Piecewise cubic profiles (lane width, border, laneOffset, elevation), vectorised over s.

One shared evaluator for every ``<width>``, ``<border>``, ``<laneOffset>`` and
``<elevation>`` record list: at position s the last record with ``s0 <= s - s_offset``
applies, with ``ds = s - s_offset - s0``; where no record applies the profile is 0.
Profiles are right-continuous. ``before`` ignores records starting at or after that s, which
gives the left limit at a lane section's end: a road-level profile (laneOffset,
elevation) that jumps where the next section starts must not move the closing border of
the section before it.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive.model import CubicPoly

NDArrayFloat = npt.NDArray[np.float64]
"""Float64 array; in this package arrays are vectorised over s (m)."""


def _coefficients(records: Sequence[CubicPoly]) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Record starts (n,) and coefficients (n, 4), after checking the starts are ordered."""
    table = np.array([(r.s0, r.a, r.b, r.c, r.d) for r in records], dtype=np.float64).reshape(-1, 5)
    if not np.isfinite(table).all():
        raise ValueError("cubic profile: a record has a non-finite s0 or coefficient")
    starts = table[:, 0]
    if len(starts) > 1 and (starts[1:] < starts[:-1]).any():
        raise ValueError(f"cubic profile: record starts are not ordered by s0: {starts.tolist()}")
    return starts, table[:, 1:]


def _locate(
    records: Sequence[CubicPoly], s: NDArrayFloat, s_offset: float, before: float | None
) -> tuple[NDArrayFloat, NDArrayFloat, npt.NDArray[np.bool_]]:
    """Per point: the applying record's coefficients (N, 4), its ds (N,), and whether one
    applies (ds 0 where none does: the first record's polynomial at a point before it could
    overflow, e.g. for a record starting at s0 = 1e308)."""
    s = np.asarray(s, dtype=np.float64)
    if before is not None:
        records = [r for r in records if r.s0 + s_offset < before]
    if not records:
        return np.zeros(s.shape + (4,)), np.zeros(s.shape), np.zeros(s.shape, dtype=bool)
    starts, coeffs = _coefficients(records)
    local = s - s_offset
    index = np.searchsorted(starts, local, side="right") - 1
    applies = index >= 0
    index = np.maximum(index, 0)
    return coeffs[index], np.where(applies, local - starts[index], 0.0), applies


def evaluate(
    records: Sequence[CubicPoly], s: NDArrayFloat, *, s_offset: float = 0.0, before: float | None = None
) -> NDArrayFloat:
    """The profile value at each s (unit of the records' ``a``); 0 where no record applies."""
    if not records:
        return np.zeros(np.shape(s))
    c, ds, applies = _locate(records, s, s_offset, before)
    value = c[..., 0] + ds * (c[..., 1] + ds * (c[..., 2] + ds * c[..., 3]))
    return np.where(applies, value, 0.0)


def derivative(
    records: Sequence[CubicPoly], s: NDArrayFloat, *, s_offset: float = 0.0, before: float | None = None
) -> NDArrayFloat:
    """d(profile)/ds at each s (unit of ``a`` per m); 0 where no record applies."""
    c, ds, applies = _locate(records, s, s_offset, before)
    value = c[..., 1] + ds * (2.0 * c[..., 2] + ds * 3.0 * c[..., 3])
    return np.where(applies, value, 0.0)
