"""Whether a run's numbers can be trusted: where the map itself is broken, GT coverage of
the scored lanes, and (crdesigner's ground truth) the ``cold-maps check`` verdict on the
lanes the drives use.

With the engine's ground truth (exact wherever the map is well formed) an evaluation is
not scored where the map is broken under the lane it measures (``BrokenStretches``): a
lane link whose borders miss by more than ``BROKEN_GAP_M`` (``network.continuity.link_gaps``;
the GT joins the ends there, moving them by half the gap) or a lane that runs over its neighbour (a negative width,
``opendrive.lanes.wrong_side_lanes``). Such evaluations are rejected "gt_unmatched" with
the reason ``MAP_BROKEN``, the rest are scored. A run says so in its one-line result and
at the top of ``summary.md`` when more than ``UNMATCHED_SHARE_LIMIT`` of a map's
evaluations are not scored (a lane was produced but rejected "gt_unmatched": no GT
lanelets matched, or the map is broken there; or "no_ground_truth": no lanelet at the
ego's pose), or, with crdesigner's ground truth, when ``check`` flags a lane the
drives use (a border off by more than its threshold, or a lane-graph edge between two of
them that is no Lanelet2 routing successor).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Final

import numpy as np
import numpy.typing as npt

from cold_maps.evaluation.collector import Collector
from cold_maps.network.lane_strip import NDArrayFloat

if TYPE_CHECKING:
    from cold_maps.network.lane_graph import LaneGraph, LaneKey
    from cold_maps.simulation.drive import Drive

MAP_BROKEN: Final[str] = "map_broken"
"""``FrameRecord.gt_unmatched`` of an evaluation over a stretch where the map is broken."""

BROKEN_GAP_M: Final[float] = 0.03
"""A lane link whose borders miss by more than this (m) is broken: the ground truth joins
the ends midway, so there it is off the engine's borders by more than half of it."""

BROKEN_MARGIN_M: Final[float] = 0.5
"""A detected point this close (m) to a broken place, plus the place's own size (the gap,
or the lane's overlap), puts its evaluation over the broken stretch."""

WRONG_SIDE_STEP_M: Final[float] = 1.0
"""Spacing (m) of the border points of a lane that runs over its neighbour."""


@dataclass(frozen=True)
class BrokenStretches:
    """Where a map is broken, as points in the world frame.

    Fields:
        points: (N, 2) x, y (m) of the broken places' points.
        radii_m: (N,) how close (m) a detected point must come to each to be over it.
        place: (N,) index into ``reasons`` of each point.
        reasons: one human-readable line per broken place.
    """

    points: NDArrayFloat
    radii_m: NDArrayFloat
    place: npt.NDArray[np.int64]
    reasons: tuple[str, ...]

    def over(self, *lines: NDArrayFloat) -> bool:
        """True when a point of ``lines`` ((M, 2), world) lies over a broken stretch."""
        if not len(self.points):
            return False
        from scipy.spatial import cKDTree

        points = np.vstack([line[:, :2] for line in lines if len(line)])
        if not len(points):
            return False
        hits = cKDTree(points).query_ball_point(self.points, r=self.radii_m)
        return any(len(found) for found in hits)


def broken_stretches(graph: LaneGraph) -> BrokenStretches:
    """The link gaps and wrong-side lanes of ``graph``'s map (lanes of its types)."""
    from cold_maps.network.continuity import link_gap_points, link_gaps
    from cold_maps.opendrive.lanes import wrong_side_lanes
    from cold_maps.opendrive.sampling import sample_lane_borders

    points: list[NDArrayFloat] = []
    radii: list[NDArrayFloat] = []
    reasons: list[str] = []
    for gap in link_gaps(graph, BROKEN_GAP_M):
        at = link_gap_points(graph, gap)
        points.append(at)
        radii.append(np.full(len(at), gap.distance_m + BROKEN_MARGIN_M))
        reasons.append(f"lane link {':'.join(map(str, gap.exit_lane))} -> {':'.join(map(str, gap.entry_lane))} "
                       f"misses by {gap.distance_m:.3f} m")
    for road in graph.odr_map.roads.values():
        for lane in wrong_side_lanes(road):
            if (road.id, lane.section, lane.lane_id) not in graph.lengths:
                continue
            samples = sample_lane_borders(road, lane.section, lane.lane_id, WRONG_SIDE_STEP_M)
            at = np.vstack((samples.inner[:, :2], samples.outer[:, :2]))
            points.append(at)
            radii.append(np.full(len(at), -lane.width_m + BROKEN_MARGIN_M))
            reasons.append(f"lane {road.id}:{lane.section}:{lane.lane_id} runs over its neighbour "
                           f"(width down to {lane.width_m:.3f} m)")
    if not points:
        return BrokenStretches(np.empty((0, 2)), np.empty(0), np.empty(0, dtype=np.int64), ())
    place = np.concatenate([np.full(len(p), i, dtype=np.int64) for i, p in enumerate(points)])
    return BrokenStretches(np.vstack(points), np.concatenate(radii), place, tuple(reasons))


UNMATCHED_SHARE_LIMIT: Final[float] = 0.01
"""Largest share of a map's evaluations without a covering GT before a run warns."""

GT_UNMATCHED: Final[str] = "gt_unmatched"
"""``FrameRecord.rejected`` of a lane whose GT does not cover it."""

NO_GROUND_TRUTH: Final[str] = "no_ground_truth"
"""``FrameRecord.rejected`` of a lane with no GT lanelet at the ego's pose at all."""

UNSCORED: Final[frozenset[str]] = frozenset({GT_UNMATCHED, NO_GROUND_TRUTH})
"""``FrameRecord.rejected`` of an evaluation that produced a lane the GT could not score."""


def driven_lanes(drives: Iterable[Drive]) -> frozenset[LaneKey]:
    """Every lane on the track of the ego or of another vehicle of ``drives``."""
    lanes = set()
    for drive in drives:
        lanes.update(drive.ego.lanes)
        for vehicle in drive.vehicles:
            if vehicle.track is not None:
                lanes.update(vehicle.track.lanes)
    return frozenset(lanes)


def check_driven(map_name: str, graph: LaneGraph, lanelet_map: Any, routing_graph: Any,
                 lanes: frozenset[LaneKey]) -> str | None:
    """A warning naming the driven ``lanes`` that ``cold-maps check`` flags on this map,
    or None when it flags none."""
    from cold_maps.groundtruth.check import check_lanelet_map  # crdesigner's ground truth alone

    report = check_lanelet_map(graph.odr_map, lanelet_map, routing_graph=routing_graph, lane_types=graph.lane_types,
                               only={tuple(lane) for lane in lanes}, lane_graph=graph)
    flagged = sorted(report.flagged_lanes())
    if not flagged:
        return None
    why = []
    if report.failing:
        worst = max(lane.max_m for lane in report.failing)
        why.append(f"{len(report.failing)} with borders off by up to {worst:.3f} m")
    if report.disconnected:
        why.append(f"{len(report.disconnected)} links without a Lanelet2 successor "
                   f"(gaps up to {report.disconnected[0].gap_m:.3f} m)")
    named = ", ".join(f"{road}:{section}:{lane}" for road, section, lane in flagged[:5])
    more = f" and {len(flagged) - 5} more" if len(flagged) > 5 else ""
    return f"{map_name}: cold-maps check flags {len(flagged)} driven lanes ({named}{more}): {', '.join(why)}"


def unmatched_warnings(collector: Collector) -> list[str]:
    """Per map whose share of unscored evaluations (``UNSCORED``: a lane was produced but
    the GT could not score it) exceeds ``UNMATCHED_SHARE_LIMIT``: a warning with the
    count and the reasons."""
    totals: Counter[str] = Counter()
    unmatched: dict[str, Counter[str]] = {}
    for key, accumulator in collector.accumulators.items():
        totals[key.map] += len(accumulator.records)
        for batch in accumulator.records.batches(("rejected", "gt_unmatched")):
            for rejected, why in zip(*(column.to_pylist() for column in batch.columns)):
                if rejected in UNSCORED:
                    unmatched.setdefault(key.map, Counter())[why or rejected] += 1
    warnings = []
    for name, reasons in unmatched.items():
        count = sum(reasons.values())
        if count > UNMATCHED_SHARE_LIMIT * totals[name]:
            causes = []
            if set(reasons) - {MAP_BROKEN}:
                causes.append("no ground-truth lanelets matched the detected lane")
            if MAP_BROKEN in reasons:
                causes.append("the map is broken under the lane (see the notes)")
            why = ", ".join(f"{reason}: {n}" for reason, n in sorted(reasons.items()))
            warnings.append(f"{name}: {count} of {totals[name]} evaluations ({count / totals[name]:.1%}) not scored, "
                            f"{' or '.join(causes)} ({why})")
    return warnings


def run_warnings(collector: Collector) -> Sequence[str]:
    """Every warning of the run: ``check`` flags on driven lanes, then GT coverage."""
    return [*collector.gt_warnings, *unmatched_warnings(collector)]


def verdict(collector: Collector) -> str:
    """The trust verdict a command's result line ends with: "" when the ground truth is
    trustworthy on the run, else ``; GROUND TRUTH NOT TRUSTWORTHY: warning | ...``."""
    warnings = run_warnings(collector)
    return f"; GROUND TRUTH NOT TRUSTWORTHY: {' | '.join(warnings)}" if warnings else ""
