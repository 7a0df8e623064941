"""Whether a point lies inside a lane (between its borders), and where along the lane.

Lanes of a junction overlap where they leave a common entry: a point a few metres past
the fork lies inside every branch until the branches have drifted apart by half a lane
width. World frame (OpenDRIVE inertial), m.
"""

from __future__ import annotations

import weakref

import numpy as np

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.network.route import route_from_lanes
from gt_matching.polyline import closest_distances

_STRIPS: dict[int, dict[LaneKey, LaneStrip]] = {}
"""Lane strips per live graph (by ``id``; an entry goes when its graph does)."""


def lane_strip(graph: LaneGraph, lane: LaneKey) -> LaneStrip:
    """The centreline and borders of one lane of ``graph`` in driving direction (cached)."""
    strips = _STRIPS.get(id(graph))
    if strips is None:
        strips = _STRIPS[id(graph)] = {}
        weakref.finalize(graph, _STRIPS.pop, id(graph), None)
    strip = strips.get(lane)
    if strip is None:
        route = route_from_lanes(graph, [lane])
        strip = strips[lane] = LaneStrip.from_borders(route.left, route.right)
    return strip


def offset_inside(graph: LaneGraph, lane: LaneKey, point: tuple[float, float]) -> float | None:
    """Distance (m) along ``lane``'s centreline to the cross-section nearest ``point`` when
    ``point`` lies inside the lane (no farther from the centreline than half the lane's
    width there), else None."""
    strip = lane_strip(graph, lane)
    distance, station = closest_distances(np.array([point], dtype=np.float64), strip.centerline)
    left, right = strip.borders_at(station)
    half_width = 0.5 * float(np.hypot(*(left[0] - right[0])))
    return float(station[0]) if float(distance[0]) <= half_width else None
