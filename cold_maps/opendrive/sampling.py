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
from cold_maps.opendrive.geometry.cubic_curve import (
    CurveStack, arc_length_table, curve_stack, stacked_parameters, stacked_poses)
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
            if np.isfinite(points).all():
                continue
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


@dataclass(frozen=True)
class SectionStack:
    """``batchable`` sections whose listed lanes ``stack_points`` evaluates together, with
    what does not depend on the stations prepared once.

    Fields:
        sections: the (road, section index, listed lane ids).
        records: (n,) the ``<geometry>`` record each section lies on (``_record_of``).
        record_s: (n,) where each record starts (m).
        record_starts: (3, n) x, y (m, inertial frame) and heading (rad) of each record's start.
        lines: (n,) whether the record is a line of positive length.
        curve: (n,) the record's table in ``curves`` (a paramPoly3 of positive length and
            arc length), -1 for the others.
        curves: the tables of those records.
        scales: per table of ``curves``, its arc length over its record's length.
        profiled: (n,) whether the road has elevation or laneOffset records.
        section_s: (n,) each section's start (m).
        widths: per side (1 left, -1 right), per place from the reference line outwards:
            (n, 5) s0, a, b, c, d of the lane's one ``<width>`` (zeros for none).
        has_width: the same places: (n,) whether the lane is there (out to the section's
            outermost listed lane) and has a ``<width>``.
        depth: per side, (n,) how many lanes out the section is evaluated.
        border_planes: each section's borders (2 per listed lane, inner then outer) as
            planes (4 per place: inner x, inner y, outer x, outer y; left places, then
            right), section after section.
        border_first: (n + 1,) where each section's borders start in ``border_planes``.
    """

    sections: tuple[tuple[Road, int, Sequence[int]], ...]
    records: tuple[Geometry, ...]
    record_s: NDArrayFloat
    record_starts: NDArrayFloat
    lines: npt.NDArray[np.bool_]
    curve: NDArrayInt
    curves: CurveStack
    scales: NDArrayFloat
    profiled: npt.NDArray[np.bool_]
    section_s: NDArrayFloat
    widths: dict[int, list[NDArrayFloat]]
    has_width: dict[int, list[npt.NDArray[np.bool_]]]
    depth: dict[int, NDArrayInt]
    border_planes: NDArrayInt
    border_first: NDArrayInt


def section_stack(sections: Sequence[tuple[Road, int, Sequence[int]]]) -> SectionStack:
    """The ``SectionStack`` of ``batchable`` (road, section index, lanes); ValueError where
    a paramPoly3 record's arc length is not finite."""
    from cold_maps.opendrive.geometry.param_poly3 import curve_of

    parts = [section_of(road, index) for road, index, _ in sections]
    records = tuple(_record_of(road, part) for (road, _, _), part in zip(sections, parts))
    tables = {i: arc_length_table(curve_of(record)) for i, record in enumerate(records)
              if record.kind == "paramPoly3" and record.length > 0.0}
    tables = {i: table for i, table in tables.items() if table.total > 0.0}
    curve = np.full(len(sections), -1, dtype=np.int64)
    curve[list(tables)] = np.arange(len(tables))
    outermost = [max((abs(i) for i in ids), default=0) for _, _, ids in sections]
    widths, has_width, depth = {}, {}, {}
    for sign in (1, -1):
        depth[sign] = np.array([min(len(_side(part, sign)), deepest) for part, deepest in zip(parts, outermost)],
                               dtype=np.int64)
        lanes = [[_side(part, sign)[place] for place in range(reach)] for part, reach in zip(parts, depth[sign])]
        widths[sign], has_width[sign] = [], []
        for place in range(int(depth[sign].max(initial=0))):
            records_at = [side[place].widths[0] if place < len(side) and side[place].widths else None for side in lanes]
            widths[sign].append(np.array([(r.s0, r.a, r.b, r.c, r.d) if r is not None else (0.0,) * 5
                                          for r in records_at], dtype=np.float64).reshape(-1, 5))
            has_width[sign].append(np.array([r is not None for r in records_at], dtype=bool))
    left = int(depth[1].max(initial=0))
    borders = [[4 * (place if lane_id > 0 else left + place) + outer
                for lane_id in ids for place in [abs(lane_id) - 1] for outer in (0, 2)] for _, _, ids in sections]
    return SectionStack(
        tuple(sections), records, np.array([record.s for record in records], dtype=np.float64),
        np.array([(record.x, record.y, record.hdg) for record in records], dtype=np.float64).reshape(-1, 3).T.copy(),
        np.array([record.kind == "line" and record.length > 0.0 for record in records], dtype=bool),
        curve, curve_stack(list(tables.values())),
        np.array([table.total / records[i].length for i, table in tables.items()], dtype=np.float64),
        np.array([bool(road.elevation or road.lane_offsets) for road, _, _ in sections], dtype=bool),
        np.array([part.s for part in parts], dtype=np.float64), widths, has_width, depth,
        np.array([plane for block in borders for plane in block], dtype=np.int64),
        np.concatenate(([0], np.cumsum([len(block) for block in borders]))).astype(np.int64))


def ragged_ranges(first: NDArrayInt, sizes: NDArrayInt) -> NDArrayInt:
    """first[0], first[0] + 1, ..., first[0] + sizes[0] - 1, first[1], ...: consecutive runs
    (``first`` 0: each element's rank in its run)."""
    ends = np.cumsum(sizes)
    return np.arange(int(ends[-1]) if len(ends) else 0) + np.repeat(first - (ends - sizes), sizes)


def _stack_poses(
    stack: SectionStack, which: NDArrayInt, s: NDArrayFloat, counts: NDArrayInt
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """``geometry.evaluate(record, max(s - record.s, 0))`` of the record of each section
    ``which[i]`` of the stack at its consecutive block of ``counts[i]`` road s (m), bit for
    bit: lines and paramPoly3 records together, the others one by one; NaN where a record
    cannot be evaluated (the caller names it)."""
    from cold_maps.opendrive.geometry import evaluate

    bounds = np.concatenate(([0], np.cumsum(counts)))
    ds = np.maximum(s - np.repeat(stack.record_s[which], counts), 0.0)
    x, y, hdg = np.full(len(s), np.nan), np.full(len(s), np.nan), np.full(len(s), np.nan)
    lines = stack.lines[which]
    if lines.any():
        at = np.repeat(lines, counts)
        x0, y0, angle = (np.repeat(start[which], counts)[at] for start in stack.record_starts)
        x[at] = x0 + ds[at] * np.cos(angle)
        y[at] = y0 + ds[at] * np.sin(angle)
        hdg[at] = angle
    curve = stack.curve[which]
    curved = curve >= 0
    if curved.any():
        chosen, sizes = curve[curved], counts[curved]
        at = np.repeat(curved, counts)
        with np.errstate(over="ignore", invalid="ignore"):
            p = stacked_parameters(stack.curves, chosen, ds[at] * np.repeat(stack.scales[chosen], sizes), sizes)
            x[at], y[at], hdg[at] = stacked_poses(stack.curves.coefficients[:, chosen],
                                                  stack.record_starts[:, which[curved]], p, sizes)
    for i in np.flatnonzero(~(lines | curved)).tolist():
        a, b = int(bounds[i]), int(bounds[i + 1])
        try:
            x[a:b], y[a:b], hdg[a:b] = evaluate(stack.records[which[i]], ds[a:b])
        except ValueError:
            continue
    return x, y, hdg


def _stack_widths(stack: SectionStack, sign: int, place: int, which: NDArrayInt, s: NDArrayFloat,
                  counts: NDArrayInt) -> NDArrayFloat:
    """``cubic_poly.evaluate(lane.widths, s, s_offset=section.s)`` of the lane at ``place``
    on side ``sign`` of each section ``which[i]`` (0 where it has none) over its block of
    ``counts[i]`` stations (m), bit for bit."""
    s0, c0, c1, c2, c3 = np.repeat(stack.widths[sign][place][which].T, counts, axis=1)  # contiguous rows
    local = s - np.repeat(stack.section_s[which], counts)
    applies = np.repeat(stack.has_width[sign][place][which], counts) & (s0 <= local)
    ds = np.where(applies, local - s0, 0.0)
    return np.where(applies, c0 + ds * (c1 + ds * (c2 + ds * c3)), 0.0)


def stacked_section_points(
    sections: Sequence[tuple[Road, int, Sequence[int]]], s: NDArrayFloat, counts: NDArrayInt
) -> tuple[NDArrayFloat, list[int]]:
    """``stack_points`` of all the sections (``batchable`` road, section index, lanes)."""
    return stack_points(section_stack(sections), np.arange(len(sections)), s, counts)


def stack_points(
    stack: SectionStack, which: NDArrayInt, s: NDArrayFloat, counts: NDArrayInt
) -> tuple[NDArrayFloat, list[int]]:
    """x, y, z (m, inertial frame) of the borders of the listed lanes of each section
    ``which[i]`` of the stack at its block of ``counts[i]`` stations in ``s`` (m): (rows,
    3), section by section, lane by lane, inner then outer, station by station
    (``section_points``' borders, bit for bit: the same elementwise arithmetic on all
    stations at once), and the row where each section starts (and the end). ValueError
    as ``section_points`` where a point is not finite."""
    bounds = np.concatenate(([0], np.cumsum(counts)))
    x, y, hdg = _stack_poses(stack, which, s, counts)
    normal_x, normal_y = -np.sin(hdg), np.cos(hdg)
    z, offset = np.zeros(len(s)), np.zeros(len(s))
    for i in np.flatnonzero(stack.profiled[which]).tolist():
        (road, index, _), a, b = stack.sections[which[i]], int(bounds[i]), int(bounds[i + 1])
        part = road.lane_sections[index]
        if road.elevation:
            z[a:b] = cubic_poly.evaluate(road.elevation, s[a:b], before=part.s_end)
        if road.lane_offsets:
            offset[a:b] = cubic_poly.evaluate(road.lane_offsets, s[a:b], before=part.s_end)
    left = len(stack.widths[1])
    stacked = np.empty((4 * (left + len(stack.widths[-1])), len(s)))
    for sign, first in ((1, 0), (-1, left)):
        inner = offset
        for place in range(int(stack.depth[sign][which].max(initial=0))):
            outer = inner + float(sign) * _stack_widths(stack, sign, place, which, s, counts)
            plane = 4 * (first + place)
            stacked[plane:plane + 4] = (x + inner * normal_x, y + inner * normal_y,
                                        x + outer * normal_x, y + outer * normal_y)
            inner = outer
    borders = stack.border_first[which + 1] - stack.border_first[which]
    planes = stack.border_planes[ragged_ranges(stack.border_first[which], borders)]
    sizes = np.repeat(counts, borders)
    at = ragged_ranges(np.repeat(bounds[:-1], borders), sizes)
    rows = np.repeat(planes, sizes) * len(s) + at
    flat = stacked.ravel()
    values = np.column_stack((flat[rows], flat[rows + len(s)], z[at]))
    starts = np.concatenate(([0], np.cumsum(borders * counts))).tolist()
    if not np.isfinite(values).all():  # section_points names the road, section, lane and s
        for i, (a, b, low, high) in enumerate(zip(bounds[:-1], bounds[1:], starts[:-1], starts[1:])):
            if not np.isfinite(values[low:high]).all():
                road, index, ids = stack.sections[which[i]]
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
