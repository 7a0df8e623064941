"""Whether a run's numbers can be trusted: GT coverage of the scored lanes and the
``cold-maps check`` verdict on the lanes the drives use.

A run says so in its one-line result and at the top of ``summary.md`` when more than
``UNMATCHED_SHARE_LIMIT`` of a map's evaluations matched no GT lanelets (rejected
"gt_unmatched", see ``groundtruth.meter``), or when ``check`` flags a lane the drives use
(a border off by more than its threshold, or a lane-graph edge between two of them that
is no Lanelet2 routing successor).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING, Any, Final

from cold_maps.evaluation.collector import Collector
from cold_maps.groundtruth.check import check_lanelet_map

if TYPE_CHECKING:
    from cold_maps.network.lane_graph import LaneGraph, LaneKey
    from cold_maps.simulation.drive import Drive

UNMATCHED_SHARE_LIMIT: Final[float] = 0.01
"""Largest share of a map's evaluations without a covering GT before a run warns."""

GT_UNMATCHED: Final[str] = "gt_unmatched"
"""``FrameRecord.rejected`` of a lane whose GT does not cover it."""


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
    """Per map whose share of evaluations rejected "gt_unmatched" exceeds
    ``UNMATCHED_SHARE_LIMIT``: a warning with the count and the reasons."""
    totals: Counter[str] = Counter()
    unmatched: dict[str, Counter[str]] = {}
    for key, accumulator in collector.accumulators.items():
        totals[key.map] += len(accumulator.records)
        for record in accumulator.records:
            if record.rejected == GT_UNMATCHED:
                unmatched.setdefault(key.map, Counter())[record.gt_unmatched] += 1
    warnings = []
    for name, reasons in unmatched.items():
        count = sum(reasons.values())
        if count > UNMATCHED_SHARE_LIMIT * totals[name]:
            why = ", ".join(f"{reason}: {n}" for reason, n in sorted(reasons.items()))
            warnings.append(f"{name}: {count} of {totals[name]} evaluations ({count / totals[name]:.1%}) not scored, "
                            f"no ground-truth lanelets matched the detected lane ({why})")
    return warnings


def run_warnings(collector: Collector) -> Sequence[str]:
    """Every warning of the run: ``check`` flags on driven lanes, then GT coverage."""
    return [*collector.gt_warnings, *unmatched_warnings(collector)]


def verdict(collector: Collector) -> str:
    """The trust verdict a command's result line ends with: "" when the ground truth is
    trustworthy on the run, else ``; GROUND TRUTH NOT TRUSTWORTHY: warning | ...``."""
    warnings = run_warnings(collector)
    return f"; GROUND TRUTH NOT TRUSTWORTHY: {' | '.join(warnings)}" if warnings else ""
