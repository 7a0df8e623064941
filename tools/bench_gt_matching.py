"""Benchmark of gt_matching: lanelet matching + GT assembly + closest-point metrics for one
frame (two 90 m borders sampled every 0.1 m) on a generated grid map of a few hundred
lanelets, against baselines without the per-map caches, in the same run.

Usage: .venv/bin/python tools/bench_gt_matching.py [--drives 40] [--frames-per-drive 10]
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
from gt_matching.polyline import NDArrayFloat, arc_lengths, resample  # noqa: E402
from gt_matching.synthetic import grid_network  # noqa: E402

DETECTION_M = 90.0
DETECTION_STEP_M = 0.1
NOISE_M = 0.05
ROUTE_M = 130.0
FRAME_ADVANCE_M = 1.0


def crop(polyline: NDArrayFloat, start_m: float, length_m: float) -> NDArrayFloat:
    """``length_m`` of ``polyline`` from arc length ``start_m``, resampled every DETECTION_STEP_M."""
    samples, _ = resample(polyline, DETECTION_STEP_M)
    s = np.arange(len(samples)) * DETECTION_STEP_M
    return samples[(s >= start_m) & (s <= start_m + length_m)]


def drives(lanelet_map: object, graph: object, count: int, frames: int, rng: np.random.Generator) -> list[tuple]:
    """Frames (left, right, pose) of ``count`` random drives along the routing graph,
    ``frames`` per drive, advancing FRAME_ADVANCE_M per frame; borders carry N(0, NOISE_M)
    noise per coordinate; the pose is the lane centre at the detection start."""
    lanelets = list(lanelet_map.laneletLayer)
    out = []
    while len(out) < count * frames:
        route = [lanelets[rng.integers(len(lanelets))]]
        while sum(arc_lengths(np.array([(p.x, p.y) for p in ll.leftBound]))[-1] for ll in route) < ROUTE_M:
            following = graph.following(route[-1])
            if not following:
                break
            route.append(following[rng.integers(len(following))])
        borders = [np.vstack([np.array([(p.x, p.y) for p in getattr(ll, side)]) for ll in route]) for side in ("leftBound", "rightBound")]
        if min(arc_lengths(b)[-1] for b in borders) < ROUTE_M:
            continue
        for frame in range(frames):
            left, right = (crop(b, frame * FRAME_ADVANCE_M, DETECTION_M) for b in borders)
            mid, ahead = 0.5 * (left[0] + right[0]), 0.5 * (left[5] + right[5])
            yaw = float(np.arctan2(ahead[1] - mid[1], ahead[0] - mid[0]))
            noisy = (b + rng.normal(0.0, NOISE_M, b.shape) for b in (left, right))
            out.append((*noisy, (float(mid[0]), float(mid[1]), yaw)))
    return out


def timed(function: Callable[[], object], repeats: int = 1) -> tuple[float, object]:
    start = time.perf_counter()
    for _ in range(repeats):
        result = function()
    return (time.perf_counter() - start) / repeats * 1e3, result


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


def stats(name: str, times: list[float]) -> str:
    values = np.array(times)
    return f"{name:<44} {values.mean():8.3f} {values.std():8.3f} {values.max():8.3f} {len(values):6d}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=6, help="junctions per side of the grid map")
    parser.add_argument("--drives", type=int, default=40)
    parser.add_argument("--frames-per-drive", type=int, default=10)
    parser.add_argument("--baseline-frames", type=int, default=30, help="frames for the slow baselines")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)

    map_ms, (lanelet_map, graph) = timed(lambda: grid_network(args.grid, args.grid))
    frames = drives(lanelet_map, graph, args.drives, args.frames_per_drive, rng)
    gt_ms, gt = timed(lambda: GroundTruth(lanelet_map, graph))
    print(
        f"map: {len(lanelet_map.laneletLayer)} lanelets, {len(gt.lines.vertices)} border line strings; "
        f"generated in {map_ms:.0f} ms, GroundTruth built in {gt_ms:.0f} ms; GT step {gt.config.step_m} m"
    )
    print(f"frames: {len(frames)} ({args.drives} drives), borders {len(frames[0][0])} + {len(frames[0][1])} points")

    results: dict[str, list[float]] = {"match": [], "evaluate": [], "evaluate exact": []}
    unmatched = mismatched = 0
    for left, right, pose in frames:
        results["match"].append(timed(lambda: gt.match(left, right, pose))[0])
        ms, metrics = timed(lambda: gt.evaluate(left, right, pose))
        results["evaluate"].append(ms)
        results["evaluate exact"].append(timed(lambda: gt.evaluate(left, right, pose, exact=True))[0])
        unmatched += metrics.left.unmatched_points + metrics.right.unmatched_points
        mismatched += not metrics.matched

    baseline: dict[str, list[float]] = {"baseline: match + KD-tree per frame": [], "baseline: match + brute force": []}
    disagreement = 0.0
    for left, right, pose in frames[: args.baseline_frames]:
        ours = gt.evaluate(left, right, pose)
        for name, distance in (
            ("baseline: match + KD-tree per frame", kd_tree_mean),
            ("baseline: match + brute force", brute_force_mean),
        ):
            def run() -> tuple[float, float]:
                found = gt.match(left, right, pose)
                return distance(left, found.left_gt_samples), distance(right, found.right_gt_samples)

            ms, (left_mean, right_mean) = timed(run)
            baseline[name].append(ms)
            disagreement = max(disagreement, abs(left_mean - ours.left.mean_error_m), abs(right_mean - ours.right.mean_error_m))

    print(f"{'per frame [ms]':<44} {'mean':>8} {'sigma':>8} {'max':>8} {'frames':>6}")
    for name, times in {**results, **baseline}.items():
        print(stats(name, times))
    print(
        f"distinct routes cached: {len(gt._routes)}; mismatched frames: {mismatched}; unmatched points: {unmatched}; "
        f"max |mean error ours - baseline|: {disagreement:.2e} m"
    )
    exact_mean = np.mean([gt.evaluate(*frame, exact=True).left.mean_error_m for frame in frames[:50]])
    print(
        f"mean exact left error over 50 frames: {exact_mean * 1e3:.2f} mm; lateral noise N(0, {NOISE_M * 1e3:.0f} mm) "
        f"gives sigma * sqrt(2 / pi) = {NOISE_M * np.sqrt(2.0 / np.pi) * 1e3:.2f} mm"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
