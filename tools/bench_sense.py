"""States, sensing and fusion benchmark: ms per frame of the evaluator's vehicle states,
detections and fusion calls on a map's default cold-eval plan (default: CARLA Town01, 300
frames on 3 routes, 16 scenarios), for one sensor profile, frame loop and block path side
by side in one process, optionally beside another commit's frame loop.

Stages (ms per frame, over every frame of every drive, ``--repeat`` passes after one untimed
pass): ``states loop`` (``Drive.states`` frame by frame), ``sense loop`` (``detection.sense``
of every vehicle, frame by frame, the camera's obstacles from ``obstacles_of``), ``states
block`` and ``sense block`` (``Drive.states_block`` and ``detection.sense_block`` over blocks
of ``evaluator.BLOCK_FRAMES``, each block's time spread evenly over its frames) and ``fuse``
(the evaluator's fusion call of every pair and scenario, plus ``is_fusible`` for the main
coop; the same calls on both paths). A commit without the block path reports the loop and
``fuse`` only.

Usage: ``python tools/bench_sense.py [--map MAP.xodr] [--sensor ideal|camera] [--repeat 3]
[--cpu] [--baseline-ref REF]``. ``--cpu`` times with the process's CPU clock (for a machine
shared with other jobs); ``--baseline-ref`` runs this script again on the tree of commit REF
(``git archive`` to a temporary folder, its code on PYTHONPATH) and prints both side by side
with the ratio REF / current of the means.
"""

from __future__ import annotations

import argparse
import io
import os
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
if str(ROOT) not in sys.path and "BENCH_SENSE_TREE" not in os.environ:
    sys.path.insert(0, str(ROOT))

import fusion  # noqa: E402
from cold_maps.cli.evaluate import _plans, build_parser  # noqa: E402
from cold_maps.evaluation.evaluator import MapEvaluator  # noqa: E402
from cold_maps.evaluation.methods import resolve_method  # noqa: E402
from cold_maps.simulation import detection  # noqa: E402
from cold_maps.simulation.lane_model_error import LaneModelErrorSampler  # noqa: E402

DEFAULT_MAP = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"
BLOCKS = hasattr(detection, "sense_block")
STAGES = ("states loop", "sense loop", *(("states block", "sense block") if BLOCKS else ()), "fuse")


def _samplers(evaluator: MapEvaluator) -> list[LaneModelErrorSampler | None]:
    """Fresh lane-model error samplers of every drive (their stamps may not go back)."""
    if evaluator.lane_errors is None:
        return [None] * len(evaluator.drives)
    return [LaneModelErrorSampler(s.params, s.seed, s.drive) for s in evaluator.lane_errors]


def _loop(evaluator: MapEvaluator, timer: Callable[[], float], out: dict[str, list[float]]) -> list[list[dict]]:
    """The frame loop of every drive, timed per frame; returns the sensed frames."""
    plan = evaluator.plan
    frames = []
    for index, (drive, lane_error) in enumerate(zip(evaluator.drives, _samplers(evaluator))):
        rng = np.random.default_rng(index)
        sensed = []
        for frame in range(drive.frames):
            start = timer()
            states = drive.states(frame)
            middle = timer()
            obstacles = detection.obstacles_of(states) if plan.sensor.kind == "camera" else {}
            sensed.append({name: detection.sense(state, evaluator.sensor, plan.errors, rng, stamp_s=frame / 10.0,
                                                 neighbours=evaluator.neighbours, lane_error=lane_error,
                                                 obstacles=obstacles.get(name, detection.NO_OBSTACLES))
                           for name, state in states.items()})
            end = timer()
            out["states loop"].append((middle - start) * 1e3)
            out["sense loop"].append((end - middle) * 1e3)
        frames.append(sensed)
    return frames


def _blocks(evaluator: MapEvaluator, timer: Callable[[], float], out: dict[str, list[float]]) -> None:
    """The block path of every drive, each block's time spread over its frames."""
    from cold_maps.evaluation.evaluator import BLOCK_FRAMES

    plan = evaluator.plan
    for index, (drive, lane_error) in enumerate(zip(evaluator.drives, _samplers(evaluator))):
        rng = np.random.default_rng(index)
        for first in range(0, drive.frames, BLOCK_FRAMES):
            block = range(first, min(first + BLOCK_FRAMES, drive.frames))
            start = timer()
            states = drive.states_block(block)
            middle = timer()
            detection.sense_block(states, evaluator.sensor, plan.errors, rng, stamps_s=[f / 10.0 for f in block],
                                  neighbours=evaluator.neighbours, lane_error=lane_error)
            end = timer()
            out["states block"] += [(middle - start) * 1e3 / len(block)] * len(block)
            out["sense block"] += [(end - middle) * 1e3 / len(block)] * len(block)


def _fuse(evaluator: MapEvaluator, frames: list[list[dict]], timer: Callable[[], float],
          out: dict[str, list[float]]) -> None:
    """The evaluator's fusion calls of every frame, timed per frame."""
    plan = evaluator.plan
    for sensed in (frame for drive in frames for frame in drive):
        ego = sensed["ego"].detection
        start = timer()
        for scenario in plan.scenarios:
            if scenario.fusion == "local" or scenario.vehicles > 2 or ego is None:
                continue
            for name, other in sensed.items():
                if name == "ego" or other.detection is None or abs(abs(other.state.lead_m) - scenario.lead_m) > 1e-9:
                    continue
                interpolation = scenario.interpolation or "paper"
                if scenario.fusion == "spline":
                    resolve_method(interpolation)(ego, other.detection, plan.params)
                else:
                    fusion.fuse(ego, other.detection, mode=scenario.fusion, interpolation=interpolation,
                                params=plan.params)
                if other.state.role == "coop":
                    fusion.is_fusible(ego, other.detection, plan.params, mode=scenario.fusion)
        out["fuse"].append((timer() - start) * 1e3)


def report(map_path: Path, sensor: str, repeat: int, cpu: bool) -> list[str]:
    """The benchmark's lines for the code on the path."""
    evaluator = MapEvaluator(_plans(build_parser().parse_args(["--map", str(map_path), "--sensor", sensor]))[0])
    timer = time.process_time if cpu else time.perf_counter
    timings: dict[str, list[float]] = {stage: [] for stage in STAGES}
    for attempt in range(repeat + 1):
        out: dict[str, list[float]] = {stage: [] for stage in STAGES}
        frames = _loop(evaluator, timer, out)
        if BLOCKS:
            _blocks(evaluator, timer, out)
        _fuse(evaluator, frames, timer, out)
        if attempt:
            for stage in STAGES:
                timings[stage] += out[stage]
    lines = [f"{map_path.name}, sensor {sensor}: {evaluator.total_frames} frames x {repeat} passes "
             f"({'CPU' if cpu else 'wall'} ms per frame: mean / σ / max)"]
    for stage in STAGES:
        values = timings[stage]
        lines.append(f"  {stage:14s} {statistics.fmean(values):8.3f} / {statistics.pstdev(values):7.3f} / "
                     f"{max(values):8.3f}")
    return lines


def _means(lines: list[str]) -> dict[str, float]:
    return {line[2:16].strip(): float(line[16:].split("/")[0]) for line in lines[1:]}


def baseline(ref: str, argv: list[str]) -> list[str]:
    """This script's lines run on commit ``ref``'s tree."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], capture_output=True,
                             check=True).stdout
    with tempfile.TemporaryDirectory(prefix="bench-sense-") as folder:
        with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
            tar.extractall(folder, filter="tar")
        environment = {**os.environ, "PYTHONPATH": folder, "BENCH_SENSE_TREE": folder}
        done = subprocess.run([sys.executable, str(Path(__file__).resolve()), *argv], check=False,
                              capture_output=True, text=True, env=environment, cwd=folder)
    if done.returncode:
        raise SystemExit(f"bench_sense.py on {ref} failed: {done.stderr.strip().splitlines()[-1:]}")
    return done.stdout.splitlines()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--sensor", default="ideal", help="sensor profile (ideal, camera, ...)")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--cpu", action="store_true", help="time with the process CPU clock")
    parser.add_argument("--baseline-ref", help="also run the frame loop of this git commit and compare")
    args = parser.parse_args(argv)
    current = report(args.map.resolve(), args.sensor, args.repeat, args.cpu)
    print("\n".join(current), flush=True)
    if args.baseline_ref:
        forwarded = ["--map", str(args.map.resolve()), "--sensor", args.sensor, "--repeat", str(args.repeat),
                     *(["--cpu"] if args.cpu else [])]
        theirs = baseline(args.baseline_ref, forwarded)
        print(f"\n{args.baseline_ref}:", *theirs, sep="\n")
        ours, base = _means(current), _means(theirs)
        print(f"\nms per frame           current   {args.baseline_ref}   ratio")
        for name, new, old in (("states", ours.get("states block", ours["states loop"]), base["states loop"]),
                               ("sense", ours.get("sense block", ours["sense loop"]), base["sense loop"]),
                               ("fuse", ours["fuse"], base["fuse"])):
            print(f"  {name:18s} {new:9.3f} {old:9.3f}   {old / new:5.2f}x")
        new_total = sum(ours.get(f"{s} block", ours.get(f"{s} loop", 0.0)) for s in ("states", "sense")) + ours["fuse"]
        old_total = base["states loop"] + base["sense loop"] + base["fuse"]
        print(f"  {'states+sense+fuse':18s} {new_total:9.3f} {old_total:9.3f}   {old_total / new_total:5.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
