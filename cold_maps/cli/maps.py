"""``cold-maps``: command-line tools on OpenDRIVE maps.

Subcommands live in ``COMMANDS``, a table of (name, help, configure, run); a new
subcommand is one more entry. Every failure (unreadable or invalid map, I/O error, bad
argument) ends with exit status 1 (2 for usage errors) and ONE line on stderr,
``cold-maps: error: ...``, never a traceback. ``export`` and ``convert`` report success in
one line on stdout (none under ``-q``, none for ``export -o -``). Output files are
written to a temporary file in the target folder and renamed into place, so a failure
leaves no partial file.

``info`` and ``export`` import only numpy and the map engine (no converter, no plotting).
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import logging
import math
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Final, Iterator, Sequence, TextIO

import numpy as np

from cold_maps.cli.common import (
    DefaultsHelpFormatter,
    UsageError,
    add_converter_option,
    add_output_options,
    add_version_option,
    cli_entry,
    make_parser,
    one_line,
    result_line,
    usage_failure,
)
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, OpenDriveMap

PROG: Final[str] = "cold-maps"
CSV_HEADER: Final[tuple[str, ...]] = ("road_id", "section", "lane_id", "side", "s", "x", "y", "z")
COORDINATE_DECIMALS: Final[int] = 4
"""Decimals of s, x, y, z (m) in exports: 0.1 mm."""
DEGREE_DECIMALS: Final[int] = 9
"""Decimals of longitude and latitude (deg) in GeoJSON: 0.1 mm of latitude."""
CRS_MEMBER: Final[str] = "cold_maps:crs"
"""GeoJSON foreign member (RFC 7946 §6.1) of the FeatureCollection saying which frame the
coordinates are in: ``{"frame": "wgs84" | "local", "description": ..., "geoReference":
PROJ string or null}``."""


@dataclass(frozen=True)
class Command:
    """One subcommand.

    Fields:
        name: the word on the command line.
        help: one-line description.
        configure: adds the subcommand's arguments to its parser.
        run: executes it and returns the exit status.
        progress: it may take long and draws progress (``--no-progress``).
    """

    name: str
    help: str
    configure: Callable[[argparse.ArgumentParser], None]
    run: Callable[[argparse.Namespace], int]
    progress: bool = False


def _load(args: argparse.Namespace) -> OpenDriveMap:
    from cold_maps.opendrive.parser import load_opendrive

    return load_opendrive(args.map, strict=args.strict)


def add_strict_option(parser: argparse.ArgumentParser) -> None:
    """``--strict``: refuse what is read leniently with a warning otherwise (records that
    omit coefficients, links whose ``contactPoint`` contradicts the geometry or that name a
    road or junction not in the file, a road's last records that draw a single point)."""
    parser.add_argument(
        "--strict", action="store_true",
        help="refuse geometry and profile records that omit coefficients, links whose contactPoint contradicts "
             "the geometry or that name a road or junction not in the file, and last paramPoly3 records that "
             "draw a single point (default: 0 / repaired / dropped / the road ends there, with a warning)",
    )


def _configure_info(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="MAP.xodr", help="OpenDRIVE file")
    add_strict_option(parser)


def _run_info(args: argparse.Namespace) -> int:
    print("\n".join(map_info(_load(args))))
    return 0


def map_info(odr_map: OpenDriveMap) -> list[str]:
    """Summary lines of a map: header, roads, sections, lanes, junctions, geometry, the lane
    graph and its issues (the first ``LISTED_MAX``, indented), then reference-line gaps and
    kinks and lane links whose borders do not meet."""
    from cold_maps.network.continuity import LISTED_MAX, continuity_report
    from cold_maps.network.lane_graph import build_lane_graph

    header = odr_map.header
    roads = odr_map.roads.values()
    sections = [section for road in roads for section in road.lane_sections]
    lane_types = Counter(lane.type for section in sections for lane in section.lanes)
    geometry = Counter(g.kind for road in roads for g in road.plan_view)
    connections = sum(len(j.connections) for j in odr_map.junctions.values())
    graph = build_lane_graph(odr_map, VEHICLE_LANE_TYPES)
    geo = header.geo_reference
    rules = Counter(road.rule for road in roads)
    return [
        f"map: {odr_map.path or '<input>'}",
        f"revision: {header.rev_major}.{header.rev_minor}",
        f"name: {header.name or '-'}",
        f"vendor: {header.vendor or '-'}",
        f"geoReference: {geo.proj or '-'}",
        f"offset: x={geo.offset_x:.15g} y={geo.offset_y:.15g} z={geo.offset_z:.15g} hdg={geo.offset_hdg:.15g}",
        f"roads: {len(odr_map.roads)} ({sum(1 for r in roads if r.junction != '-1')} in junctions), "
        f"{sum(r.length for r in roads) / 1000:.3f} km of reference line",
        f"traffic rule: {_counts(rules)}",
        f"lane sections: {len(sections)}",
        f"lanes: {sum(lane_types.values())} ({_counts(lane_types)})",
        f"driving lanes: {sum(graph.lengths.values()) / 1000:.3f} km",
        f"junctions: {len(odr_map.junctions)}",
        f"connections: {connections}",
        f"geometry: {_counts(geometry)}",
        f"lane graph: {len(graph.lanes)} driving lanes, {sum(1 for _ in graph.edges())} links, "
        f"{len(graph.issues)} issues",
        *(f"  {issue}" for issue in graph.issues[:LISTED_MAX]),
        *continuity_report(odr_map, graph),
    ]


def _counts(counter: Counter[str]) -> str:
    return ", ".join(f"{name} {count}" for name, count in sorted(counter.items())) or "-"


def _positive_length(text: str) -> float:
    """argparse type: a finite length > 0 (m)."""
    try:
        length = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of metres, got {text!r}") from None
    if not (math.isfinite(length) and length > 0):
        raise argparse.ArgumentTypeError(f"expected a finite length > 0 m, got {text!r}")
    return length


def _configure_export(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="MAP.xodr", help="OpenDRIVE file")
    parser.add_argument("--step", type=_positive_length, default=0.1, help="sampling step along s (m)")
    parser.add_argument("--format", choices=("csv", "geojson"), default="csv", help="file format")
    parser.add_argument(
        "--crs", choices=("wgs84", "local"), default=None,
        help="geojson coordinates: WGS84 lon/lat through the map's geoReference (RFC 7946, default) or the "
        "OpenDRIVE inertial frame in m (csv is always the inertial frame: --crs wgs84 is refused there)",
    )
    parser.add_argument("-o", "--output", required=True, metavar="FILE",
                        help="file to write (its folder must exist); - for standard output")
    add_strict_option(parser)


@dataclass(frozen=True)
class BorderPolyline:
    """One border of one driving lane, in the lane's driving direction.

    Fields:
        road_id, section, lane_id: the lane (section = 0-based lane-section index).
        side: "left" or "right", seen in the driving direction.
        s: (N,) road s (m) of the points.
        xyz: (N, 3) points in the OpenDRIVE inertial frame (m).
    """

    road_id: str
    section: int
    lane_id: int
    side: str
    s: NDArrayFloat
    xyz: NDArrayFloat


def lane_border_polylines(odr_map: OpenDriveMap, step: float) -> Iterator[BorderPolyline]:
    """Left then right border of every driving lane, road by road, section by section,
    every ``step`` m of s plus both ends of every ``<geometry>`` record (a jump between
    records appears as two points at one s, never as a chord)."""
    from cold_maps.network.route import road_borders

    for road in odr_map.roads.values():
        for lane in road_borders(road, step=step, lane_types=VEHICLE_LANE_TYPES, record_ends=True):
            for side, xyz in (("left", lane.left), ("right", lane.right)):
                yield BorderPolyline(*lane.lane, side, lane.s, xyz)


def _write_csv(borders: Iterator[BorderPolyline], out: TextIO) -> None:
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_HEADER)
    value = f"%.{COORDINATE_DECIMALS}f"
    for border in borders:
        label = io.StringIO()
        csv.writer(label, lineterminator="").writerow((border.road_id, border.section, border.lane_id, border.side, ""))
        # one format string for the whole border: the float formatting runs in one C loop
        row = label.getvalue().replace("%", "%%") + ",".join([value] * 4) + "\n"
        values = np.column_stack((border.s, border.xyz))
        out.write((row * len(values)) % tuple(values.ravel().tolist()))


def _geojson_crs(odr_map: OpenDriveMap, crs: str) -> tuple[dict[str, object], Callable[[NDArrayFloat], NDArrayFloat]]:
    """The ``CRS_MEMBER`` value and the (N, 3) point transform (rounded) of ``--crs``.

    Raises ValueError asking for ``--crs local`` when the map has no usable geoReference.
    """
    from cold_maps.opendrive.georeference import NoGeoReferenceError, Wgs84Transform

    geo = odr_map.header.geo_reference
    if crs == "local":
        member = {"frame": "local", "description": "OpenDRIVE inertial frame: x east, y north, z up (m); not WGS84"}
        return {**member, "geoReference": geo.proj or None}, lambda xyz: np.round(xyz, COORDINATE_DECIMALS)
    try:
        transform = Wgs84Transform(geo)
    except NoGeoReferenceError as exc:
        raise ValueError(f"{odr_map.path}: {exc}; write the inertial frame with --crs local") from None
    member = {"frame": "wgs84", "description": "EPSG:4326 longitude, latitude (deg); height z + offset z (m)"}
    scale = np.array([10.0**DEGREE_DECIMALS, 10.0**DEGREE_DECIMALS, 10.0**COORDINATE_DECIMALS])
    return {**member, "geoReference": geo.proj}, lambda xyz: np.round(transform(xyz) * scale) / scale


def _write_geojson(
    borders: Iterator[BorderPolyline], out: TextIO, crs: tuple[dict[str, object], Callable[[NDArrayFloat], NDArrayFloat]]
) -> None:
    member, transform = crs
    features = [
        {
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": transform(border.xyz).tolist()},
            "properties": {
                "road_id": border.road_id,
                "section": border.section,
                "lane_id": border.lane_id,
                "side": border.side,
                "s": np.round(border.s, COORDINATE_DECIMALS).tolist(),
            },
        }
        for border in borders
    ]
    json.dump({"type": "FeatureCollection", CRS_MEMBER: member, "features": features}, out, separators=(",", ":"))
    out.write("\n")


def _run_export(args: argparse.Namespace) -> int:
    if args.format == "csv" and args.crs == "wgs84":
        raise UsageError("--crs wgs84 needs --format geojson: csv rows are in the OpenDRIVE inertial frame "
                         "(x, y, z in m)")
    args.crs = args.crs or ("wgs84" if args.format == "geojson" else "local")
    odr_map = _load(args)
    written = Counter[str]()

    def counted(borders: Iterator[BorderPolyline]) -> Iterator[BorderPolyline]:
        for border in borders:
            written.update(borders=1, points=len(border.s))
            yield border

    borders = counted(lane_border_polylines(odr_map, args.step))
    crs = _geojson_crs(odr_map, args.crs) if args.format == "geojson" else None

    def write(out: TextIO) -> None:
        if crs is None:
            _write_csv(borders, out)
        else:
            _write_geojson(borders, out, crs)

    if args.output == "-":
        write(sys.stdout)
    else:
        from converters.atomic_io import atomic_output

        with atomic_output(Path(args.output), "w") as out:
            write(out)
        frame = "inertial frame" if args.format == "csv" or args.crs == "local" else "WGS84"
        result_line(args, f"{PROG} export", f"{written['borders']} lane borders, {written['points']} points "
                    f"({args.format}, {frame}) -> {args.output}")
    return 0


def _configure_convert(parser: argparse.ArgumentParser) -> None:
    from converters.api import configure_convert

    configure_convert(parser)
    add_converter_option(parser, "engine: the map engine's borders and lane graph; crdesigner: "
                         "commonroad-scenario-designer (the independent cross-check)")


def _run_convert(args: argparse.Namespace) -> int:
    """One result line (``-v``: and the recipe to load the file in the same frame); a
    cold conversion shows its elapsed time on a terminal. ``-vv`` shows crdesigner's own
    warnings and prints."""
    from cold_maps.cli.common import progress_stream
    from cold_maps.common.progress import Spinner
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from cold_maps.opendrive.parser import load_opendrive
    from converters import convert

    odr_map = load_opendrive(args.xodr)  # refuse what our reader refuses first (crdesigner reads the file itself)
    converter = converter_named(args.converter, odr_map)
    with Spinner(f"{PROG} convert: converting {Path(args.xodr).name}", stream=progress_stream(args)):
        recipe = convert(args.xodr, args.output, cache=not args.no_cache, verbose=args.verbose >= 2, converter=converter)
    result_line(args, f"{PROG} convert", f"{recipe.lanelets} lanelets in the OpenDRIVE inertial frame -> "
                f"{args.output} (converter {args.converter})")
    if args.verbose and not args.quiet:
        print(recipe.describe())
    return 0


def _configure_check(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``cold-maps check``: MAP.xodr [--threshold M] [--step M] [--all-lanes] [--no-cache] [--strict]."""
    from cold_maps.groundtruth.check import STEP_M, THRESHOLD_M

    parser.add_argument("map", metavar="MAP.xodr", help="OpenDRIVE map")
    parser.add_argument("--threshold", type=_positive_length, default=THRESHOLD_M,
                        help="largest allowed disagreement (m)")
    parser.add_argument("--step", type=_positive_length, default=STEP_M, help="our border sampling step along s (m)")
    parser.add_argument("--all-lanes", action="store_true", help="check every lane type, not only the vehicle lanes "
                        f"({', '.join(VEHICLE_LANE_TYPES)})")
    parser.add_argument("--no-cache", action="store_true", help="convert again; neither use nor fill the cache")
    parser.add_argument("--converter", choices=("engine", "crdesigner"), default=None,
                        help="check only this converter's ground truth (default: the engine's, crdesigner's and the "
                        "two compared; the exit status follows the engine's)")
    add_strict_option(parser)


def _check(args: argparse.Namespace) -> int:
    """Print the check report, then the map's geometry gaps (``network.continuity``); return
    the report's exit code. Raises OpenDriveError or ConversionError."""
    from cold_maps.groundtruth.check import check_map, cross_check, format_cross_check, format_report
    from cold_maps.network.continuity import continuity_report
    from cold_maps.network.lane_graph import build_lane_graph

    odr_map = _load(args)
    options = {"threshold_m": args.threshold, "step_m": args.step, "cache": not args.no_cache, "odr_map": odr_map,
               "lane_types": None if args.all_lanes else VEHICLE_LANE_TYPES}
    if args.converter is None:
        result = cross_check(args.map, **options)
        print(format_cross_check(result))
    else:
        result = check_map(args.map, converter=args.converter, **options)
        print(format_report(result))
    print("\n".join(continuity_report(odr_map, build_lane_graph(odr_map))))
    return result.exit_code


def _run_check(args: argparse.Namespace) -> int:
    """The report, printed once the elapsed-time line of the (maybe cold) conversion is gone."""
    from contextlib import redirect_stdout

    from cold_maps.cli.common import progress_stream
    from cold_maps.common.progress import Spinner
    report = io.StringIO()
    with Spinner(f"{PROG} check: converting and comparing {Path(args.map).name}", stream=progress_stream(args)), \
            redirect_stdout(report):
        status = _check(args)
    sys.stdout.write(report.getvalue())
    return status


def _configure_cache(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--clear", action="store_true", help="delete every cached conversion")


def _run_cache(args: argparse.Namespace) -> int:
    from converters.cache import CACHE_SUFFIX, cache_root, clear_cache

    root = cache_root()
    if args.clear:
        print(f"{root}: removed {clear_cache()} file(s)")
        return 0
    entries = sorted(root.glob(f"*{CACHE_SUFFIX}")) if root.is_dir() else []
    size_mb = sum(entry.stat().st_size for entry in entries) / 1e6
    print(f"{root}: {len(entries)} cached conversion(s), {size_mb:.1f} MB (override with $COLD_MAPS_CACHE_DIR)")
    return 0


COMMANDS: Final[tuple[Command, ...]] = (
    Command("info", "summarise a map: roads, lanes, junctions, geometry", _configure_info, _run_info),
    Command(
        "export",
        "write every border of every driving lane (csv or geojson)",
        _configure_export,
        _run_export,
    ),
    Command(
        "convert",
        "convert to a Lanelet2 OSM file in the OpenDRIVE frame (-v: print how to load it)",
        _configure_convert,
        _run_convert,
        progress=True,
    ),
    Command(
        "check",
        "compare the converted Lanelet2 ground truth with our borders per lane (exit 3: not trustworthy)",
        _configure_check,
        _run_check,
        progress=True,
    ),
    Command("cache", "show the Lanelet2 conversion cache, or --clear it", _configure_cache, _run_cache),
)


def build_parser(commands: Sequence[Command] = COMMANDS, selected: str | None = None) -> argparse.ArgumentParser:
    """The argument parser with one subparser per command. When ``selected`` names a
    command, only that one is configured, so a command never imports another's modules."""
    parser = make_parser(PROG, "Tools on OpenDRIVE maps for collective lane detection.", progress=True)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    names = {command.name for command in commands}
    for command in commands:
        configure = sub.add_parser(command.name, help=command.help, description=command.help,
                                   formatter_class=DefaultsHelpFormatter)
        add_version_option(configure, PROG)
        if selected not in names or command.name == selected:
            command.configure(configure)
            add_output_options(configure, progress=command.progress, inherited=True)
        configure.set_defaults(run=command.run)
    return parser


@cli_entry(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cold-maps``; returns the exit status."""
    from cold_maps.cli.common import configure_logging, fail, interruption

    argv = list(sys.argv[1:] if argv is None else argv)
    selected = next((arg for arg in argv if not arg.startswith("-")), None)
    args = build_parser(selected=selected).parse_args(argv)
    configure_logging(args.verbose, args.quiet)
    try:
        return int(args.run(args))
    except (BrokenPipeError, MemoryError):
        raise
    except UsageError as exc:
        return usage_failure(f"{PROG} {args.command}", exc)
    except KeyboardInterrupt as exc:
        what, status = interruption(exc)
        return fail(PROG, f"{what}; nothing written", status)
    except Exception as exc:  # every failure is reported as one line
        logging.getLogger(PROG).debug("failed", exc_info=exc)
        return fail(PROG, one_line(exc))


if __name__ == "__main__":
    sys.exit(main())
