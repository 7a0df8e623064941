"""A lane followed along a route: centreline and borders indexed by station.

Station = arc length along the centreline from the route start (m). The borders are
index-aligned with the centreline (point i of each border lies on the lane's cross-section
through centreline point i), so a station maps to one cross-section of the lane.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from gt_matching.polyline import arc_lengths

MIN_STATION_STEP_M: Final[float] = 1e-9


def resample_polyline(points: NDArrayFloat, distance: NDArrayFloat, start: float, end: float, step: float) -> NDArrayFloat:
    """Points every ``step`` m of arc length from ``start`` to ``end`` (end included).

    ``distance`` is the polyline's cumulative arc length; the last interval is ≤ step.
    """
    count = max(int(np.ceil((end - start) / step - 1e-9)), 1)
    samples = np.minimum(start + step * np.arange(count + 1), end)
    return np.column_stack((np.interp(samples, distance, points[:, 0]), np.interp(samples, distance, points[:, 1])))


def resample_polylines(points: NDArrayFloat, distance: NDArrayFloat, start: NDArrayFloat, end: NDArrayFloat,
                       step: float) -> tuple[NDArrayFloat, npt.NDArray[np.intp]]:
    """:func:`resample_polyline` from every ``start[k]`` to ``end[k]`` (m of arc length), the
    samples of all stretches stacked in order (the same values as one by one), and the
    (K + 1,) offsets of each stretch's first sample in the stack."""
    counts = np.maximum(np.ceil((end - start) / step - 1e-9).astype(np.intp), 1) + 1
    offsets = np.concatenate(([0], np.cumsum(counts)))
    local = np.arange(offsets[-1]) - np.repeat(offsets[:-1], counts)
    samples = np.minimum(np.repeat(start, counts) + step * local, np.repeat(end, counts))
    return np.column_stack((np.interp(samples, distance, points[:, 0]), np.interp(samples, distance, points[:, 1]))), offsets


@dataclass(frozen=True)
class LaneStrip:
    """A lane along a route, world frame (OpenDRIVE inertial), in driving direction.

    Fields:
        station: (N,) centreline arc length from the route start (m), strictly increasing.
        centerline: (N, 2) centreline points x, y (m).
        left: (N, 2) left border seen in driving direction (m), index-aligned.
        right: (N, 2) right border seen in driving direction (m), index-aligned.
        left_distance, right_distance: (N,) arc length along each border from its first
            point (m).
        heading: (N,) unwrapped centreline heading (rad, counter-clockwise from x) from
            central differences, exact at the vertices of a uniformly sampled arc.
    """

    station: NDArrayFloat
    centerline: NDArrayFloat
    left: NDArrayFloat
    right: NDArrayFloat
    left_distance: NDArrayFloat
    right_distance: NDArrayFloat
    heading: NDArrayFloat

    @classmethod
    def from_borders(cls, left: NDArrayFloat, right: NDArrayFloat) -> LaneStrip:
        """Build from index-aligned left/right borders; the centreline is their midpoint.

        Consecutive cross-sections whose centre points coincide (route joints) are merged.
        Raises ValueError for mismatched shapes, non-finite values or fewer than 2 points.
        """
        left = np.asarray(left, dtype=np.float64)
        right = np.asarray(right, dtype=np.float64)
        if left.ndim != 2 or left.shape[1] != 2 or left.shape != right.shape:
            raise ValueError(f"lane borders must be two (N, 2) arrays of equal N, got {left.shape} and {right.shape}")
        if not (np.isfinite(left).all() and np.isfinite(right).all()):
            raise ValueError("lane borders contain NaN or inf")
        centre = 0.5 * (left + right)
        step = np.hypot(*np.diff(centre, axis=0).T)
        keep = np.concatenate(([True], step > MIN_STATION_STEP_M))
        centre, left, right = centre[keep], left[keep], right[keep]
        if len(centre) < 2:
            raise ValueError("lane strip needs at least two distinct cross-sections")
        return cls(
            station=arc_lengths(centre),
            centerline=centre,
            left=left,
            right=right,
            left_distance=arc_lengths(left),
            right_distance=arc_lengths(right),
            heading=np.unwrap(np.arctan2(*np.gradient(centre, axis=0).T[::-1])),
        )

    @property
    def length(self) -> float:
        """Centreline length (m)."""
        return float(self.station[-1])

    def _weights(self, stations: NDArrayFloat) -> tuple[npt.NDArray[np.intp], NDArrayFloat]:
        """Per station (clamped to the strip), the cross-section before it and the
        interpolation weight ``(N, 1)`` of the one after it."""
        stations = np.minimum(np.maximum(np.asarray(stations, dtype=np.float64), 0.0), self.length)
        index = np.minimum(np.maximum(np.searchsorted(self.station, stations, side="right") - 1, 0),
                           len(self.station) - 2)
        span = self.station[index + 1] - self.station[index]
        return index, ((stations - self.station[index]) / span)[:, None]

    def _lines_at(self, lines: tuple[NDArrayFloat, ...], stations: NDArrayFloat) -> tuple[NDArrayFloat, ...]:
        """The points of ``lines`` (the strip's, index-aligned with ``station``) at the given
        stations (clamped to the strip), linearly between cross-sections."""
        index, w = self._weights(stations)
        after = index + 1
        return tuple(line[index] * (1.0 - w) + line[after] * w for line in lines)

    def interpolate(self, stations: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
        """Centreline, left and right points at the given stations (clamped to the strip)."""
        centre, left, right = self._lines_at((self.centerline, self.left, self.right), stations)
        return centre, left, right

    def borders_at(self, stations: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Left and right points at the given stations (clamped to the strip): those of
        :meth:`interpolate`, without the centreline."""
        left, right = self._lines_at((self.left, self.right), stations)
        return left, right

    def poses(self, stations: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
        """:meth:`pose` of every station (m): x, y (m) and heading (rad) arrays, the same
        values as station by station."""
        stations = np.asarray(stations, dtype=np.float64)
        clamped = np.minimum(np.maximum(stations, 0.0), self.length)
        index = np.minimum(np.maximum(np.searchsorted(self.station, clamped, side="right") - 1, 0),
                           len(self.station) - 2)
        before = self.station[index]
        w = ((clamped - before) / (self.station[index + 1] - before))[:, None]
        centre = self.centerline[index] * (1.0 - w) + self.centerline[index + 1] * w
        yaw = np.interp(stations, self.station, self.heading)
        return centre[:, 0], centre[:, 1], np.arctan2(np.sin(yaw), np.cos(yaw))

    def pose(self, station: float) -> tuple[float, float, float]:
        """Position (m) and heading (rad) of the centreline at a station (``_weights`` of
        one station, in scalars)."""
        clamped = min(max(float(station), 0.0), self.length)
        index = min(max(int(np.searchsorted(self.station, clamped, side="right")) - 1, 0), len(self.station) - 2)
        before, after = self.station[index:index + 2].tolist()
        w = (clamped - before) / (after - before)
        (x0, y0), (x1, y1) = self.centerline[index:index + 2].tolist()
        yaw = float(np.interp(station, self.station, self.heading))
        return x0 * (1.0 - w) + x1 * w, y0 * (1.0 - w) + y1 * w, float(np.arctan2(np.sin(yaw), np.cos(yaw)))
