"""Cross-check of the Lanelet2 ground truth against our own OpenDRIVE border sampling.

Every lane of the checked types is sampled by ``cold_maps.opendrive.sampling`` and
matched to a converted lanelet: among the lanelets whose ``opendrive:lanes`` tag names
the lane (the converter records it; crdesigner itself drops the ids), else among all
lanelets near it (maps converted by other tools), the one whose borders lie closest.
The disagreement of a lane is the exact distance from each of our
border points (every ``step`` m of s and both ends of every ``<geometry>`` record, as
``cold-maps export`` writes them) to the closest point of the matched lanelet's whole
corresponding border polyline (rings and short borders included): the inner border
is the lanelet's left one in RHT, its right one in LHT. A lane over the threshold, or
with no lanelet near it, makes the ground truth untrustworthy. A lane narrower than
``ZERO_WIDTH_M`` over its whole section has no area to drive: converters drop it
(crdesigner does), so it is listed apart and not checked.

Connectivity: every edge a → b of the engine's lane graph (lanes of the checked types)
must be a successor in the converted map's Lanelet2 routing graph (or a and b lie in one
lanelet); an edge that is not is listed with the gap between the lanelets' ends and
makes the ground truth untrustworthy (``gt_matching`` extends the GT only through
``routing_graph.following()``).
"""

from __future__ import annotations

import os
from collections import Counter
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from cold_maps.network.lane_graph import LaneGraph, LaneKey, build_lane_graph
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, OpenDriveMap
from cold_maps.opendrive.parser import load_opendrive
from cold_maps.opendrive.sampling import LaneBorderSamples, sample_road
from converters.osm import OPENDRIVE_TAG, parse_opendrive_lanes_tag
from gt_matching.polyline import NDArrayFloat, NDArrayInt, nearest_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

THRESHOLD_M: Final[float] = 0.05
"""A lane whose largest disagreement exceeds this (m) is listed; the map is then untrustworthy."""

STEP_M: Final[float] = 0.1
"""Our border sampling step along s (m)."""

SEARCH_RADIUS_M: Final[float] = 2.0
"""Lanelets with a border vertex this close (m) to one of a lane's border points are candidates."""

ZERO_WIDTH_M: Final[float] = 1e-3
"""A lane whose borders are never farther apart than this (m) in its section is zero-width."""

EXIT_TRUSTWORTHY: Final[int] = 0
EXIT_UNTRUSTWORTHY: Final[int] = 3
"""Exit status of ``cold-maps check``: 0 trustworthy, 3 not (1 stays for errors, 2 for usage)."""


@dataclass(frozen=True)
class LaneCheck:
    """Disagreement of one OpenDRIVE lane (one lane section) with its lanelet.

    Fields:
        road_id, section, lane_id: the OpenDRIVE lane (section index in the road).
        lanelet_id: id of the matched Lanelet2 lanelet, None when none is near.
        matched_by: "id" (the lanelet's opendrive:lanes tag names this lane),
            "geometry" (no lanelet names it: nearest borders) or "" (unmatched).
        median_m, max_m: median and largest distance (m) of our border points (both
            borders) to the lanelet's borders; inf when unmatched.
        points: number of our border points compared.
    """

    road_id: str
    section: int
    lane_id: int
    lanelet_id: int | None
    matched_by: str
    median_m: float
    max_m: float
    points: int

    def passes(self, threshold_m: float) -> bool:
        """True when matched and no point is farther than ``threshold_m`` (m)."""
        return self.lanelet_id is not None and self.max_m <= threshold_m


@dataclass(frozen=True)
class EdgeCheck:
    """An edge of the engine's lane graph that the converted map's routing graph lacks.

    Fields:
        source, target: the lanes (road id, section index, lane id); target follows source.
        source_lanelet, target_lanelet: the lanelets naming them (the pair with the
            smallest gap), None when no lanelet names the lane.
        gap_m: largest distance (m) between the source lanelet's left/right border end
            and the target lanelet's left/right border start; inf without lanelets.
    """

    source: tuple[str, int, int]
    target: tuple[str, int, int]
    source_lanelet: int | None
    target_lanelet: int | None
    gap_m: float


@dataclass(frozen=True)
class CheckReport:
    """Result of ``check_map``.

    Fields:
        path: the OpenDRIVE file.
        threshold_m: largest allowed disagreement per lane (m).
        step_m: our sampling step along s (m).
        lanes: one entry per checked lane and section, in map order.
        lanelets: number of lanelets in the converted map.
        zero_width: (road id, section index, lane id) of the lanes of the checked types
            that are zero-width over their whole section (not checked).
        edges: lane-graph edges checked for connectivity.
        disconnected: the edges that are not routing-graph successors, largest gap first.
    """

    path: str
    threshold_m: float
    step_m: float
    lanes: tuple[LaneCheck, ...]
    lanelets: int
    zero_width: tuple[tuple[str, int, int], ...] = ()
    edges: int = 0
    disconnected: tuple[EdgeCheck, ...] = ()

    @property
    def failing(self) -> tuple[LaneCheck, ...]:
        """Lanes over the threshold or unmatched, worst first."""
        bad = [lane for lane in self.lanes if not lane.passes(self.threshold_m)]
        return tuple(sorted(bad, key=lambda lane: -lane.max_m))

    @property
    def trustworthy(self) -> bool:
        """True when at least one lane was checked, every lane passes and every lane-graph
        edge is a routing-graph successor."""
        return bool(self.lanes) and not self.failing and not self.disconnected

    def flagged_lanes(self) -> frozenset[tuple[str, int, int]]:
        """(road id, section, lane id) of the failing lanes and of both ends of every
        disconnected edge."""
        lanes = {(lane.road_id, lane.section, lane.lane_id) for lane in self.failing}
        lanes |= {end for edge in self.disconnected for end in (edge.source, edge.target)}
        return frozenset(lanes)

    @property
    def exit_code(self) -> int:
        """``EXIT_TRUSTWORTHY`` (0) or ``EXIT_UNTRUSTWORTHY`` (3)."""
        return EXIT_TRUSTWORTHY if self.trustworthy else EXIT_UNTRUSTWORTHY


@dataclass(frozen=True, eq=False)
class _Border:
    """One lanelet border in its driving order."""

    vertices: NDArrayFloat

    def distances(self, points: NDArrayFloat) -> NDArrayFloat:
        """Exact closest-point distance (m) of each point to the whole border polyline."""
        return nearest_distances(points, self.vertices)[0]


class _LaneletIndex:
    """Borders of every lanelet and one KD-tree over all their vertices."""

    def __init__(self, lanelet_map: Any) -> None:
        from scipy.spatial import cKDTree

        self.ids: list[int] = []
        self.lanelets: list[Any] = []
        self.borders: list[tuple[_Border, _Border]] = []
        self.by_lane: dict[tuple[str, int, int], list[int]] = {}
        owners: list[NDArrayInt] = []
        vertices: list[NDArrayFloat] = []
        for slot, lanelet in enumerate(lanelet_map.laneletLayer):
            pair = []
            for line in (lanelet.leftBound, lanelet.rightBound):
                xy = np.array([(p.x, p.y) for p in line], dtype=np.float64)
                pair.append(_Border(xy))
                vertices.append(xy)
                owners.append(np.full(len(xy), slot, dtype=np.int64))
            self.ids.append(int(lanelet.id))
            self.lanelets.append(lanelet)
            self.borders.append((pair[0], pair[1]))
            for lane in parse_opendrive_lanes_tag(dict(lanelet.attributes).get(OPENDRIVE_TAG, "")):
                self.by_lane.setdefault(lane, []).append(slot)
        self.owner = np.concatenate(owners)
        self.tree: cKDTree = cKDTree(np.vstack(vertices))

    def named(self, lane: tuple[str, int, int]) -> list[int]:
        """Slots of the lanelets whose tag names the lane: by its road id, else by the id
        as crdesigner writes it (it parses road ids as integers)."""
        road_id, section, lane_id = lane
        return self.by_lane.get(lane) or self.by_lane.get((_crdesigner_road_id(road_id), section, lane_id), [])

    def candidates(self, samples: LaneBorderSamples, points: NDArrayFloat) -> tuple[str, set[int]]:
        """How the lane is matched ("id" or "geometry") and the candidate lanelet slots:
        those whose tag names the lane, else those with a border vertex within
        SEARCH_RADIUS_M of one of ``points``."""
        named = self.named((samples.road_id, samples.section, samples.lane_id))
        if named:
            return "id", set(named)
        near = self.tree.query_ball_point(points, r=SEARCH_RADIUS_M)
        return "geometry", {int(self.owner[i]) for hits in near for i in hits}


def _crdesigner_road_id(road_id: str) -> str:
    """The road id as crdesigner writes it (it parses road ids as integers)."""
    try:
        return str(int(road_id))
    except ValueError:
        return road_id


def _tagged(index: _LaneletIndex, slots: list[int], lane: tuple[str, int, int]) -> tuple[str, int, int]:
    """``lane`` as the lanelets' tag names it (its road id or crdesigner's integer form)."""
    return lane if not slots or lane in index.by_lane else (_crdesigner_road_id(lane[0]), lane[1], lane[2])


def _connected(index: _LaneletIndex, routing: Any, source: int, target: int, lane: tuple[str, int, int],
               after: tuple[str, int, int]) -> bool:
    """True when lanelet slot ``target`` follows ``source`` in the routing graph, or both
    are one lanelet naming ``lane`` and then ``after``."""
    if source == target and lane != after:
        named = parse_opendrive_lanes_tag(dict(index.lanelets[source].attributes).get(OPENDRIVE_TAG, ""))
        return lane in named and after in named and named.index(after) > named.index(lane)
    return any(int(f.id) == index.ids[target] for f in routing.following(index.lanelets[source]))


def _end_gap_m(index: _LaneletIndex, source: int, target: int) -> float:
    """Largest distance (m) between the border ends of lanelet slot ``source`` and the
    border starts of slot ``target``."""
    ends = [np.hypot(*(a.vertices[-1] - b.vertices[0])) for a, b in zip(index.borders[source], index.borders[target])]
    return float(max(ends))


def _disconnected_edges(
    edges: Sequence[tuple[LaneKey, LaneKey]], index: _LaneletIndex, routing: Any
) -> tuple[EdgeCheck, ...]:
    """The lane-graph ``edges`` that are no routing-graph successor, largest gap first."""
    missing = []
    for a, b in edges:
        sources, targets = index.named(tuple(a)), index.named(tuple(b))
        lane, after = _tagged(index, sources, tuple(a)), _tagged(index, targets, tuple(b))
        pairs = [(s, t) for s in sources for t in targets]
        if any(_connected(index, routing, s, t, lane, after) for s, t in pairs):
            continue
        gaps = [(_end_gap_m(index, s, t), s, t) for s, t in pairs if s != t or lane == after]
        gap, s, t = min(gaps, default=(np.inf, None, None))
        missing.append(EdgeCheck(tuple(a), tuple(b), None if s is None else index.ids[s],
                                 None if t is None else index.ids[t], gap))
    return tuple(sorted(missing, key=lambda edge: -edge.gap_m))


def _best_lanelet(lane: tuple[str, int, int], matched_by: str, candidates: Collection[int], index: _LaneletIndex,
                  first: NDArrayFloat, second: NDArrayFloat, first_is_left: bool) -> LaneCheck:
    """The candidate lanelet whose borders lie closest (median) to the points ``first``
    and ``second`` (compared with its left and right border, or right and left)."""
    best: tuple[float, int, NDArrayFloat] | None = None
    for slot in candidates:
        left, right = index.borders[slot]
        first_border, second_border = (left, right) if first_is_left else (right, left)
        distances = np.concatenate((first_border.distances(first), second_border.distances(second)))
        score = float(np.median(distances))
        if best is None or score < best[0]:
            best = (score, slot, distances)
    points = len(first) + len(second)
    if best is None:
        return LaneCheck(*lane, None, "", np.inf, np.inf, points)
    _, slot, distances = best
    return LaneCheck(*lane, index.ids[slot], matched_by, float(np.median(distances)), float(np.max(distances)), points)


def _check_lane(samples: LaneBorderSamples, rule: str, index: _LaneletIndex) -> LaneCheck:
    inner, outer = samples.inner[:, :2], samples.outer[:, :2]
    matched_by, candidates = index.candidates(samples, np.vstack((inner, outer)))
    lane = (samples.road_id, samples.section, samples.lane_id)
    return _best_lanelet(lane, matched_by, candidates, index, inner, outer, rule == "RHT")


def check_lanelet_map(
    odr_map: Any,
    lanelet_map: Any,
    *,
    path: str = "",
    threshold_m: float = THRESHOLD_M,
    step_m: float = STEP_M,
    lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES,
    routing_graph: Any = None,
    only: Collection[tuple[str, int, int]] | None = None,
    lane_graph: LaneGraph | None = None,
) -> CheckReport:
    """Compare a parsed OpenDRIVE map with a Lanelet2 map in its inertial frame (lanes and
    lane-graph edges; the routing graph defaults to ``converters.routing_graph``'s).
    ``only``: check just these lanes (road id, section, lane id) and the edges between them;
    ``lane_graph``: the engine's lane graph of ``odr_map`` over ``lane_types`` (built if None)."""
    if not (np.isfinite(threshold_m) and threshold_m > 0.0):
        raise ValueError(f"check: threshold must be a positive length in m, got {threshold_m}")
    if routing_graph is None:
        from converters import routing_graph as make_routing_graph

        routing_graph = make_routing_graph(lanelet_map)
    index = _LaneletIndex(lanelet_map)
    sampled = [
        (road.rule, samples)
        for road in odr_map.roads.values()
        for samples in sample_road(road, step_m, lane_types, record_ends=True)
        if len(samples.s) > 1 and (only is None or (samples.road_id, samples.section, samples.lane_id) in only)
    ]
    zero = [_is_zero_width(samples) for _, samples in sampled]
    lanes = tuple(_check_lane(samples, rule, index) for (rule, samples), empty in zip(sampled, zero) if not empty)
    skipped = tuple((s.road_id, s.section, s.lane_id) for (_, s), empty in zip(sampled, zero) if empty)
    edges = [
        (a, b)
        for a, b in (lane_graph or build_lane_graph(odr_map, lane_types)).edges()
        if not {tuple(a), tuple(b)} & set(skipped) and (only is None or {tuple(a), tuple(b)} <= set(only))
    ]
    disconnected = _disconnected_edges(edges, index, routing_graph)
    return CheckReport(path, threshold_m, step_m, lanes, len(index.ids), skipped, len(edges), disconnected)


def _is_zero_width(samples: LaneBorderSamples) -> bool:
    """True when the lane's borders are within ``ZERO_WIDTH_M`` of each other everywhere."""
    return bool(np.hypot(*(samples.outer[:, :2] - samples.inner[:, :2]).T).max() <= ZERO_WIDTH_M)


def check_map(
    xodr_path: str | os.PathLike[str],
    *,
    threshold_m: float = THRESHOLD_M,
    step_m: float = STEP_M,
    lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES,
    cache: bool = True,
    cache_dir: str | os.PathLike[str] | None = None,
    strict: bool = False,
    odr_map: OpenDriveMap | None = None,
    converter: str = "engine",
) -> CheckReport:
    """Convert (or load from the cache) the map's ground truth with ``converter`` ("engine"
    or "crdesigner") and check it against the engine's borders and lane graph.

    Raises ``OpenDriveError`` when our parser rejects the file (``strict``: see
    ``load_opendrive``) and ``converters.ConversionError`` when the converter does.
    ``odr_map``: the file already read by our parser (it is not read again).
    """
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from converters import load_lanelet2

    if odr_map is None:
        odr_map = load_opendrive(xodr_path, strict=strict)
    lanelet_map, routing = load_lanelet2(xodr_path, cache=cache, cache_dir=cache_dir,
                                         converter=converter_named(converter, odr_map))
    return check_lanelet_map(
        odr_map, lanelet_map, path=os.fspath(xodr_path), threshold_m=threshold_m, step_m=step_m, lane_types=lane_types,
        routing_graph=routing,
    )


@dataclass(frozen=True)
class CrossCheck:
    """The engine's ground truth and crdesigner's, each checked against the engine's
    borders and lane graph, and compared with each other.

    Fields:
        engine: the engine's Lanelet2 map checked (the evaluation's ground truth).
        crdesigner: crdesigner's Lanelet2 map checked; None when crdesigner failed.
        crdesigner_error: why it failed ("" when it did not).
        between: per lane of the engine's map (its lanelet's borders resampled every
            ``step_m``), the distance to the crdesigner lanelet naming the same lane
            (``LaneCheck.lanelet_id`` is crdesigner's), in map order.
    """

    engine: CheckReport
    crdesigner: CheckReport | None
    crdesigner_error: str = ""
    between: tuple[LaneCheck, ...] = ()

    @property
    def exit_code(self) -> int:
        """The engine report's: the ground truth the evaluation uses."""
        return self.engine.exit_code


def compare_lanelet_maps(reference: Any, other: Any, step_m: float = STEP_M) -> tuple[LaneCheck, ...]:
    """Per lanelet of ``reference`` tagged with exactly one OpenDRIVE lane, the distances
    of its borders (resampled every ``step_m`` m) to the closest lanelet of ``other``
    naming that lane (else to the nearest lanelets, matched "geometry")."""
    from gt_matching.polyline import resample

    index = _LaneletIndex(other)
    result = []
    for lanelet in reference.laneletLayer:
        named = parse_opendrive_lanes_tag(dict(lanelet.attributes).get(OPENDRIVE_TAG, ""))
        if len(named) != 1:
            continue
        left, right = (resample(np.array([(p.x, p.y) for p in line], dtype=np.float64), step_m)[0]
                       for line in (lanelet.leftBound, lanelet.rightBound))
        slots = index.named(named[0])
        matched_by = "id" if slots else "geometry"
        if not slots:
            near = index.tree.query_ball_point(np.vstack((left, right)), r=SEARCH_RADIUS_M)
            slots = sorted({int(index.owner[i]) for hits in near for i in hits})
        result.append(_best_lanelet(named[0], matched_by, slots, index, left, right, True))
    return tuple(result)


def cross_check(
    xodr_path: str | os.PathLike[str],
    *,
    threshold_m: float = THRESHOLD_M,
    step_m: float = STEP_M,
    lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES,
    cache: bool = True,
    cache_dir: str | os.PathLike[str] | None = None,
    odr_map: OpenDriveMap | None = None,
) -> CrossCheck:
    """``check_map`` with the engine and with crdesigner, and the two Lanelet2 maps
    compared lane by lane; a crdesigner failure is reported, not raised."""
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from converters import ConversionError, load_lanelet2

    if odr_map is None:
        odr_map = load_opendrive(xodr_path)
    graph = build_lane_graph(odr_map, lane_types)
    maps = {}
    reports = {}
    error = ""
    for name in ("engine", "crdesigner"):
        try:
            lanelet_map, routing = load_lanelet2(xodr_path, cache=cache, cache_dir=cache_dir,
                                                 converter=converter_named(name, odr_map))
        except ConversionError as exc:
            if name == "engine":
                raise
            error = str(exc)
            continue
        maps[name] = lanelet_map
        reports[name] = check_lanelet_map(odr_map, lanelet_map, path=os.fspath(xodr_path), threshold_m=threshold_m,
                                          step_m=step_m, lane_types=lane_types, routing_graph=routing, lane_graph=graph)
    between = compare_lanelet_maps(maps["engine"], maps["crdesigner"], step_m) if "crdesigner" in maps else ()
    checked = {(lane.road_id, lane.section, lane.lane_id) for lane in reports["engine"].lanes}
    between = tuple(lane for lane in between if (lane.road_id, lane.section, lane.lane_id) in checked)
    return CrossCheck(reports["engine"], reports.get("crdesigner"), error, between)


def format_cross_check(result: CrossCheck) -> str:
    """The engine's report, crdesigner's, and their lane-by-lane comparison."""
    lines = ["engine ground truth (the evaluation's):", format_report(result.engine), "",
             "crdesigner ground truth (the independent cross-check):"]
    if result.crdesigner is None:
        lines.append(f"crdesigner failed: {result.crdesigner_error}")
        return "\n".join(lines)
    lines += [format_report(result.crdesigner), ""]
    threshold = result.engine.threshold_m
    matched = [lane for lane in result.between if lane.lanelet_id is not None]
    over = sorted((lane for lane in result.between if not lane.passes(threshold)), key=lambda lane: -lane.max_m)
    lines.append(f"engine vs crdesigner Lanelet2: {len(matched)} of {len(result.between)} lanes matched")
    if matched:
        maxima = np.array([lane.max_m for lane in matched])
        worst = matched[int(np.argmax(maxima))]
        lines.append(f"per-lane largest distance: median {_mm(float(np.median(maxima)))} mm, max {_mm(worst.max_m)} mm "
                     f"(road {worst.road_id} section {worst.section} lane {worst.lane_id})")
    verdict = "AGREE" if not over else "DISAGREE"
    lines.append(f"engine and crdesigner: {verdict} ({len(over)} of {len(result.between)} lanes over "
                 f"{_mm(threshold)} mm or unmatched)")
    for lane in over[:20]:
        lanelet = "none" if lane.lanelet_id is None else str(lane.lanelet_id)
        lines.append(f"{lane.road_id:>8} {lane.section:>7} {lane.lane_id:>5} {lanelet:>8} {_mm(lane.max_m):>10}")
    if len(over) > 20:
        lines.append(f"... and {len(over) - 20} more")
    return "\n".join(lines)


def _mm(value: float) -> str:
    return "-" if not np.isfinite(value) else f"{1e3 * value:.2f}"


def format_report(report: CheckReport) -> str:
    """Summary, verdict and one line per failing lane (road, section, lane, lanelet, mm)."""
    medians = np.array([lane.median_m for lane in report.lanes if lane.lanelet_id is not None])
    maxima = np.array([lane.max_m for lane in report.lanes if lane.lanelet_id is not None])
    lines = [
        f"{report.path}: {len(report.lanes)} lanes checked against {report.lanelets} lanelets "
        f"(our borders every {report.step_m} m, threshold {_mm(report.threshold_m)} mm)",
    ]
    if len(medians):
        lines.append(
            f"per-lane median disagreement: median {_mm(float(np.median(medians)))} mm, "
            f"max {_mm(float(medians.max()))} mm; largest single point {_mm(float(maxima.max()))} mm"
        )
    by = Counter(lane.matched_by for lane in report.lanes)
    lines.append(f"lanes matched by OpenDRIVE id: {by['id']}, by geometry: {by['geometry']}, unmatched: {by['']}")
    if report.zero_width:
        named = ", ".join(f"road {road} section {section} lane {lane}" for road, section, lane in report.zero_width[:5])
        more = f" and {len(report.zero_width) - 5} more" if len(report.zero_width) > 5 else ""
        lines.append(f"zero-width lanes not checked: {len(report.zero_width)} ({named}{more})")
    lines.append(
        f"lane-graph edges that are Lanelet2 routing successors: {report.edges - len(report.disconnected)} "
        f"of {report.edges}"
    )
    failing = report.failing
    verdict = "TRUSTWORTHY" if report.trustworthy else "NOT TRUSTWORTHY"
    reason = f"{len(failing)} of {len(report.lanes)} lanes over {_mm(report.threshold_m)} mm or unmatched"
    if report.disconnected:
        reason += f", {len(report.disconnected)} of {report.edges} lane-graph edges not routing successors"
    lines.append(f"ground truth: {verdict} ({reason if report.lanes else 'no lane checked'})")
    if failing:
        lines.append(f"{'road':>8} {'section':>7} {'lane':>5} {'lanelet':>8} {'match':>8} {'median mm':>10} {'max mm':>10}")
        for lane in failing:
            lanelet = "none" if lane.lanelet_id is None else str(lane.lanelet_id)
            lines.append(
                f"{lane.road_id:>8} {lane.section:>7} {lane.lane_id:>5} {lanelet:>8} {lane.matched_by or '-':>8} "
                f"{_mm(lane.median_m):>10} {_mm(lane.max_m):>10}"
            )
    if report.disconnected:
        lines.append(f"{'from lane':>16} {'to lane':>16} {'lanelets':>17} {'gap mm':>10}")
        for edge in report.disconnected:
            lanelets = "->".join("none" if i is None else str(i) for i in (edge.source_lanelet, edge.target_lanelet))
            lines.append(f"{':'.join(map(str, edge.source)):>16} {':'.join(map(str, edge.target)):>16} "
                         f"{lanelets:>17} {_mm(edge.gap_m):>10}")
    return "\n".join(lines)
