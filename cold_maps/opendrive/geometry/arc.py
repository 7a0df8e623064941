"""``<arc>``: constant curvature (positive = left turn).

Positions use the chord form, chord = ds·sinc(k·ds/2) along the mean heading
hdg + k·ds/2, so there is no centre point and no cancellation for tiny curvature or
far from the origin; k = 0 degenerates exactly to a line.
"""

from __future__ import annotations

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import Geometry


def chord_pose(
    x0: float, y0: float, hdg0: float, curvature: float, ds: NDArrayFloat
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Pose (m, m, rad) at arc length ds along a circle of the given curvature (1/m)."""
    half_turn = 0.5 * curvature * ds
    chord = ds * np.sinc(half_turn / np.pi)
    mean_heading = hdg0 + half_turn
    return x0 + chord * np.cos(mean_heading), y0 + chord * np.sin(mean_heading), hdg0 + 2.0 * half_turn


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    return chord_pose(geom.x, geom.y, geom.hdg, geom.curvature, np.asarray(ds, dtype=np.float64))
