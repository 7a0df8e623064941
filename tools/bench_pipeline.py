"""Whole-pipeline benchmark: frames per second of cold-eval's per-frame work on a map
(default: CARLA Town01), split per stage, with a baseline in the same run.

Stages per frame: ``sense`` (every vehicle's detection from the OpenDRIVE map), ``fuse``
(convoy and spline for every vehicle pair), ``match`` (GT lanelets of every evaluated lane)
and ``metrics`` (closest-point errors to the GT resampled at 0.02 m, report records).
Baseline for match + metrics: ``gt_matching.GroundTruth.evaluate`` on the same lanes (its
own matching and per-border statistics, without the per-point distances the report pools).

Usage: ``python tools/bench_pipeline.py [--map MAP.xodr] [--frames 60] [--repeat 3] [--cpu]
[--baseline-ref REF]``. Prints mean, σ and max (ms per frame) per stage and the frames per
second; ``--cpu`` times with the process's CPU clock instead of the wall clock (for a machine
shared with other jobs). ``--baseline-ref`` also runs the benchmark of that git commit (its
own ``tools/bench_pipeline.py`` on its own code, extracted to a temporary folder, same
arguments) right after this one and prints both side by side with the ratio.
"""

from __future__ import annotations

import argparse
import io
import os
import re
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import fusion  # noqa: E402
from cold_maps.evaluation.collector import Collector  # noqa: E402
from cold_maps.evaluation.evaluator import MapEvaluator  # noqa: E402
from cold_maps.evaluation.report import FrameRecord  # noqa: E402
from cold_maps.evaluation.scenarios import MapPlan, scenarios_for  # noqa: E402
from cold_maps.simulation.detection import sense, world_borders  # noqa: E402

DEFAULT_MAP = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"
STAGES = ("sense", "fuse", "match", "metrics", "baseline evaluate")


def bench(map_path: Path, frames: int, repeat: int,
          timer: Callable[[], float] = time.perf_counter) -> dict[str, list[float]]:
    """Per stage, the time of every frame (ms, by ``timer`` in s) over ``repeat`` passes of one drive."""
    plan = MapPlan(map_path, scenarios_for([20.0], ["paper"]), frames=frames, routes=1, seed=0)
    evaluator = MapEvaluator(plan)
    evaluator.prepare()
    meter, drive, sensor = evaluator.meter, evaluator.drives[0], evaluator.sensor
    collector = Collector()
    timings: dict[str, list[float]] = {stage: [] for stage in STAGES}
    rng = np.random.default_rng(0)
    for _ in range(repeat):
        for frame in range(frames):
            clock = dict.fromkeys(STAGES, 0.0)
            start = timer()
            sensed = {name: sense(state, sensor, plan.errors, rng) for name, state in drive.states(frame).items()}
            clock["sense"] = timer() - start
            ego = sensed.pop("ego")
            lanes = [(world_borders(ego.detection), ego.state, plan.scenarios[0])]
            for scenario in plan.scenarios[1:]:
                for other in sensed.values():
                    if abs(abs(other.state.lead_m) - scenario.lead_m) > 1e-9:
                        continue
                    start = timer()
                    result = fusion.fuse(ego.detection, other.detection, mode=scenario.fusion, params=plan.params)
                    clock["fuse"] += timer() - start
                    if result.kind != "none":
                        lanes.append(((result.left, result.right), other.state, scenario))
            pose = ego.state.track.strip.pose(ego.state.station)
            for (left, right), other_state, scenario in lanes:
                reference = evaluator.true_lane(ego.state, other_state) if scenario.fusion != "local" else None
                start = timer()
                match = meter.match(*(reference or (left, right)), pose)
                clock["match"] += timer() - start
                start = timer()
                measured = meter.errors(match, left, right)
                for boundary, errors in (("left", measured.left_errors_m), ("right", measured.right_errors_m)):
                    collector.add(scenario.key(plan.name, boundary), FrameRecord(frame, 0.0, "ego", "", errors))
                clock["metrics"] += timer() - start
                start = timer()
                meter.ground_truth.evaluate(left, right, pose)
                clock["baseline evaluate"] += timer() - start
            for stage, seconds in clock.items():
                timings[stage].append(seconds * 1e3)
    return timings


STAGE_LINE = re.compile(r"^  (.+?)\s+([0-9.]+) /\s+([0-9.]+) /\s+([0-9.]+)$")
"""A stage's line of the report: name, mean, σ, max (ms per frame)."""
PIPELINE_LINE = re.compile(r"^  pipeline .*= ([0-9.]+) frames/s$")


def report(map_path: Path, frames: int, repeat: int, cpu: bool) -> list[str]:
    """The benchmark's report lines for this checkout."""
    timings = bench(map_path, frames, repeat, time.process_time if cpu else time.perf_counter)
    clock = "CPU" if cpu else "wall"
    lines = [f"{map_path.name}: {frames} frames x {repeat} passes ({clock} ms per frame: mean / σ / max)"]
    for stage in STAGES:
        values = timings[stage]
        lines.append(f"  {stage:18s} {statistics.fmean(values):7.2f} / {statistics.stdev(values):6.2f} / "
                     f"{max(values):7.2f}")
    pipeline = [sum(timings[s][i] for s in STAGES[:4]) for i in range(len(timings["sense"]))]
    baseline = [timings["sense"][i] + timings["fuse"][i] + timings["baseline evaluate"][i]
                for i in range(len(pipeline))]
    lines.append(f"  pipeline (sense+fuse+match+metrics): {statistics.fmean(pipeline):.2f} ms/frame = "
                 f"{1e3 / statistics.fmean(pipeline):.1f} frames/s")
    lines.append(f"  baseline (sense+fuse+GroundTruth.evaluate): {statistics.fmean(baseline):.2f} ms/frame = "
                 f"{1e3 / statistics.fmean(baseline):.1f} frames/s")
    return lines


def baseline_report(ref: str, argv: list[str]) -> list[str]:
    """The report lines of commit ``ref``'s own benchmark with the arguments ``argv``: its
    tree extracted (``git archive``) to a temporary folder and run there (without
    ``--cpu`` when its benchmark has no such option: it then times the wall clock)."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], capture_output=True,
                             check=True).stdout
    with tempfile.TemporaryDirectory(prefix="bench-pipeline-") as folder:
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(folder, filter="tar")
        script = Path(folder) / "tools" / "bench_pipeline.py"
        if "--cpu" not in script.read_text(encoding="utf-8"):
            argv = [arg for arg in argv if arg != "--cpu"]
        environment = {**os.environ, "PYTHONPATH": folder}
        done = subprocess.run([sys.executable, str(script), *argv],
                              check=False, capture_output=True, text=True, env=environment, cwd=folder)
    if done.returncode:
        raise SystemExit(f"bench_pipeline.py of {ref} failed: {done.stderr.strip().splitlines()[-1:]}")
    return done.stdout.splitlines()


def side_by_side(current: list[str], baseline: list[str], ref: str) -> list[str]:
    """Per stage (and the pipeline's frames/s) this checkout's figures beside ``ref``'s,
    with the ratio baseline / current of the means."""
    def stages(lines: list[str]) -> dict[str, tuple[float, float, float]]:
        found = (STAGE_LINE.match(line) for line in lines)
        return {m.group(1): (float(m.group(2)), float(m.group(3)), float(m.group(4))) for m in found if m}

    ours, theirs = stages(current), stages(baseline)
    lines = [f"{'stage (ms per frame)':22s} {'current mean / σ / max':>26s}   {ref + ' mean / σ / max':>26s}   ratio"]
    for stage in (name for name in ours if name in theirs):
        (mean, sigma, peak), (base_mean, base_sigma, base_peak) = ours[stage], theirs[stage]
        lines.append(f"  {stage:20s} {mean:8.2f} / {sigma:6.2f} / {peak:7.2f}   {base_mean:8.2f} / "
                     f"{base_sigma:6.2f} / {base_peak:7.2f}   {base_mean / mean:5.2f}x")
    fps = [next((float(m.group(1)) for m in map(PIPELINE_LINE.match, lines_) if m), float("nan"))
           for lines_ in (current, baseline)]
    lines.append(f"  pipeline frames/s: current {fps[0]:.1f}, {ref} {fps[1]:.1f} ({fps[0] / fps[1]:.2f}x)")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="time with the process CPU clock")
    parser.add_argument("--baseline-ref", help="also run the benchmark of this git commit and compare")
    args = parser.parse_args(argv)
    current = report(args.map, args.frames, args.repeat, args.cpu)
    print("\n".join(current), flush=True)
    if args.baseline_ref:
        forwarded = ["--map", str(args.map.resolve()), "--frames", str(args.frames), "--repeat", str(args.repeat),
                     *(["--cpu"] if args.cpu else [])]
        baseline = baseline_report(args.baseline_ref, forwarded)
        print(f"\n{args.baseline_ref}:", *baseline, "", *side_by_side(current, baseline, args.baseline_ref), sep="\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
