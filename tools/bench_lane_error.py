"""Per-frame cost of the cubic lane-model error (``simulation.lane_model_error``) against
none, side by side in one run.

Two plans on one map share the lane graph and the ground truth: the ideal sensor and the
same with the urban camera profile's lane-model error (σ(c0) 0.05 m, σ(c1) 2 mrad, σ(c2) 4e-5 1/m,
σ(c3) 0, white 0.01 m, τ 0.5 s). Frame by frame, alternating which goes first, it times
``sense`` of every vehicle of the frame and the evaluator's whole frame (sense, fusion,
ground-truth errors) of each plan.

Usage: ``python tools/bench_lane_error.py [--map MAP.xodr] [--frames 100] [--cpu]``. Prints
mean, σ and max (ms per frame) per stage and plan, and the ratio of the means; ``--cpu``
times with the process's CPU clock instead of the wall clock (for a machine shared with
other jobs).
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
from cold_maps.evaluation.scenarios import MapPlan, scenarios_for  # noqa: E402
from cold_maps.simulation.detection import sense  # noqa: E402
from cold_maps.simulation.lane_model_error import LaneModelErrorSampler  # noqa: E402
from cold_maps.simulation.sensor_profile import CAMERA as CAMERA_PROFILE  # noqa: E402
from cold_maps.simulation.sensor_profile import IDEAL  # noqa: E402

DEFAULT_MAP = ROOT / "maps" / "junction.xodr"
CAMERA = CAMERA_PROFILE.lane_error
"""The urban camera profile's lane-model error."""
PLANS = ("ideal", "camera")
STAGES = ("sense", "frame")


def bench(map_path: Path, frames: int, timer: Callable[[], float]) -> dict[tuple[str, str], list[float]]:
    """Per (stage, plan) the time of every frame (ms, by ``timer`` in s) of the first drive."""
    plan = MapPlan(map_path, scenarios_for([20.0], ["paper"]), frames=frames, frames_at_most=True, routes=1, seed=0)
    ideal = MapEvaluator(plan)
    ideal.prepare()
    assert ideal.meter is not None
    camera = MapEvaluator(replace(plan, sensor=replace(IDEAL, lane_error=CAMERA)), graph=ideal.graph,
                          ground_truth=ideal.meter.ground_truth)
    camera.prepare()
    evaluators = {"ideal": ideal, "camera": camera}
    sense_rngs = {name: np.random.default_rng(0) for name in PLANS}
    sense_errors = {"ideal": None, "camera": LaneModelErrorSampler(CAMERA, seed=0, drive=0)}
    """The sense stage's own sampler: the evaluator's evolves with its own frames."""
    timings: dict[tuple[str, str], list[float]] = {(stage, name): [] for stage in STAGES for name in PLANS}
    drive = ideal.drives[0]
    for frame in range(drive.frames):
        order = PLANS if frame % 2 == 0 else PLANS[::-1]
        for name in order:
            evaluator = evaluators[name]
            start = timer()
            for state in drive.states(frame).values():
                sense(state, evaluator.sensor, evaluator.plan.errors, sense_rngs[name], stamp_s=frame / 10.0,
                      lane_error=sense_errors[name])
            timings["sense", name].append((timer() - start) * 1e3)
            start = timer()
            evaluator.run_drive(0, Collector(), frames=range(frame, frame + 1))
            timings["frame", name].append((timer() - start) * 1e3)
    return timings


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--cpu", action="store_true", help="time with the process CPU clock")
    args = parser.parse_args(argv)
    timings = bench(args.map, args.frames, time.process_time if args.cpu else time.perf_counter)
    count = len(timings["sense", "ideal"])
    print(f"{args.map.name}: {count} frames of one drive, {'CPU' if args.cpu else 'wall'} ms per frame "
          "(mean / σ / max)")
    print(f"  {'stage':6s} {'ideal':>24s}   {'camera lane error':>24s}   ratio of the means")
    for stage in STAGES:
        figures = {name: timings[stage, name] for name in PLANS}
        cells = [f"{statistics.fmean(v):7.3f} / {statistics.stdev(v):6.3f} / {max(v):7.3f}" for v in figures.values()]
        ratio = statistics.fmean(figures["camera"]) / statistics.fmean(figures["ideal"])
        print(f"  {stage:6s} {cells[0]:>24s}   {cells[1]:>24s}   {ratio:5.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
