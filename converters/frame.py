"""The frame convention of the OSM files we write, and the recipe to load them.

A Lanelet2 OSM file stores latitude and longitude, so a frame needs a projector. We
store every point as the exact inverse of ``lanelet2.projection.MercatorProjector``
with origin (0°, 0°): ``lon = x / R``, ``lat = 2·atan(exp(y / R)) − π/2`` (R = 6 378 137
m, the projector's sphere). Loading with that projector returns the OpenDRIVE inertial
x, y to ~1e-9 m anywhere within ±2e7 m, whatever the map's geoReference says (zone-free,
unlike the UTM projector). ``lanelet2.io.load(path, Origin(0, 0))`` is equivalent: it
defaults to the same spherical Mercator projector. The geoReference is recorded in the file, never applied:
latitude and longitude are therefore not geographic positions for georeferenced maps.
"""

from __future__ import annotations

import json
import shlex
from dataclasses import dataclass
from typing import TYPE_CHECKING, Final

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    import lanelet2.projection

FORMAT_VERSION: Final[int] = 8
"""Version of our OSM layout and frame convention; part of the cache key (8: lanes of
type connectingRamp are converted too)."""

GENERATOR_PREFIX: Final[str] = "cold-maps-converters/"
"""Start of the ``generator`` attribute of ``<osm>`` in every file we write; every
format version shares the frame convention below."""

GENERATOR: Final[str] = f"{GENERATOR_PREFIX}{FORMAT_VERSION}"
"""``generator`` attribute of the files this version writes."""

PROJECTOR_CLASS: Final[str] = "MercatorProjector"
"""``lanelet2.projection`` class that maps our files to the inertial frame."""

ORIGIN_LAT_DEG: Final[float] = 0.0
ORIGIN_LON_DEG: Final[float] = 0.0


EARTH_RADIUS_M: Final[float] = 6378137.0
"""Radius (m) of the sphere of lanelet2's ``MercatorProjector``."""


def lat_lon_deg(x: npt.NDArray[np.float64], y: npt.NDArray[np.float64]) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]]:
    """Latitude and longitude (degrees) our files store for inertial x, y (m): the inverse
    of ``projector()``, vectorised (equal to its ``reverse`` within 3e-14 degrees, 3 nm)."""
    lat = np.arctan(np.exp(y / EARTH_RADIUS_M)) * 360.0 / np.pi - 90.0
    lon = x * 180.0 / (np.pi * EARTH_RADIUS_M)
    return lat, lon


def projector() -> lanelet2.projection.Projector:
    """The lanelet2 projector of our files (lanelet2 imported here, lazily)."""
    import lanelet2.io
    import lanelet2.projection

    return getattr(lanelet2.projection, PROJECTOR_CLASS)(lanelet2.io.Origin(ORIGIN_LAT_DEG, ORIGIN_LON_DEG))


@dataclass(frozen=True)
class LoadRecipe:
    """How to load one converted OSM file with plain lanelet2 in the OpenDRIVE frame.

    Fields:
        osm_path: the OSM file written.
        projector: ``lanelet2.projection`` class name.
        origin_lat_deg, origin_lon_deg: the projector's origin (degrees).
        geo_reference: the source map's geoReference PROJ string ("" when absent);
            recorded for reference, not applied to the coordinates.
        lanelets: number of lanelets written.
    """

    osm_path: str
    projector: str = PROJECTOR_CLASS
    origin_lat_deg: float = ORIGIN_LAT_DEG
    origin_lon_deg: float = ORIGIN_LON_DEG
    geo_reference: str = ""
    lanelets: int = 0

    def python_snippet(self) -> str:
        """A shell command that loads the file with plain lanelet2 in the inertial frame."""
        code = (
            "import lanelet2; from lanelet2.io import Origin; "
            f"from lanelet2.projection import {self.projector}; "
            f"m = lanelet2.io.load({json.dumps(self.osm_path)}, "
            f"{self.projector}(Origin({self.origin_lat_deg!r}, {self.origin_lon_deg!r}))); "
            'print(len(m.laneletLayer), "lanelets")'
        )
        return f"python -c {shlex.quote(code)}"

    def describe(self) -> str:
        """Human-readable recipe: file, projector, origin and the load command."""
        geo = self.geo_reference or "(none)"
        return (
            f"wrote {self.osm_path}: {self.lanelets} lanelets in the OpenDRIVE inertial frame\n"
            f"projector: lanelet2.projection.{self.projector}, origin "
            f"lat={self.origin_lat_deg!r} lon={self.origin_lon_deg!r} (lat/lon are not geographic)\n"
            f"source geoReference (not applied): {geo}\n"
            f"load with: {self.python_snippet()}"
        )
