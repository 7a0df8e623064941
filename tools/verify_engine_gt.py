"""Per-map verification of the engine's Lanelet2 ground truth (issue 28's "done when"):
its borders against the engine's (``cold-maps export``'s points, exact closest points),
every lane-graph edge a Lanelet2 routing successor, Lanelet2 routing and
``lanelet2.matching`` on it, and ``cold-eval``'s local (ego-only) max error on a short run.

    python tools/verify_engine_gt.py MAP.xodr ... [--families 4] [--frames 30] [--no-eval]

The border bound holds away from lane links that miss (``network.continuity.link_gaps``):
there the GT joins the ends (so the edge is a routing successor), moving the border within
``END_VERTEX_M`` of the end; such maps are broken there and ``cold-eval`` leaves the
evaluations over the joint unscored. Both figures are printed.

``--families N`` adds seeds 0..N-1 of every family of ``tools/map_families.py``
(written to a temporary folder). One line per map; exit 1 when a map fails a bound.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Sequence

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT_ROOT))
sys.path.insert(0, str(PROJECT_ROOT / "tools"))

from cold_maps.groundtruth.lanelet2_from_engine import END_VERTEX_M  # noqa: E402

AGREEMENT_M: Final[float] = 1e-3
"""The engine's Lanelet2 borders agree with the export within this (m)."""

LOCAL_ERROR_M: Final[float] = 0.02
"""Largest local (ego-only) error (m) of cold-eval on a map with scored frames."""

BROKEN_END_M: Final[float] = 2.0 * END_VERTEX_M
"""Border points this close (m) to a lane end whose link misses by over
``LINK_TOLERANCE_M`` are where the GT's snap (fading out ``END_VERTEX_M`` inside the end)
may move the border: listed apart."""

MATCHED_LANELETS: Final[int] = 50
"""Lanelets per map whose centre ``lanelet2.matching`` must match to themselves."""


@dataclass(frozen=True)
class Verification:
    """What one map gave.

    Fields:
        border_max_m: largest distance (m) of the engine's border points from the GT's.
        border_away_m: the same without the points within ``BROKEN_END_M`` of a lane end
            whose link misses (the GT snaps such ends together, by design).
        unmatched: lanes the check found no lanelet for.
        edges: lane-graph edges between checked lanes; disconnected: those without a
            Lanelet2 routing successor.
        routed: whether a Lanelet2 route along the first edge ends at its successor.
        matched: lanelets matched to themselves at their centre / tried.
        local_max_m: cold-eval's local max error (m), NaN without scored frames or eval.
        unscored: evaluations cold-eval left unscored / all (0, 0 without eval).
    """

    border_max_m: float
    border_away_m: float
    unmatched: int
    edges: int
    disconnected: int
    routed: bool
    matched: tuple[int, int]
    local_max_m: float
    unscored: tuple[int, int]

    @property
    def passes(self) -> bool:
        """Every bound held."""
        return (self.border_away_m <= AGREEMENT_M and not self.unmatched and not self.disconnected and self.routed
                and self.matched[0] == self.matched[1]
                and not (self.local_max_m > LOCAL_ERROR_M))


def _away_from_broken_links(odr_map, lanelet_map, lanes) -> float:
    """Largest distance (m) of the ``lanes``' (``LaneCheck``s) border points from their
    lanelet's borders, without the points within ``BROKEN_END_M`` of a broken link's end."""
    import numpy as np

    from cold_maps.groundtruth.lanelet2_from_engine import LANE_TYPES
    from cold_maps.network.continuity import LINK_TOLERANCE_M, link_gap_points, link_gaps
    from cold_maps.network.lane_graph import build_lane_graph
    from cold_maps.opendrive.sampling import sample_road
    from gt_matching.polyline import nearest_distances

    graph = build_lane_graph(odr_map, LANE_TYPES)
    broken = [link_gap_points(graph, gap) for gap in link_gaps(graph, LINK_TOLERANCE_M)]
    ends = np.vstack(broken) if broken else np.empty((0, 2))
    by_id = {ll.id: ll for ll in lanelet_map.laneletLayer}
    worst = 0.0
    for lane in lanes:
        road = odr_map.roads[lane.road_id]
        samples = next(s for s in sample_road(road, 0.1, None, record_ends=True)
                       if (s.section, s.lane_id) == (lane.section, lane.lane_id))
        lanelet = by_id[lane.lanelet_id]
        left, right = (np.array([(p.x, p.y) for p in line]) for line in (lanelet.leftBound, lanelet.rightBound))
        inner_border, outer_border = (left, right) if road.rule == "RHT" else (right, left)
        for points, border in ((samples.inner[:, :2], inner_border), (samples.outer[:, :2], outer_border)):
            if len(ends):
                near = np.min(np.hypot(points[:, None, 0] - ends[None, :, 0], points[:, None, 1] - ends[None, :, 1]), axis=1)
                points = points[near > BROKEN_END_M]
            if len(points):
                worst = max(worst, float(nearest_distances(points, border)[0].max()))
    return worst


def _routing_and_matching(odr_map, lanelet_map, routing) -> tuple[bool, tuple[int, int]]:
    import numpy as np
    from lanelet2.matching import Object2d, Pose2d, getDeterministicMatches

    from cold_maps.network.lane_graph import build_lane_graph

    named = {dict(ll.attributes).get("opendrive:lanes", ""): ll for ll in lanelet_map.laneletLayer}
    routed = True
    for a, b in build_lane_graph(odr_map).edges():
        start, goal = named.get(f"{a.road_id}:{a.section}:{a.lane_id}"), named.get(f"{b.road_id}:{b.section}:{b.lane_id}")
        if start is None or goal is None:
            continue
        route = routing.getRoute(start, goal)
        routed = route is not None and route.shortestPath()[-1].id == goal.id
        break
    tried = matched = 0
    lanelets = sorted(lanelet_map.laneletLayer, key=lambda ll: ll.id)
    for lanelet in lanelets[:: max(1, len(lanelets) // MATCHED_LANELETS)][:MATCHED_LANELETS]:
        centre = np.array([(p.x, p.y) for p in lanelet.centerline])
        if len(centre) < 2:
            continue
        middle = len(centre) // 2
        ahead = centre[min(middle + 1, len(centre) - 1)] - centre[max(middle - 1, 0)]
        obj = Object2d()
        obj.pose = Pose2d(float(centre[middle][0]), float(centre[middle][1]), math.atan2(ahead[1], ahead[0]))
        tried += 1
        matched += lanelet.id in {m.lanelet.id for m in getDeterministicMatches(lanelet_map, obj, 0.5)}
    return routed, (matched, tried)


def _local_error(path: Path, frames: int, folder: Path) -> tuple[float, tuple[int, int]]:
    from cold_maps.cli import evaluate

    out = folder / f"eval-{path.stem}"
    status = evaluate.main(["--map", str(path), "--routes", "2", "--frames", str(frames), "--gaps", "20",
                            "--interpolation", "paper", "--no-distractors", "--no-mcap", "--no-plots", "-q",
                            "--workers", "1", "--out", str(out)])
    if status != 0:
        return math.nan, (0, 0)
    scenarios = json.loads((out / "metrics.json").read_text())["scenarios"]
    local = [s for s in scenarios if s["fusion"] == "local" and s["fused_frames"] > 0]
    unscored = sum(sum(s.get("gt_unmatched", {}).values()) + s["rejected"].get("no_ground_truth", 0) for s in scenarios)
    total = sum(s["frames"] for s in scenarios)
    return (max((s["max_error_m"] for s in local), default=math.nan), (unscored, total))


def verify(path: Path, frames: int, folder: Path, evaluate: bool) -> Verification:
    """The verification of one map (module docstring)."""
    from cold_maps.groundtruth.check import check_lanelet_map
    from cold_maps.groundtruth.lanelet2_from_engine import engine_converter
    from cold_maps.opendrive.parser import load_opendrive
    from converters import load_lanelet2

    odr_map = load_opendrive(path)
    lanelet_map, routing = load_lanelet2(path, cache=False, converter=engine_converter(odr_map))
    report = check_lanelet_map(odr_map, lanelet_map, routing_graph=routing)
    matched = [lane for lane in report.lanes if lane.lanelet_id is not None]
    routed, matches = _routing_and_matching(odr_map, lanelet_map, routing)
    local, unscored = _local_error(path, frames, folder) if evaluate else (math.nan, (0, 0))
    over = [lane for lane in matched if lane.max_m > AGREEMENT_M]
    border_max = max((lane.max_m for lane in matched), default=0.0)
    away = max([lane.max_m for lane in matched if lane.max_m <= AGREEMENT_M]
               + [_away_from_broken_links(odr_map, lanelet_map, over)] if over else [border_max])
    return Verification(border_max, away, len(report.lanes) - len(matched),
                        report.edges, len(report.disconnected), routed, matches, local, unscored)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("maps", nargs="*", type=Path)
    parser.add_argument("--families", type=int, default=0, help="seeds 0..N-1 of every map family")
    parser.add_argument("--frames", type=int, default=30, help="frames per route of the cold-eval run")
    parser.add_argument("--no-eval", action="store_true", help="skip the cold-eval run")
    args = parser.parse_args(argv)
    failed = 0
    with tempfile.TemporaryDirectory(prefix="verify-engine-gt-") as name:
        folder = Path(name)
        maps = list(args.maps)
        if args.families:
            from map_families import FAMILIES, write_maps

            maps += write_maps(folder / "families", FAMILIES, range(args.families))
        print(f"{'map':<34} {'border max':>11} {'elsewhere':>10} {'unmatched':>9} {'edges':>6} {'no succ.':>8} {'route':>5} "
              f"{'matched':>8} {'local max':>10} {'unscored':>10}  verdict")
        for path in maps:
            try:
                result = verify(path, args.frames, folder, not args.no_eval)
            except Exception as exc:  # one line per map, whatever failed
                failed += 1
                print(f"{path.name:<34} ERROR {type(exc).__name__}: {str(exc).splitlines()[0][:120]}", flush=True)
                continue
            failed += not result.passes
            print(f"{path.name:<34} {result.border_max_m * 1e3:8.3f} mm {result.border_away_m * 1e3:7.3f} mm "
                  f"{result.unmatched:>9} {result.edges:>6} "
                  f"{result.disconnected:>8} {'ok' if result.routed else 'FAIL':>5} "
                  f"{result.matched[0]:>3}/{result.matched[1]:<4} {result.local_max_m * 1e3:7.2f} mm "
                  f"{result.unscored[0]:>4}/{result.unscored[1]:<5}  {'ok' if result.passes else 'FAIL'}", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
