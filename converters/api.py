"""Public entry points: load a converted map, write one, and the ``convert`` arguments.

Every entry point takes a ``Converter``: the reader that turns the OpenDRIVE file into
lanelets (crdesigner by default; ``cold_maps.groundtruth.lanelet2_from_engine`` gives the
map engine's). Its kind and version are part of the cache key.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from converters import frame
from converters.cache import atomic_write, cache_path
from converters.crdesigner_bridge import SourceLanelet, crdesigner_version, odr_to_lanelets, read_geo_reference
from converters.errors import ConversionError
from converters.joins import JOIN_TOLERANCE_M
from converters.lanes import routing_graph
from converters.osm import MERGE_TOLERANCE_M, SIMPLIFY_TOLERANCE_M, build_osm, read_generator

if TYPE_CHECKING:
    import lanelet2.core
    import lanelet2.routing

PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class Converter:
    """A reader of OpenDRIVE files into lanelets, served by the Lanelet2 writer and the cache.

    Fields:
        kind: its name, in the cache key and in messages ("crdesigner", "engine").
        version: its version (part of the cache key).
        lanelets: (path, verbose) → the lanelets (inertial frame, m) and the map's
            geoReference ("" if none); raises ConversionError naming the file.
        merge_tolerance_m: points of different borders closer than this (m) become one node.
        join_tolerance_m: successor ends this close (m, may be inf) are snapped together.
        simplify_tolerance_m: Douglas-Peucker tolerance of the ways (m), None: none.
    """

    kind: str
    version: str
    lanelets: Callable[[Path, bool], tuple[list[SourceLanelet], str]]
    merge_tolerance_m: float = MERGE_TOLERANCE_M
    join_tolerance_m: float = JOIN_TOLERANCE_M
    simplify_tolerance_m: float | None = SIMPLIFY_TOLERANCE_M


def _crdesigner_lanelets(path: Path, verbose: bool) -> tuple[list[SourceLanelet], str]:
    return odr_to_lanelets(path, verbose=verbose)


def crdesigner_converter() -> Converter:
    """commonroad-scenario-designer (``converters.crdesigner_bridge``), the default here."""
    return Converter("crdesigner", crdesigner_version(), _crdesigner_lanelets)


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ConversionError(str(path), f"cannot read the map: {exc.strerror or exc}") from exc


def _convert_bytes(xodr: Path, verbose: bool, converter: Converter) -> bytes:
    lanelets, geo_reference = converter.lanelets(xodr, verbose)
    return build_osm(lanelets, geo_reference=geo_reference, source=str(xodr),
                     merge_tolerance_m=converter.merge_tolerance_m, join_tolerance_m=converter.join_tolerance_m,
                     simplify_tolerance_m=converter.simplify_tolerance_m)


def _cached_osm(xodr: Path, cache_dir: PathLike | None, verbose: bool, converter: Converter) -> tuple[Path, bool]:
    """The cache file of ``xodr`` and whether it was there already (else it is converted
    and stored first)."""
    target = cache_path(_read(xodr), converter.version, cache_dir, kind=converter.kind)
    if target.is_file():
        return target, True
    atomic_write(target, _convert_bytes(xodr, verbose, converter), create_folder=True)
    return target, False


def convert(
    xodr_path: PathLike,
    osm_path: PathLike,
    *,
    cache: bool = True,
    cache_dir: PathLike | None = None,
    verbose: bool = False,
    converter: Converter | None = None,
) -> frame.LoadRecipe:
    """Convert an OpenDRIVE map to a standard Lanelet2 OSM file in its inertial frame
    (with ``converter``, default crdesigner).

    The file is written atomically; the returned recipe says how plain lanelet2 loads it
    in the same frame. Raises ConversionError naming the file on any failure.
    """
    xodr, out = Path(xodr_path), Path(osm_path)
    converter = converter or crdesigner_converter()
    if cache:
        data = _read(_cached_osm(xodr, cache_dir, verbose, converter)[0])
    else:
        data = _convert_bytes(xodr, verbose, converter)
    atomic_write(out, data)
    return frame.LoadRecipe(
        osm_path=str(out), geo_reference=read_geo_reference(xodr, header_only=True), lanelets=data.count(b'<tag k="type" v="lanelet"/>')
    )


def load_lanelet2(
    path: PathLike,
    *,
    cache: bool = True,
    cache_dir: PathLike | None = None,
    verbose: bool = False,
    converter: Converter | None = None,
) -> tuple[lanelet2.core.LaneletMap, lanelet2.routing.RoutingGraph]:
    """``load_lanelet_map`` and the map's vehicle routing graph (``routing_graph``)."""
    lanelet_map = load_lanelet_map(path, cache=cache, cache_dir=cache_dir, verbose=verbose, converter=converter)
    return lanelet_map, routing_graph(lanelet_map)


def load_lanelet_map(
    path: PathLike,
    *,
    cache: bool = True,
    cache_dir: PathLike | None = None,
    verbose: bool = False,
    converter: Converter | None = None,
) -> lanelet2.core.LaneletMap:
    """Lanelet2 map (inertial frame, m) of an ``.xodr`` map (converted by ``converter``,
    default crdesigner; cached unless ``cache=False``) or of an ``.osm`` file we wrote.

    Raises ConversionError naming the file for an unreadable map, a converter crash, an
    empty result or an OSM file not written by this converter (its frame is unknown).
    """
    source = Path(path)
    suffix = source.suffix.lower()
    if suffix == ".osm":
        generator = read_generator(source)
        if not generator.startswith(frame.GENERATOR_PREFIX):
            raise ConversionError(
                str(source), f"written by {generator or 'an unknown tool'!r}, not {frame.GENERATOR}: frame unknown"
            )
        return _load_osm(source)
    if suffix != ".xodr":
        raise ConversionError(str(source), f"unknown map type {suffix or '(no suffix)'!r}: expected .xodr or .osm")
    converter = converter or crdesigner_converter()
    if cache:
        cached, hit = _cached_osm(source, cache_dir, verbose, converter)
        try:
            return _load_osm(cached, source=source)
        except ConversionError:
            if not hit:
                raise
        cached.unlink(missing_ok=True)  # a damaged cache entry: convert again
        return _load_osm(_cached_osm(source, cache_dir, verbose, converter)[0], source=source)
    with tempfile.TemporaryDirectory(prefix="cold-maps-") as folder:
        osm = Path(folder) / "map.osm"
        osm.write_bytes(_convert_bytes(source, verbose, converter))
        return _load_osm(osm, source=source)


def _load_osm(osm: Path, *, source: Path | None = None) -> lanelet2.core.LaneletMap:
    import lanelet2.io

    named = str(source or osm)
    try:
        lanelet_map = lanelet2.io.load(str(osm), frame.projector())
    except Exception as exc:  # lanelet2 raises its own RuntimeError subclasses
        raise ConversionError(named, f"lanelet2 cannot load {osm}: {exc}") from exc
    if len(lanelet_map.laneletLayer) == 0:
        raise ConversionError(named, "the converted map has no lanelets")
    return lanelet_map


def configure_convert(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``cold-maps convert``: MAP.xodr -o MAP.osm [--no-cache] (the command
    itself, with its output conventions, is ``cold_maps.cli.maps``)."""
    parser.add_argument("xodr", metavar="MAP.xodr", help="OpenDRIVE map")
    parser.add_argument("-o", "--output", metavar="MAP.osm", required=True, help="Lanelet2 OSM file to write")
    parser.add_argument("--no-cache", action="store_true", help="convert again; neither use nor fill the cache")
