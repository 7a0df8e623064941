"""Convoy weights and stated σ on analytic roads: ``paper`` / ``mean`` / ``inverse-variance``.

Each pair: an ego and a coop ``--lead`` m ahead on a random road (straight, an arc of radius
100–500 m, or an S-bend of two such arcs), both detecting ``--range`` m of their lane with
the camera's cubic lane-model error (``cold_maps.simulation.lane_model_error``: per
detection and border δc0…δc3 and white noise, the camera profile's σ by default) and
stating its closed-form σ(x) and its lane model (``LaneDetection.lane_model_sigma``); the coop's reported pose carries a Gaussian error of
``σ_xy``/``σ_yaw`` and states that covariance (the ego is the reference, exact). The same
pairs are fused with each weighting; per pose-error level the table gives the max / p95 /
mean error of all fused points against the true borders, the inverse-variance coop weight
at the overlap's middle (closed form on a straight road, after the pose update), and the calibration of the stated σ (share of points within
1σ and 2σ); the same errors and calibration over the overlap's fused points alone. With ``--gap`` the coop drives that far past the ego's range instead (spline
fusion, calibration of the bridge σ; weights do not apply).

    .venv/bin/python tools/study_convoy_weights.py [--pairs 200] [--seed 1] [--lead 25] [--range 50]

With ``--maps`` it runs ``cold-eval`` instead (in this process, ``--no-mcap --no-plots``, the
same routes, frames, gaps and seed for every run) on each map (a name of ``tools/study_sensor.py``
or an ``.xodr`` file, named by its stem) × sensor (``ideal``,
``camera``, or one of them with ``--sensors``) × coop pose error (none, 0.05 m / 2 mrad, 0.1 m / 5 mrad: ``--pose-xy``,
``--pose-yaw``) × ``--convoy-weights`` (paper, mean, inverse-variance) and tabulates the
convoy scenario's errors of correct fusions (``tools/study_sensor.py``'s ``correct_errors``:
the larger of the two borders' max and p95; the mean of both borders' means) and the
calibration of the stated σ of every fused scenario (both borders' points pooled). Writes
``study.json`` (every figure and how it was made) and ``study.md`` to ``--out``. With
``--parts`` (cold-eval then runs with one worker, in this process) it also gives where the
largest error of the correct convoy fusions lies: the max per part of the fused lane (the
ego's points before the overlap, the overlap's fused points, the coop's points past it; the
parts beside the overlap include its 5 m seam blends) and how far past the overlap's end
the largest error's point lies:

    .venv/bin/python tools/study_convoy_weights.py --maps rural,Town01,Town04 --out out/study-weights \
        [--routes 3] [--frames 100] [--eval-seed 0] [--gaps 20,30,50] [--workers 2] [--sensors camera] [--parts]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import shlex
import sys
from dataclasses import replace
from pathlib import Path
from typing import Any, Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import cold_maps  # noqa: E402
import fusion  # noqa: E402
from cold_maps.simulation.lane_model_error import LaneModelErrorParams  # noqa: E402
from fusion.analytic import AnalyticRoad, Segment, detect  # noqa: E402
from fusion.geometry import distance_to_polyline  # noqa: E402
from fusion.registration import pose_update  # noqa: E402
from fusion.uncertainty import lane_model_basis, lane_model_covariance  # noqa: E402
from study_sensor import MAPS, StudyMap, correct_errors, run_eval, sha256, shown  # noqa: E402

PARTS = ("ego", "overlap", "coop")

CAMERA = LaneModelErrorParams(sigma_c0_m=0.05, sigma_c1_rad=0.002, sigma_c2_per_m=4e-5, sigma_c3_per_m2=0.0,
                              white_m=0.01)
POSE_LEVELS = ((0.0, 0.0), (0.05, 0.002), (0.1, 0.005))  # (σ_xy m, σ_yaw rad) of the coop's reported pose
WEIGHTS = ("paper", "mean", "inverse-variance")
HALF_WIDTH_M = 1.75
SENSORS = ("ideal", "camera")


def middle_weight(lead_m: float, range_m: float, sigma_xy: float, sigma_yaw: float) -> float:
    """The inverse-variance w_coop at the overlap's middle on a straight road (closed form):
    the coop's pose error after the update from the overlap's ends (both borders, levers 0
    and range − lead from the coop, the camera's σ and lane model there), then
    σ_e² / (σ_e² + σ_c² + J P⁺ Jᵀ − 2·own), own the correction's share of the coop point's
    own lane model (``fusion.registration.own_shared``)."""
    overlap = range_m - lead_m
    sigma = lambda x: float(CAMERA.sigma_m(np.array(x)))  # noqa: E731
    rows = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, overlap]] * 2)
    model = CAMERA.coefficient_sigmas
    ends = [np.array([lead_m, range_m]), np.array([0.0, overlap])]
    border = sum(lane_model_covariance(model, x, CAMERA.sigma_m(x) ** 2) for x in ends)
    noise = np.kron(np.eye(2), border)
    cov = np.diag([sigma_xy**2, sigma_xy**2, sigma_yaw**2])
    update = pose_update(rows, np.zeros(4), noise, cov, np.zeros((3, 3)), (lead_m, 0.0))
    x = 0.5 * (lead_m + range_m)
    jacobian = np.array([0.0, 1.0, x - lead_m])
    basis = [lane_model_basis(model, np.array(at), CAMERA.sigma_m(np.array(at)) ** 2) for at in (ends[1], [x - lead_m])]
    own = float(jacobian @ update.gain[:, :2] @ basis[0] @ basis[1][0])
    ego_var = sigma(x) ** 2
    coop_var = sigma(x - lead_m) ** 2 + float(jacobian @ update.relative @ jacobian) - 2.0 * own
    return ego_var / (ego_var + coop_var)


def random_road(rng: np.random.Generator) -> AnalyticRoad:
    kind = rng.integers(3)
    k = rng.choice((-1.0, 1.0)) / rng.uniform(100.0, 500.0)
    body = [Segment(300.0)] if kind == 0 else [Segment(300.0, k)] if kind == 1 else [Segment(150.0, k),
                                                                                       Segment(150.0, -k)]
    return AnalyticRoad([Segment(20.0), *body], yaw0=rng.uniform(-math.pi, math.pi))


def sensed(road: AnalyticRoad, s_from: float, range_m: float, model: LaneModelErrorParams,
           rng: np.random.Generator) -> fusion.LaneDetection:
    """A detection with the lane-model error drawn per border, stating its σ(x) and its lane model."""
    det = detect(road, s_from, range_m, HALF_WIDTH_M, -HALF_WIDTH_M)
    borders, sigmas = [], []
    for border in (det.left, det.right):
        x = border[:, 0]
        c = rng.normal(0.0, (model.sigma_c0_m, model.sigma_c1_rad, model.sigma_c2_per_m, model.sigma_c3_per_m2))
        error = c[0] + c[1] * x + c[2] * x**2 / 2 + c[3] * x**3 / 6 + rng.normal(0.0, model.white_m, x.shape)
        borders.append(border + np.column_stack((np.zeros_like(x), error)))
        sigmas.append(model.sigma_m(x))
    return fusion.LaneDetection(det.pose, borders[0], borders[1], left_sigma=sigmas[0], right_sigma=sigmas[1],
                                lane_model_sigma=model.coefficient_sigmas)


def with_pose_error(det: fusion.LaneDetection, sigma_xy: float, sigma_yaw: float,
                    rng: np.random.Generator) -> fusion.LaneDetection:
    dx, dy = rng.normal(0.0, sigma_xy, 2) if sigma_xy else (0.0, 0.0)
    dyaw = rng.normal(0.0, sigma_yaw) if sigma_yaw else 0.0
    pose = fusion.Pose2D(det.pose.x + dx, det.pose.y + dy, det.pose.yaw + dyaw)
    return replace(det, pose=pose, pose_cov=np.diag([sigma_xy**2, sigma_xy**2, sigma_yaw**2]))


def convoy_row(metrics: dict[str, Any]) -> dict[str, Any]:
    """Errors of the correct convoy fusions of one run (module docstring) and how many."""
    records = [r for r in metrics["scenarios"] if r["fusion"] == "convoy"]
    worst = [correct_errors(r) for r in records]
    means = []
    for record in records:
        groups = [g for g in record.get("by_route", {}).values() if g["fused"]]
        if groups:
            means.append(sum(g["fused"] * g["mean_error_m"] for g in groups) / sum(g["fused"] for g in groups))

    def larger(name: str) -> float | None:
        values = [w[name] for w in worst if w.get(name) is not None]
        return max(values) if values else None

    return {"fused": sum(g["fused"] for g in records[0].get("by_route", {}).values()) if records else 0,
            "max_error_m": larger("max_error_m"), "p95_error_m": larger("p95_error_m"),
            "mean_error_m": sum(means) / len(means) if means else None}


@contextlib.contextmanager
def convoy_parts() -> Iterator[dict[str, Any]]:
    """While open, the largest error [m] of every part (:data:`PARTS`: the points labelled
    ego, fused, coop) of the correct convoy fusions cold-eval measures in this process, the
    part of the point with the largest error of all (``max_part``) and, in the coop's part,
    its distance [m] along the border from the overlap's last point (``max_past_overlap_m``)."""
    from cold_maps.evaluation import evaluator

    found: dict[str, Any] = {name: 0.0 for name in PARTS} | {"max": 0.0, "max_part": None,
                                                             "max_past_overlap_m": None}
    sources: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    truths: dict[int, bool] = {}
    fuse, record, keep = fusion.fuse, evaluator.MapEvaluator._record, evaluator.MapEvaluator._keep_overlay

    def fuse_and_keep(*args, **kwargs):  # type: ignore[no-untyped-def]
        result = fuse(*args, **kwargs)
        if kwargs.get("mode") == "convoy" and result.kind == "convoy":
            for side in ("left", "right"):
                sources[id(getattr(result, side))] = (getattr(result, side), getattr(result, f"{side}_source"))
        return result

    def record_truth(self, collector, scenario, keys, measured, *args, **kwargs):  # type: ignore[no-untyped-def]
        truths[id(measured)] = bool(args[6])
        return record(self, collector, scenario, keys, measured, *args, **kwargs)

    def measure_parts(self, collector, scenario, index, measured, detections, lanes):  # type: ignore[no-untyped-def]
        truth = truths.pop(id(measured), False)
        for side, errors in (("left", measured.left_errors_m), ("right", measured.right_errors_m)):
            kept = sources.pop(id(lanes.get(side)), None)
            if kept is None or kept[0] is not lanes[side] or not truth or errors.size != kept[1].size:
                continue
            source = kept[1]
            masks = {"ego": source == fusion.Source.EGO, "overlap": source == fusion.Source.FUSED,
                     "coop": source == fusion.Source.COOP}
            for name, mask in masks.items():
                if mask.any():
                    found[name] = max(found[name], float(errors[mask].max()))
            worst = int(np.argmax(errors))
            if errors[worst] > found["max"]:
                part = next(name for name, mask in masks.items() if mask[worst])
                end = int(np.flatnonzero(masks["overlap"])[-1]) if masks["overlap"].any() else worst
                found["max"], found["max_part"] = float(errors[worst]), part
                found["max_past_overlap_m"] = float(np.hypot(*np.diff(lanes[side][end: worst + 1], axis=0).T).sum()) \
                    if part == "coop" else None
        return keep(self, collector, scenario, index, measured, detections, lanes)

    fusion.fuse, evaluator.MapEvaluator._record = fuse_and_keep, record_truth
    evaluator.MapEvaluator._keep_overlay = measure_parts
    try:
        yield found
    finally:
        fusion.fuse, evaluator.MapEvaluator._record, evaluator.MapEvaluator._keep_overlay = fuse, record, keep


def calibration_rows(metrics: dict[str, Any]) -> list[dict[str, Any]]:
    """Calibration of every fused scenario of one run, both borders' points pooled."""
    pooled: dict[str, list[dict[str, Any]]] = {}
    for record in metrics["scenarios"]:
        if record["fusion"] != "local" and record.get("calibration"):
            label = record["fusion"] if record["fusion"] != "spline" else \
                f"spline-{record['interpolation']}-d{record['d_s']:g}"
            pooled.setdefault(label, []).append(record["calibration"])
    rows = []
    for label, parts in pooled.items():
        points = sum(p["points"] for p in parts)
        rows.append({"scenario": label, "points": points,
                     **{key: sum(p[key] * p["points"] for p in parts) / points
                        for key in ("within_1sigma", "within_2sigma", "mean_sigma_m", "mean_error_m")}})
    return rows


def _num(value: float | None, digits: int = 3) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def maps_markdown(study: dict[str, Any]) -> str:
    """The tables of a ``--maps`` study."""
    lines = [f"Made by `{study['command']}` (cold-maps {study['version']}; cold-eval options "
             f"`{study['eval_options']}`).", "",
             "Convoy, errors of correct fusions [m] (max / p95: the larger border's; mean: both borders'):", "",
             "| map | sensor | pose σ_xy [m] / σ_yaw [mrad] | " + " | ".join(
                 f"{w} max | {w} p95 | {w} mean" for w in WEIGHTS) + " | fused |",
             "|---|---|---|" + "---|" * (3 * len(WEIGHTS) + 1)]
    for row in study["rows"]:
        cells = [f"{_num(row[w]['max_error_m'])} | {_num(row[w]['p95_error_m'])} | {_num(row[w]['mean_error_m'])}"
                 for w in WEIGHTS]
        lines.append(f"| {row['map']} | {row['sensor']} | {row['pose'][0]:g} / {1e3 * row['pose'][1]:g} | "
                     + " | ".join(cells) + f" | {row['paper']['fused']} |")
    with_parts = [row for row in study["rows"] if "parts" in row["paper"]]
    if with_parts:
        lines += ["", "Where the largest error of the correct convoy fusions lies (max per part [m]: the ego's "
                  "points, the overlap's fused points, the coop's points; the part of the largest error and, in "
                  "the coop's part, its distance along the border from the overlap's last point [m]):", "",
                  "| map | sensor | pose σ_xy [m] / σ_yaw [mrad] | weights | ego max | overlap max | coop max "
                  "| largest in | past the overlap [m] |", "|---|---|---|---|---|---|---|---|---|"]
        for row in with_parts:
            for w in WEIGHTS:
                part = row[w]["parts"]
                lines.append(f"| {row['map']} | {row['sensor']} | {row['pose'][0]:g} / {1e3 * row['pose'][1]:g} | "
                             f"{w} | " + " | ".join(_num(part[name]) for name in PARTS)
                             + f" | {part['max_part'] or '–'} | {_num(part['max_past_overlap_m'], 1)} |")
    lines += ["", "Calibration of the stated σ (share of fused points within 1σ / 2σ, %; the convoy "
              "row per weighting, spline rows from the inverse-variance run; 68.3 / 95.4 when calibrated):", "",
              "| map | pose σ_xy [m] / σ_yaw [mrad] | scenario | within 1σ | within 2σ | mean σ [m] "
              "| mean error [m] |",
              "|---|---|---|---|---|---|---|"]
    for row in study["rows"]:
        for w in WEIGHTS:
            for cal in row[w]["calibration"]:
                if cal["scenario"] != "convoy" and w != "inverse-variance":
                    continue
                name = f"{cal['scenario']} ({w})" if cal["scenario"] == "convoy" else cal["scenario"]
                lines.append(f"| {row['map']} | {row['pose'][0]:g} / {1e3 * row['pose'][1]:g} | {name} | "
                             f"{100 * cal['within_1sigma']:.1f} | {100 * cal['within_2sigma']:.1f} | "
                             f"{cal['mean_sigma_m']:.3f} | {cal['mean_error_m']:.3f} |")
    return "\n".join(lines)


def maps_study(args: argparse.Namespace, argv: list[str]) -> int:
    """The ``--maps`` study (module docstring)."""
    specs = {m.name: m for m in MAPS}
    wanted = [name for name in args.maps.split(",") if name]
    for name in wanted:
        if name not in specs and name.endswith(".xodr"):
            specs[name] = StudyMap(Path(name).stem, Path(name), True)
    unknown = sorted(set(wanted) - set(specs))
    if unknown:
        print(f"study_convoy_weights: --maps: unknown map(s) {', '.join(unknown)} (known: {', '.join(specs)})",
              file=sys.stderr)
        return 2
    options = ["--routes", args.routes, "--frames", args.frames, "--seed", args.eval_seed, "--gaps", args.gaps,
               "--interpolation", "both", "--workers", "1" if args.parts else args.workers, "--no-mcap", "--no-plots",
               "-q"]
    study: dict[str, Any] = {"command": shlex.join(["python", "tools/study_convoy_weights.py", *argv]),
                             "version": cold_maps.__version__, "eval_options": shlex.join(options), "maps": [],
                             "rows": []}
    for key in wanted:
        spec = specs[key]
        name = spec.name
        if not spec.path.is_file():
            print(f"{name}: skipped, {spec.path} not found", file=sys.stderr)
            study["maps"].append({"name": name, "path": shown(spec.path), "sha256": None})
            continue
        study["maps"].append({"name": name, "path": shown(spec.path), "sha256": sha256(spec.path)})
        for sensor in args.sensors.split(","):
            for sigma_xy, sigma_yaw in POSE_LEVELS:
                row: dict[str, Any] = {"map": name, "sensor": sensor, "pose": [sigma_xy, sigma_yaw]}
                for weights in WEIGHTS:
                    out = args.out / name / sensor / f"pose{sigma_xy:g}_{sigma_yaw:g}" / weights
                    run = ["--map", str(spec.path), "--sensor", sensor, "--pose-xy", f"{sigma_xy:g}", "--pose-yaw",
                           f"{sigma_yaw:g}", "--convoy-weights", weights, *options, "--out", str(out)]
                    with convoy_parts() if args.parts else contextlib.nullcontext({}) as parts:
                        status, err, seconds = run_eval(run)
                    print(f"{name} {sensor} {sigma_xy:g}/{sigma_yaw:g} {weights}: exit {status} in {seconds:.0f} s",
                          file=sys.stderr)
                    if status != 0:
                        print(f"study_convoy_weights: cold-eval exit {status}: {err}", file=sys.stderr)
                        return 1
                    metrics = json.loads((out / "metrics.json").read_text())
                    row[weights] = convoy_row(metrics) | {"calibration": calibration_rows(metrics),
                                                          "cold_eval": shlex.join(["cold-eval", *run])}
                    if parts:
                        row[weights]["parts"] = parts
                study["rows"].append(row)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "study.json").write_text(json.dumps(study, indent=1) + "\n")
    (args.out / "study.md").write_text(maps_markdown(study) + "\n")
    print(f"study: {args.out / 'study.md'}, {args.out / 'study.json'}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=200, help="pairs per pose-error level (default 200)")
    parser.add_argument("--seed", type=int, default=1, help="seed (default 1)")
    parser.add_argument("--lead", type=float, default=25.0, help="coop ahead of the ego, m (default 25)")
    parser.add_argument("--range", type=float, default=50.0, help="sensor range, m (default 50, the camera's)")
    parser.add_argument("--gap", type=float, default=None, help="spline study: gap d_s past the ego's range, m")
    parser.add_argument("--interpolation", choices=("paper", "hermite"), default="hermite",
                        help="interpolation of the spline study (default hermite)")
    parser.add_argument("--maps", default="", help="comma-separated maps of tools/study_sensor.py (e.g. "
                        "rural,Town01,Town04) or .xodr files: the cold-eval study instead of the analytic one")
    parser.add_argument("--out", type=Path, default=Path("out/study-weights"), help="--maps: output folder")
    parser.add_argument("--routes", default="3", help="--maps: cold-eval --routes (default 3)")
    parser.add_argument("--frames", default="100", help="--maps: cold-eval --frames (default 100)")
    parser.add_argument("--eval-seed", default="0", help="--maps: cold-eval --seed (default 0)")
    parser.add_argument("--gaps", default="20,30,50", help="--maps: cold-eval --gaps (default 20,30,50)")
    parser.add_argument("--workers", default="2", help="--maps: cold-eval --workers (default 2)")
    parser.add_argument("--parts", action="store_true",
                        help="--maps: also where the largest convoy error lies (cold-eval with one worker)")
    parser.add_argument("--sensors", default=",".join(SENSORS), choices=(*SENSORS, ",".join(SENSORS)),
                        help="--maps: the sensors, ideal, camera or both (default ideal,camera)")
    args = parser.parse_args(argv)
    if args.maps:
        return maps_study(args, argv)
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
            if name == "inverse-variance" and args.gap is None:
                w = f"{middle_weight(lead, args.range, sigma_xy, sigma_yaw):.2f}"
            print(f"| {sigma_xy:g} / {1e3 * sigma_yaw:g} | {name} | {e.max():.3f} | {np.percentile(e, 95):.3f} | "
                  f"{e.mean():.3f} | {o.max():.3f} | {np.percentile(o, 95):.3f} | {o.mean():.3f} | {w} | {100 * np.mean(e <= s):.1f} | {100 * np.mean(e <= 2 * s):.1f} | "
                  f"{100 * np.mean(o <= o_sigma):.1f} | {100 * np.mean(o <= 2 * o_sigma):.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
