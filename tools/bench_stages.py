"""Per-stage benchmark of a whole ``cold-eval`` run in one process: where each frame's time
goes (states, sensing, fusion, ground truth, records, the MCAP outputs) and what the run pays once
(imports, lane graph, ground-truth preparation, outputs), with the ideal and the camera
sensor, beside a baseline commit in the same run.

The run is the one ``cold-eval --map MAP [--frames N]`` makes (its own plans, default
scenarios), evaluated in each pass by a fresh ``MapEvaluator`` (its public ``run_drive``)
with an MCAP ``Recorder`` attached, then finalised (``run.mcap``), reported (``write_outputs``: ``frames.csv``,
``summary.md``, ``metrics.json``) and plotted (``write_plots``) into a temporary folder.
Stages are timed by wrapping the functions that do them (:data:`STAGE_TARGETS`, looked up
where the evaluator finds them; a name a checkout lacks is skipped and listed), each call
timed exclusively (a stage called inside another counts for itself only); what no
wrapper covers is ``other``. A frame ends when ``run_drive`` reports it (``on_frame``); a
checkout that evaluates frames in blocks shows its blocks in σ and max, not in the mean.

Printed per sensor: per stage the time per frame (ms: mean / σ / max over every frame of
every pass) for this checkout and the baseline, with the ratio; frames/s of the frame
pipeline (every stage but the MCAP), of the frames with the MCAP, and of the
whole run (imports, start-up and outputs included); the one-off times (s). The baseline
(``--baseline-ref``, default 0abd8c1, the frame loop before issue 27) runs this same
script on that commit's code (``git archive`` to a temporary folder), alternating with this
checkout, one process each. ``--cpu`` times with the process CPU clock (a shared machine).

Usage: ``python tools/bench_stages.py [--map MAP.xodr] [--frames N] [--repeat 2]
[--sensors ideal,camera] [--cpu] [--baseline-ref 0abd8c1 | --no-baseline]``.
"""

from __future__ import annotations

import argparse
import functools
import importlib
import io
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path
from typing import Any, Callable, Final

ROOT: Final[Path] = Path(__file__).resolve().parents[1]
DEFAULT_MAP: Final[Path] = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"
DEFAULT_BASELINE_REF: Final[str] = "0abd8c1"

STAGE_TARGETS: Final[dict[str, tuple[str, ...]]] = {
    "states": ("cold_maps.simulation.drive:Drive.states", "cold_maps.simulation.drive:Drive.states_block"),
    "sensing": ("cold_maps.simulation.detection:sense", "cold_maps.simulation.detection:sense_block",
                "cold_maps.simulation.detection:obstacles_of"),
    "fusion": ("fusion:fuse", "fusion:fuse_history", "fusion:fuse_chain", "fusion:is_fusible"),
    "ground truth": ("cold_maps.groundtruth.meter:GroundTruthMeter.measure",
                     "cold_maps.groundtruth.meter:GroundTruthMeter.measure_many",
                     "cold_maps.evaluation.trust:BrokenStretches.over"),
    "records": ("cold_maps.evaluation.collector:Collector.add", "cold_maps.evaluation.collector:Collector.add_traffic",
                "cold_maps.evaluation.collector:Collector.add_check_ms",
                "cold_maps.evaluation.evaluator:MapEvaluator._record",
                "cold_maps.evaluation.evaluator:MapEvaluator._keep_overlay"),
    "outputs (MCAP)": ("cold_maps.recording.recorder:Recorder.write_detection",
                       "cold_maps.recording.recorder:Recorder.write_gt",
                       "cold_maps.recording.recorder:Recorder.write_fused",
                       "cold_maps.recording.recorder:Recorder.write_metrics"),
}
"""Per stage, the functions (``module:attribute``, methods as ``Class.method``) whose calls
are its time: the frame loop's and the array path's (issue 27: ``states_block``,
``sense_block``); a checkout has some of them."""
STAGES: Final[tuple[str, ...]] = (*STAGE_TARGETS, "other")
PIPELINE: Final[tuple[str, ...]] = tuple(stage for stage in STAGES if stage != "outputs (MCAP)")
"""The stages of the frame pipeline (sense, fuse, measure, record): all but the MCAP."""
LAZY_MODULES: Final[tuple[str, ...]] = ("scipy.spatial", "lanelet2", "shapely", "orjson", "foxglove",
                                        "matplotlib.figure", "matplotlib.backends.backend_agg")
"""Modules a default run imports after start-up (each where it is first used)."""
ONE_OFF: Final[tuple[str, ...]] = ("imports (cold-eval)", "imports (lazy)", "lane graph and drives",
                                   "ground-truth preparation", "outputs: MCAP finalising", "outputs: report files",
                                   "outputs: plots")


class StageClock:
    """Exclusive time per stage: a call of a wrapped function counts from its start to its
    end minus the calls of wrapped functions inside it (which count for their own stage)."""

    def __init__(self, timer: Callable[[], float]) -> None:
        self.timer = timer
        self.totals = dict.fromkeys(STAGES, 0.0)
        self._stack: list[str] = []
        self._since = timer()
        self.patched: list[tuple[Any, str, Any]] = []

    def _charge(self) -> None:
        """The time since the last reading to the stage running (``other`` when none)."""
        now = self.timer()
        self.totals[self._stack[-1] if self._stack else "other"] += now - self._since
        self._since = now

    def _switch(self, stage: str | None) -> None:
        self._charge()
        if stage is None:
            self._stack.pop()
        else:
            self._stack.append(stage)

    def wrap(self, stage: str, function: Callable[..., Any]) -> Callable[..., Any]:
        @functools.wraps(function)
        def timed(*args: Any, **kwargs: Any) -> Any:
            self._switch(stage)
            try:
                return function(*args, **kwargs)
            finally:
                self._switch(None)

        return timed

    def take(self) -> dict[str, float]:
        """The time per stage (s) since the last call, ``other`` included."""
        self._charge()
        totals, self.totals = self.totals, dict.fromkeys(STAGES, 0.0)
        return totals

    def restore(self) -> None:
        """Puts back every function :func:`install` wrapped."""
        for owner, name, original in reversed(self.patched):
            setattr(owner, name, original)
        self.patched.clear()


def install(clock: StageClock) -> list[str]:
    """Wraps every :data:`STAGE_TARGETS` function in ``clock``: the attribute itself and every
    module-level name bound to it in the loaded ``cold_maps``/``fusion``/``gt_matching``
    modules (:meth:`StageClock.restore` puts them back); returns the targets this checkout
    lacks."""
    missing = []
    for stage, targets in STAGE_TARGETS.items():
        for target in targets:
            module_name, _, path = target.partition(":")
            try:
                owner: Any = importlib.import_module(module_name)
                *outer, name = path.split(".")
                for part in outer:
                    owner = getattr(owner, part)
                original = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)
            except (ImportError, AttributeError, KeyError):
                missing.append(target)
                continue
            wrapped = clock.wrap(stage, original)
            owners = [owner] if isinstance(owner, type) else [
                module for module in list(sys.modules.values())
                if getattr(module, "__name__", "").split(".")[0] in ("cold_maps", "fusion", "gt_matching")
                and getattr(module, name, None) is original]
            for bound in {id(o): o for o in [owner, *owners]}.values():
                clock.patched.append((bound, name, original))
                setattr(bound, name, wrapped)
    return missing


def _imports(timer: Callable[[], float]) -> tuple[float, float]:
    """Seconds to import the ``cold-eval`` command, then the :data:`LAZY_MODULES`."""
    start = timer()
    import cold_maps.cli.evaluate  # noqa: F401

    middle = timer()
    for name in LAZY_MODULES:
        importlib.import_module(name)
    return middle - start, timer() - middle


def measure(map_path: Path, sensor: str, frames: int | None, repeat: int, cpu: bool) -> dict[str, Any]:
    """One side's figures with ``sensor``: per frame and stage the seconds, the one-off
    seconds, the frames evaluated, the targets it lacks."""
    timer = time.process_time if cpu else time.perf_counter
    one_off = dict.fromkeys(ONE_OFF, 0.0)
    one_off["imports (cold-eval)"], one_off["imports (lazy)"] = _imports(timer)
    from cold_maps.cli.evaluate import _plans, build_parser
    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.evaluator import MapEvaluator
    from cold_maps.evaluation.run import write_outputs, write_plots
    from cold_maps.recording.recorder import Recorder

    argv = ["--map", str(map_path), "--sensor", sensor, *(["--frames", str(frames)] if frames else [])]
    (plan,) = _plans(build_parser().parse_args(argv))
    clock = StageClock(timer)
    missing = install(clock)
    per_frame: list[dict[str, float]] = []
    with tempfile.TemporaryDirectory(prefix="bench-stages-") as folder:
        for index in range(repeat):  # each pass a fresh evaluator (error models start over), as a run
            start = timer()
            evaluator = MapEvaluator(plan)
            prepared = timer()
            evaluator.prepare()
            if index == 0:
                one_off["lane graph and drives"] = prepared - start
                one_off["ground-truth preparation"] = timer() - prepared
            collector = Collector()
            with Recorder(Path(folder) / "run.mcap", map_path=str(map_path), stamp_base_ns=0) as recorder:
                offset = 0
                clock.take()
                for drive in range(len(evaluator.drives)):
                    offset = evaluator.run_drive(drive, collector, recorder=recorder, frame_offset=offset,
                                                 on_frame=lambda: per_frame.append(clock.take()))
                finalising = timer()
            one_off["outputs: MCAP finalising"] += (timer() - finalising) / repeat
            start = timer()
            write_outputs(Path(folder), collector, partial=False, plots=False)
            one_off["outputs: report files"] += (timer() - start) / repeat
            start = timer()
            write_plots(Path(folder), collector)
            one_off["outputs: plots"] += (timer() - start) / repeat
    return {"per_frame": per_frame, "one_off": one_off, "frames": len(per_frame) // repeat, "missing": missing}


def _stats(values: list[float]) -> tuple[float, float, float]:
    """Mean, σ, max (ms) of seconds."""
    ms = [v * 1e3 for v in values]
    return statistics.fmean(ms), statistics.stdev(ms) if len(ms) > 1 else 0.0, max(ms)


def rates(side: dict[str, Any]) -> dict[str, float]:
    """Frames per second of the pipeline, of the frames with the MCAP, of the whole run."""
    frames = side["per_frame"]
    pipeline = statistics.fmean(sum(f[s] for s in PIPELINE) for f in frames)
    recorded = statistics.fmean(sum(f.values()) for f in frames)
    whole = recorded + sum(side["one_off"].values()) / side["frames"]
    return {"pipeline": 1.0 / pipeline, "with MCAP": 1.0 / recorded, "whole run": 1.0 / whole}


def table(sensor: str, sides: dict[str, dict[str, Any]]) -> list[str]:
    """The side-by-side lines of one sensor (``sides``: name -> :func:`measure`)."""
    names = list(sides)
    current = sides[names[0]]
    lines = [f"sensor {sensor}: {current['frames']} frames per pass, "
             f"{len(current['per_frame']) // current['frames']} passes"]
    header = "".join(f"{name + ' mean / σ / max':>30s}" for name in names)
    lines.append(f"  {'stage (ms per frame)':24s}{header}{'   ratio (baseline / current)' if len(names) > 1 else ''}")
    for stage in STAGES:
        figures = [_stats([f[stage] for f in sides[name]["per_frame"]]) for name in names]
        cells = "".join(f"{m:12.3f} / {s:6.3f} / {x:7.2f}" for m, s, x in figures)
        ratio = f"   {figures[1][0] / figures[0][0]:5.2f}x" if len(names) > 1 and figures[0][0] > 0 else ""
        lines.append(f"  {stage:24s}{cells}{ratio}")
    for what in ("pipeline", "with MCAP", "whole run"):
        fps = [rates(sides[name])[what] for name in names]
        ratio = f"   {fps[0] / fps[1]:5.2f}x" if len(names) > 1 else ""
        lines.append(f"  {'frames/s ' + what:24s}" + "".join(f"{v:30.1f}" for v in fps) + ratio)
    lines.append(f"  {'one-off (s)':24s}")
    for what in ONE_OFF:
        values = [sides[name]["one_off"][what] for name in names]
        ratio = f"   {values[1] / values[0]:5.2f}x" if len(names) > 1 and values[0] > 0 else ""
        lines.append(f"  {what:24s}" + "".join(f"{v:30.3f}" for v in values) + ratio)
    for name in names:
        if sides[name]["missing"]:
            lines.append(f"  {name} lacks (not timed): {', '.join(sides[name]['missing'])}")
    return lines


def run_side(source: Path, argv: list[str]) -> dict[str, Any]:
    """This script's ``--json`` figures run on the code in ``source``, in a fresh process."""
    environment = {**os.environ, "PYTHONPATH": str(source)}
    done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--json", *argv], capture_output=True,
                          text=True, env=environment, cwd=source, check=False)
    if done.returncode:
        raise SystemExit(f"bench_stages: the run on {source} failed: {done.stderr.strip().splitlines()[-1:]}")
    return json.loads(done.stdout.splitlines()[-1])


def extract(ref: str, folder: Path) -> Path:
    """Commit ``ref``'s tree extracted into ``folder``."""
    archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], capture_output=True,
                             check=True).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(folder, filter="tar")
    return folder


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--frames", type=int, help="frames per drive (default: cold-eval's)")
    parser.add_argument("--repeat", type=int, default=2, help="passes over the drives per side")
    parser.add_argument("--sensors", default="ideal,camera", help="comma-separated sensor profiles")
    parser.add_argument("--cpu", action="store_true", help="time with the process CPU clock")
    parser.add_argument("--baseline-ref", default=DEFAULT_BASELINE_REF, help="the commit to compare with")
    parser.add_argument("--no-baseline", action="store_true", help="this checkout only")
    parser.add_argument("--json", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if not args.map.is_file():
        raise SystemExit(f"bench_stages: {args.map}: no such map")
    if args.repeat < 1:
        raise SystemExit("bench_stages: --repeat must be >= 1")
    sensors = [s for s in args.sensors.split(",") if s]
    if args.json:
        print(json.dumps(measure(args.map.resolve(), sensors[0], args.frames, args.repeat, args.cpu)))
        return 0
    forwarded = ["--map", str(args.map.resolve()), "--repeat", str(args.repeat), *(["--cpu"] if args.cpu else []),
                 *(["--frames", str(args.frames)] if args.frames else [])]
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="bench-stages-ref-") as folder:
        baseline = None if args.no_baseline else extract(args.baseline_ref, Path(folder))
        print(f"{args.map.name}: {'CPU' if args.cpu else 'wall'} clock, this tree"
              + ("" if baseline is None else f" beside {args.baseline_ref}") + ", one process per side", flush=True)
        for sensor in sensors:
            sides = {"current": run_side(ROOT, [*forwarded, "--sensors", sensor])}
            if baseline is not None:
                sides[args.baseline_ref] = run_side(baseline, [*forwarded, "--sensors", sensor])
            print("\n".join(table(sensor, sides)), flush=True)
    print(f"load average before {load_before:.2f}, after {os.getloadavg()[0]:.2f} ({os.cpu_count()} cores)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
