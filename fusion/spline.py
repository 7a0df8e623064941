"""Gap interpolation for spline fusion (paper sec. III-B) and the G1 Hermite variant.

Both work on one border in the world frame and return the points strictly inside the gap,
at most ``spacing_m`` apart, from the ego border's last point to the coop border's first.
"""

from __future__ import annotations

import math
from typing import Final, Sequence

import numpy as np

from fusion.geometry import EndFit, fit_end, noise_level, sample_curve
from fusion.types import NDArrayFloat

_MIN_ARC_TURN_RAD: Final[float] = 1e-3
_MIN_KNOT_STEP_M: Final[float] = 1e-9
_NOISE_SAMPLE_M: Final[float] = 5.0
_WINDOWS_M: Final[tuple[float, ...]] = (2.0, 3.0, 4.5, 6.0)


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def estimate_apex(p_end: NDArrayFloat, d_end: tuple[float, float], p_start: NDArrayFloat,
                  d_start: tuple[float, float], ratio: float) -> NDArrayFloat | None:
    """Paper's apex estimate P_c = P_i + ratio·(P_j − P_i) (eq. 2).

    P_i is the intersection of the ego end tangent line (point ``p_end``, direction ``d_end``)
    with the coop start tangent line (``p_start``, ``d_start``); P_j is the foot of P_i on the
    chord ``p_end → p_start``. Returns ``None`` when the tangents are parallel or P_i does not
    lie ahead of the ego end and behind the coop start (no single curve between them).
    """
    chord = p_start - p_end
    denom = _cross(d_end[0], d_end[1], d_start[0], d_start[1])
    if abs(denom) < 1e-9:
        return None
    a = _cross(chord[0], chord[1], d_start[0], d_start[1]) / denom
    b = _cross(d_end[0], d_end[1], chord[0], chord[1]) / denom
    if a <= 0.0 or b <= 0.0:
        return None
    p_i = p_end + a * np.asarray(d_end)
    c2 = float(chord @ chord)
    p_j = p_end + chord * (float((p_i - p_end) @ chord) / c2)
    return p_i + ratio * (p_j - p_i)


def natural_spline_moments(h: NDArrayFloat, y: NDArrayFloat) -> NDArrayFloat:
    """Second derivatives M of the natural cubic spline through ``y`` (knot steps ``h``).

    Solves the paper's tridiagonal system (eq. 4) with M_0 = M_n = 0 by the Thomas
    algorithm; ``y`` is ``(n+1, d)``, the result ``(n+1, d)``.
    """
    n = h.shape[0]
    moments = np.zeros_like(y)
    if n < 2:
        return moments
    slope = np.diff(y, axis=0) / h[:, None]
    rhs = slope[1:] - slope[:-1]
    diag = (h[:-1] + h[1:]) / 3.0
    off = h[1:-1] / 6.0
    m = n - 1
    c = np.empty(m)
    d = np.empty_like(rhs)
    c[0] = (off[0] / diag[0]) if m > 1 else 0.0
    d[0] = rhs[0] / diag[0]
    for i in range(1, m):
        denom = diag[i] - off[i - 1] * c[i - 1]
        c[i] = off[i] / denom if i < m - 1 else 0.0
        d[i] = (rhs[i] - off[i - 1] * d[i - 1]) / denom
    for i in range(m - 2, -1, -1):
        d[i] = d[i] - c[i] * d[i + 1]
    moments[1:-1] = d
    return moments


def paper_gap(ego: NDArrayFloat, coop: NDArrayFloat, apex_min_turn_rad: float, apex_ratio: float,
              spacing_m: float, uniform: bool = False) -> NDArrayFloat:
    """The paper's spline through ego[-3], ego[-1], (apex), coop[0], coop[2], sampled in the gap.

    The spline is parametric in cumulative chord length (a 90° curve is not a function
    y(x)), or in the knot index with ``uniform``, with natural boundary conditions. The apex P_c is added when the end directions
    ego[-3]→ego[-1] and coop[0]→coop[2] differ by more than ``apex_min_turn_rad``.
    """
    e0, e1 = ego[max(0, ego.shape[0] - 3)], ego[-1]
    c0, c1 = coop[0], coop[min(2, coop.shape[0] - 1)]
    knots = [e0, e1]
    de, dc = e1 - e0, c1 - c0
    ne, nc = math.hypot(de[0], de[1]) or 1.0, math.hypot(dc[0], dc[1]) or 1.0
    de_u, dc_u = (de[0] / ne, de[1] / ne), (dc[0] / nc, dc[1] / nc)
    turn = math.atan2(_cross(*de_u, *dc_u), de_u[0] * dc_u[0] + de_u[1] * dc_u[1])
    if abs(turn) > apex_min_turn_rad:
        apex = estimate_apex(e1, de_u, c0, dc_u, apex_ratio)
        if apex is not None:
            knots.append(apex)
    knots += [c0, c1]
    q = np.array(knots)
    chords = np.hypot(*np.diff(q, axis=0).T)
    keep = np.concatenate(([True], chords > _MIN_KNOT_STEP_M))
    if not keep.all():
        q, chords = q[keep], chords[keep[1:]]
    h = np.ones_like(chords) if uniform else chords
    t = np.concatenate(([0.0], np.cumsum(h)))
    moments = natural_spline_moments(h, q)

    def evaluate(u: NDArrayFloat) -> NDArrayFloat:
        i = np.clip(np.searchsorted(t, u, side="right") - 1, 0, h.shape[0] - 1)
        hi = h[i][:, None]
        a = (t[i + 1][:, None] - u[:, None])
        b = (u[:, None] - t[i][:, None])
        return ((moments[i] * a**3 + moments[i + 1] * b**3) / (6.0 * hi)
                + (q[i] / hi - moments[i] * hi / 6.0) * a
                + (q[i + 1] / hi - moments[i + 1] * hi / 6.0) * b)

    first, last = 1, q.shape[0] - 2
    return sample_curve(evaluate, float(t[first]), float(t[last]), float(chords[first:last].sum()), spacing_m)


def _bezier_gap(p0: NDArrayFloat, d0: NDArrayFloat, p3: NDArrayFloat, d1: NDArrayFloat,
                spacing_m: float) -> NDArrayFloat:
    """Cubic Bézier with arms of a third of the chord (straight or S-shaped transition)."""
    arm = math.hypot(*(p3 - p0)) / 3.0
    ctrl = np.array([p0, p0 + arm * d0, p3 - arm * d1, p3])

    def evaluate(u: NDArrayFloat) -> NDArrayFloat:
        v = 1.0 - u
        basis = np.stack((v**3, 3.0 * v * v * u, 3.0 * v * u * u, u**3), axis=1)
        return basis @ ctrl

    return sample_curve(evaluate, 0.0, 1.0, 3.0 * arm, spacing_m)


def _mean_dir(a: tuple[float, float], b: tuple[float, float]) -> NDArrayFloat:
    d = np.array((a[0] + b[0], a[1] + b[1]))
    return d / (math.hypot(d[0], d[1]) or 1.0)


def hermite_lane(fits: Sequence[EndFit], spacing_m: float) -> tuple[NDArrayFloat, NDArrayFloat]:
    """G1 gap interpolation of both borders of a lane; returns the (left, right) gap points.

    ``fits`` are the least-squares end fits of (ego left, ego right, coop left, coop right)
    from :func:`lane_end_fits`; the end directions of the two borders are averaged (the
    borders of a lane are parallel), which halves the heading variance. Each border's gap
    is :func:`hermite_gap` between the fitted ends.
    """
    d0 = _mean_dir(fits[0].direction, fits[1].direction)
    d1 = _mean_dir(fits[2].direction, fits[3].direction)
    return (hermite_gap(fits[0].point, d0, fits[2].point, d1, spacing_m),
            hermite_gap(fits[1].point, d0, fits[3].point, d1, spacing_m))


def lane_end_fits(ego: tuple[NDArrayFloat, NDArrayFloat], coop: tuple[NDArrayFloat, NDArrayFloat],
                  window_m: float | None, spacing_m: float) -> tuple[EndFit, EndFit, EndFit, EndFit]:
    """End fits of (ego left, ego right) at their ends and (coop left, coop right) at their starts.

    Windows: ``window_m``, or with ``None`` adaptive among 2–6 m from the noise σ estimated
    on the last/first 5 m of the four borders (:func:`fusion.geometry.fit_end`).
    """
    count = max(3, int(round(_NOISE_SAMPLE_M / spacing_m)))
    sigma = (sum(noise_level(b, count) for b in ego) + sum(noise_level(b[::-1], count) for b in coop)) / 4.0
    windows = _WINDOWS_M if window_m is None else (window_m,)
    return (fit_end(ego[0], True, windows, sigma), fit_end(ego[1], True, windows, sigma),
            fit_end(coop[0], False, windows, sigma), fit_end(coop[1], False, windows, sigma))


def hermite_gap(p0: NDArrayFloat, d0: NDArrayFloat, p3: NDArrayFloat, d1: NDArrayFloat,
                spacing_m: float) -> NDArrayFloat:
    """G1 Hermite interpolation from ``p0`` (direction ``d0``) to ``p3`` (``d1``), world frame.

    The two tangent lines meet at P_i, at distance a from p0 and b from p3. The curve is the
    largest circular arc tangent to both lines (tangent length m = min(a, b), radius
    m / tan(θ/2) for the turn θ) preceded or followed by a straight of length |a − b| on the
    longer side. A circular arc between the ends is therefore reproduced exactly (a = b),
    and so is a curve that starts or ends inside the gap; it is sampled in closed form every
    ≤ ``spacing_m``, ends excluded. (A cubic Bézier with arms (4/3)·R·tan(θ/4) would
    approximate the same arc to 3·10⁻⁴·R.) Parallel or S-shaped end tangents (no triangle
    ahead of both ends) use a cubic Bézier with arms of a third of the chord.
    """
    chord = p3 - p0
    denom = _cross(d0[0], d0[1], d1[0], d1[1])
    turn = math.atan2(denom, float(d0 @ d1))
    if abs(turn) < _MIN_ARC_TURN_RAD:
        return _bezier_gap(p0, d0, p3, d1, spacing_m)
    a = _cross(chord[0], chord[1], d1[0], d1[1]) / denom
    b = _cross(d0[0], d0[1], chord[0], chord[1]) / denom
    if a <= 0.0 or b <= 0.0:
        return _bezier_gap(p0, d0, p3, d1, spacing_m)
    m = min(a, b)
    radius = m / math.tan(abs(turn) / 2.0)
    kappa = math.copysign(1.0 / radius, turn)
    lead, arc, tail = a - m, radius * abs(turn), b - m
    total = lead + arc + tail
    n_steps = math.ceil(total / spacing_m * (1.0 + 1e-9))
    if n_steps < 2:
        return np.empty((0, 2))
    u = np.linspace(0.0, total, n_steps + 1)[1:-1]
    t0 = p0 + lead * d0
    psi0 = math.atan2(d0[1], d0[0])
    ua = np.clip(u - lead, 0.0, arc)
    heading = psi0 + kappa * ua
    out = np.empty((u.shape[0], 2))
    out[:, 0] = t0[0] + (np.sin(heading) - math.sin(psi0)) / kappa
    out[:, 1] = t0[1] - (np.cos(heading) - math.cos(psi0)) / kappa
    before = u < lead
    out[before] = p0 + u[before, None] * d0
    after = u > lead + arc
    out[after] = (p3 - b * d1 + m * d1) + (u[after] - lead - arc)[:, None] * d1
    return out
