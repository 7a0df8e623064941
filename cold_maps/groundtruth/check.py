"""Cross-check of the Lanelet2 ground truth against our own OpenDRIVE border sampling.

Every lane of the checked types is sampled by ``cold_maps.opendrive.sampling`` and
matched to a converted lanelet: among the lanelets whose ``opendrive:lanes`` tag names
the lane (the converter records it; crdesigner itself drops the ids), else among all
lanelets near it (maps converted by other tools), the one whose borders lie closest.
The disagreement of a lane is the distance from each of our
border points to the matched lanelet's corresponding border polyline: the inner border
is the lanelet's left one in RHT, its right one in LHT. A lane over the threshold, or
with no lanelet near it, makes the ground truth untrustworthy. A lane narrower than
``ZERO_WIDTH_M`` over its whole section has no area to drive: converters drop it
(crdesigner does), so it is listed apart and not checked.
"""

from __future__ import annotations

import argparse
import os
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from cold_maps.opendrive.parser import load_opendrive
from cold_maps.opendrive.sampling import LaneBorderSamples, sample_road
from converters.osm import OPENDRIVE_TAG, parse_opendrive_lanes_tag
from gt_matching.polyline import NDArrayFloat, NDArrayInt, resample, windowed_distances

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

THRESHOLD_M: Final[float] = 0.05
"""A lane whose largest disagreement exceeds this (m) is listed; the map is then untrustworthy."""

STEP_M: Final[float] = 0.1
"""Our border sampling step along s (m)."""

SEARCH_RADIUS_M: Final[float] = 2.0
"""Lanelets with a border vertex this close (m) to one of a lane's border points are candidates."""

RESAMPLE_STEP_M: Final[float] = 0.25
"""Lanelet borders are resampled this finely (m) to find where along them to search the
closest segment (gt_matching's windowed search, reach = this step)."""

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
    """

    path: str
    threshold_m: float
    step_m: float
    lanes: tuple[LaneCheck, ...]
    lanelets: int
    zero_width: tuple[tuple[str, int, int], ...] = ()

    @property
    def failing(self) -> tuple[LaneCheck, ...]:
        """Lanes over the threshold or unmatched, worst first."""
        bad = [lane for lane in self.lanes if not lane.passes(self.threshold_m)]
        return tuple(sorted(bad, key=lambda lane: -lane.max_m))

    @property
    def trustworthy(self) -> bool:
        """True when at least one lane was checked and every lane passes."""
        return bool(self.lanes) and not self.failing

    @property
    def exit_code(self) -> int:
        """``EXIT_TRUSTWORTHY`` (0) or ``EXIT_UNTRUSTWORTHY`` (3)."""
        return EXIT_TRUSTWORTHY if self.trustworthy else EXIT_UNTRUSTWORTHY


@dataclass(frozen=True, eq=False)
class _Border:
    """One lanelet border in its driving order, with a KD-tree of its resampled points."""

    vertices: NDArrayFloat
    tree: cKDTree

    def distances(self, points: NDArrayFloat) -> NDArrayFloat:
        """Closest-point distance (m) of each point to this border."""
        arc = self.tree.query(points)[1] * RESAMPLE_STEP_M
        return windowed_distances(points, self.vertices, arc, RESAMPLE_STEP_M)[0]


class _LaneletIndex:
    """Borders of every lanelet and one KD-tree over all their vertices."""

    def __init__(self, lanelet_map: Any) -> None:
        from scipy.spatial import cKDTree

        self.ids: list[int] = []
        self.borders: list[tuple[_Border, _Border]] = []
        self.by_lane: dict[tuple[str, int, int], list[int]] = {}
        owners: list[NDArrayInt] = []
        vertices: list[NDArrayFloat] = []
        for slot, lanelet in enumerate(lanelet_map.laneletLayer):
            pair = []
            for line in (lanelet.leftBound, lanelet.rightBound):
                xy = np.array([(p.x, p.y) for p in line], dtype=np.float64)
                pair.append(_Border(xy, cKDTree(resample(xy, RESAMPLE_STEP_M)[0])))
                vertices.append(xy)
                owners.append(np.full(len(xy), slot, dtype=np.int64))
            self.ids.append(int(lanelet.id))
            self.borders.append((pair[0], pair[1]))
            for lane in parse_opendrive_lanes_tag(dict(lanelet.attributes).get(OPENDRIVE_TAG, "")):
                self.by_lane.setdefault(lane, []).append(slot)
        self.owner = np.concatenate(owners)
        self.tree: cKDTree = cKDTree(np.vstack(vertices))

    def candidates(self, samples: LaneBorderSamples, points: NDArrayFloat) -> tuple[str, set[int]]:
        """How the lane is matched ("id" or "geometry") and the candidate lanelet slots:
        those whose tag names the lane, else those with a border vertex within
        SEARCH_RADIUS_M of one of ``points``."""
        named = self.by_lane.get((_crdesigner_road_id(samples.road_id), samples.section, samples.lane_id))
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


def _check_lane(samples: LaneBorderSamples, rule: str, index: _LaneletIndex) -> LaneCheck:
    inner, outer = samples.inner[:, :2], samples.outer[:, :2]
    best: tuple[float, int, NDArrayFloat] | None = None
    matched_by, candidates = index.candidates(samples, np.vstack((inner, outer)))
    for slot in candidates:
        left, right = index.borders[slot]
        inner_border, outer_border = (left, right) if rule == "RHT" else (right, left)
        distances = np.concatenate((inner_border.distances(inner), outer_border.distances(outer)))
        score = float(np.median(distances))
        if best is None or score < best[0]:
            best = (score, slot, distances)
    points = 2 * len(samples.s)
    if best is None:
        return LaneCheck(samples.road_id, samples.section, samples.lane_id, None, "", np.inf, np.inf, points)
    _, slot, distances = best
    return LaneCheck(
        samples.road_id,
        samples.section,
        samples.lane_id,
        index.ids[slot],
        matched_by,
        float(np.median(distances)),
        float(np.max(distances)),
        points,
    )


def check_lanelet_map(
    odr_map: Any,
    lanelet_map: Any,
    *,
    path: str = "",
    threshold_m: float = THRESHOLD_M,
    step_m: float = STEP_M,
    lane_types: Sequence[str] | None = ("driving",),
) -> CheckReport:
    """Compare a parsed OpenDRIVE map with a Lanelet2 map in its inertial frame."""
    if not (np.isfinite(threshold_m) and threshold_m > 0.0):
        raise ValueError(f"check: threshold must be a positive length in m, got {threshold_m}")
    index = _LaneletIndex(lanelet_map)
    sampled = [
        (road.rule, samples)
        for road in odr_map.roads.values()
        for samples in sample_road(road, step_m, lane_types)
        if len(samples.s) > 1
    ]
    zero = [_is_zero_width(samples) for _, samples in sampled]
    lanes = tuple(_check_lane(samples, rule, index) for (rule, samples), empty in zip(sampled, zero) if not empty)
    skipped = tuple((s.road_id, s.section, s.lane_id) for (_, s), empty in zip(sampled, zero) if empty)
    return CheckReport(path, threshold_m, step_m, lanes, len(index.ids), skipped)


def _is_zero_width(samples: LaneBorderSamples) -> bool:
    """True when the lane's borders are within ``ZERO_WIDTH_M`` of each other everywhere."""
    return bool(np.hypot(*(samples.outer[:, :2] - samples.inner[:, :2]).T).max() <= ZERO_WIDTH_M)


def check_map(
    xodr_path: str | os.PathLike[str],
    *,
    threshold_m: float = THRESHOLD_M,
    step_m: float = STEP_M,
    lane_types: Sequence[str] | None = ("driving",),
    cache: bool = True,
    cache_dir: str | os.PathLike[str] | None = None,
    strict: bool = False,
) -> CheckReport:
    """Convert (or load from the cache) the map's ground truth and cross-check it.

    Raises ``OpenDriveError`` when our parser rejects the file (``strict``: see
    ``load_opendrive``) and ``converters.ConversionError`` when the converter does.
    """
    from converters import load_lanelet2

    odr_map = load_opendrive(xodr_path, strict=strict)
    lanelet_map, _ = load_lanelet2(xodr_path, cache=cache, cache_dir=cache_dir)
    return check_lanelet_map(
        odr_map, lanelet_map, path=os.fspath(xodr_path), threshold_m=threshold_m, step_m=step_m, lane_types=lane_types
    )


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
    failing = report.failing
    verdict = "TRUSTWORTHY" if report.trustworthy else "NOT TRUSTWORTHY"
    reason = f"{len(failing)} of {len(report.lanes)} lanes over {_mm(report.threshold_m)} mm or unmatched"
    lines.append(f"ground truth: {verdict} ({reason if report.lanes else 'no lane checked'})")
    if failing:
        lines.append(f"{'road':>8} {'section':>7} {'lane':>5} {'lanelet':>8} {'match':>8} {'median mm':>10} {'max mm':>10}")
        for lane in failing:
            lanelet = "none" if lane.lanelet_id is None else str(lane.lanelet_id)
            lines.append(
                f"{lane.road_id:>8} {lane.section:>7} {lane.lane_id:>5} {lanelet:>8} {lane.matched_by or '-':>8} "
                f"{_mm(lane.median_m):>10} {_mm(lane.max_m):>10}"
            )
    return "\n".join(lines)


def configure_check(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``cold-maps check``: MAP.xodr [--threshold M] [--step M] [--all-lanes] [--no-cache]."""
    parser.add_argument("map", metavar="MAP.xodr", help="OpenDRIVE map")
    parser.add_argument("--threshold", type=float, default=THRESHOLD_M, help="largest allowed disagreement (m)")
    parser.add_argument("--step", type=float, default=STEP_M, help="our border sampling step along s (m)")
    parser.add_argument("--all-lanes", action="store_true", help="check every lane type, not only driving")
    parser.add_argument("--no-cache", action="store_true", help="convert again; neither use nor fill the cache")
    parser.add_argument("--strict", action="store_true", help="refuse records that omit coefficients")


def run_check(args: argparse.Namespace) -> int:
    """Print the report, then the map's geometry gaps (``network.continuity``); return
    the report's exit code. Raises OpenDriveError or ConversionError."""
    from cold_maps.network.continuity import continuity_report
    from cold_maps.network.lane_graph import build_lane_graph

    report = check_map(
        args.map,
        threshold_m=args.threshold,
        step_m=args.step,
        lane_types=None if args.all_lanes else ("driving",),
        cache=not args.no_cache,
        strict=args.strict,
    )
    print(format_report(report))
    odr_map = load_opendrive(args.map, strict=args.strict)
    print("\n".join(continuity_report(odr_map, build_lane_graph(odr_map))))
    return report.exit_code
