"""World → road projection: which road, section and lane contain a point, at which (s, t).

``MapLocator`` indexes coarse reference-line samples of every road in a KD-tree
(scipy.spatial.cKDTree). ``locate`` takes the roads with a sample near the point, refines
s on each by Newton steps on the reference line (foot of the perpendicular), reads t,
and picks the lane whose borders enclose t at that s.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.lanes import section_borders
from cold_maps.opendrive.model import OpenDriveMap, Road
from cold_maps.opendrive.reference_line import reference_pose
from cold_maps.opendrive.sampling import sample_s

DEFAULT_MAX_DISTANCE_M: Final[float] = 1.0
COARSE_STEP_M: Final[float] = 1.0
NEWTON_ITERATIONS: Final[int] = 30
NEWTON_TOLERANCE_M: Final[float] = 1e-10
CURVATURE_STEP_M: Final[float] = 1e-3
MIN_RADIAL_FACTOR: Final[float] = 0.1
"""Floor of 1 - curvature·t in the Newton step (points near the centre of curvature)."""


@dataclass(frozen=True)
class RoadPosition:
    """A point located on the map.

    Fields:
        road_id: id of the road.
        section: index of the lane section containing s.
        lane_id: the lane whose borders enclose t (the nearest lane when none does).
        s: road s (m) of the foot of the perpendicular on the reference line.
        t: lateral offset (m) from the reference line, positive to the left.
        distance: distance (m) from the point to that lane: 0 inside it, else the lateral
            gap to its nearer border combined with any overshoot past the road's ends.
    """

    road_id: str
    section: int
    lane_id: int
    s: float
    t: float
    distance: float


def _frame_offsets(road: Road, x: float, y: float, s: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """(along, lateral) offsets (m) of point (x, y) in the reference frame at each s, and the heading (rad)."""
    px, py, heading = reference_pose(road, s)
    dx, dy = x - px, y - py
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    return dx * cos_h + dy * sin_h, dy * cos_h - dx * sin_h, heading


def _project(road: Road, x: float, y: float, s: float) -> tuple[float, float, float]:
    """Newton refinement of the foot point from a start s: (s, t, overshoot past an end), in m."""
    for _ in range(NEWTON_ITERATIONS):
        probe = np.clip(s + np.array([-CURVATURE_STEP_M, 0.0, CURVATURE_STEP_M]), 0.0, road.length)
        along, lateral, heading = _frame_offsets(road, x, y, probe)
        curvature = (heading[2] - heading[0]) / max(probe[2] - probe[0], 1e-12)
        step = along[1] / max(1.0 - curvature * lateral[1], MIN_RADIAL_FACTOR)
        s_next = float(np.clip(s + step, 0.0, road.length))
        converged = abs(s_next - s) < NEWTON_TOLERANCE_M
        s = s_next
        if converged:
            break
    along, lateral, _ = _frame_offsets(road, x, y, np.array([s]))
    overshoot = abs(float(along[0])) if s in (0.0, road.length) else 0.0
    return s, float(lateral[0]), overshoot


def _lane_at(road: Road, s: float, t: float) -> tuple[int, int, float, float]:
    """(section index, lane id, lateral gap in m, |t - lane centre| in m) for t at s."""
    starts = np.array([section.s for section in road.lane_sections])
    section = int(np.clip(np.searchsorted(starts, s, side="right") - 1, 0, len(starts) - 1))
    borders = section_borders(road, section, np.array([s]))
    best: tuple[float, bool, int, int, float] | None = None
    for lane_id, (inner, outer) in borders.items():
        if lane_id == 0:
            continue
        low, high = sorted((float(inner[0]), float(outer[0])))
        gap = max(low - t, t - high, 0.0)
        key = (gap, high <= low, abs(lane_id), lane_id, abs(t - 0.5 * (low + high)))
        if best is None or key < best:
            best = key
    if best is None:
        offset = float(borders[0][0][0])
        return section, 0, abs(t - offset), abs(t - offset)
    return section, best[3], best[0], best[4]


class MapLocator:
    """Nearest road / section / lane and (s, t) of inertial points on one map."""

    def __init__(
        self,
        odr_map: OpenDriveMap,
        *,
        max_distance: float = DEFAULT_MAX_DISTANCE_M,
        coarse_step: float = COARSE_STEP_M,
    ):
        """Index every road's reference line every ``coarse_step`` m; ``max_distance`` in m."""
        from scipy.spatial import cKDTree

        if not (np.isfinite(max_distance) and max_distance >= 0.0):
            raise ValueError(f"MapLocator: max_distance must be a finite length >= 0 m, got {max_distance}")
        roads = [road for road in odr_map.roads.values() if road.plan_view and road.lane_sections]
        if not roads:
            raise ValueError(f"MapLocator: map {odr_map.path or '<input>'} has no road with geometry and lanes")
        self._roads = roads
        self._max_distance = float(max_distance)
        self._step = float(coarse_step)
        points, owners, params, reaches = [], [], [], []
        for index, road in enumerate(roads):
            s = sample_s(0.0, road.length, coarse_step)
            x, y, _ = reference_pose(road, s)
            points.append(np.column_stack((x, y)))
            owners.append(np.full(s.size, index))
            params.append(s)
            reaches.append(self._reach(road, coarse_step))
        self._tree = cKDTree(np.concatenate(points))
        self._owner = np.concatenate(owners)
        self._s = np.concatenate(params)
        self._reach_by_road: NDArrayFloat = np.array(reaches)
        self._radius = float(self._reach_by_road.max()) + self._max_distance + coarse_step

    @staticmethod
    def _reach(road: Road, step: float) -> float:
        """Largest |t| (m) of any lane border of the road, on the coarse grid."""
        reach = 0.0
        for index, section in enumerate(road.lane_sections):
            s = sample_s(section.s, section.s_end, step)
            for inner, outer in section_borders(road, index, s).values():
                reach = max(reach, float(np.abs(inner).max()), float(np.abs(outer).max()))
        return reach

    def locate(self, x: float, y: float) -> RoadPosition | None:
        """The lane position of inertial point (x, y) in m; None when no lane is within max_distance."""
        if not (np.isfinite(x) and np.isfinite(y)):
            raise ValueError(f"MapLocator.locate: point ({x}, {y}) is not finite")
        hits = np.asarray(self._tree.query_ball_point((x, y), self._radius), dtype=np.intp)
        if hits.size == 0:
            return None
        distances = np.hypot(self._tree.data[hits, 0] - x, self._tree.data[hits, 1] - y)
        best: tuple[tuple[float, float, float], RoadPosition] | None = None
        for road_index in np.unique(self._owner[hits]):
            mine = self._owner[hits] == road_index
            nearest = int(np.argmin(np.where(mine, distances, np.inf)))
            if distances[nearest] > self._reach_by_road[road_index] + self._max_distance + self._step:
                continue
            road = self._roads[road_index]
            s, t, overshoot = _project(road, x, y, float(self._s[hits[nearest]]))
            section, lane_id, gap, off_centre = _lane_at(road, s, t)
            distance = float(np.hypot(gap, overshoot))
            if distance > self._max_distance:
                continue
            key = (distance, overshoot, off_centre)
            if best is None or key < best[0]:
                best = (key, RoadPosition(road.id, section, lane_id, s, t, distance))
        return None if best is None else best[1]
