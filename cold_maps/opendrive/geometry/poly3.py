"""``<poly3>``: v(u) = a + b·u + c·u² + d·u³ in the local frame (u along the start heading).

ds is arc length along the curve: u(ds) inverts ∫₀ᵘ sqrt(1 + v'(x)²) dx (see
``cubic_curve``). Since that integral is ≥ u, the table over u in [0, length] covers
every ds in [0, length].
"""

from __future__ import annotations

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.geometry.cubic_curve import CubicCurve, arc_length_table, pose_at_parameter
from cold_maps.opendrive.model import Geometry


def curve_of(geom: Geometry) -> CubicCurve:
    """The record's local cubic curve, u over [0, length]."""
    return CubicCurve(u=(0.0, 1.0, 0.0, 0.0), v=(geom.a, geom.b, geom.c, geom.d), p_end=geom.length)


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    curve = curve_of(geom)
    u = arc_length_table(curve).parameter(np.asarray(ds, dtype=np.float64))
    return pose_at_parameter(geom, curve, u)
