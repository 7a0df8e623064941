"""Where a map's geometry does not join: reference-line records and lane-graph links.

A road's ``<geometry>`` records should meet end to start with the same heading, and two
linked lanes should share their borders where one leaves and the other enters. Real maps
jump (a CommonRoad-written map 2-4 cm at record joints, LGSVL maps up to 10 cm); these
functions find and size every jump, in the OpenDRIVE inertial frame (m, rad), so
``cold-maps info`` and ``check`` can report them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.network.route import borders_in_driving_direction
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import OpenDriveMap
from cold_maps.opendrive.reference_line import record_joint
from cold_maps.opendrive.sampling import sample_lane_borders

GAP_TOLERANCE_M: Final[float] = 1e-3
"""Reference-line record joints farther apart than this (m) are reported."""

KINK_TOLERANCE_RAD: Final[float] = math.radians(0.1)
"""Reference-line record joints whose heading changes by more than this (rad) are reported."""

LINK_TOLERANCE_M: Final[float] = 0.01
"""Lane-graph links whose borders are farther apart than this (m) are reported."""

LISTED_MAX: Final[int] = 10
"""Report lines list at most this many of the largest items."""


@dataclass(frozen=True)
class RecordJoint:
    """Where a road's ``<geometry>`` record ends and the next one starts.

    Fields:
        road_id: the road.
        s: start of the next record (m along the road).
        gap_m: distance (m) from the end of the previous record (evaluated at ``s``) to
            the start of the next one, in the x-y plane.
        kink_rad: absolute heading change (rad, in [0, π]) across the joint.
    """

    road_id: str
    s: float
    gap_m: float
    kink_rad: float


@dataclass(frozen=True)
class LinkGap:
    """A lane-graph link whose borders do not meet.

    Fields:
        exit_lane: the lane a vehicle leaves.
        entry_lane: the lane it enters.
        distance_m: the larger of the left-border and right-border distances (m, x-y
            plane) between the exit end of ``exit_lane`` and the entry end of ``entry_lane``.
    """

    exit_lane: LaneKey
    entry_lane: LaneKey
    distance_m: float


def record_joints(odr_map: OpenDriveMap) -> list[RecordJoint]:
    """Every joint between consecutive ``<geometry>`` records of every road, in map order."""
    joints = []
    for road in odr_map.roads.values():
        for index in range(1, len(road.plan_view)):
            end, start = record_joint(road, index)
            turn = (float(start[2] - end[2]) + math.pi) % (2.0 * math.pi) - math.pi
            gap = math.hypot(*(start[:2] - end[:2]))
            joints.append(RecordJoint(road.id, road.plan_view[index].s, gap, abs(turn)))
    return joints


def reference_line_defects(
    odr_map: OpenDriveMap, gap_m: float = GAP_TOLERANCE_M, kink_rad: float = KINK_TOLERANCE_RAD
) -> list[RecordJoint]:
    """Record joints with a gap above ``gap_m`` (m) or a kink above ``kink_rad`` (rad)."""
    return _defects(record_joints(odr_map), gap_m, kink_rad)


def _defects(joints: Sequence[RecordJoint], gap_m: float, kink_rad: float) -> list[RecordJoint]:
    return [joint for joint in joints if joint.gap_m > gap_m or joint.kink_rad > kink_rad]


def _lane_ends(graph: LaneGraph, lane: LaneKey) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(2, 2) left and (2, 2) right border points (x, y in m) at the lane's entry and exit."""
    road = graph.odr_map.roads[lane.road_id]
    section = road.lane_sections[lane.section]
    step = max(section.s_end - section.s, 1e-6)
    _, left, right = borders_in_driving_direction(road, sample_lane_borders(road, lane.section, lane.lane_id, step))
    return left[[0, -1], :2], right[[0, -1], :2]


def link_gap_points(graph: LaneGraph, gap: LinkGap) -> NDArrayFloat:
    """(4, 2) x, y (m) of the exit lane's left and right border ends and the entry lane's
    left and right border starts of a link gap."""
    (left_a, right_a), (left_b, right_b) = _lane_ends(graph, gap.exit_lane), _lane_ends(graph, gap.entry_lane)
    return np.array([left_a[1], right_a[1], left_b[0], right_b[0]])


def link_gaps(graph: LaneGraph, tolerance_m: float = LINK_TOLERANCE_M) -> list[LinkGap]:
    """Graph edges whose exit and entry borders are farther apart than ``tolerance_m`` (m)."""
    ends: dict[LaneKey, tuple[NDArrayFloat, NDArrayFloat]] = {}

    def lane_ends(lane: LaneKey) -> tuple[NDArrayFloat, NDArrayFloat]:
        if lane not in ends:
            ends[lane] = _lane_ends(graph, lane)
        return ends[lane]

    gaps = []
    for exit_lane, entry_lane in graph.edges():
        (left_a, right_a), (left_b, right_b) = lane_ends(exit_lane), lane_ends(entry_lane)
        distance = max(float(np.hypot(*(left_a[1] - left_b[0]))), float(np.hypot(*(right_a[1] - right_b[0]))))
        if distance > tolerance_m:
            gaps.append(LinkGap(exit_lane, entry_lane, distance))
    return gaps


def _lane(lane: LaneKey) -> str:
    return f"road {lane.road_id} section {lane.section} lane {lane.lane_id}"


def record_length_mismatches(odr_map: OpenDriveMap, tolerance_m: float = GAP_TOLERANCE_M) -> list[RecordJoint]:
    """``<geometry>`` records whose ``length`` ends more than ``tolerance_m`` before or after
    the next record's ``s`` (or the road's length, for the last): the reference line follows
    the records' s (each drawn on to the next), so the length is ignored there; as
    ``RecordJoint`` with ``s`` the record's end by s and ``gap_m`` the signed mismatch (m,
    > 0: the record is longer), ``kink_rad`` 0."""
    found = []
    for road in odr_map.roads.values():
        for index, record in enumerate(road.plan_view):
            end = road.plan_view[index + 1].s if index + 1 < len(road.plan_view) else road.length
            mismatch = record.s + record.length - end
            if abs(mismatch) > tolerance_m:
                found.append(RecordJoint(road.id, end, mismatch, 0.0))
    return found


def continuity_report(odr_map: OpenDriveMap, graph: LaneGraph) -> list[str]:
    """Report lines: reference-line gaps and kinks, geometry records whose length
    disagrees with where the next one starts, then lane links whose borders do not meet,
    each a count line followed by the ``LISTED_MAX`` largest, indented."""
    every = record_joints(odr_map)
    joints = _defects(every, GAP_TOLERANCE_M, KINK_TOLERANCE_RAD)
    lines = [
        f"reference-line joints over {GAP_TOLERANCE_M * 1e3:g} mm or {math.degrees(KINK_TOLERANCE_RAD):g} deg: "
        f"{len(joints)} of {len(every)}"
    ]
    for joint in sorted(joints, key=lambda j: (-j.gap_m, -j.kink_rad))[:LISTED_MAX]:
        lines.append(
            f"  road {joint.road_id} s={joint.s:.3f}: gap {joint.gap_m * 1e3:.1f} mm, "
            f"kink {math.degrees(joint.kink_rad):.3f} deg"
        )
    mismatches = record_length_mismatches(odr_map)
    records = sum(len(road.plan_view) for road in odr_map.roads.values())
    lines.append(f"geometry records whose length ends over {GAP_TOLERANCE_M * 1e3:g} mm from the next record's s or "
                 f"the road end (drawn to it): {len(mismatches)} of {records}")
    for joint in sorted(mismatches, key=lambda j: -abs(j.gap_m))[:LISTED_MAX]:
        lines.append(f"  road {joint.road_id} record ending at s={joint.s:.3f}: length off by {joint.gap_m:+.3f} m")
    gaps = link_gaps(graph)
    lines.append(
        f"lane links whose borders miss by over {LINK_TOLERANCE_M * 1e2:g} cm: {len(gaps)} of {sum(1 for _ in graph.edges())}"
    )
    for gap in sorted(gaps, key=lambda g: -g.distance_m)[:LISTED_MAX]:
        lines.append(f"  {_lane(gap.exit_lane)} -> {_lane(gap.entry_lane)}: {gap.distance_m * 1e2:.1f} cm")
    return lines
