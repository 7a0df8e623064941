"""``<line>``: a straight reference-line record."""

from __future__ import annotations

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import Geometry


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    ds = np.asarray(ds, dtype=np.float64)
    return (
        geom.x + ds * np.cos(geom.hdg),
        geom.y + ds * np.sin(geom.hdg),
        np.full(ds.shape, geom.hdg),
    )
