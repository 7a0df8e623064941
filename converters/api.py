"""Public entry points: load a converted map, write one, and the ``convert`` arguments."""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING

from converters import frame
from converters.cache import atomic_write, cache_path
from converters.crdesigner_bridge import crdesigner_version, odr_to_lanelets, read_geo_reference
from converters.errors import ConversionError
from converters.lanes import routing_graph
from converters.osm import build_osm, read_generator

if TYPE_CHECKING:
    import lanelet2.core
    import lanelet2.routing

PathLike = str | os.PathLike[str]


def _read(path: Path) -> bytes:
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ConversionError(str(path), f"cannot read the map: {exc.strerror or exc}") from exc


def _convert_bytes(xodr: Path, verbose: bool) -> bytes:
    lanelets, geo_reference = odr_to_lanelets(xodr, verbose=verbose)
    return build_osm(lanelets, geo_reference=geo_reference, source=str(xodr))


def _cached_osm(xodr: Path, cache_dir: PathLike | None, verbose: bool) -> tuple[Path, bool]:
    """The cache file of ``xodr`` and whether it was there already (else it is converted
    and stored first)."""
    target = cache_path(_read(xodr), crdesigner_version(), cache_dir)
    if target.is_file():
        return target, True
    atomic_write(target, _convert_bytes(xodr, verbose), create_folder=True)
    return target, False


def convert(
    xodr_path: PathLike,
    osm_path: PathLike,
    *,
    cache: bool = True,
    cache_dir: PathLike | None = None,
    verbose: bool = False,
) -> frame.LoadRecipe:
    """Convert an OpenDRIVE map to a standard Lanelet2 OSM file in its inertial frame.

    The file is written atomically; the returned recipe says how plain lanelet2 loads it
    in the same frame. Raises ConversionError naming the file on any failure.
    """
    xodr, out = Path(xodr_path), Path(osm_path)
    if cache:
        data = _read(_cached_osm(xodr, cache_dir, verbose)[0])
    else:
        data = _convert_bytes(xodr, verbose)
    atomic_write(out, data)
    return frame.LoadRecipe(
        osm_path=str(out), geo_reference=read_geo_reference(xodr), lanelets=data.count(b'<tag k="type" v="lanelet"/>')
    )


def load_lanelet2(
    path: PathLike,
    *,
    cache: bool = True,
    cache_dir: PathLike | None = None,
    verbose: bool = False,
) -> tuple[lanelet2.core.LaneletMap, lanelet2.routing.RoutingGraph]:
    """Lanelet2 map (inertial frame, m) and vehicle routing graph of an ``.xodr`` map
    (converted, cached unless ``cache=False``) or of an ``.osm`` file we wrote.

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
    if cache:
        cached, hit = _cached_osm(source, cache_dir, verbose)
        try:
            return _load_osm(cached, source=source)
        except ConversionError:
            if not hit:
                raise
        cached.unlink(missing_ok=True)  # a damaged cache entry: convert again
        return _load_osm(_cached_osm(source, cache_dir, verbose)[0], source=source)
    with tempfile.TemporaryDirectory(prefix="cold-maps-") as folder:
        osm = Path(folder) / "map.osm"
        osm.write_bytes(_convert_bytes(source, verbose))
        return _load_osm(osm, source=source)


def _load_osm(
    osm: Path, *, source: Path | None = None
) -> tuple[lanelet2.core.LaneletMap, lanelet2.routing.RoutingGraph]:
    import lanelet2.io

    named = str(source or osm)
    try:
        lanelet_map = lanelet2.io.load(str(osm), frame.projector())
    except Exception as exc:  # lanelet2 raises its own RuntimeError subclasses
        raise ConversionError(named, f"lanelet2 cannot load {osm}: {exc}") from exc
    if len(lanelet_map.laneletLayer) == 0:
        raise ConversionError(named, "the converted map has no lanelets")
    return lanelet_map, routing_graph(lanelet_map)


def configure_convert(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``cold-maps convert``: MAP.xodr -o MAP.osm [--no-cache] (the command
    itself, with its output conventions, is ``cold_maps.cli.maps``)."""
    parser.add_argument("xodr", metavar="MAP.xodr", help="OpenDRIVE map")
    parser.add_argument("-o", "--output", metavar="MAP.osm", required=True, help="Lanelet2 OSM file to write")
    parser.add_argument("--no-cache", action="store_true", help="convert again; neither use nor fill the cache")
