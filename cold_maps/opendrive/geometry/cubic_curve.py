"""A planar cubic curve (u(p), v(p)) in a record's local frame, evaluated by arc length.

Shared by ``poly3`` (u = p) and ``paramPoly3``. The arc length S(p) = ∫ |r'(p)| dp is
tabulated with 8-point Gauss–Legendre quadrature on uniform p intervals; a target arc
length is located in the table, interpolated linearly, then refined by safeguarded Newton
steps on S(p) - s (each S(p) again by Gauss–Legendre from the table node), which reaches
the float64 round-off of S, far below 0.1 mm.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Final

import numpy as np
import numpy.typing as npt

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.model import Geometry

GAUSS_ORDER: Final[int] = 8
TABLE_INTERVAL_M: Final[float] = 2.0
MAX_TABLE_INTERVALS: Final[int] = 4096
NEWTON_ITERATIONS: Final[int] = 8
NEWTON_TOLERANCE_M: Final[float] = 1e-12
NEWTON_CHUNK: Final[int] = 2048
"""Rows whose quadrature nodes ``stacked_parameters`` evaluates at once (their (nodes, rows)
arrays stay in the processor's cache)."""
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


@dataclass(frozen=True)
class CurveStack:
    """Arc-length tables of several curves end to end, for ``stacked_parameters``.

    Fields:
        params: (M,) each table's parameters, table after table.
        lengths: (M,) each table's cumulative arc lengths (m), table after table.
        first: (n,) index into ``params`` of each table's first entry.
        last: (n,) each table's last interval (its size - 2).
        coefficients: (8, n) u[0..3] and v[0..3] (m) of each table's curve.
    """

    params: NDArrayFloat
    lengths: NDArrayFloat
    first: npt.NDArray[np.int64]
    last: npt.NDArray[np.int64]
    coefficients: NDArrayFloat


def curve_stack(tables: Sequence[ArcLengthTable]) -> CurveStack:
    """The ``CurveStack`` of these tables."""
    sizes = np.array([table.params.size for table in tables], dtype=np.int64)
    return CurveStack(
        np.concatenate([table.params for table in tables] or [np.zeros(0)]),
        np.concatenate([table.lengths for table in tables] or [np.zeros(0)]),
        np.cumsum(sizes) - sizes, sizes - 2,
        np.array([table.curve.u + table.curve.v for table in tables], dtype=np.float64).reshape(-1, 8).T.copy())


def stacked_parameters(
    stack: CurveStack, which: npt.NDArray[np.int64], s: NDArrayFloat, counts: npt.NDArray[np.int64]
) -> NDArrayFloat:
    """``ArcLengthTable.parameter`` of the stack's table ``which[i]`` of each consecutive
    block of ``counts[i]`` arc lengths (m) in ``s``, bit for bit, evaluated together: the
    Newton steps of a block stop together, as in one call, and each block's quadrature
    sums are its own matrix product (OpenBLAS rounds a row by its place in the product)."""
    s = np.asarray(s, dtype=np.float64)
    bounds = np.concatenate(([0], np.cumsum(counts))).astype(np.int64)
    first, last = stack.first[which], stack.last[which]
    found = [np.searchsorted(stack.lengths[f:f + n + 2], s[a:b], side="right")
             for f, n, a, b in zip(first.tolist(), last.tolist(), bounds[:-1].tolist(), bounds[1:].tolist())]
    last = np.repeat(last, counts)
    k = np.minimum(np.maximum(np.concatenate(found or [np.zeros(0, dtype=np.int64)]) - 1, 0), last)
    at = np.repeat(first, counts) + k
    p_lo, p_hi, s_lo, s_hi = stack.params[at], stack.params[at + 1], stack.lengths[at], stack.lengths[at + 1]
    span = np.where(s_hi > s_lo, s_hi - s_lo, 1.0)
    p = p_lo + (s - s_lo) / span * (p_hi - p_lo)
    upper = np.where(k == last, np.inf, p_hi)
    _, u1, u2, u3, _, v1, v2, v3 = np.repeat(stack.coefficients[:, which], counts, axis=1)
    active = np.flatnonzero(np.diff(bounds) > 0)  # blocks still iterating
    for _ in range(NEWTON_ITERATIONS):
        if not len(active):
            break
        blocks = np.diff(bounds)[active]
        ends = np.cumsum(blocks)
        rows: slice | np.ndarray = slice(None) if ends[-1] == len(s) else (  # all of them: views, no copies
            np.arange(ends[-1]) + np.repeat(bounds[active] - (ends - blocks), blocks))
        lo, now, c1, c2, c3, d1, d2, d3 = (a[rows] for a in (p_lo, p, u1, u2, u3, v1, v2, v3))
        half, mid = 0.5 * (now - lo), 0.5 * (now + lo)
        speeds = np.empty((len(now), GAUSS_ORDER))
        for a in range(0, len(now), NEWTON_CHUNK):
            b = a + NEWTON_CHUNK
            nodes = np.multiply(half[a:b], _NODES[:, None])  # (nodes, rows): long inner loops
            nodes += mid[a:b]
            speeds[a:b] = np.hypot(_tangent_at(nodes, c1[a:b], c2[a:b], c3[a:b]),
                                   _tangent_at(nodes, d1[a:b], d2[a:b], d3[a:b])).T
        sums = np.concatenate([speeds[b - n:b] @ _WEIGHTS for b, n in zip(ends.tolist(), blocks.tolist())])
        residual = s_lo[rows] + half * sums - s[rows]
        speed = np.hypot(c1 + now * (2.0 * c2 + now * 3.0 * c3), d1 + now * (2.0 * d2 + now * 3.0 * d3))
        p[rows] = np.clip(now - residual / np.maximum(speed, 1e-12), lo, upper[rows])
        active = active[~(np.maximum.reduceat(np.abs(residual), ends - blocks) < NEWTON_TOLERANCE_M)]
    return p


def _tangent_at(nodes: NDArrayFloat, c1: NDArrayFloat, c2: NDArrayFloat, c3: NDArrayFloat) -> NDArrayFloat:
    """c1 + p·(2·c2 + p·3·c3) at the (K, N) parameters ``nodes``, one coefficient per
    column, in ``CubicCurve.tangent``'s order of operations (in place: the arrays are large)."""
    value = np.multiply(nodes, 3.0)
    value *= c3
    value += 2.0 * c2
    value *= nodes
    value += c1
    return value


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


def stacked_poses(
    coefficients: NDArrayFloat, starts: NDArrayFloat, p: NDArrayFloat, counts: npt.NDArray[np.int64]
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """``pose_at_parameter`` of curves of ``coefficients`` (8, n; u[0..3], v[0..3], m)
    whose records start at ``starts`` (3, n, C order; x, y in m, heading in rad) at each
    consecutive block of ``counts[i]`` parameters in ``p``, bit for bit."""
    u0, u1, u2, u3, v0, v1, v2, v3 = np.repeat(coefficients, counts, axis=1)
    cos_h, sin_h = (np.repeat(f(starts[2]), counts) for f in (np.cos, np.sin))
    u, v = u0 + p * (u1 + p * (u2 + p * u3)), v0 + p * (v1 + p * (v2 + p * v3))
    du, dv = u1 + p * (2.0 * u2 + p * 3.0 * u3), v1 + p * (2.0 * v2 + p * 3.0 * v3)
    x0, y0, hdg0 = np.repeat(starts, counts, axis=1)
    return x0 + u * cos_h - v * sin_h, y0 + u * sin_h + v * cos_h, hdg0 + np.arctan2(dv, du)


def pose_at_parameter(
    geom: Geometry, curve: CubicCurve, p: NDArrayFloat
) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) of the curve point at parameter p."""
    u, v = curve.point(p)
    du, dv = curve.tangent(p)
    cos_h, sin_h = np.cos(geom.hdg), np.sin(geom.hdg)
    return geom.x + u * cos_h - v * sin_h, geom.y + u * sin_h + v * cos_h, geom.hdg + np.arctan2(dv, du)
