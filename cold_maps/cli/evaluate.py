"""``cold-eval``: batch evaluation of collective lane detection on OpenDRIVE maps.

``cold-eval --map MAP.xodr [--map ...]`` drives routes spread over each map (``--routes``,
``--frames``, ``--seed``) with an ego, cooperative vehicles (convoy headway 25 m, spline
gaps ``--gaps``) and distractors, fuses per frame (``--interpolation``) and measures against
Lanelet2 ground truth. ``cold-eval --paper`` runs the paper's experiments on the bundled
straight, curve90 and rural maps. Outputs in ``--out``: summary.md, metrics.json,
frames.csv, plots/*.png, run.mcap. Exit 0; 1 with one line on stderr for bad input or a
crash (partial outputs marked as such); 130 when interrupted.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable, Final, Sequence

from cold_maps.cli.common import cli_entry, make_parser
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.report import ScenarioResult
from cold_maps.evaluation.scenarios import INTERPOLATIONS, MapPlan, params_for_gaps, scenarios_for
from cold_maps.simulation.drive import DEFAULT_SPEED_MPS, PAPER_GAPS_M

SectionsCallback = Callable[[Collector, list[ScenarioResult]], list[tuple[str, str]]]

PROG: Final[str] = "cold-eval"
DEFAULT_OUT: Final[str] = "out/cold-eval"
DEFAULT_FRAMES: Final[int] = 100
DEFAULT_ROUTES: Final[int] = 3


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text}")
    return value


def _routes(text: str) -> int | None:
    return None if text == "all" else _positive_int(text)


def _gaps(text: str) -> tuple[float, ...]:
    try:
        gaps = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated distances in m, got {text!r}") from None
    if not gaps or any(not 0 < g < 1e4 for g in gaps):
        raise argparse.ArgumentTypeError(f"gaps must be > 0 m, got {text!r}")
    return gaps


def build_parser() -> argparse.ArgumentParser:
    """The ``cold-eval`` argument parser."""
    description = __doc__.split("\n\n")[1].replace("\n", " ").replace("``", "")
    parser = make_parser(PROG, description, progress=True)
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--map", action="append", type=Path, metavar="MAP.xodr", help="OpenDRIVE map (repeatable)")
    what.add_argument("--paper", action="store_true", help="the paper's experiments on the bundled maps")
    parser.add_argument("--out", type=Path, default=Path(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--routes", type=_routes, default=DEFAULT_ROUTES,
                        help="routes per map, or 'all' for as many as cover every driving lane (default 3)")
    parser.add_argument("--frames", type=_positive_int, default=None,
                        help=f"frames per route (default {DEFAULT_FRAMES}, fewer on a map too short for them; "
                             "--paper: the whole route at 1 m per frame)")
    parser.add_argument("--seed", type=int, default=0, help="seed of routes and error models (default 0)")
    parser.add_argument("--speed", type=float, default=DEFAULT_SPEED_MPS, help="ego speed in m/s (default 10)")
    parser.add_argument("--interpolation", choices=(*INTERPOLATIONS, "both"), default="both",
                        help="spline interpolation (default both)")
    parser.add_argument("--gaps", type=_gaps, default=PAPER_GAPS_M,
                        help="spline gaps d_s in m, comma-separated (default 20,30,50)")
    parser.add_argument("--no-distractors", action="store_true",
                        help="no turning, adjacent, opposite or behind vehicles")
    errors = parser.add_argument_group("sensor error models (all off by default, seeded)")
    for flag, name, unit in (("--lateral-offset", "lateral_offset_m", "m"), ("--noise", "noise_sigma_m", "m, σ"),
                             ("--heading-bias", "heading_bias_rad", "rad"),
                             ("--range-jitter", "range_jitter_sigma_m", "m, σ"),
                             ("--drop", "drop_probability", "probability"),
                             ("--pose-xy", "pose_sigma_xy_m", "m, σ, coop poses"),
                             ("--pose-yaw", "pose_sigma_yaw_rad", "rad, σ, coop poses")):
        errors.add_argument(flag, dest=name, type=float, default=0.0, help=f"({unit})")
    parser.add_argument("--no-mcap", action="store_true", help="do not write run.mcap")
    parser.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    return parser


def _interpolations(args: argparse.Namespace) -> tuple[str, ...]:
    return INTERPOLATIONS if args.interpolation == "both" else (args.interpolation,)


def _plans(args: argparse.Namespace) -> list[MapPlan]:
    from cold_maps.simulation.sensor_errors import SensorErrorModel

    errors = SensorErrorModel(**{name: getattr(args, name) for name in (
        "lateral_offset_m", "noise_sigma_m", "heading_bias_rad", "range_jitter_sigma_m", "drop_probability",
        "pose_sigma_xy_m", "pose_sigma_yaw_rad")})
    interpolations = _interpolations(args)
    if args.paper:
        from dataclasses import replace

        from cold_maps.evaluation.paper import paper_plans

        plans = paper_plans(frames=args.frames, seed=args.seed, speed_mps=args.speed, interpolations=interpolations)
        return [replace(plan, errors=errors) for plan in plans]
    seen: dict[str, Path] = {}
    for path in args.map:
        if path.stem in seen:
            raise ValueError(f"--map {seen[path.stem]} and --map {path} share the name {path.stem!r}; the report "
                             "keys results by map name: give every map its own file name")
        seen[path.stem] = path
    params = params_for_gaps(args.gaps)
    scenarios = scenarios_for(args.gaps, interpolations)
    return [MapPlan(path, scenarios, frames=args.frames or DEFAULT_FRAMES, frames_at_most=args.frames is None,
                    routes=args.routes, seed=args.seed, speed_mps=args.speed, distractors=not args.no_distractors, errors=errors, params=params)
            for path in args.map]


def _sections(paper: bool, interpolations: Sequence[str]) -> SectionsCallback:
    """The extra summary sections: Table II per interpolation and the longest gap for
    ``--paper``, the runtime table (Table I) always."""
    from cold_maps.evaluation.paper import gap_limit_markdown, runtime_markdown, table_ii_markdown

    def sections(collector: Collector, results: list[ScenarioResult]) -> list[tuple[str, str]]:
        found = []
        if paper:
            found += [(f"Table II vs the paper, `{name}` interpolation", table_ii_markdown(results, name))
                      for name in interpolations]
            found.append(("Longest gap", gap_limit_markdown(results)))
        found.append(("Runtime (Table I)", runtime_markdown(collector)))
        return found

    return sections


@cli_entry
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cold-eval``; returns the exit status."""
    args = build_parser().parse_args(argv)
    from cold_maps.cli.common import (configure_logging, fail, interruption, progress_stream, result_line,
                                      startup_failure)
    from cold_maps.evaluation.run import RunOptions, run_evaluation

    configure_logging(args.verbose, args.quiet)
    try:
        plans = _plans(args)
        options = RunOptions(out=args.out, mcap=not args.no_mcap, plots=not args.no_plots, progress=progress_stream(args),
                             run_params={k: str(v) for k, v in sorted(vars(args).items())})
        run = run_evaluation(plans, options, extra_sections=_sections(args.paper, _interpolations(args)))
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - every failure is reported as one line
        return startup_failure(PROG, exc)
    if isinstance(run.error, KeyboardInterrupt):
        what, status = interruption(run.error)
        return fail(PROG, f"{what}; partial report in {args.out}", status)
    if run.error is not None:
        return fail(PROG, f"run failed ({type(run.error).__name__}: {run.error}); partial report in {args.out}")
    reduced = run.collector.reduced_maps
    fitted = f" ({', '.join(reduced)}: what did not fit the map is listed in summary.md)" if reduced else ""
    result_line(args, PROG, f"{len(run.results)} scenario records, {run.collector.frames_done} frames -> {args.out}{fitted}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
