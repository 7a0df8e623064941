"""``cold-eval sweep``: a grid of evaluations (map × gap × method × sensor × error level ×
seed).

``cold-eval sweep --map MAP.xodr [--map ...] [--gaps D_S,...] [--interpolation NAME,...]
[--sensor SENSOR,...] [--noise SIGMA_M,...] [--pose-xy SIGMA_M,...] [--seeds SEED,...] [--frames N] --out DIR``
runs every cell (each combination of the lists) in ``--workers`` processes (default: the
cores) or, with ``--scheduler tcp://HOST:PORT``, on a Dask cluster (maps shipped to the
workers). Outputs in DIR: results.parquet, results.csv, summary.md, plots/*.png,
cells/*.json (one per finished cell: run the same command again after an interrupt and only
the missing cells are computed; an interrupt while the tables are written leaves
summary.md marked partial and no tables or plots). Exit 0; 1 with one line on stderr for
bad input or a failed cell; 2 for a bad command line; 130 when interrupted, 143 on SIGTERM.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Final, Sequence, TypeVar

from cold_maps.cli.common import builds, fusion_method, gap_list, int_in, make_parser, positive_int, validated
from cold_maps.simulation.drive import MAX_COVER_ROUTES, PAPER_GAPS_M
from cold_maps.simulation.sensor_errors import SensorErrorModel
from cold_maps.simulation.sensor_profile import IDEAL, SensorProfile

PROG: Final[str] = "cold-eval sweep"
UNRECORDED: Final[frozenset[str]] = frozenset({"workers", "scheduler", "verbose", "quiet", "no_progress"})
"""Options that change no result, left out of the provenance parameters."""
DEFAULT_FRAMES: Final[int] = 100
DEFAULT_ROUTES: Final[int] = 3

T = TypeVar("T")


def _list(kind: Callable[[str], T], what: str) -> Callable[[str], tuple[T, ...]]:
    def parse(text: str) -> tuple[T, ...]:
        try:
            values = tuple(kind(part.strip()) for part in text.split(",") if part.strip())
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected comma-separated {what}, got {text!r}") from None
        if not values:
            raise argparse.ArgumentTypeError(f"expected at least one of {what}, got {text!r}")
        return tuple(dict.fromkeys(values))

    return parse


def _levels(field: str) -> Callable[[str], tuple[float, ...]]:
    """argparse type: comma-separated values of a ``SensorErrorModel`` field, each one it accepts."""
    check = builds(SensorErrorModel, field)
    return validated(_list(float, "σ in m"), lambda values: [check(value) for value in values])


def _sensors(text: str) -> tuple[SensorProfile, ...]:
    """argparse type: comma-separated built-in sensor profile names or FILE.toml paths."""
    from cold_maps.simulation.sensor_profile import load_profile

    names = [part.strip() for part in dict.fromkeys(text.split(",")) if part.strip()]
    if not names:
        raise argparse.ArgumentTypeError(f"expected at least one sensor profile, got {text!r}")
    try:
        return tuple(load_profile(name) for name in names)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _seeds(text: str) -> tuple[int, ...]:
    values = _list(int, "integers")(text)
    if any(v < 0 for v in values):
        raise argparse.ArgumentTypeError(f"seeds must be >= 0, got {text!r}")
    return values


def build_parser() -> argparse.ArgumentParser:
    """The ``cold-eval sweep`` argument parser."""
    parser = make_parser(PROG, __doc__.split("\n\n")[1], progress=True)
    parser.add_argument("--map", action="append", type=Path, required=True, metavar="MAP.xodr",
                        help="OpenDRIVE map (repeatable)")
    parser.add_argument("--gaps", type=gap_list, default=PAPER_GAPS_M, metavar="D_S,...",
                        help="spline gaps d_s in m (default 20,30,50)")
    parser.add_argument("--interpolation", type=_list(fusion_method, "method names"), default=("paper", "hermite"),
                        metavar="NAME,...", help="spline methods: paper, hermite, registered names or "
                                                 "package.module:function (default paper,hermite)")
    parser.add_argument("--method", action="append", type=fusion_method, default=[], metavar="NAME",
                        help="another fusion method: registered name or package.module:function, looked up in the "
                             "installed packages and the current folder (repeatable; default: none)")
    parser.add_argument("--sensor", type=_sensors, default=(IDEAL,), metavar="SENSOR,...",
                        help="lane sensor profiles: ideal, camera, camera-highway or FILE.toml (see cold-eval "
                             "--help; default ideal)")
    parser.add_argument("--noise", type=_levels("noise_sigma_m"), default=(0.0,), metavar="SIGMA_M,...",
                        help="sensor noise σ levels in m (default 0: off)")
    parser.add_argument("--pose-xy", type=_levels("pose_sigma_xy_m"), default=(0.0,), metavar="SIGMA_M,...",
                        help="coop pose σ levels in m (default 0: off)")
    parser.add_argument("--seeds", type=_seeds, default=(0,), metavar="SEED,...", help="seeds (default 0)")
    parser.add_argument("--frames", type=positive_int, default=DEFAULT_FRAMES,
                        help=f"frames per route (default {DEFAULT_FRAMES})")
    parser.add_argument("--routes", type=int_in(1, MAX_COVER_ROUTES), default=DEFAULT_ROUTES,
                        help=f"routes per map and cell (default {DEFAULT_ROUTES})")
    parser.add_argument("--out", type=Path, required=True, help="output folder (finished cells are kept there)")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="worker processes (default: this machine's cores); ignored with --scheduler")
    parser.add_argument("--scheduler", metavar="tcp://HOST:PORT", default=None,
                        help="run the cells on this Dask scheduler's workers (default: none, local processes)")
    parser.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cold-eval sweep``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    from cold_maps.cli.common import (configure_logging, fail, interruption, progress_stream, result_line,
                                      startup_failure)
    from cold_maps.common.progress import ProgressBar
    from cold_maps.common.provenance import make_provenance, recorded_params
    from cold_maps.evaluation.parallel import default_workers, process_pool
    from cold_maps.evaluation.run import prepare_out_dir
    from cold_maps.evaluation.sweep import SweepSpec, dask_executor, run_sweep, write_tables
    from cold_maps.evaluation.sweep_report import write_report

    configure_logging(args.verbose, args.quiet)
    spec = SweepSpec(tuple(args.map), args.gaps, tuple(dict.fromkeys((*args.interpolation, *args.method))),
                     args.noise, args.pose_xy, args.seeds, args.frames, args.routes, args.sensor)
    try:
        cells = spec.cells()
        provenance = make_provenance(PROG, argv, recorded_params(vars(args), UNRECORDED),
                                     inputs=[("map", path) for path in args.map])
        out = prepare_out_dir(args.out)
        workers = min(args.workers or default_workers(), len(cells))
        executor = (dask_executor(args.scheduler) if args.scheduler
                    else process_pool(workers) if workers > 1 else None)
        with ProgressBar(len(cells), PROG, stream=progress_stream(args)) as bar:
            result = run_sweep(spec, out, executor=executor, ship_maps=args.scheduler is not None,
                               on_cells=bar.update, cells=cells)
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - every failure is reported as one line
        return startup_failure(PROG, exc)
    finished = result.computed + result.reused
    counts = f"{result.computed} cells computed, {result.reused} finished before, {len(result.cells)} in the grid"
    try:
        if result.rows:
            write_tables(out, result.rows)
        write_report(out, result.rows, cells=len(result.cells), finished=finished, plots=not args.no_plots,
                     provenance=provenance)
    except KeyboardInterrupt as exc:
        from cold_maps.common.signals import signals_ignored
        from cold_maps.evaluation.sweep_report import discard_outputs

        with signals_ignored():
            discard_outputs(out)
            write_report(out, result.rows, cells=len(result.cells), finished=finished, plots=False,
                         interrupted=True, provenance=provenance)
        what, status = interruption(exc)
        return fail(PROG, f"{what} while writing the tables ({counts}; the finished cells are kept, summary.md "
                    f"marked partial); run the same command again to write them -> {args.out}", status)
    if isinstance(result.error, KeyboardInterrupt):
        what, status = interruption(result.error)
        return fail(PROG, f"{what} ({counts}); run the same command again to finish -> {args.out}", status)
    if result.error is not None:
        return fail(PROG, f"a cell failed ({type(result.error).__name__}: {result.error}; {counts}); partial results "
                    f"in {args.out}")
    result_line(args, PROG, f"{counts}, {len(result.rows)} rows -> {args.out}")
    return 0
