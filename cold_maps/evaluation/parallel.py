"""Work units in worker processes: one drive (route) of one map per unit.

A worker evaluates its unit into a fresh :class:`Collector` and records the MCAP writes in
a :class:`CallLog` instead of writing them; the parent merges the collectors and replays
the writes into the one ``Recorder`` in unit order, so ``metrics.json``, ``frames.csv``
and ``run.mcap`` hold the same records in the same (frame) order as a run in one process.
Workers ignore SIGINT: on Ctrl-C the parent keeps the units that finished, terminates the
workers and writes partial outputs as a one-process run does.
"""

from __future__ import annotations

import os
import signal
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Final, Iterator, Sequence

from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.scenarios import MapPlan

if TYPE_CHECKING:
    from cold_maps.network.lane_graph import LaneGraph
    from gt_matching import GroundTruth

START_METHOD: Final[str] = "spawn"
"""Worker processes start fresh (no fork of a parent holding threads and Lanelet2 maps)."""
CACHED_MAPS: Final[int] = 4
"""Maps (lane graph and ground truth) a worker keeps loaded between units."""


def default_workers() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _ignore_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def process_pool(workers: int) -> Iterator[Executor]:
    """``workers`` worker processes; on any exception (Ctrl-C included) pending units are
    cancelled and the workers terminated before it propagates."""
    executor = ProcessPoolExecutor(max_workers=workers, mp_context=get_context(START_METHOD),
                                   initializer=_ignore_sigint)
    try:
        yield executor
    except BaseException:
        processes = list((getattr(executor, "_processes", None) or {}).values())
        executor.shutdown(wait=False, cancel_futures=True)
        for process in processes:
            process.terminate()
        raise
    executor.shutdown()


class CallLog:
    """Stands in for the ``Recorder`` in a worker: keeps every ``write_*`` call in order
    to :meth:`replay` into the real recorder in the parent."""

    def __init__(self) -> None:
        self.calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []

    def __getattr__(self, name: str) -> Callable[..., None]:
        if not name.startswith("write_"):
            raise AttributeError(name)

        def record(*args: Any, **kwargs: Any) -> None:
            self.calls.append((name, args, kwargs))

        return record

    def replay(self, recorder: Any) -> None:
        """Makes the recorded calls on ``recorder``, in order."""
        for name, args, kwargs in self.calls:
            getattr(recorder, name)(*args, **kwargs)


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


@dataclass(frozen=True)
class WorkUnit:
    """One drive of one map.

    Fields:
        plan: the map's plan (the worker rebuilds the same drives from its seed).
        drive: index of the drive in the plan's evaluator.
        frame_offset: global index of the drive's first frame.
        frames: frames of the drive.
    """

    plan: MapPlan
    drive: int
    frame_offset: int
    frames: int


@dataclass(frozen=True)
class UnitResult:
    """What a worker measured for a unit.

    Fields:
        collector: the unit's records, runtimes and overlays.
        log: its MCAP writes, in order.
    """

    collector: Collector
    log: CallLog


def run_unit(unit: WorkUnit, *, record: bool) -> UnitResult:
    """Evaluates ``unit`` (in a worker); ``record``: keep its MCAP writes."""
    collector, log = Collector(), CallLog()
    cached_evaluator(unit.plan).run_drive(unit.drive, collector, recorder=log if record else None,
                                          frame_offset=unit.frame_offset)
    return UnitResult(collector, log)


def work_units(evaluators: Sequence[MapEvaluator]) -> list[WorkUnit]:
    """Every drive of every evaluator, global frame indices continuing across them."""
    units, offset = [], 0
    for evaluator in evaluators:
        for index, drive in enumerate(evaluator.drives):
            units.append(WorkUnit(evaluator.plan, index, offset, drive.frames))
            offset += drive.frames
    return units


def run_units(evaluators: Sequence[MapEvaluator], collector: Collector, recorder: Any,
              on_frames: Callable[[int], None], executor: Executor) -> None:
    """Runs every drive of ``evaluators`` as a unit on ``executor`` and merges the results
    into ``collector`` and ``recorder`` in unit order (the notes as :meth:`MapEvaluator.run`
    writes them); on an exception the units finished so far are merged, then it propagates."""
    units = work_units(evaluators)
    owners = [evaluator for evaluator in evaluators for _ in evaluator.drives]
    futures: dict[Future[UnitResult], int] = {
        executor.submit(run_unit, unit, record=recorder is not None): n for n, unit in enumerate(units)}
    finished: dict[int, UnitResult] = {}

    def merge(n: int) -> None:
        unit, result, evaluator = units[n], finished.pop(n), owners[n]
        if unit.drive == 0:
            evaluator.note_drives(collector)
        collector.merge(result.collector)
        if recorder is not None:
            result.log.replay(recorder)
        if unit.drive == len(evaluator.drives) - 1:
            evaluator.note_unmatched(collector)

    merged = 0
    try:
        for future in as_completed(futures):
            n = futures[future]
            finished[n] = future.result()
            on_frames(units[n].frames)
            while merged in finished:
                merge(merged)
                merged += 1
    finally:
        for n in sorted(finished):
            merge(n)
