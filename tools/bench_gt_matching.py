"""Benchmark of gt_matching: lanelet matching + GT assembly + closest-point metrics for one
frame (two 90 m borders sampled every 0.1 m) on a generated grid map of a few hundred
lanelets, against baselines without the per-map caches, in the same run.

Usage: .venv/bin/python tools/bench_gt_matching.py [--drives 40] [--frames-per-drive 10]
       [--map ../shared/maps/carla/Town04.xodr]
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gt_matching import GroundTruth  # noqa: E402
from gt_matching.polyline import NDArrayFloat, arc_lengths  # noqa: E402
from gt_matching.geometry import LaneletGeometry  # noqa: E402
from gt_matching.synthetic import grid_network, sequence_borders  # noqa: E402

DETECTION_M = 90.0
DETECTION_STEP_M = 0.1
NOISE_M = 0.05
ROUTE_M = 130.0
FRAME_ADVANCE_M = 1.0


def drives(lanelet_map: object, graph: object, count: int, frames: int, rng: np.random.Generator) -> list[tuple]:
    """Frames (left, right, pose) of ``count`` random drives along the routing graph from
    lanelets vehicles may use, ``frames`` per drive, advancing FRAME_ADVANCE_M per frame;
    borders DETECTION_M long with N(0, NOISE_M) noise per coordinate; the pose is the lane
    centre at the detection start, heading along it."""
    import lanelet2

    rules = lanelet2.traffic_rules.create(
        lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
    )
    lanelets = [ll for ll in lanelet_map.laneletLayer if rules.canPass(ll)]
    out = []
    while len(out) < count * frames:
        route = [lanelets[rng.integers(len(lanelets))]]
        length = LaneletGeometry.of(route[0]).length_m
        while length < ROUTE_M and graph.following(route[-1]):
            following = graph.following(route[-1])
            route.append(following[rng.integers(len(following))])
            length += LaneletGeometry.of(route[-1]).length_m
        left, right = sequence_borders(route, DETECTION_STEP_M)
        s = arc_lengths(0.5 * (left + right))
        if s[-1] < ROUTE_M:
            continue
        for frame in range(frames):
            keep = (s >= frame * FRAME_ADVANCE_M) & (s <= frame * FRAME_ADVANCE_M + DETECTION_M)
            mid = 0.5 * (left[keep] + right[keep])
            yaw = float(np.arctan2(mid[5, 1] - mid[0, 1], mid[5, 0] - mid[0, 0]))
            noisy = (b[keep] + rng.normal(0.0, NOISE_M, b[keep].shape) for b in (left, right))
            out.append((*noisy, (float(mid[0, 0]), float(mid[0, 1]), yaw)))
    return out


def timed(function: Callable[[], object]) -> tuple[float, float, object]:
    """Wall and CPU time of one call, ms, and its result."""
    wall, cpu = time.perf_counter(), time.process_time()
    result = function()
    return (time.perf_counter() - wall) * 1e3, (time.process_time() - cpu) * 1e3, result


def brute_force_mean(points: NDArrayFloat, gt_samples: NDArrayFloat) -> float:
    """Mean closest-point distance to the resampled GT, all pairs, no tree."""
    best = np.empty(len(points))
    for i in range(0, len(points), 64):
        chunk = points[i : i + 64]
        best[i : i + 64] = np.sqrt(np.min(np.sum((chunk[:, None, :] - gt_samples[None]) ** 2, axis=2), axis=1))
    return float(best.mean())


def kd_tree_mean(points: NDArrayFloat, gt_samples: NDArrayFloat) -> float:
    """Mean closest-point distance to the resampled GT with a KD-tree built this frame."""
    from scipy.spatial import cKDTree

    return float(cKDTree(gt_samples).query(points)[0].mean())


def stats(name: str, wall: list[float], cpu: list[float]) -> str:
    w, c = np.array(wall), np.array(cpu)
    return f"{name:<40} {w.mean():7.3f} {w.std():7.3f} {w.max():8.3f} | {c.mean():7.3f} {c.std():7.3f} {c.max():8.3f} {len(w):6d}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=6, help="junctions per side of the generated grid map")
    parser.add_argument("--map", help="an .xodr map to use instead (converted to Lanelet2 by converters, cached)")
    parser.add_argument("--drives", type=int, default=40)
    parser.add_argument("--frames-per-drive", type=int, default=10)
    parser.add_argument("--baseline-frames", type=int, default=30, help="frames for the slow baselines")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)

    if args.map:
        from converters import load_lanelet2

        map_ms, _, (lanelet_map, graph) = timed(lambda: load_lanelet2(args.map))
    else:
        map_ms, _, (lanelet_map, graph) = timed(lambda: grid_network(args.grid, args.grid))
    frames = drives(lanelet_map, graph, args.drives + 1, args.frames_per_drive, rng)
    warm_up, frames = frames[0], frames[args.frames_per_drive :]
    gt_ms, _, gt = timed(lambda: GroundTruth(lanelet_map, graph))
    gt.evaluate(*warm_up)
    print(
        f"map: {args.map or 'grid'}, {len(lanelet_map.laneletLayer)} lanelets, {len(gt.lines.vertices)} border line "
        f"strings; loaded in {map_ms:.0f} ms, GroundTruth built in {gt_ms:.0f} ms; GT step {gt.config.step_m} m"
    )
    print(
        f"frames: {len(frames)} ({args.drives} drives, {FRAME_ADVANCE_M} m apart), borders "
        f"{len(frames[0][0])} + {len(frames[0][1])} points, noise N(0, {NOISE_M} m)"
    )

    rows: dict[str, tuple[list[float], list[float]]] = {}

    def record(name: str, wall: float, cpu: float) -> None:
        rows.setdefault(name, ([], []))
        rows[name][0].append(wall)
        rows[name][1].append(cpu)

    unmatched = mismatched = 0
    for left, right, pose in frames:
        routes = len(gt._routes)
        wall, cpu, metrics = timed(lambda: gt.evaluate(left, right, pose))
        cold = len(gt._routes) != routes
        record("evaluate (all frames)", wall, cpu)
        record("evaluate, new lanelet sequence" if cold else "evaluate, cached lanelet sequence", wall, cpu)
        record("evaluate exact", *timed(lambda: gt.evaluate(left, right, pose, exact=True))[:2])
        record("match only", *timed(lambda: gt.match(left, right, pose))[:2])
        unmatched += metrics.left.unmatched_points + metrics.right.unmatched_points
        mismatched += not metrics.matched

    disagreement = 0.0
    for left, right, pose in frames[: args.baseline_frames]:
        ours = gt.evaluate(left, right, pose)
        for name, distance in (
            ("baseline: match + KD-tree per frame", kd_tree_mean),
            ("baseline: match + brute force", brute_force_mean),
        ):

            def run(distance: Callable[[NDArrayFloat, NDArrayFloat], float] = distance) -> tuple[float, float]:
                found = gt.match(left, right, pose)
                return distance(left, found.left_gt_samples), distance(right, found.right_gt_samples)

            wall, cpu, (left_mean, right_mean) = timed(run)
            record(name, wall, cpu)
            disagreement = max(disagreement, abs(left_mean - ours.left.mean_error_m), abs(right_mean - ours.right.mean_error_m))
    for left, right, pose in frames[: max(1, args.baseline_frames // 3)]:
        record(
            "baseline: no per-map cache",
            *timed(lambda: GroundTruth(lanelet_map, graph).evaluate(left, right, pose))[:2],
        )

    print(f"{'per frame [ms]':<40} {'wall':>7} {'sigma':>7} {'max':>8} | {'CPU':>7} {'sigma':>7} {'max':>8} {'frames':>6}")
    for name, (wall_ms, cpu_ms) in rows.items():
        print(stats(name, wall_ms, cpu_ms))
    print(
        f"mismatched frames: {mismatched}; unmatched points: {unmatched} of {2 * len(frames) * len(frames[0][0])}; "
        f"max |mean error ours - baseline|: {disagreement:.1e} m"
    )
    exact_mean = np.mean([gt.evaluate(*frame, exact=True).left.mean_error_m for frame in frames[:50]])
    print(
        f"mean exact left error over 50 frames: {exact_mean * 1e3:.2f} mm; N(0, {NOISE_M * 1e3:.0f} mm) per coordinate "
        f"gives sigma * sqrt(2 / pi) = {NOISE_M * np.sqrt(2.0 / np.pi) * 1e3:.2f} mm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
