"""Synthetic Lanelet2 maps built from lane centrelines, for tests and benchmarks.

Lanelets whose borders meet at the same position share Lanelet2 points, and a border
whose points another lanelet already uses (in either order) shares its line string, so
successors and neighbours connect in the routing graph. Right-hand traffic.
"""

from __future__ import annotations

import math
from typing import Any, Final

import numpy as np

from gt_matching.geometry import line_xy
from gt_matching.polyline import NDArrayFloat, at_fractions, paired_fractions

#: Positions closer than this share one Lanelet2 point, m.
POINT_RESOLUTION_M: Final = 1e-6


def offset_polyline(centre: NDArrayFloat, offset_m: float, headings: NDArrayFloat | None = None) -> NDArrayFloat:
    """``centre`` (``(N, 2)``, m) moved ``offset_m`` to the left (negative: right) along the
    normal of ``headings`` (rad, per vertex; default: direction of the neighbouring vertices).
    On a finely sampled circular arc this is the concentric arc."""
    centre = np.asarray(centre, dtype=np.float64)
    if headings is None:
        ahead = np.vstack((centre[1:2] - centre[0:1], centre[2:] - centre[:-2], centre[-1:] - centre[-2:-1]))
        headings = np.arctan2(ahead[:, 1], ahead[:, 0])
    return centre + offset_m * np.column_stack((-np.sin(headings), np.cos(headings)))


class LaneletMapBuilder:
    """Collects lanes (centreline + width) and builds a ``LaneletMap`` and routing graph."""

    def __init__(self) -> None:
        self._points: dict[tuple[int, int], Any] = {}
        self._lines: dict[tuple[int, ...], Any] = {}
        self._lanelets: list[Any] = []

    def add_lane(self, centre: NDArrayFloat, width_m: float, headings: NDArrayFloat | None = None) -> int:
        """Add a lanelet around ``centre`` (``(N, 2)``, m, driving order) of constant width;
        borders are offset by ``width_m / 2`` along the normal of ``headings`` (rad, per
        vertex; default: direction of the neighbouring vertices). Returns the lanelet id."""
        from lanelet2.core import Lanelet, getId

        left = offset_polyline(centre, 0.5 * width_m, headings)
        right = offset_polyline(centre, -0.5 * width_m, headings)
        lanelet = Lanelet(getId(), self._line(left), self._line(right))
        lanelet.attributes["subtype"] = "road"
        lanelet.attributes["location"] = "urban"
        lanelet.attributes["one_way"] = "yes"
        self._lanelets.append(lanelet)
        return int(lanelet.id)

    def build(self) -> tuple[Any, Any]:
        """The ``LaneletMap`` and its routing graph (Germany, vehicle traffic rules)."""
        import lanelet2
        from lanelet2.traffic_rules import Locations, Participants

        lanelet_map = lanelet2.core.createMapFromLanelets(self._lanelets)
        rules = lanelet2.traffic_rules.create(Locations.Germany, Participants.Vehicle)
        return lanelet_map, lanelet2.routing.RoutingGraph(lanelet_map, rules)

    def _point(self, xy: NDArrayFloat) -> Any:
        from lanelet2.core import Point3d, getId

        key = (round(xy[0] / POINT_RESOLUTION_M), round(xy[1] / POINT_RESOLUTION_M))
        point = self._points.get(key)
        if point is None:
            point = self._points[key] = Point3d(getId(), float(xy[0]), float(xy[1]), 0.0)
        return point

    def _line(self, xy: NDArrayFloat) -> Any:
        from lanelet2.core import LineString3d, getId

        points = [self._point(p) for p in xy]
        ids = tuple(p.id for p in points)
        if ids in self._lines:
            return self._lines[ids]
        if ids[::-1] in self._lines:
            return self._lines[ids[::-1]].invert()
        line = self._lines[ids] = LineString3d(getId(), points)
        line.attributes["type"] = "line_thin"
        line.attributes["subtype"] = "dashed"
        return line


def arc(
    start: tuple[float, float], heading: float, radius_m: float, turn_rad: float, step_m: float
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Circular arc from ``start`` (m) with initial ``heading`` (rad), turning ``turn_rad``
    (positive: left) on ``radius_m``; vertices every <= ``step_m`` along it and their headings."""
    count = max(2, math.ceil(abs(turn_rad) * radius_m / step_m) + 1)
    side = math.copysign(1.0, turn_rad)
    centre = np.array(start) + side * radius_m * np.array((-math.sin(heading), math.cos(heading)))
    angles = heading - side * math.pi / 2.0 + np.linspace(0.0, turn_rad, count)
    points = centre + radius_m * np.column_stack((np.cos(angles), np.sin(angles)))
    points[0] = start
    return points, heading + np.linspace(0.0, turn_rad, count)


def straight(
    start: tuple[float, float], heading: float, length_m: float, step_m: float
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Straight line from ``start`` (m) along ``heading`` (rad), vertices every <= ``step_m``,
    and their headings."""
    count = max(2, math.ceil(length_m / step_m) + 1)
    s = np.linspace(0.0, length_m, count)
    points = np.array(start) + s[:, None] * np.array((math.cos(heading), math.sin(heading)))
    return points, np.full(count, heading)


def grid_network(
    rows: int,
    cols: int,
    *,
    spacing_m: float = 100.0,
    lane_width_m: float = 3.5,
    junction_half_m: float = 12.0,
    vertex_step_m: float = 1.0,
) -> tuple[Any, Any]:
    """A ``rows`` x ``cols`` grid of four-way junctions ``spacing_m`` apart, joined by
    two-lane roads (one lane per direction); in each junction every incoming lane connects
    to every outgoing arm but its own (straight lines and circular turns).

    Returns the ``LaneletMap`` and its routing graph.
    """
    builder = LaneletMapBuilder()
    half_lane = lane_width_m / 2.0
    road_m = spacing_m - 2.0 * junction_half_m
    directions = [0.0, math.pi / 2.0, math.pi, -math.pi / 2.0]

    def arm_exists(i: int, j: int, direction: int) -> bool:
        di, dj = round(math.cos(directions[direction])), round(math.sin(directions[direction]))
        return 0 <= i + di < cols and 0 <= j + dj < rows

    def lane_pose(i: int, j: int, direction: int, distance_m: float) -> tuple[float, float]:
        """Point on the right-hand lane heading ``direction`` at ``distance_m`` from junction (i, j)."""
        heading = directions[direction]
        return (
            i * spacing_m + distance_m * math.cos(heading) + half_lane * math.sin(heading),
            j * spacing_m + distance_m * math.sin(heading) - half_lane * math.cos(heading),
        )

    for j in range(rows):
        for i in range(cols):
            for out in range(4):
                if arm_exists(i, j, out):
                    points, headings = straight(lane_pose(i, j, out, junction_half_m), directions[out], road_m, vertex_step_m)
                    builder.add_lane(points, lane_width_m, headings)
                    for into in range(4):
                        if into == (out + 2) % 4 or not arm_exists(i, j, (into + 2) % 4):
                            continue
                        start = lane_pose(i, j, into, -junction_half_m)
                        turn = (out - into + 2) % 4 - 2
                        if turn == 0:
                            points, headings = straight(start, directions[into], 2.0 * junction_half_m, vertex_step_m)
                        else:
                            radius = junction_half_m + (half_lane if turn > 0 else -half_lane)
                            points, headings = arc(start, directions[into], radius, turn * math.pi / 2.0, vertex_step_m)
                        builder.add_lane(points, lane_width_m, headings)
    return builder.build()



def sequence_borders(lanelets: list[Any], step_m: float) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Left and right borders of a lanelet sequence (driving order) as a lane sensor pairs
    them: each lanelet's borders sampled at the same fractions of their lengths, about
    every ``step_m`` of the longer one; ``(N, 2)`` each, m, world frame."""
    lefts, rights = [], []
    for i, lanelet in enumerate(lanelets):
        left, right = line_xy(lanelet.leftBound, f"lanelet {lanelet.id}"), line_xy(lanelet.rightBound, f"lanelet {lanelet.id}")
        fractions = paired_fractions(left, right, step_m)[1 if i else 0 :]
        lefts.append(at_fractions(left, fractions))
        rights.append(at_fractions(right, fractions))
    return np.vstack(lefts), np.vstack(rights)
