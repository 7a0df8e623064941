"""Route geometry: one continuous lane centreline with its borders, in driving direction.

Built from a sequence of lanes that follow each other in the lane graph. Every lane is
sampled on its section's s grid (``sampling.sample_lane_borders``), put in driving order,
and appended; the first point of a lane is dropped when it coincides with the last point
of the previous lane (within ``JOIN_TOLERANCE_M``). Seen in the driving direction the
left border is the lane's border on the +t side (left of the reference line) when the lane
is driven along s and the one on the -t side when driven against s; the traffic rule and
the lane's ``direction`` ("reversed") both enter only through ``Road.drives_along_s``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, OpenDriveMap, Road
from cold_maps.opendrive.sampling import LaneBorderSamples, sample_lane_borders, sample_road

JOIN_TOLERANCE_M: Final[float] = 1e-3
"""Centre points of successive lanes closer than this (m) are one point."""


@dataclass(frozen=True)
class RoutePiece:
    """One lane followed over part of its section.

    Fields:
        road_id: id of the road.
        section: 0-based lane-section index.
        lane_id: OpenDRIVE lane id.
        s_start: road s (m) where the route enters the lane.
        s_end: road s (m) where it leaves; below ``s_start`` when driving against s.
    """

    road_id: str
    section: int
    lane_id: int
    s_start: float
    s_end: float


@dataclass(frozen=True)
class Route:
    """A drivable route, world frame (OpenDRIVE inertial), ordered in driving direction.

    Fields:
        pieces: the lanes it is made of, in order.
        centre: (N, 2) centreline x, y (m).
        left: (N, 2) left border seen in driving direction (m), index-aligned with centre.
        right: (N, 2) right border seen in driving direction (m), index-aligned.
        distance: (N,) arc length along the centreline from its first point (m).
        piece: (N,) index into ``pieces`` of the lane each cross-section lies in.
        s: (N,) road s (m) of each cross-section on its piece's road.
        left_z, right_z: (N,) height (m, inertial frame) of each border point.
    """

    pieces: tuple[RoutePiece, ...]
    centre: NDArrayFloat
    left: NDArrayFloat
    right: NDArrayFloat
    distance: NDArrayFloat
    piece: npt.NDArray[np.int64]
    s: NDArrayFloat
    left_z: NDArrayFloat
    right_z: NDArrayFloat

    @property
    def length(self) -> float:
        """Centreline length (m)."""
        return float(self.distance[-1])


def borders_in_driving_direction(
    road: Road, samples: LaneBorderSamples
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """s (N,), left (N, 3) and right (N, 3) borders of a sampled lane in driving order.

    Left is the driver's left: the +t border (outer for lanes > 0, inner for lanes < 0)
    when the lane is driven along s, the -t border when driven against s (by the road's
    rule and the lane's ``direction``).
    """
    plus_t, minus_t = (samples.outer, samples.inner) if samples.lane_id > 0 else (samples.inner, samples.outer)
    if road.drives_along_s(samples.lane_id, samples.section):
        return samples.s, plus_t, minus_t
    return samples.s[::-1], minus_t[::-1], plus_t[::-1]


@dataclass(frozen=True)
class DrivingBorders:
    """One lane's borders as its driver sees them, world frame (OpenDRIVE inertial), in driving order.

    Fields:
        lane: the lane (road id, 0-based lane-section index, lane id).
        s: (N,) road s (m) of each cross-section; decreasing when the lane is driven against s.
        left: (N, 3) x, y, z (m) of the driver's left border.
        right: (N, 3) x, y, z (m) of the driver's right border, index-aligned with ``left``.
    """

    lane: LaneKey
    s: NDArrayFloat
    left: NDArrayFloat
    right: NDArrayFloat


def _driving_borders(road: Road, samples: LaneBorderSamples) -> DrivingBorders:
    return DrivingBorders(LaneKey(road.id, samples.section, samples.lane_id),
                          *borders_in_driving_direction(road, samples))


def lane_borders(
    odr_map: OpenDriveMap, lane: tuple[str, int, int], *, step: float = 0.1, record_ends: bool = False
) -> DrivingBorders:
    """Left and right border of one lane (road id, section index, lane id) in driving order,
    every ``step`` m of s over its section (``record_ends`` as in ``sampling.sample_road``).

    The rows ``cold-maps export`` writes for this lane are these borders with ``record_ends=True``.
    Raises KeyError naming the road or lane when the map has no such lane, IndexError
    naming the road when it has no such section.
    """
    road_id, section, lane_id = lane
    if road_id not in odr_map.roads:
        raise KeyError(f"{odr_map.path}: no road {road_id!r}")
    road = odr_map.roads[road_id]
    return _driving_borders(road, sample_lane_borders(road, section, lane_id, step, record_ends=record_ends))


def road_borders(
    road: Road, *, step: float = 0.1, lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES,
    record_ends: bool = False,
) -> list[DrivingBorders]:
    """``lane_borders`` of every lane of a road whose type is in ``lane_types`` (None: all),
    in ``sampling.sample_road``'s order; the reference line is evaluated once per section."""
    return [_driving_borders(road, samples)
            for samples in sample_road(road, step=step, lane_types=lane_types, record_ends=record_ends)]


def route_from_lanes(graph: LaneGraph, lanes: Sequence[LaneKey], *, step: float = 0.1) -> Route:
    """The route through ``lanes`` (each followed whole), sampled every ``step`` m of s.

    Raises ValueError when ``lanes`` is empty, names a lane not in the graph, or two
    successive lanes are not joined by a graph edge.
    """
    if not lanes:
        raise ValueError("a route needs at least one lane")
    for lane in lanes:
        if lane not in graph.lengths:
            raise ValueError(f"route lane {tuple(lane)} is not in the lane graph")
    for before, after in zip(lanes, lanes[1:]):
        if after not in graph.successors[before]:
            raise ValueError(f"route lane {tuple(after)} does not follow lane {tuple(before)}")
    centres: list[NDArrayFloat] = []
    lefts: list[NDArrayFloat] = []
    rights: list[NDArrayFloat] = []
    stations: list[NDArrayFloat] = []
    for lane in lanes:
        road = graph.odr_map.roads[lane.road_id]
        samples = sample_lane_borders(road, lane.section, lane.lane_id, step=step)
        s, left, right = borders_in_driving_direction(road, samples)
        centre = 0.5 * (left[:, :2] + right[:, :2])
        if centres and np.hypot(*(centre[0] - centres[-1][-1])) < JOIN_TOLERANCE_M:
            s, centre, left, right = s[1:], centre[1:], left[1:], right[1:]
        centres.append(centre)
        lefts.append(left)
        rights.append(right)
        stations.append(s)
    centre = np.concatenate(centres)
    left, right = np.concatenate(lefts), np.concatenate(rights)
    piece = np.repeat(np.arange(len(lanes), dtype=np.int64), [len(s) for s in stations])
    pieces = tuple(
        RoutePiece(lane.road_id, lane.section, lane.lane_id, graph.entry_s(lane), graph.exit_s(lane))
        for lane in lanes
    )
    distance = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(centre, axis=0).T))))
    return Route(pieces, centre, np.ascontiguousarray(left[:, :2]), np.ascontiguousarray(right[:, :2]), distance,
                 piece, np.concatenate(stations), left[:, 2].copy(), right[:, 2].copy())
