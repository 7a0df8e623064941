"""A planar cubic curve (u(p), v(p)) in a record's local frame, evaluated by arc length.

Shared by ``poly3`` (u = p) and ``paramPoly3``. The arc length S(p) = ∫ |r'(p)| dp is
tabulated with 8-point Gauss–Legendre quadrature on uniform p intervals; a target arc
length is located in the table, interpolated linearly, then refined by safeguarded Newton
steps on S(p) - s (each S(p) again by Gauss–Legendre from the table node), which reaches
the float64 round-off of S, far below 0.1 mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Final

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import Geometry

GAUSS_ORDER: Final[int] = 8
TABLE_INTERVAL_M: Final[float] = 2.0
MAX_TABLE_INTERVALS: Final[int] = 4096
NEWTON_ITERATIONS: Final[int] = 8
NEWTON_TOLERANCE_M: Final[float] = 1e-12
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(GAUSS_ORDER)


@dataclass(frozen=True)
class CubicCurve:
    """u(p) = u[0] + u[1]·p + u[2]·p² + u[3]·p³ and likewise v(p), in metres, p in [0, p_end]."""

    u: tuple[float, float, float, float]
    v: tuple[float, float, float, float]
    p_end: float

    def point(self, p: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Local (u, v) at parameter p (m)."""
        u, v = self.u, self.v
        return (
            u[0] + p * (u[1] + p * (u[2] + p * u[3])),
            v[0] + p * (v[1] + p * (v[2] + p * v[3])),
        )

    def tangent(self, p: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
        """(du/dp, dv/dp) at parameter p."""
        u, v = self.u, self.v
        return u[1] + p * (2.0 * u[2] + p * 3.0 * u[3]), v[1] + p * (2.0 * v[2] + p * 3.0 * v[3])

    def speed(self, p: NDArrayFloat) -> NDArrayFloat:
        """|r'(p)| (m per unit p)."""
        return np.hypot(*self.tangent(p))

    def integral(self, p_from: NDArrayFloat, p_to: NDArrayFloat) -> NDArrayFloat:
        """Arc length (m) from p_from to p_to, Gauss–Legendre on the whole span."""
        half = 0.5 * (p_to - p_from)
        mid = 0.5 * (p_to + p_from)
        nodes = mid[..., None] + half[..., None] * _NODES
        return half * (self.speed(nodes) @ _WEIGHTS)


@dataclass(frozen=True)
class ArcLengthTable:
    """Cumulative arc length ``lengths`` (m) at the parameters ``params`` of a curve."""

    curve: CubicCurve
    params: NDArrayFloat
    lengths: NDArrayFloat

    @property
    def total(self) -> float:
        """Arc length of the whole curve (m)."""
        return float(self.lengths[-1])

    def parameter(self, s: NDArrayFloat) -> NDArrayFloat:
        """Parameter p at arc length s (m) from the curve start."""
        s = np.asarray(s, dtype=np.float64)
        n = self.params.size - 1
        k = np.clip(np.searchsorted(self.lengths, s, side="right") - 1, 0, n - 1)
        p_lo, p_hi = self.params[k], self.params[k + 1]
        s_lo, s_hi = self.lengths[k], self.lengths[k + 1]
        span = np.where(s_hi > s_lo, s_hi - s_lo, 1.0)
        p = p_lo + (s - s_lo) / span * (p_hi - p_lo)
        upper = np.where(k == n - 1, np.inf, p_hi)
        for _ in range(NEWTON_ITERATIONS):
            residual = s_lo + self.curve.integral(p_lo, p) - s
            step = residual / np.maximum(self.curve.speed(p), 1e-12)
            p = np.clip(p - step, p_lo, upper)
            if np.max(np.abs(residual), initial=0.0) < NEWTON_TOLERANCE_M:
                break
        return p


@lru_cache(maxsize=8192)
def arc_length_table(curve: CubicCurve) -> ArcLengthTable:
    """Arc-length table of a curve over [0, p_end] (cached: curves are immutable).

    ValueError when the arc length is not finite."""
    approx = float(curve.integral(np.array(0.0), np.array(curve.p_end)))
    if not np.isfinite(approx):
        raise ValueError(f"cubic curve over p in [0, {curve.p_end:.6g}]: its arc length is not finite "
                         "(coefficients too large)")
    intervals = int(np.clip(np.ceil(approx / TABLE_INTERVAL_M), 8, MAX_TABLE_INTERVALS))
    params = np.linspace(0.0, curve.p_end, intervals + 1)
    pieces = curve.integral(params[:-1], params[1:])
    return ArcLengthTable(curve, params, np.concatenate(([0.0], np.cumsum(pieces))))


def pose_at_parameter(
    geom: Geometry, curve: CubicCurve, p: NDArrayFloat
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) of the curve point at parameter p."""
    u, v = curve.point(p)
    du, dv = curve.tangent(p)
    cos_h, sin_h = np.cos(geom.hdg), np.sin(geom.hdg)
    return geom.x + u * cos_h - v * sin_h, geom.y + u * sin_h + v * cos_h, geom.hdg + np.arctan2(dv, du)
