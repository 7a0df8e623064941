"""``cold-eval``: batch evaluation of collective lane detection on OpenDRIVE maps.

``cold-eval --map MAP.xodr [--map ...]`` drives routes spread over each map (``--routes``,
``--frames``, ``--seed``) with an ego, cooperative vehicles (convoy headway 25 m, spline
gaps ``--gaps``) and distractors, fuses per frame (``--interpolation``) and measures against
Lanelet2 ground truth. ``cold-eval --paper`` runs the paper's experiments on the bundled
straight, curve90 and rural maps. The drives run in ``--workers`` processes (default: the
cores) with the same outputs for any number; ``--method`` adds your own fusion method.
Outputs in ``--out``: summary.md, metrics.json, frames.csv, plots/*.png, run.mcap (``--osi``: the
detections as an ASAM OSI trace too). Exit 0;
1 with one line on stderr for bad input or a crash (partial outputs marked as such); 2 for
a bad command line; 130 when interrupted, 143 on SIGTERM. ``--sensor`` picks the lane
sensor (``simulation.sensor_profile``). ``cold-eval sweep ...``: a grid
of evaluations (see ``cold-eval sweep --help``).
"""

from __future__ import annotations

import argparse
import decimal
import sys
from pathlib import Path
from typing import Callable, Final, Sequence

from cold_maps.cli.common import (UsageError, add_converter_option, builds, cli_entry, finite_number, fusion_method, gap_list, int_in,
                                  make_parser, positive_int, validated, within)
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.report import ScenarioResult
from cold_maps.evaluation.safety import (
    DEFAULT_DECELERATION_MPS2,
    DEFAULT_REACTION_TIME_S,
    LANE_ACCURACY_M,
    STOPPING_FORMULA,
    StoppingError,
    StoppingRule,
)
from cold_maps.evaluation.scenarios import INTERPOLATIONS, MapPlan, params_for_gaps, scenarios_for
from cold_maps.recording.recorder import MAX_STAMP_BASE_NS, NS_PER_S
from cold_maps.simulation.drive import DEFAULT_SPEED_MPS, MAX_COVER_ROUTES, MAX_SPEED_MPS, PAPER_GAPS_M
from cold_maps.simulation.messages import DEFAULT_CHANGE_TOLERANCE_M, DEFAULT_MAX_INTERVAL_S, MessageModel
from cold_maps.simulation.odometry import DEFAULT_HISTORY_M, TYPICAL_HEADING_DRIFT_RAD_PER_M, TYPICAL_SCALE_ERROR
from cold_maps.simulation.sensor_errors import SensorErrorModel
from cold_maps.simulation.sensor_profile import BUILTIN_PROFILES, DEFAULT_PROFILE, SensorProfile, load_profile
from fusion.bezier import DEFAULT_TOLERANCE_M
from fusion.types import ASSOCIATION_RULES, CONVOY_WEIGHTS

SectionsCallback = Callable[[Collector, list[ScenarioResult]], list[tuple[str, str]]]

PROG: Final[str] = "cold-eval"
DEFAULT_OUT: Final[str] = "out/cold-eval"
DEFAULT_FRAMES: Final[int] = 100
DEFAULT_ROUTES: Final[int] = 3
MAX_LANES: Final[int] = 8
MAX_OPTION_VALUE: Final[float] = 1e6
"""Bound (exclusive) of the non-negative amounts (history m, drift σ, tolerances m, loss,
latency and intervals s): far above any meaningful setting, and finite arithmetic on them."""
UNRECORDED: Final[frozenset[str]] = frozenset({"workers", "verbose", "quiet", "no_progress"})
"""Options that change no result, left out of the recording's ``cold.run`` parameters."""


_route_count = int_in(1, MAX_COVER_ROUTES)


def _routes(text: str) -> int | None:
    """argparse type: 'all' (None) or a route count from 1 to ``MAX_COVER_ROUTES``."""
    return None if text == "all" else _route_count(text)


def _non_negative(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not 0 <= value < MAX_OPTION_VALUE:
        raise argparse.ArgumentTypeError(f"expected a number >= 0 and < {MAX_OPTION_VALUE:g}, got {text}")
    return value


def _message_option(field: str) -> Callable[[str], float]:
    """argparse type of a ``MessageModel`` field: a number >= 0 and < ``MAX_OPTION_VALUE``
    that the model accepts."""
    return validated(_non_negative, builds(MessageModel, field))


def _stopping_value(field: str) -> Callable[[str], float]:
    """argparse type: a value of the :class:`StoppingRule` field ``field``, checked by the rule."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
        try:
            return float(getattr(StoppingRule(**{field: value}), field))
        except StoppingError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    return parse


def _stamp_base(text: str) -> int:
    """Seconds since the Unix epoch (decimal, >= 0) as whole ns."""
    try:
        seconds = decimal.Decimal(text)
    except decimal.InvalidOperation:
        seconds = decimal.Decimal("NaN")
    if not seconds.is_finite() or not 0 <= seconds * NS_PER_S <= MAX_STAMP_BASE_NS:
        raise argparse.ArgumentTypeError(f"expected seconds since the Unix epoch, 0 ... "
                                         f"{MAX_STAMP_BASE_NS // NS_PER_S}, got {text}")
    return int(seconds * NS_PER_S)


def _sensor(text: str) -> SensorProfile:
    """argparse type: a built-in sensor profile's name or a FILE.toml."""
    try:
        return load_profile(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _osi_path(text: str) -> Path:
    """argparse type: a file path for the OSI trace (not a folder)."""
    path = Path(text)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; expected a trace file name such as {text}/run.osi")
    return path


def _cooperation(plan: MapPlan, args: argparse.Namespace) -> MapPlan:
    """``plan`` with the chains, history and messages asked for (unchanged when none is)."""
    from dataclasses import replace

    from cold_maps.evaluation.scenarios import extended_scenarios
    from cold_maps.simulation.odometry import OdometryModel

    heading = TYPICAL_HEADING_DRIFT_RAD_PER_M if args.drift else 0.0
    scale = TYPICAL_SCALE_ERROR if args.drift else 0.0
    odometry = OdometryModel(heading if args.drift_heading is None else args.drift_heading,
                             scale if args.drift_scale is None else args.drift_scale)
    messages = MessageModel(args.exchange or "none", bezier_tolerance_m=args.bezier_tolerance,
                            loss_probability=args.loss, latency_s=args.latency,
                            max_interval_s=args.max_interval, change_tolerance_m=args.change_tolerance)
    if args.history == 0 and (args.drift or args.drift_heading is not None or args.drift_scale is not None):
        raise UsageError("--drift, --drift-heading and --drift-scale bend the lane history: add --history")
    if not messages.enabled and (args.loss or args.latency):
        raise UsageError("--loss and --latency act on lane messages: add --exchange sampled|bezier")
    if args.coops == 1 and args.history == 0 and not messages.enabled:
        return plan
    scenarios = extended_scenarios(plan.scenarios, coops=args.coops, history_m=args.history,
                                   exchange=args.exchange or "")
    return replace(plan, scenarios=scenarios, history_m=args.history, odometry=odometry, messages=messages)


def build_parser() -> argparse.ArgumentParser:
    """The ``cold-eval`` argument parser."""
    parser = make_parser(PROG, __doc__.split("\n\n")[1], progress=True)
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--map", action="append", type=Path, metavar="MAP.xodr", help="OpenDRIVE map (repeatable)")
    what.add_argument("--paper", action="store_true", help="the paper's experiments on the bundled maps")
    parser.add_argument("--out", type=Path, default=Path(DEFAULT_OUT), help=f"output folder (default {DEFAULT_OUT})")
    parser.add_argument("--routes", type=_routes, default=DEFAULT_ROUTES,
                        help="routes per map, or 'all' for one more until every lane a route of the drive's "
                             "length can start on is covered (default 3)")
    parser.add_argument("--frames", type=positive_int, default=None,
                        help=f"frames per route (default {DEFAULT_FRAMES}, fewer on a map too short for them; "
                             "--paper: the whole route at 1 m per frame)")
    parser.add_argument("--seed", type=int_in(0), default=0, help="seed of routes and error models (default 0)")
    parser.add_argument("--speed", type=validated(finite_number, within(0.0, MAX_SPEED_MPS, "m/s", low_open=True)),
                        default=DEFAULT_SPEED_MPS, help=f"ego speed in m/s (default {DEFAULT_SPEED_MPS:g})")
    parser.add_argument("--interpolation", choices=(*INTERPOLATIONS, "both"), default="both",
                        help="spline interpolation (default both)")
    parser.add_argument("--gaps", type=gap_list, default=PAPER_GAPS_M, metavar="D_S,...",
                        help="spline gaps d_s in m, comma-separated (default 20,30,50)")
    parser.add_argument("--method", action="append", type=fusion_method, default=[], metavar="NAME",
                        help="also evaluate this fusion method across the gaps: a name registered in the "
                             "cold_maps.fusion_methods entry points or package.module:function, looked up in the "
                             "installed packages and the current folder (repeatable; default: none)")
    parser.add_argument("--convoy-weights", choices=CONVOY_WEIGHTS, default="paper",
                        help="weights of the convoy overlap: the paper's fixed 0.75 coop / 0.25 ego, 0.5 each, or "
                             "inverse-variance point by point from the detections' σ and pose covariances, the coop's "
                             "pose first corrected from the overlap (the weights of mean when the detections state "
                             "no σ) (default paper)")
    parser.add_argument("--association", choices=ASSOCIATION_RULES, default="legacy",
                        help="lane association decision: the geometric and lane rules alone (legacy), also reject "
                             "pairs below the association confidence 0.4 as ambiguous (confidence), and also "
                             "single-lane gap pairs whose lane a width aside passes the geometry too (strict) or "
                             "passes it about as well (separation, which also reads d_s <= d_i to 1 mm), and also "
                             "coops that continue a lane branching off where the ego's detection ends or stops "
                             "short, and single-lane gap pairs whose ego detection ends where the markings stop "
                             "(fork); see "
                             "docs/fusion/association.md (default legacy)")
    parser.add_argument("--lanes", type=int_in(0, MAX_LANES), default=0,
                        help="neighbour lanes the sensor detects on each side, with the road edges and lanes leaving "
                             "at forks (default 0: the vehicle's own lane only)")
    parser.add_argument("--sensor", type=_sensor, default=DEFAULT_PROFILE, metavar="|".join((*BUILTIN_PROFILES,
                                                                                           "FILE.toml")),
                        help="lane sensor: ideal (the paper's: the lane 30 m ahead, never failing), camera (urban: "
                             "3-50 m, ±25°, crests, vehicles ahead, unmarked borders), camera-highway (3-100 m) or a "
                             "TOML file overriding a profile's fields (default ideal)")
    parser.add_argument("--no-distractors", action="store_true",
                        help="no turning, adjacent, opposite or behind vehicles")
    safety = parser.add_argument_group(
        f"stopping distance {STOPPING_FORMULA} to which the lane is known within "
        f"{LANE_ACCURACY_M:g} m (v = --speed; docs/metrics.md)")
    safety.add_argument("--reaction-time", type=_stopping_value("reaction_time_s"), default=DEFAULT_REACTION_TIME_S,
                        metavar="S",
                        help=f"reaction time t_r in s (default {DEFAULT_REACTION_TIME_S:g}: AASHTO Green Book, "
                             "stopping sight distance)")
    safety.add_argument("--deceleration", type=_stopping_value("deceleration_mps2"),
                        default=DEFAULT_DECELERATION_MPS2, metavar="MPS2",
                        help=f"deceleration a in m/s² (default {DEFAULT_DECELERATION_MPS2:g}: AASHTO Green Book, "
                             "stopping sight distance)")
    errors = parser.add_argument_group("sensor error models (all off by default, seeded)")
    for flag, name, unit in (("--lateral-offset", "lateral_offset_m", "m"), ("--noise", "noise_sigma_m", "m, σ"),
                             ("--heading-bias", "heading_bias_rad", "rad"),
                             ("--range-jitter", "range_jitter_sigma_m", "m, σ"),
                             ("--drop", "drop_probability", "probability"),
                             ("--pose-xy", "pose_sigma_xy_m", "m, σ, coop poses"),
                             ("--pose-yaw", "pose_sigma_yaw_rad", "rad, σ, coop poses")):
        errors.add_argument(flag, dest=name, type=validated(finite_number, builds(SensorErrorModel, name)),
                            default=0.0, help=f"{unit} (default 0: off)")
    coop = parser.add_argument_group("chains, lane history and messages (all off by default, seeded)")
    coop.add_argument("--coops", type=positive_int, default=1,
                      help="coops per chain: K > 1 adds chains of 2..K coops ahead, spaced like the pair (default 1)")
    coop.add_argument("--history", type=_non_negative, nargs="?", const=DEFAULT_HISTORY_M, default=0.0, metavar="M",
                      help=f"lane history every coop sends, m (no value: {DEFAULT_HISTORY_M:g}; default 0 = none)")
    coop.add_argument("--drift", action="store_true",
                      help=f"typical odometry drift: σ {TYPICAL_HEADING_DRIFT_RAD_PER_M:g} rad/m heading, "
                           f"{TYPICAL_SCALE_ERROR:g} scale")
    coop.add_argument("--drift-heading", type=_non_negative, default=None,
                      help=f"σ of the heading drift, rad/m (default 0: off; {TYPICAL_HEADING_DRIFT_RAD_PER_M:g} "
                           "with --drift)")
    coop.add_argument("--drift-scale", type=_non_negative, default=None,
                      help=f"σ of the odometry scale error (default 0: off; {TYPICAL_SCALE_ERROR:g} with --drift)")
    coop.add_argument("--exchange", choices=("sampled", "bezier"), default=None,
                      help="lanes travel as messages in this format (default: detections fused directly)")
    coop.add_argument("--bezier-tolerance", type=_message_option("bezier_tolerance_m"), default=DEFAULT_TOLERANCE_M,
                      help=f"fit tolerance of the Bézier encoding, m (default {DEFAULT_TOLERANCE_M:g}; with "
                           "detection noise σ use about 4σ, or the fit chases the noise)")
    coop.add_argument("--loss", type=_message_option("loss_probability"), default=0.0,
                      help="message loss probability (default 0: none lost)")
    coop.add_argument("--latency", type=_message_option("latency_s"), default=0.0,
                      help="message latency, s (default 0: none)")
    coop.add_argument("--max-interval", type=_message_option("max_interval_s"), default=DEFAULT_MAX_INTERVAL_S,
                      help=f"longest time between messages (s, default {DEFAULT_MAX_INTERVAL_S:g})")
    coop.add_argument("--change-tolerance", type=_message_option("change_tolerance_m"),
                      default=DEFAULT_CHANGE_TOLERANCE_M,
                      help=f"lane change (RMS, m) that triggers a message (default {DEFAULT_CHANGE_TOLERANCE_M:g})")
    parser.add_argument("--workers", type=positive_int, default=None,
                        help="worker processes, one drive (route) each at a time (default: this machine's cores)")
    add_converter_option(parser, "converter of the Lanelet2 ground truth: engine (the map engine's borders and lane "
                         "graph) or crdesigner (commonroad-scenario-designer)")
    parser.add_argument("--no-mcap", action="store_true", help="do not write run.mcap")
    parser.add_argument("--osi", type=_osi_path, default=None, metavar="TRACE.osi",
                        help="also write every vehicle's detections per frame as an ASAM OSI SensorData trace "
                             "(length-prefixed binary; cold-fuse --input reads it; default: none)")
    parser.add_argument("--no-plots", action="store_true", help="do not write PNG plots")
    parser.add_argument("--stamp-base", type=_stamp_base, default=None, metavar="UNIX_S",
                        help="MCAP log time of frame 0 in s since the Unix epoch (default: the run's start)")
    return parser


def _interpolations(args: argparse.Namespace) -> tuple[str, ...]:
    chosen = INTERPOLATIONS if args.interpolation == "both" else (args.interpolation,)
    return tuple(dict.fromkeys((*chosen, *args.method)))


def _plans(args: argparse.Namespace) -> list[MapPlan]:
    from cold_maps.simulation.sensor_errors import SensorErrorModel

    if args.osi is not None and (args.lanes or args.history):
        raise UsageError("--osi writes the border pair of each vehicle's own lane: it cannot carry --lanes or "
                         "--history")
    errors = SensorErrorModel(**{name: getattr(args, name) for name in (
        "lateral_offset_m", "noise_sigma_m", "heading_bias_rad", "range_jitter_sigma_m", "drop_probability",
        "pose_sigma_xy_m", "pose_sigma_yaw_rad")})
    interpolations = _interpolations(args)
    stopping = StoppingRule(args.reaction_time, args.deceleration)
    if args.paper:
        from dataclasses import replace

        from cold_maps.evaluation.paper import paper_plans

        plans = paper_plans(frames=args.frames, seed=args.seed, speed_mps=args.speed, interpolations=interpolations)
        return [_cooperation(replace(plan, errors=errors, lanes=args.lanes, stopping=stopping, sensor=args.sensor,
                                     ground_truth=args.converter,
                                     params=replace(plan.params, convoy_weights=args.convoy_weights,
                                                    association=args.association)), args)
                for plan in plans]
    seen: dict[str, Path] = {}
    for path in args.map:
        if path.stem in seen:
            raise UsageError(f"--map {seen[path.stem]} and --map {path} share the name {path.stem!r}; the report "
                             "keys results by map name: give every map its own file name")
        seen[path.stem] = path
    params = params_for_gaps(args.gaps, args.convoy_weights, args.association)
    scenarios = scenarios_for(args.gaps, interpolations)
    return [_cooperation(MapPlan(path, scenarios, frames=args.frames or DEFAULT_FRAMES,
                                 frames_at_most=args.frames is None, routes=args.routes, seed=args.seed,
                                 speed_mps=args.speed, distractors=not args.no_distractors, errors=errors,
                                 params=params, lanes=args.lanes, stopping=stopping, sensor=args.sensor,
                                 ground_truth=args.converter), args)
            for path in args.map]


def _sections(paper: bool, interpolations: Sequence[str], convoy_weights: str) -> SectionsCallback:
    """The extra summary sections: Table II per interpolation and the longest gap for
    ``--paper`` and the convoy weights always (the runtime table, Table I, is part of every
    summary)."""
    from cold_maps.evaluation.paper import gap_limit_markdown, table_ii_markdown

    def sections(collector: Collector, results: list[ScenarioResult]) -> list[tuple[str, str]]:
        found = []
        if paper:
            found += [(f"Table II vs the paper, `{name}` interpolation", table_ii_markdown(results, name))
                      for name in interpolations]
            found.append(("Longest gap", gap_limit_markdown(results)))
        found.append(("Convoy weights", f"`--convoy-weights {convoy_weights}`\n"))
        return found

    return sections


@cli_entry(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cold-eval`` (``cold-eval sweep ...``: :mod:`cold_maps.cli.sweep`);
    returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv[:1] == ["sweep"]:
        from cold_maps.cli import sweep

        return sweep.main(argv[1:])
    args = build_parser().parse_args(argv)
    from cold_maps.cli.common import (configure_logging, fail, interruption, progress_stream, result_line,
                                      startup_failure)
    from cold_maps.common.provenance import make_provenance, recorded_params
    from cold_maps.evaluation.parallel import default_workers
    from cold_maps.evaluation.run import RunOptions, run_evaluation
    from cold_maps.evaluation.trust import verdict

    configure_logging(args.verbose, args.quiet)
    try:
        plans = _plans(args)
        options = RunOptions(out=args.out, mcap=not args.no_mcap, plots=not args.no_plots,
                             progress=progress_stream(args),
                             provenance=make_provenance(PROG, argv, recorded_params(vars(args), UNRECORDED),
                                                        inputs=[("map", plan.path) for plan in plans]),
                             workers=args.workers or default_workers(), stamp_base_ns=args.stamp_base,
                             osi=args.osi)
        run = run_evaluation(plans, options, extra_sections=_sections(args.paper, _interpolations(args),
                                                                            args.convoy_weights))
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - every failure is reported as one line
        return startup_failure(PROG, exc)
    if isinstance(run.error, KeyboardInterrupt):
        what, status = interruption(run.error)
        return fail(PROG, f"{what}; partial report in {args.out}", status)
    if run.error is not None:
        return fail(PROG, f"run failed ({type(run.error).__name__}: {run.error}); partial report in {args.out}")
    reduced = run.collector.reduced_maps
    fitted = f" ({', '.join(reduced)}: what did not fit the map is listed in summary.md)" if reduced else ""
    result_line(args, PROG, f"{len(run.results)} scenario records, {run.collector.frames_done} frames -> "
                f"{args.out}{fitted}{verdict(run.collector)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
