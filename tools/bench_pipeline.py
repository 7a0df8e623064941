"""Whole-pipeline benchmark: frames per second of cold-eval's per-frame work on a map
(default: CARLA Town01), split per stage, with a baseline in the same run.

Stages per frame: ``sense`` (every vehicle's detection from the OpenDRIVE map), ``fuse``
(convoy and spline for every vehicle pair), ``match`` (GT lanelets of every evaluated lane)
and ``metrics`` (closest-point errors to the GT resampled at 0.02 m, report records).
Baseline for match + metrics: ``gt_matching.GroundTruth.evaluate`` on the same lanes (its
own matching and per-border statistics, without the per-point distances the report pools).

Usage: ``python tools/bench_pipeline.py [--map MAP.xodr] [--frames 60] [--repeat 3] [--cpu]``.
Prints mean, σ and max (ms per frame) per stage and the frames per second; ``--cpu`` times
with the process's CPU clock instead of the wall clock (for a machine shared with other
jobs).
"""

from __future__ import annotations

import argparse
import statistics
import sys
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--frames", type=int, default=60)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="time with the process CPU clock")
    args = parser.parse_args(argv)
    timings = bench(args.map, args.frames, args.repeat, time.process_time if args.cpu else time.perf_counter)
    print(f"{args.map.name}: {args.frames} frames x {args.repeat} passes ({'CPU' if args.cpu else 'wall'} ms per "
          f"frame: mean / σ / max)")
    for stage in STAGES:
        values = timings[stage]
        print(f"  {stage:18s} {statistics.fmean(values):7.2f} / {statistics.stdev(values):6.2f} / {max(values):7.2f}")
    pipeline = [sum(timings[s][i] for s in STAGES[:4]) for i in range(len(timings["sense"]))]
    baseline = [timings["sense"][i] + timings["fuse"][i] + timings["baseline evaluate"][i]
                for i in range(len(pipeline))]
    print(f"  pipeline (sense+fuse+match+metrics): {statistics.fmean(pipeline):.2f} ms/frame = "
          f"{1e3 / statistics.fmean(pipeline):.1f} frames/s")
    print(f"  baseline (sense+fuse+GroundTruth.evaluate): {statistics.fmean(baseline):.2f} ms/frame = "
          f"{1e3 / statistics.fmean(baseline):.1f} frames/s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
