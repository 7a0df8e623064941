"""Inertial frame → WGS84 longitude/latitude through the map's ``<geoReference>``.

The ``<header><offset>`` places the inertial frame in the projected CRS of the PROJ
string: a point is rotated by ``offset_hdg`` about z, then shifted by (``offset_x``,
``offset_y``, ``offset_z``) (ASAM OpenDRIVE 1.6+ §"Coordinate systems", as ASAM OSI's
``ProjFrameOffset``). The projected x, y then go through pyproj to EPSG:4326 in
longitude, latitude order (RFC 7946). Only the horizontal CRS is used (a vertical grid
such as CARLA's ``+geoidgrids=egm96_15.gtx`` need not be installed); heights stay
z + ``offset_z`` in the map's own vertical datum. pyproj is imported lazily.
"""

from __future__ import annotations

import math
from typing import Final

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import GeoReference

WGS84: Final[str] = "EPSG:4326"
"""The geographic CRS of RFC 7946 (lon, lat in degrees)."""


class NoGeoReferenceError(ValueError):
    """The map has no usable ``<geoReference>``, so it cannot be placed on the earth."""


def to_projected(geo: GeoReference, xyz: NDArrayFloat) -> NDArrayFloat:
    """(N, 3) inertial points (m) → (N, 3) points in the projected CRS (m) via ``<offset>``."""
    xyz = np.asarray(xyz, dtype=np.float64)
    cos, sin = math.cos(geo.offset_hdg), math.sin(geo.offset_hdg)
    x = cos * xyz[:, 0] - sin * xyz[:, 1] + geo.offset_x
    y = sin * xyz[:, 0] + cos * xyz[:, 1] + geo.offset_y
    return np.column_stack((x, y, xyz[:, 2] + geo.offset_z))


class Wgs84Transform:
    """Callable (N, 3) inertial points (m) → (N, 3) lon (deg), lat (deg), height (m).

    Raises ``NoGeoReferenceError`` for a map without a geoReference or with one pyproj
    cannot read, naming the PROJ string.
    """

    def __init__(self, geo: GeoReference) -> None:
        if not geo.proj:
            raise NoGeoReferenceError("the map has no <geoReference>")
        import pyproj

        try:
            crs = pyproj.CRS.from_user_input(geo.proj)
            source = crs.to_2d()
            self._transformer = pyproj.Transformer.from_crs(source, WGS84, always_xy=True)
        except pyproj.exceptions.CRSError as exc:
            raise NoGeoReferenceError(f"pyproj cannot read the <geoReference> {geo.proj[:80]!r}: {exc}") from None
        self._geo = geo

    def __call__(self, xyz: NDArrayFloat) -> NDArrayFloat:
        projected = to_projected(self._geo, xyz)
        lon, lat = self._transformer.transform(projected[:, 0], projected[:, 1])
        result = np.column_stack((lon, lat, projected[:, 2]))
        if not np.all(np.isfinite(result)):
            raise NoGeoReferenceError(f"the <geoReference> {self._geo.proj[:80]!r} maps points outside its domain")
        return result
