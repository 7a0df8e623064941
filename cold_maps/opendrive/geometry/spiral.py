"""``<spiral>``: exact clothoid, curvature linear from curvStart to curvEnd over the length.

With rate c = (curvEnd - curvStart)/length the heading is hdg + k0·u + c·u²/2. Completing
the square, u + k0/c = w, turns the position integral into Fresnel integrals
(scipy.special.fresnel) of w·sqrt(|c|/π); this covers spirals that start at any curvature
and curvature sign changes. When the curvature is constant to within a lateral deviation
|c|·length³/6 below ``ARC_FALLBACK_DEVIATION_M`` the record is evaluated as an arc of
curvature k0 (the Fresnel form would divide by c ≈ 0).
"""

from __future__ import annotations

from typing import Final

import numpy as np
from scipy.special import fresnel

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.geometry.arc import chord_pose
from cold_maps.opendrive.model import Geometry

ARC_FALLBACK_DEVIATION_M: Final[float] = 1e-10


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    ds = np.asarray(ds, dtype=np.float64)
    k0 = geom.curv_start
    rate = (geom.curv_end - geom.curv_start) / geom.length
    heading = geom.hdg + ds * (k0 + 0.5 * rate * ds)
    if abs(rate) * geom.length**3 / 6.0 < ARC_FALLBACK_DEVIATION_M:
        x, y, _ = chord_pose(geom.x, geom.y, geom.hdg, k0, ds)
        return x, y, heading
    sign = np.sign(rate)
    scale = np.sqrt(np.pi / abs(rate))
    w0 = k0 / rate
    s_start, c_start = fresnel(w0 / scale)
    s_end, c_end = fresnel((ds + w0) / scale)
    phase = geom.hdg - 0.5 * k0 * w0
    re = scale * (c_end - c_start)
    im = scale * sign * (s_end - s_start)
    cos_p, sin_p = np.cos(phase), np.sin(phase)
    return geom.x + re * cos_p - im * sin_p, geom.y + re * sin_p + im * cos_p, heading
