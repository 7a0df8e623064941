"""``<paramPoly3>``: u(p), v(p) cubic in the local frame, pRange "arcLength" or "normalized".

p runs over [0, length] ("arcLength") or [0, 1] ("normalized"). ds is true arc length:
p(ds) inverts the arc-length integral (see ``cubic_curve``). The record's ``length`` is
taken as the curve's arc length; when the polynomial's own length S differs from it
(rounding in the writing tool), ds is scaled by S/length so the record still ends at
p_end, keeping consecutive records continuous.
"""

from __future__ import annotations

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.geometry.cubic_curve import CubicCurve, arc_length_table, pose_at_parameter
from cold_maps.opendrive.model import Geometry


def curve_of(geom: Geometry) -> CubicCurve:
    """The record's local cubic curve with its parameter range."""
    p_end = geom.length if geom.p_range == "arcLength" else 1.0
    return CubicCurve(
        u=(geom.au, geom.bu, geom.cu, geom.du), v=(geom.av, geom.bv, geom.cv, geom.dv), p_end=p_end
    )


def is_single_point(geom: Geometry) -> bool:
    """True for a paramPoly3 whose u(p), v(p) are constant (every coefficient but aU, aV
    is 0: RoadRunner's empty ``<paramPoly3/>``): the record draws one point."""
    return geom.kind == "paramPoly3" and not any((geom.bu, geom.cu, geom.du, geom.bv, geom.cv, geom.dv))


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    curve = curve_of(geom)
    table = arc_length_table(curve)
    if not table.total > 0.0:
        raise ValueError(f"paramPoly3 at s={geom.s}: u(p), v(p) describe a single point (zero arc length)")
    p = table.parameter(np.asarray(ds, dtype=np.float64) * (table.total / geom.length))
    return pose_at_parameter(geom, curve, p)
