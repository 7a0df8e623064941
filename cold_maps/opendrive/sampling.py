"""Sampling lane borders into 3-D polylines, and road → world coordinates.

Points are in the inertial frame (x, y, z in m). z is the reference line's elevation
(``<elevationProfile>``) at the same s, plus the superelevation (``<lateralProfile>``):
the cross section is rolled by the angle θ(s) about the reference line, so a border at
t lies tan θ·t higher, except across lanes with ``level="true"``, which stay flat at the
height of their inner border (lanes beyond continue from there). The horizontal
position stays t from the reference line (as in commonroad-scenario-designer and every
2-D consumer; libOpenDRIVE instead measures t along the tilted surface, which moves a
border by t·(1 − cos θ) inwards: 1.4 cm at t = 7 m and θ = 3.5°). Lane ``height``
and lateral ``shape`` are not applied.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive import cubic_poly
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.lanes import lane_of, section_borders, section_of
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, Geometry, Lane, LaneSection, Road
from cold_maps.opendrive.reference_line import check_s, record_index, record_joint, reference_pose

NDArrayInt = npt.NDArray[np.int64]

JOINED_M: Final[float] = 1e-6
"""Geometry records whose end and next start are closer than this (m) join: one sample."""

SLIVER_FRACTION: Final[float] = 1e-9
"""A grid point closer than this fraction of the step to the end point is merged into it."""
MAX_SAMPLES: Final[int] = 10_000_000
"""Most points ``sample_s`` returns (checked before allocating): 80 MB per float64 array,
ten times a 100 km road (``validation.MAX_ROAD_LENGTH_M``) at the default 0.1 m step."""


def sample_s(s_start: float, s_end: float, step: float) -> NDArrayFloat:
    """s_start, s_start + step, ..., then exactly s_end (m).

    Every interval is ``step`` except the last, which is in (0, step]; a sliver shorter
    than ``SLIVER_FRACTION``·step is merged into the last interval instead of creating a
    near-duplicate end point (unless it is the whole range). s_start == s_end gives the
    single point s_start. ValueError (before any allocation) when that is more than
    ``MAX_SAMPLES`` points.
    """
    if not (np.isfinite(s_start) and np.isfinite(s_end)):
        raise ValueError(f"sample_s: s_start={s_start} and s_end={s_end} must be finite")
    if not (np.isfinite(step) and step > 0.0):
        raise ValueError(f"sample_s: step must be a positive finite length in m, got {step}")
    if s_end < s_start:
        raise ValueError(f"sample_s: s_end={s_end} is before s_start={s_start}")
    if s_end == s_start:
        return np.array([float(s_start)])
    intervals = np.ceil((s_end - s_start) / step)
    if not intervals < MAX_SAMPLES:
        raise ValueError(f"sampling [{s_start:.6g}, {s_end:.6g}] m every {step:g} m takes {intervals:.3g} points, "
                         f"more than {MAX_SAMPLES}: use a longer step")
    count = int(intervals)
    grid = s_start + step * np.arange(count, dtype=np.float64)
    interior = grid[1:][grid[1:] < s_end - SLIVER_FRACTION * step]
    return np.concatenate(([float(s_start)], interior, [float(s_end)]))


def road_to_world(road: Road, s: NDArrayFloat, t: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) of road coordinates (s along the reference line, t to its left), broadcast."""
    x, y, hdg = reference_pose(road, s)
    t = np.asarray(t, dtype=np.float64)
    if not np.all(np.isfinite(t)):
        raise ValueError(f"road {road.id}: t contains NaN or infinity")
    return x - t * np.sin(hdg), y + t * np.cos(hdg)


def elevation(road: Road, s: NDArrayFloat) -> NDArrayFloat:
    """z (m) of the reference line at each s (m) from ``<elevationProfile>``; 0 without records."""
    return cubic_poly.evaluate(road.elevation, check_s(road, s))


@dataclass(frozen=True)
class LaneBorderSamples:
    """Both borders of one lane in one lane section, sampled on a common s grid.

    Fields:
        road_id: id of the road.
        section: index of the lane section in ``road.lane_sections``.
        lane_id: OpenDRIVE lane id.
        s: (N,) road s (m), strictly increasing (NOT the driving direction), both section
            ends included; with record ends, every interior start of a ``<geometry>``
            record is sampled, twice where the records do not join (``JOINED_M``):
            first the end of the record before it, then its start.
        inner: (N, 3) x, y, z (m, inertial frame) of the border nearer lane 0.
        outer: (N, 3) x, y, z (m, inertial frame) of the border farther from lane 0.
    """

    road_id: str
    section: int
    lane_id: int
    s: NDArrayFloat
    inner: NDArrayFloat
    outer: NDArrayFloat

    def __post_init__(self) -> None:
        """ValueError naming road, section, lane and s where a border point is not finite."""
        for side, points in (("inner", self.inner), ("outer", self.outer)):
            bad = ~np.all(np.isfinite(points), axis=1)
            if np.any(bad):
                raise ValueError(f"road {self.road_id}: lane section {self.section}, lane {self.lane_id}: the {side} "
                                 f"border is not finite at s={float(self.s[bad][0]):.6g} m")


def record_indices(road: Road, s_start: float, s_end: float) -> list[int]:
    """Indices of the road's ``<geometry>`` records that start strictly inside (s_start, s_end) m."""
    return [i for i, record in enumerate(road.plan_view) if s_start < record.s < s_end]


@dataclass(frozen=True)
class RecordJoints:
    """The ``<geometry>`` record starts inside one lane section, for sampling record ends.

    Fields:
        boundaries: (K,) road s (m) of each record start strictly inside the section.
        jumps: (K,) whether the record before it ends farther than ``JOINED_M`` from it.
        ends: (J, 3) x, y (m, inertial frame) and heading (rad) where the record before
            each jumping start ends (J = jumps.sum()).
    """

    boundaries: NDArrayFloat
    jumps: npt.NDArray[np.bool_]
    ends: NDArrayFloat


def record_joints(road: Road, section_index: int) -> RecordJoints:
    """The record starts inside a section and where the records do not join."""
    section = section_of(road, section_index)
    indices = record_indices(road, section.s, section.s_end)
    joints = [record_joint(road, i) for i in indices]
    jumps = np.array([np.hypot(*(end[:2] - start[:2])) > JOINED_M for end, start in joints], dtype=bool)
    ends = np.array([end for (end, _), jump in zip(joints, jumps) if jump], dtype=np.float64).reshape(-1, 3)
    return RecordJoints(np.array([road.plan_view[i].s for i in indices], dtype=np.float64), jumps, ends)


def _reference_with_record_ends(
    road: Road, section: LaneSection, s: NDArrayFloat, joints: RecordJoints
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """s with each interior record start added, and doubled where the records do not join
    (end and start farther apart than ``JOINED_M``), with the reference pose there: the
    first of a pair on the record that ends at it, the second on the record that starts."""
    boundaries = joints.boundaries
    s = np.sort(np.concatenate((s[~np.isin(s, boundaries)], boundaries, boundaries[joints.jumps])))
    x, y, hdg = reference_pose(road, s, before=section.s_end)
    for boundary, end in zip(boundaries[joints.jumps], joints.ends):
        first = int(np.searchsorted(s, boundary, side="left"))
        x[first], y[first], hdg[first] = end
    return s, x, y, hdg


def _border_heights(
    road: Road, section: LaneSection, s: NDArrayFloat, z: NDArrayFloat,
    borders: dict[int, tuple[NDArrayFloat, NDArrayFloat]],
) -> dict[int, tuple[NDArrayFloat, NDArrayFloat]]:
    """z (m) of each lane's (inner, outer) border: reference elevation plus superelevation."""
    if not road.superelevation:
        return {lane_id: (z, z) for lane_id in borders}
    slope = np.tan(cubic_poly.evaluate(road.superelevation, s, before=section.s_end))
    centre = z + slope * borders[0][0]
    heights = {0: (centre, centre)}
    for side in (section.left, section.right):
        inner_z = centre
        for lane in side:
            if lane.id not in borders:
                break
            inner, outer = borders[lane.id]
            outer_z = inner_z if lane.level else inner_z + slope * (outer - inner)
            heights[lane.id] = (inner_z, outer_z)
            inner_z = outer_z
    return heights


def _section_samples(
    road: Road, section_index: int, step: float, lane_ids: Sequence[int], record_ends: bool = False
) -> list[LaneBorderSamples]:
    """Samples of the listed lanes of one section; the reference line is evaluated once."""
    section = section_of(road, section_index)
    return sample_section_at(road, section_index, sample_s(section.s, section.s_end, step), lane_ids, record_ends)


def section_points(
    road: Road, section_index: int, s: NDArrayFloat, lane_ids: Sequence[int], joints: RecordJoints | None = None
) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Stations (N,) (m) and borders (L, 2, N, 3) (x, y, z in m, inertial frame; inner
    then outer of each of the L listed lanes) of one section at ``s`` (m, strictly
    increasing inside the section); with ``joints`` (``record_joints`` of the section)
    its record ends are added as in ``sample_road``. ValueError naming road, section,
    lane and s where a border point is not finite."""
    section = section_of(road, section_index)
    if joints is not None and len(joints.boundaries):
        s, x, y, hdg = _reference_with_record_ends(road, section, s, joints)
    else:
        x, y, hdg = reference_pose(road, s, before=section.s_end)
    normal_x, normal_y = -np.sin(hdg), np.cos(hdg)
    z = cubic_poly.evaluate(road.elevation, s, before=section.s_end)
    outermost = max((abs(i) for i in lane_ids), default=0)
    borders = section_borders(road, section_index, s, outermost=outermost)
    heights = _border_heights(road, section, s, z, borders)
    points = np.empty((len(lane_ids), 2, len(s), 3))
    for index, lane_id in enumerate(lane_ids):
        for which in (0, 1):
            t = borders[lane_id][which]
            points[index, which, :, 0] = x + t * normal_x
            points[index, which, :, 1] = y + t * normal_y
            points[index, which, :, 2] = heights[lane_id][which]
    bad = ~np.isfinite(points).all(axis=3)
    if bad.any():
        lane, which, at = (int(i[0]) for i in np.nonzero(bad))
        raise ValueError(f"road {road.id}: lane section {section_index}, lane {lane_ids[lane]}: the "
                         f"{('inner', 'outer')[which]} border is not finite at s={float(s[at]):.6g} m")
    return s, points


def batchable(road: Road, section_index: int, lane_ids: Sequence[int]) -> bool:
    """Whether ``stacked_section_points`` evaluates the listed lanes of a section: no record
    starts inside it, no superelevation, and every lane out to the outermost listed one
    has at most one ``<width>`` record (and no ``<border>`` in its stead)."""
    section = section_of(road, section_index)
    if road.superelevation or not road.plan_view or record_indices(road, section.s, section.s_end):
        return False
    outermost = max((abs(i) for i in lane_ids), default=0)
    lanes = [(sign, lane) for sign in (1, -1) for lane in _side(section, sign)[:outermost]]
    return ({lane.id for _, lane in lanes} >= set(lane_ids)
            and all(sign * lane.id > 0 and (len(lane.widths) == 1 or not (lane.widths or lane.borders))
                    for sign, lane in lanes))


def _record_of(road: Road, section: LaneSection) -> Geometry:
    """The ``<geometry>`` record ``reference_pose(..., before=section.s_end)`` takes
    everywhere on a section no record starts inside."""
    return road.plan_view[int(record_index(road, np.float64(section.s), before=section.s_end))]


def _records_poses(
    records: Sequence[Geometry], s: NDArrayFloat, counts: NDArrayInt
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """``geometry.evaluate(records[i], max(s - records[i].s, 0))`` of each consecutive
    block of ``counts[i]`` road s (m), bit for bit: lines and paramPoly3 records together,
    the others one by one; NaN where a record cannot be evaluated (the caller names it)."""
    from cold_maps.opendrive.geometry import evaluate
    from cold_maps.opendrive.geometry.cubic_curve import arc_length_table, parameters, poses_at_parameters
    from cold_maps.opendrive.geometry.param_poly3 import curve_of

    bounds = np.concatenate(([0], np.cumsum(counts)))
    ds = np.maximum(s - np.repeat([record.s for record in records], counts), 0.0)
    x, y, hdg = np.full(len(s), np.nan), np.full(len(s), np.nan), np.full(len(s), np.nan)
    done = np.zeros(len(records), dtype=bool)
    lines = np.array([record.kind == "line" and record.length > 0.0 for record in records], dtype=bool)
    if lines.any():
        at = np.repeat(lines, counts)
        angle = np.repeat([record.hdg for record in records], counts)[at]
        x[at] = np.repeat([record.x for record in records], counts)[at] + ds[at] * np.cos(angle)
        y[at] = np.repeat([record.y for record in records], counts)[at] + ds[at] * np.sin(angle)
        hdg[at] = angle
        done |= lines
    curved = [(i, arc_length_table(curve_of(record))) for i, record in enumerate(records)
              if record.kind == "paramPoly3" and record.length > 0.0]
    curved = [(i, table) for i, table in curved if table.total > 0.0]
    if curved:
        chosen = [records[i] for i, _ in curved]
        tables = [table for _, table in curved]
        sizes = counts[[i for i, _ in curved]]
        at = np.repeat(np.isin(np.arange(len(records)), [i for i, _ in curved]), counts)
        scale = np.repeat([table.total / record.length for table, record in zip(tables, chosen)], sizes)
        with np.errstate(over="ignore", invalid="ignore"):
            p = parameters(tables, ds[at] * scale, sizes)
            x[at], y[at], hdg[at] = poses_at_parameters(chosen, [table.curve for table in tables], p, sizes)
        done[[i for i, _ in curved]] = True
    for i in np.flatnonzero(~done).tolist():
        a, b = int(bounds[i]), int(bounds[i + 1])
        try:
            x[a:b], y[a:b], hdg[a:b] = evaluate(records[i], ds[a:b])
        except ValueError:
            continue
    return x, y, hdg


def _single_width(
    lanes: Sequence[Lane | None], sections: Sequence[LaneSection], s: NDArrayFloat, counts: NDArrayInt
) -> NDArrayFloat:
    """``cubic_poly.evaluate(lane.widths, s, s_offset=section.s)`` of each lane (at most one
    record; None: no lane, 0) over its block of ``counts`` stations (m), bit for bit."""
    records = [lane.widths[0] if lane is not None and lane.widths else None for lane in lanes]
    table = np.array([(r.s0, r.a, r.b, r.c, r.d) if r is not None else (0.0,) * 5 for r in records]).reshape(-1, 5)
    s0, c0, c1, c2, c3 = np.repeat(table.T, counts, axis=1)  # contiguous rows
    local = s - np.repeat([section.s for section in sections], counts)
    applies = np.repeat([r is not None for r in records], counts) & (s0 <= local)
    ds = np.where(applies, local - s0, 0.0)
    return np.where(applies, c0 + ds * (c1 + ds * (c2 + ds * c3)), 0.0)


def stacked_section_points(
    sections: Sequence[tuple[Road, int, Sequence[int]]], s: NDArrayFloat, counts: NDArrayInt
) -> tuple[NDArrayFloat, list[int]]:
    """x, y, z (m, inertial frame) of the borders of the listed lanes of each (road,
    section index, lanes), all ``batchable``, at its block of ``counts`` stations in ``s``
    (m): (rows, 3), section by section, lane by lane, inner then outer, station by
    station (``section_points``' borders, bit for bit: the same elementwise arithmetic on
    all stations at once), and the row where each section starts (and the end).
    ValueError as ``section_points`` where a point is not finite."""
    bounds = np.concatenate(([0], np.cumsum(counts)))
    parts = [section_of(road, index) for road, index, _ in sections]
    x, y, hdg = _records_poses([_record_of(road, part) for (road, _, _), part in zip(sections, parts)], s, counts)
    normal_x, normal_y = -np.sin(hdg), np.cos(hdg)
    z, offset = np.zeros(len(s)), np.zeros(len(s))
    for (road, _, _), part, a, b in zip(sections, parts, bounds[:-1].tolist(), bounds[1:].tolist()):
        if road.elevation:
            z[a:b] = cubic_poly.evaluate(road.elevation, s[a:b], before=part.s_end)
        if road.lane_offsets:
            offset[a:b] = cubic_poly.evaluate(road.lane_offsets, s[a:b], before=part.s_end)
    depth = max((abs(i) for _, _, ids in sections for i in ids), default=0)
    planes = {}  # (side, place) → the plane index of its inner x, y (outer: + 2)
    xy = []
    for sign in (1, -1):
        inner = offset
        for place in range(depth):
            lanes = [_side(part, sign)[place] if place < min(len(_side(part, sign)), max(map(abs, ids), default=0))
                     else None for part, (_, _, ids) in zip(parts, sections)]
            if not any(lanes):
                break
            outer = inner + float(sign) * _single_width(lanes, parts, s, counts)
            planes[sign, place] = len(xy)
            xy += [x + inner * normal_x, y + inner * normal_y, x + outer * normal_x, y + outer * normal_y]
            inner = outer
    # each border row: its plane (x; y is the next) and its section's block of stations
    plane, first, size = [], [], []
    for (_, _, ids), part, a, count in zip(sections, parts, bounds[:-1].tolist(), counts.tolist()):
        places = {lane.id: (sign, place) for sign in (1, -1) for place, lane in enumerate(_side(part, sign))}
        for lane_id in ids:
            plane += [planes[places[lane_id]], planes[places[lane_id]] + 2]
            first += [a, a]
            size += [count, count]
    sizes = np.asarray(size, dtype=np.int64)
    ends = np.cumsum(sizes)
    at = np.arange(int(ends[-1]) if len(ends) else 0) + np.repeat(np.asarray(first, dtype=np.int64) - (ends - sizes), sizes)
    stacked = np.stack(xy) if xy else np.zeros((0, len(s)))
    rows = np.repeat(np.asarray(plane, dtype=np.int64), sizes) * len(s) + at
    values = np.column_stack((stacked.ravel()[rows], stacked.ravel()[rows + len(s)], z[at]))
    starts = np.concatenate(([0], np.cumsum([2 * len(ids) * count for (_, _, ids), count
                                              in zip(sections, counts.tolist())]))).tolist()
    if not np.isfinite(values).all():  # section_points names the road, section, lane and s
        for (road, index, ids), a, b, low, high in zip(sections, bounds[:-1], bounds[1:], starts[:-1], starts[1:]):
            if not np.isfinite(values[low:high]).all():
                section_points(road, index, s[a:b], ids)
        raise ValueError("a lane border is not finite")  # not reached: section_points raised
    return values, starts


def _side(section: LaneSection, sign: int) -> tuple[Lane, ...]:
    """The section's left (sign 1) or right (-1) lanes, from the reference line outwards."""
    return section.left if sign > 0 else section.right


def sample_section_at(
    road: Road, section_index: int, s: NDArrayFloat, lane_ids: Sequence[int], record_ends: bool = False,
    joints: RecordJoints | None = None,
) -> list[LaneBorderSamples]:
    """Borders of the listed lanes of one section at the given stations ``s`` (m, strictly
    increasing inside the section; with ``record_ends`` the interior record starts are
    added, and doubled where the records do not join, as in ``sample_road``; ``joints``:
    the section's ``record_joints`` when already computed)."""
    if record_ends and joints is None:
        joints = record_joints(road, section_index)
    stations, points = section_points(road, section_index, s, lane_ids, joints if record_ends else None)
    return [LaneBorderSamples(road.id, section_index, lane_id, stations, points[index, 0], points[index, 1])
            for index, lane_id in enumerate(lane_ids)]


def sample_lane_borders(
    road: Road, section_index: int, lane_id: int, step: float = 0.1, *, record_ends: bool = False
) -> LaneBorderSamples:
    """Inner and outer border of one lane every ``step`` m over its section (ends included);
    ``record_ends`` as in ``sample_road``."""
    lane_of(road, section_index, lane_id)
    return _section_samples(road, section_index, step, [lane_id], record_ends)[0]


def sample_road(
    road: Road, step: float = 0.1, lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES, *,
    record_ends: bool = False
) -> list[LaneBorderSamples]:
    """Borders of every lane whose type is in ``lane_types`` (None: all lanes), section by section.

    Ordered by section, then left lanes outwards, then right lanes outwards. With
    ``record_ends`` the end and start of every ``<geometry>`` record inside a section
    are sampled too (see ``LaneBorderSamples.s``), so a jump between records is drawn
    exactly rather than as a chord.
    """
    result: list[LaneBorderSamples] = []
    for index, section in enumerate(road.lane_sections):
        ids = [lane.id for lane in section.lanes if lane_types is None or lane.type in lane_types]
        if ids:
            result.extend(_section_samples(road, index, step, ids, record_ends))
    return result
