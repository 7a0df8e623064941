"""Convoy weights and stated σ on analytic roads: ``paper`` / ``mean`` / ``inverse-variance``.

Each pair: an ego and a coop ``--lead`` m ahead on a random road (straight, an arc of radius
100–500 m, or an S-bend of two such arcs), both detecting ``--range`` m of their lane with
the camera's cubic lane-model error (``cold_maps.simulation.lane_model_error``: per
detection and border δc0…δc3 and white noise, the camera profile's σ by default) and
stating its closed-form σ(x); the coop's reported pose carries a Gaussian error of
``σ_xy``/``σ_yaw`` and states that covariance (the ego is the reference, exact). The same
pairs are fused with each weighting; per pose-error level the table gives the max / p95 /
mean error of all fused points against the true borders, the inverse-variance coop weight
at the overlap's middle (closed form), and the calibration of the stated σ (share of points within
1σ and 2σ); the same errors and calibration over the overlap's fused points alone. With ``--gap`` the coop drives that far past the ego's range instead (spline
fusion, calibration of the bridge σ; weights do not apply).

    .venv/bin/python tools/study_convoy_weights.py [--pairs 200] [--seed 1] [--lead 25] [--range 50]
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fusion  # noqa: E402
from cold_maps.simulation.lane_model_error import LaneModelErrorParams  # noqa: E402
from fusion.analytic import AnalyticRoad, Segment, detect  # noqa: E402
from fusion.geometry import distance_to_polyline  # noqa: E402

CAMERA = LaneModelErrorParams(sigma_c0_m=0.05, sigma_c1_rad=0.002, sigma_c2_per_m=4e-5, sigma_c3_per_m2=0.0,
                              white_m=0.01)
POSE_LEVELS = ((0.0, 0.0), (0.05, 0.002), (0.1, 0.005))  # (σ_xy m, σ_yaw rad) of the coop's reported pose
WEIGHTS = ("paper", "mean", "inverse-variance")
HALF_WIDTH_M = 1.75


def random_road(rng: np.random.Generator) -> AnalyticRoad:
    kind = rng.integers(3)
    k = rng.choice((-1.0, 1.0)) / rng.uniform(100.0, 500.0)
    body = [Segment(300.0)] if kind == 0 else [Segment(300.0, k)] if kind == 1 else [Segment(150.0, k),
                                                                                       Segment(150.0, -k)]
    return AnalyticRoad([Segment(20.0), *body], yaw0=rng.uniform(-math.pi, math.pi))


def sensed(road: AnalyticRoad, s_from: float, range_m: float, model: LaneModelErrorParams,
           rng: np.random.Generator) -> fusion.LaneDetection:
    """A detection with the lane-model error drawn per border, stating its σ(x)."""
    det = detect(road, s_from, range_m, HALF_WIDTH_M, -HALF_WIDTH_M)
    borders, sigmas = [], []
    for border in (det.left, det.right):
        x = border[:, 0]
        c = rng.normal(0.0, (model.sigma_c0_m, model.sigma_c1_rad, model.sigma_c2_per_m, model.sigma_c3_per_m2))
        error = c[0] + c[1] * x + c[2] * x**2 / 2 + c[3] * x**3 / 6 + rng.normal(0.0, model.white_m, x.shape)
        borders.append(border + np.column_stack((np.zeros_like(x), error)))
        sigmas.append(model.sigma_m(x))
    return fusion.LaneDetection(det.pose, borders[0], borders[1], left_sigma=sigmas[0], right_sigma=sigmas[1])


def with_pose_error(det: fusion.LaneDetection, sigma_xy: float, sigma_yaw: float,
                    rng: np.random.Generator) -> fusion.LaneDetection:
    dx, dy = rng.normal(0.0, sigma_xy, 2) if sigma_xy else (0.0, 0.0)
    dyaw = rng.normal(0.0, sigma_yaw) if sigma_yaw else 0.0
    pose = fusion.Pose2D(det.pose.x + dx, det.pose.y + dy, det.pose.yaw + dyaw)
    return replace(det, pose=pose, pose_cov=np.diag([sigma_xy**2, sigma_xy**2, sigma_yaw**2]))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=200, help="pairs per pose-error level (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="seed (default 1)")
    parser.add_argument("--lead", type=float, default=25.0, help="coop ahead of the ego, m (default 25)")
    parser.add_argument("--range", type=float, default=50.0, help="sensor range, m (default 50, the camera's)")
    parser.add_argument("--gap", type=float, default=None, help="spline study: gap d_s past the ego's range, m")
    parser.add_argument("--interpolation", choices=("paper", "hermite"), default="hermite",
                        help="interpolation of the spline study (default hermite)")
    args = parser.parse_args()
    lead = args.lead if args.gap is None else args.range + args.gap
    schemes = WEIGHTS if args.gap is None else ("paper",)
    middle_source = fusion.Source.FUSED if args.gap is None else fusion.Source.INTERPOLATED
    print(f"camera lane-model error {CAMERA}; {args.pairs} pairs per row; coop {lead:g} m ahead, range "
          f"{args.range:g} m" + ("" if args.gap is None else f", spline ({args.interpolation})"))
    part = "overlap" if args.gap is None else "bridge"
    print(f"| σ_xy [m] / σ_yaw [mrad] | weights | max [m] | p95 [m] | mean [m] | {part} max [m] | {part} p95 [m] | "
          f"{part} mean [m] | w_coop mid-overlap | within 1σ [%] | within 2σ [%] | {part} within 1σ [%] | "
          f"{part} within 2σ [%] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for sigma_xy, sigma_yaw in POSE_LEVELS:
        rng = np.random.default_rng(args.seed)
        errors: dict[str, list[np.ndarray]] = {name: [] for name in schemes}
        overlap: dict[str, list[np.ndarray]] = {name: [] for name in schemes}
        overlap_sigmas: dict[str, list[np.ndarray]] = {name: [] for name in schemes}
        sigmas: dict[str, list[np.ndarray]] = {name: [] for name in schemes}
        for _ in range(args.pairs):
            road = random_road(rng)
            ego = sensed(road, 10.0, args.range, CAMERA, rng)
            coop = with_pose_error(sensed(road, 10.0 + lead, args.range, CAMERA, rng), sigma_xy, sigma_yaw, rng)
            truth = [road.border(HALF_WIDTH_M), road.border(-HALF_WIDTH_M)]
            for name in schemes:
                result = fusion.fuse(ego, coop, interpolation=args.interpolation,
                                     params=fusion.FusionParams(convoy_weights=name))
                if result.kind == "none":
                    continue
                for points, sigma, source, line in ((result.left, result.left_sigma, result.left_source, truth[0]),
                                                    (result.right, result.right_sigma, result.right_source, truth[1])):
                    errors[name].append(distance_to_polyline(points, line))
                    overlap[name].append(errors[name][-1][source == middle_source])
                    overlap_sigmas[name].append(sigma[source == middle_source])
                    sigmas[name].append(sigma)
        for name in schemes:
            e, s, o = np.concatenate(errors[name]), np.concatenate(sigmas[name]), np.concatenate(overlap[name])
            o_sigma = np.concatenate(overlap_sigmas[name])
            w = "–"
            if name == "inverse-variance" and args.gap is None:  # closed form at the overlap's middle
                x = 0.5 * (lead + args.range)
                ego_var = float(CAMERA.sigma_m(np.array(x))) ** 2
                coop_var = float(CAMERA.sigma_m(np.array(x - lead))) ** 2 + sigma_xy**2 + (sigma_yaw * (x - lead)) ** 2
                w = f"{ego_var / (ego_var + coop_var):.2f}"
            print(f"| {sigma_xy:g} / {1e3 * sigma_yaw:g} | {name} | {e.max():.3f} | {np.percentile(e, 95):.3f} | "
                  f"{e.mean():.3f} | {o.max():.3f} | {np.percentile(o, 95):.3f} | {o.mean():.3f} | {w} | {100 * np.mean(e <= s):.1f} | {100 * np.mean(e <= 2 * s):.1f} | "
                  f"{100 * np.mean(o <= o_sigma):.1f} | {100 * np.mean(o <= 2 * o_sigma):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
