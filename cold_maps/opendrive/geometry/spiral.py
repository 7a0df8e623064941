"""``<spiral>``: exact clothoid, curvature linear from curvStart to curvEnd over the length.

With rate c = (curvEnd - curvStart)/length the heading is hdg + k0·u + c·u²/2. Completing
the square, u + k0/c = w, turns the position integral into Fresnel integrals
(scipy.special.fresnel) of w·sqrt(|c|/π); this covers spirals that start at any curvature
and curvature sign changes.

The Fresnel form loses about 2e-16·|k0/c| m to round-off (it differences Fresnel values at
arguments shifted by k0/c) and overflows for c → 0. When that shift exceeds
``FRESNEL_MAX_SHIFT_M`` or the curvature change turns the heading by less than
``NEAR_ARC_TURN_RAD`` over the record (nearly constant curvature, including c = 0), the
record is evaluated as its starting arc (chord form) plus the small clothoid correction
∫ e^{i(hdg + k0·u)}·(e^{i·c·u²/2} - 1) du, which Gauss–Legendre quadrature resolves to a
tiny fraction of its already tiny size. A record so short that the rate overflows (a
length below ~1e-300 m) is its starting arc: the curvature change turns its heading by at
most |curvEnd - curvStart|·length/2, and that exactly (no more past the record's end).
"""

from __future__ import annotations

from typing import Final

import numpy as np
from scipy.special import fresnel

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.geometry.arc import chord_pose
from cold_maps.opendrive.model import Geometry

FRESNEL_MAX_SHIFT_M: Final[float] = 1e6
NEAR_ARC_TURN_RAD: Final[float] = 1e-3
CORRECTION_GAUSS_ORDER: Final[int] = 32
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(CORRECTION_GAUSS_ORDER)


def _fresnel_offset(k0: float, rate: float, hdg: float, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(dx, dy) in m from the start, by Fresnel integrals (rate != 0)."""
    sign = np.sign(rate)
    scale = np.sqrt(np.pi / abs(rate))
    w0 = k0 / rate
    s_start, c_start = fresnel(w0 / scale)
    s_end, c_end = fresnel((ds + w0) / scale)
    phase = hdg - 0.5 * k0 * w0
    re = scale * (c_end - c_start)
    im = scale * sign * (s_end - s_start)
    cos_p, sin_p = np.cos(phase), np.sin(phase)
    return re * cos_p - im * sin_p, re * sin_p + im * cos_p


def _correction_offset(k0: float, rate: float, hdg: float, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(dx, dy) in m of the clothoid from its starting arc, by Gauss–Legendre quadrature."""
    half = 0.5 * ds[..., None]
    u = half * (1.0 + _NODES)
    arc_phase = hdg + k0 * u
    extra = 0.5 * rate * u * u
    re_extra, im_extra = -2.0 * np.sin(0.5 * extra) ** 2, np.sin(extra)
    cos_a, sin_a = np.cos(arc_phase), np.sin(arc_phase)
    re = (cos_a * re_extra - sin_a * im_extra) * half
    im = (sin_a * re_extra + cos_a * im_extra) * half
    return re @ _WEIGHTS, im @ _WEIGHTS


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) from the record start."""
    ds = np.asarray(ds, dtype=np.float64)
    k0 = geom.curv_start
    change = geom.curv_end - geom.curv_start
    with np.errstate(over="ignore"):  # the rate of a record shorter than ~1e-300 m overflows: handled below
        rate = change / np.float64(geom.length)
    if not np.isfinite(rate):
        x, y, _ = chord_pose(geom.x, geom.y, geom.hdg, k0, ds)
        with np.errstate(over="ignore"):  # ds / length is capped at 1 (past the end of the record)
            fraction = np.minimum(ds / geom.length, 1.0)
        return x, y, geom.hdg + ds * k0 + 0.5 * change * geom.length * fraction * fraction
    heading = geom.hdg + ds * (k0 + 0.5 * rate * ds)
    if abs(k0) >= FRESNEL_MAX_SHIFT_M * abs(rate) or 0.5 * abs(rate) * geom.length**2 < NEAR_ARC_TURN_RAD:
        x, y, _ = chord_pose(geom.x, geom.y, geom.hdg, k0, ds)
        dx, dy = _correction_offset(k0, rate, geom.hdg, ds)
        return x + dx, y + dy, heading
    dx, dy = _fresnel_offset(k0, rate, geom.hdg, ds)
    return geom.x + dx, geom.y + dy, heading
