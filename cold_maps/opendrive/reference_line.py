"""A road's reference line (``<planView>``): pose at any s, vectorised."""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive import geometry
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import Road

S_TOLERANCE_M: Final[float] = 1e-6
"""How far outside [0, road.length] an s may lie (round-off of the caller's arithmetic)."""


def check_s(road: Road, s: NDArrayFloat) -> NDArrayFloat:
    """s as a float64 array; ValueError naming the road when s is NaN or off the road."""
    s = np.asarray(s, dtype=np.float64)
    if not np.all(np.isfinite(s)):
        raise ValueError(f"road {road.id}: s contains NaN or infinity")
    if s.size and (s.min() < -S_TOLERANCE_M or s.max() > road.length + S_TOLERANCE_M):
        raise ValueError(
            f"road {road.id}: s in [{s.min():.6g}, {s.max():.6g}] m leaves the road [0, {road.length:.6g}] m"
        )
    return s


def reference_pose(
    road: Road, s: NDArrayFloat, *, before: float | None = None
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) of the reference line at each s (m), same shape as s.

    Each s is evaluated on the last ``<geometry>`` record starting at or before it, among
    the records starting before ``before`` (m) when given: at a lane section's end this
    takes the record the section's interior uses, so a small gap the map has between
    two records does not bend the section's closing border.
    """
    s = check_s(road, s)
    if not road.plan_view:
        raise ValueError(f"road {road.id}: <planView> has no <geometry> record")
    index = record_index(road, s, before=before)
    if s.ndim and s.size and index.min() == index.max():  # one record: no masks
        return _evaluate(road, int(index.flat[0]), s)
    x = np.empty_like(s)
    y = np.empty_like(s)
    hdg = np.empty_like(s)
    for i in np.unique(index):
        mask = index == i
        x[mask], y[mask], hdg[mask] = _evaluate(road, int(i), s[mask])
    return x, y, hdg


def record_index(road: Road, s: NDArrayFloat, *, before: float | None = None) -> npt.NDArray[np.intp]:
    """Index of the ``<geometry>`` record :func:`reference_pose` evaluates each s (m) on:
    the last one starting at or before it, among those starting before ``before`` (m)
    when given (the road has at least one record)."""
    if len(road.plan_view) == 1:
        return np.zeros(np.shape(s), dtype=np.intp)
    starts = np.array([g.s for g in road.plan_view])
    last = len(starts) if before is None else max(int(np.searchsorted(starts, before, side="left")), 1)
    return np.clip(np.searchsorted(starts[:last], s, side="right") - 1, 0, last - 1)


def _evaluate(road: Road, index: int, s: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Pose (x, y in m, heading in rad) at road s (m) on record ``index`` (s before its start: at its start)."""
    record = road.plan_view[index]
    try:
        return geometry.evaluate(record, np.maximum(s - record.s, 0.0))
    except ValueError as exc:
        raise ValueError(f"road {road.id}: {exc}") from None


def record_joint(road: Road, index: int) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Poses (x, y in m, heading in rad; arrays of 3) at the joint in front of record ``index``
    (≥ 1): where the record before it is when it reaches this record's s (the reference line
    the lanes are drawn on), and where this record starts (its parametric curve at 0, so a
    paramPoly3 with aU, aV ≠ 0 starts off its x, y)."""
    s = road.plan_view[index].s
    end = np.concatenate(reference_pose(road, np.array([s]), before=s))
    start = np.concatenate(reference_pose(road, np.array([s]), before=np.nextafter(s, np.inf)))
    return end, start
