"""Work units in worker processes: the drives (routes) of the maps, each cut into frame
ranges when its frames are independent (:attr:`MapEvaluator.frames_independent`).

A worker evaluates a unit into a fresh :class:`Collector` that streams its records into
the parent collector's spool folder (segment files, :mod:`cold_maps.evaluation.records`)
and a detached ``Recorder`` (the MCAP messages encoded there); the parent merges the
collectors (adopting the segments: what comes back is their names, the records not yet in a
segment as one Arrow batch, the unit's counters, check runtimes and overlays) and writes the
messages in unit order, so ``metrics.json``, ``frames.csv`` and ``run.mcap`` hold the same
records in the same (frame) order as a run in one process. After the evaluation the plots
are drawn in worker processes too (:func:`plot_pool`).

On Linux the run's workers are forked from the parent once it has prepared the maps: they
start with its evaluators (lane graphs, ground truth, drives) instead of importing and
loading everything again, and the fork happens before the recording and the progress bar
start threads. Elsewhere they are spawned and load each map once (:func:`cached_evaluator`).
Workers ignore SIGINT: on Ctrl-C the parent keeps the units that finished, terminates the
workers and writes partial outputs as a one-process run does.
"""

from __future__ import annotations

import importlib
import math
import os
import signal
import sys
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from itertools import pairwise
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Final, Iterator, Sequence

from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.records import Spool
from cold_maps.evaluation.scenarios import MapPlan

if TYPE_CHECKING:
    from cold_maps.network.lane_graph import LaneGraph
    from cold_maps.recording.recorder import EncodedMessage, Recorder
    from gt_matching import GroundTruth

START_METHOD: Final[str] = "spawn"
"""Workers of :func:`process_pool` start fresh (no fork of a parent holding threads)."""
RUN_START_METHOD: Final[str] = "fork" if sys.platform.startswith("linux") else "spawn"
"""Workers of :func:`run_pool`: forked on Linux (module docstring)."""
CACHED_MAPS: Final[int] = 4
"""Maps (lane graph and ground truth) a worker keeps loaded between units."""
UNITS_PER_WORKER: Final[int] = 6
"""Work units per worker a run aims at (drives cut into frame ranges), so that the workers
finish together."""
MIN_UNIT_FRAMES: Final[int] = 10
"""Frames of a drive's range below which it is not cut further."""
MAX_UNIT_FRAMES: Final[int] = 1000
"""Frames of a drive's range above which it is cut further when it can be: what a unit hands
back (its MCAP messages, held until the parent writes them) does not grow with the drive."""
TERMINATE_WAIT_S: Final[float] = 5.0
"""How long :func:`terminate` waits for each terminated worker to exit [s]."""


def default_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _ignore_sigint() -> None:
    """Worker set-up: Ctrl-C is the parent's to handle; SIGTERM ends the worker silently
    (not the parent's handler, inherited by fork, that raises in the worker)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)


def terminate(executor: Executor) -> None:
    """Cancels the pending work of a :class:`ProcessPoolExecutor` and terminates its workers
    (waits until they have exited: nothing they were writing changes after)."""
    processes = list((getattr(executor, "_processes", None) or {}).values())
    executor.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(TERMINATE_WAIT_S)


@contextmanager
def process_pool(workers: int, start_method: str = START_METHOD,
                 initializer: Callable[..., None] = _ignore_sigint, initargs: tuple[Any, ...] = ()) -> Iterator[Executor]:
    """``workers`` worker processes (``initializer(*initargs)`` in each, which must ignore
    SIGINT); on any exception (Ctrl-C included) pending units are cancelled and the
    workers terminated before it propagates."""
    executor = ProcessPoolExecutor(max_workers=workers, mp_context=get_context(start_method),
                                   initializer=initializer, initargs=initargs)
    try:
        yield executor
    except BaseException:
        terminate(executor)
        raise
    executor.shutdown()


_MAPS: dict[tuple[Path, int, int], tuple[LaneGraph, GroundTruth]] = {}


def cached_evaluator(plan: MapPlan) -> MapEvaluator:
    """An evaluator of ``plan`` with its map's lane graph and ground truth loaded once per
    worker process (keyed by path, size and modification time)."""
    stat = plan.path.stat()
    key = (plan.path.resolve(), stat.st_size, stat.st_mtime_ns)
    if key not in _MAPS:
        while len(_MAPS) >= CACHED_MAPS:
            del _MAPS[next(iter(_MAPS))]
        evaluator = MapEvaluator(plan)
        evaluator.prepare()
        assert evaluator.meter is not None
        _MAPS[key] = (evaluator.graph, evaluator.meter.ground_truth)
        return evaluator
    graph, ground_truth = _MAPS[key]
    return MapEvaluator(plan, graph=graph, ground_truth=ground_truth)


_EVALUATORS: dict[int, MapEvaluator] = {}
"""The run's evaluators by map index: in a forked worker the parent's (prepared, no drive
run yet), in a spawned one built from :data:`_PLANS` at its first unit of the map."""
_PLANS: tuple[MapPlan, ...] = ()


def _start_worker(plans: tuple[MapPlan, ...]) -> None:
    global _PLANS
    _ignore_sigint()
    _PLANS = plans


def _evaluator(map_index: int) -> MapEvaluator:
    if map_index not in _EVALUATORS:
        _EVALUATORS[map_index] = cached_evaluator(_PLANS[map_index])
    return _EVALUATORS[map_index]


@contextmanager
def run_pool(evaluators: Sequence[MapEvaluator], workers: int) -> Iterator[Executor]:
    """The worker processes of a run over ``evaluators`` (prepared; module docstring); the
    workers start at the first :func:`submit_units`."""
    forked = RUN_START_METHOD == "fork"
    if forked:
        # the workers hand back their records encoded (RecordStore pickles them as Arrow):
        # pyarrow imported once here instead of in each of them
        importlib.import_module("pyarrow")

        _EVALUATORS.update(enumerate(evaluators))
    plans = () if forked else tuple(e.plan for e in evaluators)
    try:
        with process_pool(workers, RUN_START_METHOD, _start_worker, (plans,)) as executor:
            yield executor
    finally:
        _EVALUATORS.clear()


def prepare_plots(executor: Executor, workers: int) -> None:
    """Has matplotlib imported for the plots of a run whose units ``executor`` (its
    ``workers``) runs: on Linux here, while the units run (:func:`plot_pool` forks the
    plot workers from this process), elsewhere in each worker once it has no unit left."""
    from cold_maps.evaluation.plots import preload

    if RUN_START_METHOD == "fork":
        preload()
        return
    for _ in range(workers):
        executor.submit(preload)


@contextmanager
def plot_pool(run: Executor, workers: int) -> Iterator[Executor]:
    """The workers that draw a run's plots once its units are merged: on Linux ``workers``
    processes forked from this one after ``run``'s workers have exited (they start with
    the matplotlib of :func:`prepare_plots`: one import instead of one per worker; with
    ``run``'s threads joined and the recording and progress bar closed, this process has
    no other thread then), elsewhere ``run``'s own workers."""
    if RUN_START_METHOD != "fork":
        yield run
        return
    run.shutdown()
    with process_pool(workers, RUN_START_METHOD) as executor:
        yield executor


@dataclass(frozen=True)
class WorkUnit:
    """Frames of one drive of one map.

    Fields:
        map_index: the map's evaluator in the run.
        drive: index of the drive in it.
        first, stop: the drive's frames ``range(first, stop)``.
        frame_offset: global index of the drive's frame 0.
    """

    map_index: int
    drive: int
    first: int
    stop: int
    frame_offset: int


@dataclass(frozen=True)
class UnitResult:
    """What a worker measured for a unit.

    Fields:
        collector: the unit's records, runtimes and overlays.
        messages: its MCAP messages, encoded, in order.
    """

    collector: Collector
    messages: list[EncodedMessage]


def run_unit(unit: WorkUnit, recording: Callable[[], Recorder] | None, spool: Path | None = None) -> UnitResult:
    """Evaluates ``unit`` (in a worker); ``recording`` makes its detached ``Recorder``
    (picklable, e.g. a ``functools.partial`` of ``Recorder.detached``), None when nothing is
    recorded; the records are spooled into the folder ``spool`` (None: a temporary one)."""
    collector = Collector(spool=Spool(spool))
    recorder = None if recording is None else recording()
    _evaluator(unit.map_index).run_drive(unit.drive, collector, recorder=recorder, frame_offset=unit.frame_offset,
                                         frames=range(unit.first, unit.stop))
    return UnitResult(collector, [] if recorder is None else recorder.take())


def _most_pieces(evaluator: MapEvaluator, frames: int) -> int:
    """How many frame ranges a drive of ``frames`` frames of ``evaluator`` may be cut into."""
    return max(frames // MIN_UNIT_FRAMES, 1) if evaluator.frames_independent else 1


def most_units(evaluators: Sequence[MapEvaluator]) -> int:
    """The most work units the drives of ``evaluators`` can be cut into (no use for more workers)."""
    return sum(_most_pieces(e, drive.frames) for e in evaluators for drive in e.drives)


def work_units(evaluators: Sequence[MapEvaluator], workers: int) -> list[WorkUnit]:
    """Every drive of every evaluator, global frame indices continuing across them; a drive
    with independent frames cut into ranges (about :data:`UNITS_PER_WORKER` units per
    worker over the run, none shorter than :data:`MIN_UNIT_FRAMES` frames, none longer than
    :data:`MAX_UNIT_FRAMES` when that many can be cut)."""
    drives = sum(len(e.drives) for e in evaluators)
    pieces = math.ceil(UNITS_PER_WORKER * workers / max(drives, 1))
    units, offset = [], 0
    for map_index, evaluator in enumerate(evaluators):
        for index, drive in enumerate(evaluator.drives):
            count = min(max(pieces, math.ceil(drive.frames / MAX_UNIT_FRAMES)), _most_pieces(evaluator, drive.frames))
            bounds = [round(k * drive.frames / count) for k in range(count + 1)]
            units.extend(WorkUnit(map_index, index, first, stop, offset) for first, stop in pairwise(bounds))
            offset += drive.frames
    return units


@dataclass(frozen=True)
class SubmittedUnits:
    """The units of a run on its pool.

    Fields:
        evaluators: the run's evaluators.
        units: the units, in frame order.
        futures: their results by unit number.
    """

    evaluators: Sequence[MapEvaluator]
    units: list[WorkUnit]
    futures: dict[Future[UnitResult], int]


def submit_units(executor: Executor, evaluators: Sequence[MapEvaluator], workers: int,
                 recording: Callable[[], Recorder] | None, spool: Path | None = None) -> SubmittedUnits:
    """Starts every unit of ``evaluators`` on ``executor`` (the first submission starts the
    workers); ``recording`` and ``spool`` (the parent collector's folder) as in :func:`run_unit`."""
    units = work_units(evaluators, workers)
    return SubmittedUnits(evaluators, units,
                          {executor.submit(run_unit, unit, recording, spool): n for n, unit in enumerate(units)})


def merge_units(submitted: SubmittedUnits, collector: Collector, recorder: Any,
                on_frames: Callable[[int], None]) -> None:
    """Merges the results into ``collector`` and ``recorder`` in unit order as they come
    (the notes as :meth:`MapEvaluator.run` writes them); on an exception the units finished
    so far are merged, then it propagates."""
    units, futures = submitted.units, submitted.futures
    finished: dict[int, UnitResult] = {}

    def merge(n: int) -> None:
        unit, result = units[n], finished.pop(n)
        evaluator = submitted.evaluators[unit.map_index]
        if unit.drive == 0 and unit.first == 0:
            evaluator.note_drives(collector)
        collector.merge(result.collector)
        if recorder is not None:
            recorder.log(result.messages)
        if unit.drive == len(evaluator.drives) - 1 and unit.stop == evaluator.drives[unit.drive].frames:
            evaluator.note_unmatched(collector)

    merged = 0
    try:
        for future in as_completed(futures):
            n = futures[future]
            finished[n] = future.result()
            on_frames(units[n].stop - units[n].first)
            while merged in finished:
                merge(merged)
                merged += 1
    finally:
        for n in sorted(finished):
            merge(n)
