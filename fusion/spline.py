"""Gap interpolation for spline fusion (paper sec. III-B) and the G1 Hermite variant.

Both work on one border in the world frame and return the points strictly inside the gap,
at most ``spacing_m`` apart, from the ego border's last point to the coop border's first.
"""

from __future__ import annotations

import math

import numpy as np

from fusion.geometry import fit_end_tangent, sample_curve
from fusion.types import NDArrayFloat


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
              spacing_m: float) -> NDArrayFloat:
    """The paper's spline through ego[-3], ego[-1], (apex), coop[0], coop[2], sampled in the gap.

    The spline is parametric in cumulative chord length (a 90° curve is not a function
    y(x)) with natural boundary conditions. The apex P_c is added when the end directions
    ego[-3]→ego[-1] and coop[0]→coop[2] differ by more than ``apex_min_turn_rad``.
    """
    e0, e1 = ego[max(0, ego.shape[0] - 3)], ego[-1]
    c0, c1 = coop[0], coop[min(2, coop.shape[0] - 1)]
    knots = [e0, e1]
    de, dc = e1 - e0, c1 - c0
    de_u = (de[0] / math.hypot(*de), de[1] / math.hypot(*de))
    dc_u = (dc[0] / math.hypot(*dc), dc[1] / math.hypot(*dc))
    turn = math.atan2(_cross(*de_u, *dc_u), de_u[0] * dc_u[0] + de_u[1] * dc_u[1])
    if abs(turn) > apex_min_turn_rad:
        apex = estimate_apex(e1, de_u, c0, dc_u, apex_ratio)
        if apex is not None:
            knots.append(apex)
    knots += [c0, c1]
    q = np.array(knots)
    h = np.hypot(*np.diff(q, axis=0).T)
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

    return sample_curve(evaluate, float(t[1]), float(t[-2]), float(t[-2] - t[1]), spacing_m)


def bezier_arm_factor(turn_rad: float) -> float:
    """Ratio of a cubic Bézier arm to the tangent-triangle leg that reproduces a circular arc.

    For an arc turning by θ the tangent legs are R·tan(θ/2) and the Bézier arm is
    (4/3)·R·tan(θ/4), so the factor is (4/3)·tan(θ/4)/tan(θ/2) (→ 2/3 for θ → 0).
    """
    theta = abs(turn_rad)
    if theta < 1e-6:
        return 2.0 / 3.0
    return (4.0 / 3.0) * math.tan(theta / 4.0) / math.tan(theta / 2.0)


def hermite_gap(ego: NDArrayFloat, coop: NDArrayFloat, window_m: float, spacing_m: float) -> NDArrayFloat:
    """G1 cubic Bézier from ego[-1] to coop[0], sampled in the gap.

    End directions come from least-squares fits over ``window_m`` of each detection
    (:func:`fusion.geometry.fit_end_tangent`). Arm lengths: the two tangent lines and the
    chord form a triangle with legs a (ego side) and b (coop side); the arms are
    a·k(θ) and b·k(θ) with :func:`bezier_arm_factor` k, which reproduces a circular arc
    (a = b) to within 3·10⁻⁴·R and stretches the arms for a curve starting later in the gap.
    For parallel or S-shaped tangents (no triangle) the arms are chord/3, a straight or
    symmetric transition.
    """
    p0, p3 = ego[-1], coop[0]
    d0 = fit_end_tangent(ego, True, window_m)
    d1 = fit_end_tangent(coop, False, window_m)
    chord = p3 - p0
    c = math.hypot(chord[0], chord[1])
    turn = math.atan2(_cross(*d0, *d1), d0[0] * d1[0] + d0[1] * d1[1])
    arm0 = arm1 = c / 3.0
    denom = _cross(d0[0], d0[1], d1[0], d1[1])
    if abs(turn) > 1e-3 and abs(denom) > 1e-9:
        a = _cross(chord[0], chord[1], d1[0], d1[1]) / denom
        b = _cross(d0[0], d0[1], chord[0], chord[1]) / denom
        if a > 0.0 and b > 0.0:
            k = bezier_arm_factor(turn)
            arm0, arm1 = min(a * k, c), min(b * k, c)
    ctrl = np.array([p0, p0 + arm0 * np.asarray(d0), p3 - arm1 * np.asarray(d1), p3])

    def evaluate(u: NDArrayFloat) -> NDArrayFloat:
        v = 1.0 - u
        basis = np.stack((v**3, 3.0 * v * v * u, 3.0 * v * u * u, u**3), axis=1)
        return basis @ ctrl

    return sample_curve(evaluate, 0.0, 1.0, arm0 + arm1 + c / 3.0, spacing_m)
