"""A ``cold-eval`` run: evaluators for the maps, the MCAP recording, the progress bar and
the output folder (``summary.md``, ``metrics.json``, ``frames.csv``, ``frames.parquet``, ``plots/*.png``,
``run.mcap``).

Everything that can fail on bad input (maps, routes, ground truth, the output folder) is
checked before the first output file is opened. An interrupted or crashed run still
finalises the MCAP (marked ``partial``) and writes the report marked partial; an
interruption while the report is written rewrites it as partial without plots, and one
after it is written (while the workers shut down) is dropped: the report stands complete.
"""

from __future__ import annotations

import functools
import glob
import logging
import os
import re
import tempfile
import time
from concurrent.futures import Executor
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Final, Iterator, Sequence, TextIO

import numpy as np

from cold_maps.common.memory import release_free_heap
from cold_maps.common.progress import ProgressBar
from cold_maps.common.provenance import Provenance
from cold_maps.common.signals import signals_ignored
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.records import PointPool, Spool, list_values
from cold_maps.evaluation.report import (
    ScenarioAccumulator,
    ScenarioResult,
    atomic_write_text,
    flags,
    scenario_label,
    scenario_results,
    summary_markdown,
    write_frames,
    write_metrics_json,
)
from cold_maps.evaluation.scenarios import MapPlan
from cold_maps.evaluation.trust import run_warnings

if TYPE_CHECKING:
    from cold_maps.recording.recorder import Recorder

LOG = logging.getLogger("cold_maps.evaluation.run")

MCAP_NAME: Final[str] = "run.mcap"
PLOTS_DIR: Final[str] = "plots"


class OutputError(Exception):
    """An output folder that cannot be created or written; the message names it."""


def prepare_out_dir(path: str | os.PathLike[str]) -> Path:
    """Creates ``path`` if needed and checks that files can be written into it."""
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise OutputError(f"{out}: output folder cannot be written: {exc.strerror or exc}") from exc
    return out


def _missing_folders(path: Path) -> list[Path]:
    """``path`` and its parents that do not exist yet, innermost first."""
    missing = []
    while not path.exists() and path != path.parent:
        missing.append(path)
        path = path.parent
    return missing


def _file_part(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text)


def plot_jobs(out: Path, collector: Collector) -> Iterator[functools.partial[None]]:
    """The plots of a run, each a call drawing one PNG into ``out/plots`` (created) from
    the data it needs (picklable, for a worker process), made one at a time: per map and
    scenario the overlay of its worst frame (Fig. 8, the frame of the scenario's max error
    over all its pairs; first, as they need no pass over the records) and the error per frame
    of its own coop (Fig. 7), routes marked; per map and spline kind (gap, vehicles) with more
    than one method, the methods' errors on one axis; per map, when the run records vehicle
    counts, the max error against the perception range of every fusion; per map, when its
    lanes state σ, the reliability of that σ."""
    from cold_maps.evaluation.plots import (
        ErrorSeries,
        plot_error_series,
        plot_error_vs_range,
        plot_frame_overlay,
        plot_reliability,
        range_points,
        reliability_points,
    )

    folder = out / PLOTS_DIR
    folder.mkdir(exist_ok=True)
    for (map_name, label), overlay in collector.overlays.items():
        path = folder / f"overlay_{_file_part(map_name)}_{_file_part(label)}.png"
        yield functools.partial(
            plot_frame_overlay, path, gt=overlay.gt, detections=overlay.detections, fused=overlay.fused,
            title=f"{map_name}: {label}, frame {overlay.frame}, {' + '.join(overlay.detections)} "
                  f"(max error {overlay.max_error_m:.3f} m)")
    groups: dict[tuple[str, str], list[ScenarioAccumulator]] = {}
    for key, accumulator in collector.accumulators.items():
        groups.setdefault((key.map, key.label), []).append(accumulator)
    methods: dict[tuple[str, str], dict[str, list[ScenarioAccumulator]]] = {}
    for (map_name, label), accumulators in groups.items():
        series = [ErrorSeries.pooled(f"{a.key.fusion} {a.key.boundary}", [a], own_only=True) for a in accumulators]
        if not any(np.isfinite(line.means).any() for line in series):
            continue
        path = folder / f"errors_{_file_part(map_name)}_{_file_part(label)}.png"
        yield functools.partial(plot_error_series, path, series, title=f"{map_name}: {label}, error per frame (own coop)",
                                route_starts=collector.route_starts(map_name))
        key = accumulators[0].key
        if key.fusion == "spline":
            kind = scenario_label(key.fusion, "", key.d_s, key.vehicles).replace("spline--", "spline-")
            methods.setdefault((map_name, kind), {})[key.interpolation] = accumulators
    for (map_name, kind), by_method in methods.items():
        if len(by_method) < 2:
            continue
        path = folder / f"methods_{_file_part(map_name)}_{_file_part(kind)}.png"
        yield functools.partial(
            plot_error_series, path, [ErrorSeries.pooled(method, a, own_only=True) for method, a in by_method.items()],
            title=f"{map_name}: {kind}, methods, error per frame (own coop, both borders)",
            route_starts=collector.route_starts(map_name))
    extended: dict[str, list[ScenarioAccumulator]] = {}
    for key, accumulator in collector.accumulators.items():
        if key.vehicles > 1 and any(np.diff(list_values(batch.column(0))[1]).any()
                                    for batch in accumulator.records.batches(("errors_m",))):
            extended.setdefault(key.map, []).append(accumulator)
    for map_name, accumulators in extended.items():
        path = folder / f"error_vs_range_{_file_part(map_name)}.png"
        yield functools.partial(plot_error_vs_range, path, range_points(accumulators),
                                title=f"{map_name}: max error against perception range")
    by_map: dict[str, list[ScenarioAccumulator]] = {}
    for key, accumulator in collector.accumulators.items():
        by_map.setdefault(key.map, []).append(accumulator)
    for map_name, accumulators in by_map.items():
        curves = reliability_points(accumulators)
        if curves:
            path = folder / f"reliability_{_file_part(map_name)}.png"
            yield functools.partial(plot_reliability, path, curves,
                                    title=f"{map_name}: reliability of the stated σ")


def start_plots(out: Path, collector: Collector, executor: Executor | None) -> Callable[[], list[Path]]:
    """Starts drawing the :func:`plot_jobs` of a run on ``executor``'s workers, each as soon
    as its data is made; returns the call that waits for them (without an executor: that
    draws them here) and returns the files."""
    jobs = []
    drawing = []
    for job in plot_jobs(out, collector):
        jobs.append(job)
        if executor is not None:
            drawing.append(executor.submit(job))

    def finish() -> list[Path]:
        for job in jobs if executor is None else ():
            job()
        for future in drawing:
            future.result()
        return [job.args[0] for job in jobs]

    return finish


def write_plots(out: Path, collector: Collector) -> list[Path]:
    """Draws the :func:`plot_jobs` of a run here; returns the files."""
    return start_plots(out, collector, None)()


NO_FUSIONS: Final[str] = "None: no pair was fused.\n"
"""Body of a summary section that tabulates fused pairs when there are none."""


UNKNOWN_RELATIONS: Final[str] = ("Not determined: {fused} fused pairs, none with a known true lane relation "
                                  "(a recording carries none; cold-eval takes it from the drives' lane graph).\n")
"""Body of the false-fusion section when pairs were fused but none can be judged."""


def _judged_fusions(accumulator: ScenarioAccumulator, spool: Spool) -> tuple[int, int, PointPool]:
    """Of a scenario's fused records with a known true relation: how many, how many false,
    and the pooled errors of the correct ones (close the pool after use)."""
    fused = wrong = 0
    right = PointPool(spool)
    for batch in accumulator.records.batches(("errors_m", "truly_fusible")):
        values, offsets = list_values(batch.column("errors_m"))
        lengths = np.diff(offsets)
        column = batch.column("truly_fusible")
        known, truly = flags(column)
        judged = (lengths > 0) & known
        fused += int(np.count_nonzero(judged))
        wrong += int(np.count_nonzero(judged & ~truly))
        right.append(values[offsets[0]:offsets[-1]][np.repeat(judged & truly, lengths)])
    return fused, wrong, right


def false_fusion_markdown(collector: Collector) -> str:
    """Per scenario with fusibility decisions (a vehicles column when chains run): the fusions
    of pairs that are not on one lane (their errors are in the main table) and the errors of
    the correct fusions alone;
    :data:`UNKNOWN_RELATIONS` when pairs were fused but none has a known true relation; ""
    when no pair was fused."""
    rows = []
    fused_pairs = sum(int(np.count_nonzero(np.diff(list_values(batch.column(0))[1]) > 0))
                      for key, accumulator in collector.accumulators.items()  # a pair fuses both borders
                      if key.fusion != "local" and key.boundary == "left"
                      for batch in accumulator.records.batches(("errors_m",)))
    chains = any(key.vehicles > 0 for key in collector.accumulators)
    for key, accumulator in collector.accumulators.items():
        fused, wrong, errors = _judged_fusions(accumulator, collector.spool)
        if fused:
            stats = f"{errors.mean():.3f} | {errors.max():.3f}" if errors.size else "– | –"
            vehicles = f"{key.vehicles} | " if chains else ""
            rows.append(f"| {key.map} | {key.fusion} | {key.interpolation or '–'} | {key.d_s:g} | {vehicles}"
                        f"{key.boundary} | {fused} | {wrong} | {stats} |")
        errors.close()
    if not rows:
        return UNKNOWN_RELATIONS.format(fused=fused_pairs) if fused_pairs else ""
    return ("Fused pairs whose vehicles are not on one lane (true lane relation from the lane graph) count as "
            "false fusions; their errors are included in the table above. The last two columns pool the "
            "correct fusions only.\n\n| map | fusion | interp. | d_s [m] | " + ("vehicles | " if chains else "")
            + "boundary | fused | false fusions | mean [m] | max [m] |\n|---|---|---|---|" + ("---|" if chains else "")
            + "---|---|---|---|---|\n" + "\n".join(rows) + "\n")


def write_outputs(out: Path, collector: Collector, *, partial: bool, sections: Sequence[tuple[str, str]] = (),
                  plots: bool = True, results: Sequence[ScenarioResult] | None = None,
                  program: str = "cold-eval", provenance: Provenance | None = None) -> list[ScenarioResult]:
    """``frames.csv`` and ``frames.parquet``, ``summary.md`` of the command ``program`` (how it was made:
    ``provenance``, the per-scenario table, notes, then ``sections``: (title, markdown)),
    ``metrics.json`` (with the same ``provenance``) and the plots; returns the scenario
    results (``results``: the collector's, when the caller has them already)."""
    accumulators = list(collector.accumulators.values())
    results = scenario_results(accumulators) if results is None else list(results)
    write_frames(out / "frames.csv", out / "frames.parquet", accumulators)
    text = summary_markdown(results, partial=partial, warnings=run_warnings(collector), program=program,
                            provenance=provenance, check_ms=collector.check_ms)
    if collector.notes:
        text += "\n## Drives\n\n" + "".join(f"- {note}\n" for note in collector.notes)
    sections = [*sections, ("False fusions", false_fusion_markdown(collector))]
    for title, body in sections:
        text += f"\n## {title}\n\n{body or NO_FUSIONS}"
    atomic_write_text(out / "summary.md", text)
    write_metrics_json(out / "metrics.json", results, partial=partial, provenance=provenance)
    if plots and not partial:
        write_plots(out, collector)
    return results


@dataclass(frozen=True)
class RunOptions:
    """How to run and what to write.

    Fields:
        out: the output folder.
        mcap: write ``run.mcap``.
        plots: write the PNG plots.
        progress: stream of the progress bar (drawn only on a TTY).
        provenance: how the run was made (command line, version, maps and their sha256,
            every parameter): its ``params`` go into the MCAP ``cold.run`` metadata, the whole
            block to the top of ``summary.md`` and into ``metrics.json``.
        workers: processes evaluating the drives (work units) in parallel; 1 runs them
            in this process. The outputs are the same for any number.
        stamp_base_ns: MCAP log time of frame 0 (ns since the Unix epoch); None: the
            recording's wall-clock start.
        osi: the OSI trace of the detections to write (:mod:`cold_maps.recording.osi`),
            or None.
    """

    out: Path
    mcap: bool = True
    plots: bool = True
    progress: TextIO | None = None
    provenance: Provenance | None = None
    workers: int = 1
    stamp_base_ns: int | None = None
    osi: Path | None = None


@dataclass(frozen=True)
class RunResult:
    """What a run did.

    Fields:
        results: the scenario results written to ``metrics.json``.
        collector: everything measured.
        partial: True when interrupted or crashed.
        error: the exception that ended it early, or None.
    """

    results: list[ScenarioResult]
    collector: Collector
    partial: bool
    error: BaseException | None


def run_evaluation(plans: Sequence[MapPlan], options: RunOptions, *,
                   extra_sections: Callable[[Collector, list[ScenarioResult]], list[tuple[str, str]]] | None = None,
                   ) -> RunResult:
    """Prepares every map (routes, ground truth), then evaluates them all into one MCAP and
    one report. ``extra_sections(collector, results)`` returns more (title, markdown)
    summary sections. Bad input raises before any output file is opened (and removes the
    output folder again when it created it); an exception
    during the run (Ctrl-C included) ends it with partial outputs, returned in the result."""
    created = _missing_folders(Path(options.out))
    out = prepare_out_dir(options.out)
    try:
        if options.osi is not None:
            created[:0] = _missing_folders(options.osi.parent)
            prepare_out_dir(options.osi.parent)
        evaluators = _prepared(plans)
    except BaseException:
        for folder in created:
            if any(folder.iterdir()):
                break
            folder.rmdir()
        raise
    collector = Collector()
    error: BaseException | None = None
    workers = 1
    # once the run ends early, and once its report is written, Ctrl-C and SIGTERM are held
    # (``held`` closes last, after the workers are shut down): a second signal (``timeout``
    # sends two, a user presses twice) must not cut the partial report short, and one after
    # the report would claim a complete report is missing
    with ExitStack() as held, ExitStack() as stack:
        executor: Executor | None = None
        if options.workers > 1:
            from cold_maps.evaluation.parallel import most_units, run_pool

            workers = min(options.workers, most_units(evaluators))
            if workers > 1:
                executor = stack.enter_context(run_pool(evaluators, workers))
        try:
            _run_all(plans, evaluators, collector, options, executor, workers)
        except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - any crash must still leave partial outputs
            held.enter_context(signals_ignored())
            error = exc
            LOG.debug("run ended early", exc_info=True)
            _stop(executor)
            executor = None
        evaluators.clear()  # the report reads the collector alone: the drives and ground truths go first
        release_free_heap()
        try:
            if executor is not None and options.plots:
                from cold_maps.evaluation.parallel import plot_pool

                executor = stack.enter_context(plot_pool(executor, workers))
            results = _write_report(out, collector, options.plots and error is None, executor, extra_sections,
                                    partial=error is not None, provenance=options.provenance)
        except KeyboardInterrupt as exc:  # while writing a complete report: rewritten as partial, without plots
            held.enter_context(signals_ignored())
            error = exc
            LOG.debug("interrupted while writing the report", exc_info=True)
            _stop(executor)
            executor = None
            _discard_plots(out, collector)
            results = _write_report(out, collector, False, None, extra_sections, partial=True,
                                    provenance=options.provenance)
        if error is None:
            held.enter_context(signals_ignored())
    return RunResult(results, collector, error is not None, error)


def _prepared(plans: Sequence[MapPlan]) -> list[MapEvaluator]:
    """An evaluator per plan, its ground truth loaded (a function: no loop variable of the
    run keeps one alive once the run drops them)."""
    evaluators = [MapEvaluator(plan) for plan in plans]
    for evaluator in evaluators:
        LOG.info("%s: preparing ground truth", evaluator.plan.path)
        evaluator.prepare()
        if LOG.isEnabledFor(logging.DEBUG):  # the check costs a pass over the driven lanes: once, in note_drives
            LOG.debug("%s: %s", evaluator.plan.name, evaluator.gt_warning or "ground truth trustworthy on the drives")
    return evaluators


def _stop(executor: Executor | None) -> None:
    """Terminates ``executor``'s workers, if any (their pending work is dropped)."""
    if executor is not None:
        from cold_maps.evaluation.parallel import terminate

        terminate(executor)


def _write_report(out: Path, collector: Collector, plots: bool, executor: Executor | None,
                  extra_sections: Callable[[Collector, list[ScenarioResult]], list[tuple[str, str]]] | None, *,
                  partial: bool, provenance: Provenance | None) -> list[ScenarioResult]:
    """The report of a run (:func:`write_outputs`), the plots (when ``plots``) drawn on
    ``executor``'s workers meanwhile; returns the scenario results."""
    plotted = start_plots(out, collector, executor) if plots else None
    results = scenario_results(collector.accumulators.values())
    sections = list(extra_sections(collector, results)) if extra_sections is not None else []
    results = write_outputs(out, collector, partial=partial, sections=sections, plots=False, results=results,
                            provenance=provenance)
    if plotted is not None:
        plotted()
    return results


def _discard_plots(out: Path, collector: Collector) -> None:
    """Removes the plot files of this run (complete or not) from ``out/plots``, and the folder
    when nothing else is left in it: a partial report has no plots."""
    folder = out / PLOTS_DIR
    if not folder.is_dir():
        return
    for job in plot_jobs(out, collector):
        path = job.args[0]
        for written in (path, *folder.glob(f".{glob.escape(path.name)}.*.part")):  # a terminated worker's
            written.unlink(missing_ok=True)
    if not any(folder.iterdir()):
        folder.rmdir()


def _map_names(plans: Sequence[MapPlan]) -> str:
    """The maps of a run as the recordings name them: their paths, comma-separated."""
    return ", ".join(str(p.path) for p in plans)


def _detached_recording(plans: Sequence[MapPlan], options: RunOptions,
                        stamp_base_ns: int) -> Callable[[], Recorder] | None:
    """What makes a worker's detached ``Recorder`` for the outputs of ``options`` (None
    when nothing is recorded)."""
    if not options.mcap and options.osi is None:
        return None
    from cold_maps.recording.recorder import Recorder

    return functools.partial(Recorder.detached, stamp_base_ns, mcap=options.mcap, osi=options.osi is not None,
                             map_path=_map_names(plans))


def _run_all(plans: Sequence[MapPlan], evaluators: Sequence[MapEvaluator], collector: Collector,
             options: RunOptions, executor: Executor | None, workers: int) -> None:
    """Evaluates every drive, on ``executor``'s workers if given, into ``collector`` and the
    recording. The workers start (fork) before the progress bar and the recording start
    threads; with plots, matplotlib is imported meanwhile
    (:func:`cold_maps.evaluation.parallel.prepare_plots`)."""
    stamp_base_ns = time.time_ns() if options.stamp_base_ns is None else options.stamp_base_ns
    submitted = None
    if executor is not None:
        from cold_maps.evaluation.parallel import submit_units

        submitted = submit_units(executor, evaluators, workers, _detached_recording(plans, options, stamp_base_ns),
                                 collector.spool.path)
        if options.plots:
            from cold_maps.evaluation.parallel import prepare_plots

            prepare_plots(executor, workers)
    with ExitStack() as stack:
        bar = stack.enter_context(ProgressBar(sum(e.total_frames for e in evaluators), "cold-eval",
                                              stream=options.progress))
        recorder = None
        if options.mcap or options.osi is not None:
            from cold_maps.recording.recorder import Recorder

            recorder = stack.enter_context(Recorder(Path(options.out) / MCAP_NAME if options.mcap else None,
                                                    map_path=_map_names(plans), params=options.provenance.params if options.provenance else None,
                                                    stamp_base_ns=stamp_base_ns, osi=options.osi))
        if submitted is not None:
            from cold_maps.evaluation.parallel import merge_units

            merge_units(submitted, collector, recorder, bar.update)
            return
        offset = 0
        for evaluator in evaluators:
            offset = evaluator.run(collector, recorder=recorder, frame_offset=offset, on_frame=bar.update)
