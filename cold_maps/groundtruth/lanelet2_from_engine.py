"""The Lanelet2 ground truth built from the map engine: the lane borders the sensor reads
and ``cold-maps export`` writes, the lane graph's successors, through the converters'
Lanelet2 writer and cache (``converters.Converter`` of kind "engine").

- A lanelet per lane and lane section of ``LANE_TYPES`` (lanes narrower than
  ``ZERO_WIDTH_M`` over their whole section are dropped, as crdesigner drops them), its
  borders in the driver's frame (the inner border is on the left when the lane drives
  along s on the right of the reference line, or against s on its left), tagged
  ``opendrive:lanes`` with the lane and ``ele`` with the engine's heights (elevation and
  superelevation).
- Borders sampled adaptively (``adaptive_section_samples``): every ``<geometry>`` record
  end (a jump between records drawn exactly), every width, border, laneOffset, elevation
  and superelevation record start, both section ends and a vertex ``END_VERTEX_M`` inside
  each end, then intervals halved until the border's midpoint lies within
  ``CHORD_TOLERANCE_M`` of the chord (checked at a quarter, half and three quarters of
  each interval; a failing one is split into as many pieces as the chord error's square
  root says, the error growing with the interval squared). All lanes of a section share the stations, so neighbours share their
  border exactly and the writer makes it one way (Lanelet2 adjacency). Sections on one
  line or paramPoly3 record whose lanes have one ``<width>`` each are refined together
  (``adaptive_samples``), with the same stations and points, bit for bit.
- Successors are the lane graph's edges (``network.lane_graph``); linked ends at one
  point are one node, others are snapped to their centroid whatever
  the gap (``converters.joins``, join tolerance infinite), so every lane-graph edge is a
  Lanelet2 routing successor. A snap moves the border end by at most half the gap and
  fades out at the vertex ``END_VERTEX_M`` inside the end (the writer's Douglas-Peucker
  keeps it once the end moved). Such gaps are where the map is broken
  (``network.continuity.link_gaps``); elsewhere the borders are the engine's within the
  chord tolerance (the writer keeps every vertex: no further simplification).
- Line types from ``<roadMark>`` (``opendrive.road_marks.classify_border`` every
  ``MARK_STEP_M`` and at each mark start, the kind covering most of the border's length): solid → line_thin/solid (bold → line_thick),
  broken and botts dots → dashed, solid solid → solid_solid, solid broken / broken solid
  → solid_dashed or dashed_solid (OpenDRIVE names the lines from the reference line out;
  Lanelet2 from left to right along the way), curb → curbstone/high, grass and edge →
  road_border, an unpainted border towards another drivable lane → virtual.
- Lanelet types from the lane type and the road ``<type>`` at the section
  (``road_rules``): town roads urban, motorways highway; junction lanes intersection.
- Regulatory elements from ``road_rules`` (speed limits; traffic lights, stop and yield
  signs from the engine's reading of ``<signal>``).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from cold_maps.network.lane_graph import LaneGraph, LaneKey, build_lane_graph
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.lanes import section_borders
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, OpenDriveMap, Road
from cold_maps.opendrive.road_marks import NO_MARK, BorderMarking, BoundaryType, classify_border, uniform_marking
from cold_maps.opendrive.sampling import (
    MAX_SAMPLES, SLIVER_FRACTION, LaneBorderSamples, NDArrayInt, batchable, ragged_ranges, record_joints, sample_s,
    section_points, section_stack, stack_points)
from converters import Converter, ConversionError
from converters.crdesigner_bridge import SourceLanelet
from converters.regulatory import LaneletRegulations

KIND: Final[str] = "engine"
"""The converter kind of this ground truth (cache key, ``--converter``)."""

BUILDER_VERSION: Final[str] = "1"
"""Version of this builder's output (part of the cache key with the package version)."""

LANE_TYPES: Final[tuple[str, ...]] = VEHICLE_LANE_TYPES + (
    "restricted", "bidirectional", "shoulder", "sidewalk", "walking")
"""OpenDRIVE lane types that get a lanelet: the vehicle lanes and crdesigner's other
default types (``filter_types``), so neighbour lanes and walkways stay as today."""

CHORD_TOLERANCE_M: Final[float] = 5e-4
"""Largest distance (m) of a border's midpoint between two stations from their chord."""

INITIAL_STEP_M: Final[float] = 50.0
"""Longest interval (m) the adaptive sampling starts from."""

MIN_STEP_M: Final[float] = 1e-3
"""Intervals this short (m) are not halved further (a jump in a width record)."""

MAX_ROUNDS: Final[int] = 24
"""Most halvings of one interval (2 m / 2**24 is far below ``MIN_STEP_M``)."""

SPLIT_MARGIN: Final[float] = 1.25
"""An interval whose chord error is e is split into ceil(margin·sqrt(e / tolerance)) pieces."""

MAX_PIECES: Final[int] = 64
"""Most pieces an interval is split into in one round."""

END_VERTEX_M: Final[float] = 0.1
"""A station this far (m) inside each section end: where a snapped join fades out."""

MERGE_TOLERANCE_M: Final[float] = 0.0
"""Only equal border points become one node: the borders neighbours share are computed
once, bit-identical; linked ends are joined (``converters.joins``) whatever their gap."""

ZERO_WIDTH_M: Final[float] = 1e-3
"""A lane never wider than this (m) over its section gets no lanelet."""


def _breakpoints(road: Road, section_index: int) -> NDArrayFloat:
    """Road s (m) where a record of the section's geometry, widths, borders, laneOffset,
    elevation or superelevation starts, inside the section."""
    section = road.lane_sections[section_index]
    starts = [record.s for record in road.plan_view]
    starts += [poly.s0 for records in (road.lane_offsets, road.elevation, road.superelevation) for poly in records]
    starts += [section.s + poly.s0 for lane in section.lanes for poly in lane.widths + lane.borders]
    inside = np.array([s for s in starts if section.s < s < section.s_end], dtype=np.float64)
    return inside


CHECK_FRACTIONS: Final[tuple[float, ...]] = (0.25, 0.5, 0.75)
"""Where inside each interval the border is compared with the chord (a cubic width
symmetric about the midpoint leaves the midpoint on the chord, not the quarter points)."""


def _chord_errors(points: NDArrayFloat, checked: NDArrayFloat, open_: npt.NDArray[np.bool_]) -> NDArrayFloat:
    """Per open interval, the largest distance (m, 3-D) of a border point at one of
    ``CHECK_FRACTIONS`` (``checked``: (borders, fractions, intervals, 3)) from the chord's
    point at the same fraction (``points``: (borders, stations, 3))."""
    low, high = points[:, None, :-1][:, :, open_], points[:, None, 1:][:, :, open_]
    fractions = np.asarray(CHECK_FRACTIONS)[:, None, None]
    chord = (1.0 - fractions) * low + fractions * high
    return np.sqrt(np.square(checked - chord).sum(axis=3)).max(axis=(0, 1), initial=0.0)


def _check_stations(
    stations: NDArrayFloat,
) -> tuple[npt.NDArray[np.bool_], NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Which intervals between ``stations`` (m) are open (longer than 0), their ends (m),
    and the stations at ``CHECK_FRACTIONS`` of each (m, fraction by fraction)."""
    open_ = stations[1:] > stations[:-1]
    low, high = stations[:-1][open_], stations[1:][open_]
    return open_, low, high, np.concatenate([low + f * (high - low) for f in CHECK_FRACTIONS])


def _initial_stations(road: Road, section_index: int) -> NDArrayFloat:
    """Where ``adaptive_section_samples`` starts (m): the section's ends, the record
    starts inside it, a station ``END_VERTEX_M`` inside each end, at most
    ``INITIAL_STEP_M`` apart."""
    return _initial_together([(road, section_index)])[0]


def _initial_together(sections: Sequence[tuple[Road, int]]) -> tuple[NDArrayFloat, NDArrayInt]:
    """``_initial_stations`` (m) of each (road, section index), end to end (``sample_s``'s
    grid, then ``np.unique`` of each section's stations, bit for bit), and the index of
    the section of each."""
    parts = [road.lane_sections[index] for road, index in sections]
    first = np.array([part.s for part in parts], dtype=np.float64)
    last = np.array([part.s_end for part in parts], dtype=np.float64)
    with np.errstate(invalid="ignore"):
        intervals = np.ceil((last - first) / INITIAL_STEP_M)  # sample_s's
        bad = np.flatnonzero(~(np.isfinite(first) & np.isfinite(last) & (last >= first) & (intervals < MAX_SAMPLES)))
    if len(bad):  # its ValueError
        sample_s(float(first[bad[0]]), float(last[bad[0]]), INITIAL_STEP_M)
    count = intervals.astype(np.int64)
    rank = ragged_ranges(np.zeros_like(count), count)
    grid = np.repeat(first, count) + INITIAL_STEP_M * rank.astype(np.float64)
    inside = (rank > 0) & (grid < np.repeat(last - SLIVER_FRACTION * INITIAL_STEP_M, count))
    extra = [(number, s) for number, ((road, index), part) in enumerate(zip(sections, parts))
             for s in [*_breakpoints(road, index).tolist(),
                       *((part.s + END_VERTEX_M, part.s_end - END_VERTEX_M)
                         if part.s_end - part.s > 2.0 * END_VERTEX_M else ())]]
    numbers = np.arange(len(parts))
    s = np.concatenate((first, grid[inside], last, np.array([value for _, value in extra], dtype=np.float64)))
    owner = np.concatenate((numbers, np.repeat(numbers, count)[inside], numbers,
                            np.array([number for number, _ in extra], dtype=np.int64)))
    order = np.lexsort((s, owner))
    s, owner = s[order], owner[order]
    new = np.ones(len(s), dtype=bool)
    new[1:] = (s[1:] != s[:-1]) | (owner[1:] != owner[:-1])
    return s[new], owner[new]


def _splits(
    low: NDArrayFloat, high: NDArrayFloat, errors: NDArrayFloat, tolerance_m: float
) -> tuple[npt.NDArray[np.bool_], NDArrayInt, NDArrayFloat]:
    """Which intervals [low, high] (m) to split (chord error over ``tolerance_m``, not
    shorter than ``MIN_STEP_M``), how many stations each of them gets, and those
    stations (m), interval by interval."""
    refine = (errors > tolerance_m) & ((high - low) > MIN_STEP_M)
    # the chord error grows with the square of the interval: split into that many pieces at once
    pieces = np.clip(np.ceil(SPLIT_MARGIN * np.sqrt(errors[refine] / tolerance_m)), 2, MAX_PIECES).astype(np.int64)
    extra = pieces - 1
    offsets = (ragged_ranges(np.zeros_like(extra), extra) + 1) / np.repeat(pieces, extra)
    return refine, extra, np.repeat(low[refine], extra) + offsets * np.repeat((high - low)[refine], extra)


def _refined(
    s: NDArrayFloat, low: NDArrayFloat, high: NDArrayFloat, errors: NDArrayFloat, tolerance_m: float
) -> NDArrayFloat | None:
    """``s`` (m) with the intervals [low, high] whose chord error exceeds ``tolerance_m``
    split (:func:`_splits`), or None when none does (or they are shorter than ``MIN_STEP_M``)."""
    refine, _, added = _splits(low, high, errors, tolerance_m)
    return np.union1d(s, added) if refine.any() else None


def adaptive_section_samples(
    road: Road, section_index: int, lane_ids: Sequence[int], tolerance_m: float = CHORD_TOLERANCE_M
) -> list[LaneBorderSamples]:
    """Borders of the listed lanes of one section (record ends included, see
    ``sample_road``) at stations refined until, in every interval, the borders at
    ``CHECK_FRACTIONS`` lie within ``tolerance_m`` (m) of the chord (or the interval is
    shorter than ``MIN_STEP_M``). Refinement starts from the section's ends, the record
    starts (``_breakpoints``) and a station ``END_VERTEX_M`` inside each end, with no
    interval longer than ``INITIAL_STEP_M``."""
    s = _initial_stations(road, section_index)
    joints = record_joints(road, section_index)
    for _ in range(MAX_ROUNDS):
        if len(joints.boundaries):  # record ends add stations: evaluate them before the checks
            stations, points = section_points(road, section_index, s, lane_ids, joints)
            open_, low, high, checks = _check_stations(stations)
            checked = section_points(road, section_index, checks, lane_ids)[1]
        else:  # the stations are s: stations and checks in one evaluation
            stations = s
            open_, low, high, checks = _check_stations(stations)
            both = section_points(road, section_index, np.concatenate((stations, checks)), lane_ids)[1]
            points, checked = np.ascontiguousarray(both[:, :, :len(stations)]), both[:, :, len(stations):]
        borders = points.reshape(-1, len(stations), 3)
        errors = _chord_errors(borders, checked.reshape(len(borders), len(CHECK_FRACTIONS), len(low), 3), open_)
        refined = _refined(s, low, high, errors, tolerance_m)
        if refined is None:
            break
        s = refined
    return _samples(road, section_index, lane_ids, stations, points)


def _samples(road: Road, section_index: int, lane_ids: Sequence[int], stations: NDArrayFloat,
             points: NDArrayFloat) -> list[LaneBorderSamples]:
    """The samples of each listed lane from a section's stations and borders (lanes, 2, N, 3)."""
    return [LaneBorderSamples(road.id, section_index, lane_id, stations, points[index, 0], points[index, 1])
            for index, lane_id in enumerate(lane_ids)]


BATCH_SECTIONS: Final[int] = 32
"""Sections ``adaptive_samples`` refines together (bounds the arrays of one round)."""


def adaptive_samples(
    sections: Sequence[tuple[Road, int, Sequence[int]]], tolerance_m: float = CHORD_TOLERANCE_M
) -> list[list[LaneBorderSamples]]:
    """``adaptive_section_samples`` of each (road, section index, lanes), bit for bit; the
    sections ``sampling.batchable`` evaluates are refined ``BATCH_SECTIONS`` at a time,
    their stations and checks evaluated, compared with the chords and split together
    round by round. A ValueError is the one of the first section that fails."""
    try:
        result: dict[int, list[LaneBorderSamples]] = {}
        together = []
        for number, (road, index, lane_ids) in enumerate(sections):
            if batchable(road, index, lane_ids):
                together.append(number)
            else:
                result[number] = adaptive_section_samples(road, index, lane_ids, tolerance_m)
        for first in range(0, len(together), BATCH_SECTIONS):
            numbers = together[first:first + BATCH_SECTIONS]
            for number, (stations, points) in zip(numbers, _refine_together([sections[n] for n in numbers],
                                                                              tolerance_m)):
                result[number] = _samples(*sections[number], stations, points)
        return [result[number] for number in range(len(sections))]
    except ValueError:
        for road, index, lane_ids in sections:  # the error of the first section that fails, as one by one
            adaptive_section_samples(road, index, lane_ids, tolerance_m)
        raise


def _refine_together(
    sections: Sequence[tuple[Road, int, Sequence[int]]], tolerance_m: float
) -> list[tuple[NDArrayFloat, NDArrayFloat]]:
    """Stations (m) and borders (lanes, 2, stations, 3) of ``adaptive_section_samples`` of
    each ``batchable`` section: its rounds on the sections' concatenated stations."""
    done: list[tuple[NDArrayFloat, NDArrayFloat] | None] = [None] * len(sections)
    s, owner = _initial_together([(road, index) for road, index, _ in sections])  # owner: index into `active`
    active = np.arange(len(sections))
    lanes = np.array([len(lane_ids) for _, _, lane_ids in sections], dtype=np.int64)
    stack = section_stack(sections)
    for round_ in range(MAX_ROUNDS):
        count = np.bincount(owner, minlength=len(active))
        begin = np.cumsum(count) - count
        intervals = np.flatnonzero((s[1:] > s[:-1]) & (owner[1:] == owner[:-1]))  # the open ones, low ends
        low, high, of = s[intervals], s[intervals + 1], owner[intervals]
        opened = np.bincount(of, minlength=len(active))
        place = np.arange(len(intervals)) - (np.cumsum(opened) - opened)[of]  # interval's rank in its section
        size = count + len(CHECK_FRACTIONS) * opened  # stations, then the checks fraction by fraction
        request_begin = np.cumsum(size) - size
        request = np.empty(int(size.sum()))
        request[request_begin[owner] + np.arange(len(s)) - begin[owner]] = s
        for rank, fraction in enumerate(CHECK_FRACTIONS):
            request[request_begin[of] + count[of] + rank * opened[of] + place] = low + fraction * (high - low)
        values, starts = stack_points(stack, active, request, size)
        # each interval's largest distance of a checked point from its chord, border by border
        borders = 2 * lanes[active]
        station = intervals - begin[of]
        checks = count[of] + place
        errors = np.zeros(len(intervals))
        for border in range(int(borders.max())):
            here: slice | NDArrayInt = slice(None) if border < borders.min() else np.flatnonzero(borders[of] > border)
            row = np.asarray(starts)[of[here]] + border * size[of[here]]
            low_at = row + station[here]
            low_point, high_point, checked_at = values[low_at], values[low_at + 1], row + checks[here]
            for rank, fraction in enumerate(CHECK_FRACTIONS):
                chord = (1.0 - fraction) * low_point + fraction * high_point
                checked = values[checked_at + rank * opened[of[here]]]
                errors[here] = np.maximum(errors[here], np.sqrt(np.square(checked - chord).sum(axis=1)))
        refine, extra, added = _splits(low, high, errors, tolerance_m)
        finished = (np.bincount(of[refine], minlength=len(active)) == 0) | (round_ == MAX_ROUNDS - 1)
        for i in np.flatnonzero(finished).tolist():
            block = values[starts[i]:starts[i + 1]].reshape(lanes[active[i]], 2, size[i], 3)
            done[active[i]] = s[begin[i]:begin[i] + count[i]], np.ascontiguousarray(block[:, :, :count[i]])
        if finished.all():
            break
        renumber = np.cumsum(~finished) - 1
        keep = ~finished[owner]
        merged_owner = np.concatenate((renumber[owner[keep]], renumber[np.repeat(of[refine], extra)]))
        merged = np.concatenate((s[keep], added))
        order = np.lexsort((merged, merged_owner))
        merged, merged_owner = merged[order], merged_owner[order]
        new = np.ones(len(merged), dtype=bool)
        new[1:] = (merged[1:] != merged[:-1]) | (merged_owner[1:] != merged_owner[:-1])
        s, owner, active = merged[new], merged_owner[new], active[~finished]
    return done  # type: ignore[return-value]


def _is_zero_width(samples: LaneBorderSamples) -> bool:
    return bool(np.hypot(*(samples.outer[:, :2] - samples.inner[:, :2]).T).max() <= ZERO_WIDTH_M)


_EDGE_TAGS: Final[dict[int, dict[str, str]]] = {
    BoundaryType.NO_LINE: {"type": "virtual"},
    BoundaryType.CURB: {"type": "curbstone", "subtype": "high"},
    BoundaryType.ROAD_EDGE: {"type": "road_border"},
    BoundaryType.GRASS_EDGE: {"type": "road_border"},
}
"""Line tags of the boundary types that need no ``<roadMark>`` details."""

_PAINT: Final[dict[str, str]] = {"solid": "solid", "broken": "dashed", "botts dots": "dashed", "custom": "solid"}
"""One-line ``<roadMark>`` type → Lanelet2 line subtype (custom: a line of unknown pattern)."""

_DOUBLE: Final[dict[str, tuple[str, str]]] = {
    "solid solid": ("solid", "solid"), "broken broken": ("dashed", "dashed"),
    "solid broken": ("solid", "dashed"), "broken solid": ("dashed", "solid"),
}
"""Double ``<roadMark>`` type → its lines from the reference line outwards."""


MARK_STEP_M: Final[float] = 5.0
"""Spacing (m) of the stations where a border's marking is classified (besides the
``<roadMark>`` starts of the section): the kind covering most of the length wins."""


def mark_stations(road: Road, section_index: int) -> NDArrayFloat:
    """Stations (m) of a section where its borders' markings are classified: every
    ``MARK_STEP_M``, and each ``<roadMark>`` start."""
    section = road.lane_sections[section_index]
    starts = [section.s + mark.s_offset for lane in (section.center, *section.lanes) for mark in lane.road_marks]
    inside = [s for s in starts if section.s < s < section.s_end]
    return np.union1d(sample_s(section.s, section.s_end, MARK_STEP_M), np.asarray(inside, dtype=np.float64))


def _longest(marking: BorderMarking, s: NDArrayFloat) -> int:
    """The first station (index into ``s``, m) of the (type, owner, mark) covering most of the length."""
    # (type, owner, mark index) as one integer in the same lexicographic order
    owners = marking.owner - marking.owner.min()
    marks = marking.mark_index - NO_MARK
    keys = (marking.type * (int(owners.max()) + 1) + owners) * (int(marks.max()) + 1) + marks
    if not (keys != keys[0]).any():
        return 0
    unique, inverse = np.unique(keys, return_inverse=True)
    best = int(np.argmax(np.bincount(inverse, weights=np.gradient(s), minlength=len(unique))))
    return int(np.argmax(inverse == best))


SectionStations = Callable[[], tuple[NDArrayFloat, dict[int, tuple[NDArrayFloat, NDArrayFloat]]]]
"""A section's ``mark_stations`` and ``section_borders`` there, computed on the first call."""


def section_stations(road: Road, section_index: int) -> SectionStations:
    """The ``SectionStations`` of a section (computed once, when a border needs them)."""
    @cache
    def stations() -> tuple[NDArrayFloat, dict[int, tuple[NDArrayFloat, NDArrayFloat]]]:
        s = mark_stations(road, section_index)
        return s, section_borders(road, section_index, s)

    return stations


def line_tags(road: Road, section_index: int, lane_id: int, side: Literal["inner", "outer"], way_along_s: bool,
              stations: SectionStations | None = None) -> tuple[tuple[str, str], ...]:
    """Lanelet2 way tags of a lane border whose way runs along s when ``way_along_s``: the
    boundary kind covering most of its length (module docstring), classified at the
    section's ``mark_stations`` (``stations``: the section's ``section_stations``) unless
    ``uniform_marking`` gives it at once."""
    marking = uniform_marking(road, section_index, lane_id, side)
    at = 0
    if marking is None:
        s, borders = (stations or section_stations(road, section_index))()
        marking = classify_border(road, section_index, lane_id, side, s, borders)
        at = _longest(marking, s)
    kind, owner = int(marking.type[at]), int(marking.owner[at])
    if kind in _EDGE_TAGS:
        return tuple(_EDGE_TAGS[kind].items())
    mark = marking.mark(road, section_index, at)
    if mark is None:
        return (("type", "virtual"),)
    line = "line_thick" if mark.weight == "bold" else "line_thin"
    if mark.type in _DOUBLE:
        inside, outside = _DOUBLE[mark.type]
        # Along +s, a line right of the reference line (owner <= 0) has its inner line on the left.
        left, right = (inside, outside) if owner <= 0 else (outside, inside)
        if not way_along_s:
            left, right = right, left
        subtype = left if left == right else f"{left}_{right}"
        return (("type", line), ("subtype", subtype))
    return (("type", line), ("subtype", _PAINT.get(mark.type, "solid")))


_LANE_KINDS: Final[dict[str, str]] = {
    "sidewalk": "sidewalk", "walking": "sidewalk", "shoulder": "shoulder", "restricted": "restricted",
}
"""OpenDRIVE lane type → CommonRoad lanelet type (the writer's ``_SUBTYPES`` read them)."""

_ROAD_KINDS: Final[dict[str, str]] = {"motorway": "highway", "rural": "country"}
"""OpenDRIVE road type → CommonRoad lanelet type; "town..." is urban, the rest none."""


def lanelet_types(road: Road, lane_type: str, road_type: str) -> frozenset[str]:
    """CommonRoad lanelet types of a lane (the writer maps them to subtype and location)."""
    types = {_LANE_KINDS[lane_type]} if lane_type in _LANE_KINDS else set()
    if road_type.startswith("town") or road_type in ("lowSpeed", "pedestrian", "bicycle"):
        types.add("urban")
    elif road_type in _ROAD_KINDS and lane_type not in _LANE_KINDS:
        types.add(_ROAD_KINDS[road_type])
    if road.junction != "-1":
        types.add("intersection")
    return frozenset(types)


def engine_lanelets(
    odr_map: OpenDriveMap,
    graph: LaneGraph,
    road_types: Mapping[str, Sequence[tuple[float, str]]] | None = None,
    regulations: Mapping[LaneKey, LaneletRegulations] | None = None,
    priority: Mapping[LaneKey, Sequence[LaneKey]] | None = None,
) -> list[SourceLanelet]:
    """One ``SourceLanelet`` per lane and section of ``graph`` (ids 1, 2, ... in map
    order; zero-width lanes omitted), successors from the graph's edges. ``road_types``:
    road id → (s, type) records; ``regulations``: per lane, what the writer adds;
    ``priority``: per yielding lane, the lanes with the right of way."""
    road_types = road_types or {}
    regulations = regulations or {}
    priority = priority or {}
    sections = []
    kinds: dict[LaneKey, str] = {}
    for road in odr_map.roads.values():
        for index, section in enumerate(road.lane_sections):
            lanes = {lane.id: lane.type for lane in section.lanes if LaneKey(road.id, index, lane.id) in graph.lengths}
            if lanes and section.s_end > section.s:
                sections.append((road, index, list(lanes)))
                kinds.update((LaneKey(road.id, index, lane_id), kind) for lane_id, kind in lanes.items())
    sampled = [(road, samples, kinds[LaneKey(road.id, samples.section, samples.lane_id)])
               for (road, _, _), section_samples in zip(sections, adaptive_samples(sections))
               for samples in section_samples if not _is_zero_width(samples)]
    ids = {LaneKey(s.road_id, s.section, s.lane_id): number for number, (_, s, _) in enumerate(sampled, start=1)}
    lanelets = []
    section_key: tuple[str, int] | None = None
    for road, samples, lane_type in sampled:
        if section_key != (road.id, samples.section):  # a section's lanes come one after the other
            section_key = road.id, samples.section
            stations = section_stations(road, samples.section)
        key = LaneKey(samples.road_id, samples.section, samples.lane_id)
        along = road.drives_along_s(samples.lane_id, samples.section)
        left_side, right_side = ("inner", "outer") if (samples.lane_id > 0) != along else ("outer", "inner")
        left, right = getattr(samples, left_side), getattr(samples, right_side)
        if not along:
            left, right = left[::-1], right[::-1]
        road_type = _type_at(road_types.get(road.id, ()), road.lane_sections[samples.section].s)
        lanelets.append(SourceLanelet(
            id=ids[key],
            left=np.ascontiguousarray(left[:, :2]),
            right=np.ascontiguousarray(right[:, :2]),
            types=lanelet_types(road, lane_type, road_type),
            opendrive_lanes=((samples.road_id, samples.section, samples.lane_id),),
            junctions=() if road.junction == "-1" else (road.junction,),
            left_z=np.ascontiguousarray(left[:, 2]),
            right_z=np.ascontiguousarray(right[:, 2]),
            regulations=replace(regulations.get(key, LaneletRegulations()),
                                priority_lanelets=tuple(ids[n] for n in priority.get(key, ()) if n in ids)),
            successors=tuple(ids[n] for n in graph.successors[key] if n in ids),
            left_tags=line_tags(road, samples.section, samples.lane_id, left_side, along, stations),
            right_tags=line_tags(road, samples.section, samples.lane_id, right_side, along, stations),
        ))
    return lanelets


def _type_at(records: Sequence[tuple[float, str]], s: float) -> str:
    """The road type in force at s (m): the last record starting at or before it ("" if none)."""
    current = ""
    for start, kind in records:
        if start <= s + 1e-9:
            current = kind
    return current


def engine_converter(odr_map: OpenDriveMap | None = None) -> Converter:
    """The map engine as a ``converters.Converter`` (kind "engine"); ``odr_map``: the map
    already read (used when the converted path is its file, else the file is read)."""
    from cold_maps import __version__

    def lanelets(path: Path, verbose: bool) -> tuple[list[SourceLanelet], str]:
        from cold_maps.groundtruth.road_rules import read_road_rules
        from cold_maps.opendrive.errors import OpenDriveError
        from cold_maps.opendrive.parser import load_opendrive

        try:
            same = odr_map is not None and bool(odr_map.path) and os.path.samefile(odr_map.path, path)
        except OSError as exc:
            raise ConversionError(str(path), f"cannot read the map: {exc.strerror or exc}") from exc
        try:
            engine_map = odr_map if same and odr_map is not None else load_opendrive(path)
            graph = build_lane_graph(engine_map, LANE_TYPES, length_step=None)  # its edges, not its lengths
            rules = read_road_rules(engine_map, graph)
            result = engine_lanelets(engine_map, graph, rules.road_types, rules.regulations, rules.priority)
        except (OpenDriveError, ValueError) as exc:
            reason = str(exc).removeprefix(f"{path}:").strip()
            raise ConversionError(str(path), f"the map engine cannot build the ground truth: {reason}") from exc
        if not result:
            raise ConversionError(str(path), "the map has no lane to convert")
        return result, " ".join(engine_map.header.geo_reference.proj.split())

    return Converter(KIND, f"{__version__}.{BUILDER_VERSION}", lanelets, MERGE_TOLERANCE_M, float("inf"), None)


CONVERTERS: Final[tuple[str, ...]] = (KIND, "crdesigner")
"""Names of the ground-truth converters (``--converter``), the default first."""


def converter_named(name: str, odr_map: OpenDriveMap | None = None) -> Converter:
    """The converter called ``name`` (one of ``CONVERTERS``); ``odr_map``: see ``engine_converter``."""
    from converters import crdesigner_converter

    if name == KIND:
        return engine_converter(odr_map)
    if name == "crdesigner":
        return crdesigner_converter()
    raise ValueError(f"unknown ground-truth converter {name!r}: expected one of {', '.join(CONVERTERS)}")
