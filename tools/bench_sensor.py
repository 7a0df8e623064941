"""Sensor benchmark: the evaluator's whole per-frame work (sensing, fusion, ground truth,
records) with the ``ideal`` sensor and a camera profile side by side in one run, on one map
(default: CARLA Town01), and the sensing alone.

Both sides evaluate the same drives (same plan and seed but the sensor) and share one
ground truth; they alternate ``--repeat`` times after one untimed pass each. Printed per
side: ms per frame (mean / σ / max over every frame of every pass) for the whole frame
and for every vehicle's sensing alone, and the ratio camera / ideal of the means. Issue 26
asks the camera for at most 2× the per-frame time of ideal.

Usage: ``python tools/bench_sensor.py [--map MAP.xodr] [--sensor camera] [--frames 100]
[--routes 2] [--repeat 3] [--cpu]``.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cold_maps.evaluation.collector import Collector  # noqa: E402
from cold_maps.evaluation.evaluator import MapEvaluator  # noqa: E402
from cold_maps.evaluation.scenarios import MapPlan, params_for_gaps, scenarios_for  # noqa: E402
from cold_maps.network.lane_graph import load_graph  # noqa: E402
from cold_maps.simulation.detection import obstacles_of, sense  # noqa: E402
from cold_maps.simulation.lane_model_error import LaneModelErrorSampler  # noqa: E402
from cold_maps.simulation.sensor_profile import IDEAL, load_profile  # noqa: E402

DEFAULT_MAP = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"


def frame_times(evaluator: MapEvaluator, timer: Callable[[], float]) -> tuple[list[float], list[float]]:
    """ms per frame of one pass over every drive: the whole frame, and the sensing alone.
    Each pass starts the drives' lane-model errors afresh (their stamps may not go back)."""
    whole, sensing = [], []
    if evaluator.lane_errors is not None:
        evaluator.lane_errors = [LaneModelErrorSampler(s.params, s.seed, s.drive) for s in evaluator.lane_errors]
    collector = Collector()
    rng = np.random.default_rng(0)
    for index, drive in enumerate(evaluator.drives):
        for frame in range(drive.frames):
            start = timer()
            evaluator.run_drive(index, collector, frames=range(frame, frame + 1))
            whole.append((timer() - start) * 1e3)
            states = drive.states(frame)
            start = timer()
            obstacles = obstacles_of(states)
            for name, state in states.items():
                sense(state, evaluator.sensor, evaluator.plan.errors, rng, obstacles=obstacles[name])
            sensing.append((timer() - start) * 1e3)
    return whole, sensing


def _stats(values: list[float]) -> str:
    return f"{statistics.fmean(values):7.2f} / {statistics.stdev(values):6.2f} / {max(values):7.2f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--sensor", default="camera", help="the camera profile compared with ideal")
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--routes", type=int, default=2)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="time with the process's CPU clock")
    args = parser.parse_args(argv)
    timer = time.process_time if args.cpu else time.perf_counter
    plan = MapPlan(args.map, scenarios_for([20.0], ["paper"]), frames=args.frames, routes=args.routes, seed=0,
                   params=params_for_gaps([20.0]))
    from converters import load_lanelet2
    from gt_matching import GroundTruth

    graph = load_graph(args.map)
    ground_truth = GroundTruth(*load_lanelet2(args.map), prepare_all=False)
    ideal = MapEvaluator(replace(plan, sensor=IDEAL), ground_truth=ground_truth, graph=graph)
    camera = MapEvaluator(replace(plan, sensor=load_profile(args.sensor)), ground_truth=ground_truth, graph=graph)
    sides = {"ideal": ideal, args.sensor: camera}
    times: dict[str, tuple[list[float], list[float]]] = {name: ([], []) for name in sides}
    for evaluator in sides.values():
        frame_times(evaluator, timer)
    for _ in range(args.repeat):
        for name, evaluator in sides.items():
            whole, sensing = frame_times(evaluator, timer)
            times[name][0].extend(whole)
            times[name][1].extend(sensing)
    clock = "CPU" if args.cpu else "wall"
    print(f"{args.map.name}: {ideal.total_frames} frames x {args.repeat} passes ({clock} ms per frame: "
          "mean / σ / max)")
    for name, (whole, sensing) in times.items():
        print(f"  {name:16s} frame {_stats(whole)}   sensing {_stats(sensing)}")
    ratio = statistics.fmean(times[args.sensor][0]) / statistics.fmean(times["ideal"][0])
    sensing_ratio = statistics.fmean(times[args.sensor][1]) / statistics.fmean(times["ideal"][1])
    print(f"  {args.sensor} / ideal: frame {ratio:.2f}x, sensing {sensing_ratio:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
