"""Gap interpolation for spline fusion (paper sec. III-B) and the G1 Hermite variant.

Both work on the borders of one lane in a common frame and return, per border, the points
strictly inside the gap, at most ``spacing_m`` apart, from the ego border's last point to the
coop border's first. The hot path avoids scipy: the paper's spline has at most five knots,
so its tridiagonal system is solved in closed form on floats, and all curve pieces of both
borders are sampled by arc length in one vectorised pass (:func:`sample_pieces`).
"""

from __future__ import annotations

import cmath
import math
from typing import Final, Sequence

import numpy as np

from fusion.fusibility import clearly_curved
from fusion.geometry import EndFit, fit_ends
from fusion.types import FusionParams, NDArrayFloat

_MIN_ARC_TURN_RAD: Final[float] = 1e-3
_MIN_KNOT_STEP_M: Final[float] = 1e-9
_NOISE_SAMPLE_M: Final[float] = 5.0
_WINDOWS_M: Final[tuple[float, ...]] = (2.0, 3.0, 4.5, 6.0)
_STRAIGHT_SIGMAS: Final[float] = 2.5
_WHOLE_WINDOW_M: Final[float] = 1e6  # longer than any detection: a fit over all of a border's points
_WHOLE_MAX_TURN_RAD: Final[float] = 0.75
"""Largest turn [rad] of a border's chord at its end fit's curvature for which the fit over
the whole border is tried: the quadratic model of :func:`fusion.geometry.fit_ends` is exact
to about 1 % in κ up to this turn per window (8 m radius over 6 m); a tighter curve over a
whole detection is no arc in that model."""
_RESOLVED_SIGMAS: Final[float] = 10.0
"""An end fit with |κ| ≥ this many σ_κ (and clearly curved) measures its curvature to 10 %:
its arc's radius interval (± 2 % + 3σ) is then narrow enough without the whole detection."""
_AGREE_SIGMAS: Final[float] = 3.0  # an end and its whole border are one arc when their curvatures agree within this
TRANSITION_SHARE: Final[float] = 0.5  # share of a turn between straight ends in its clothoids (equal thirds)
_GL_NODES, _GL_WEIGHTS = (np.polynomial.legendre.leggauss(16) + np.array([[1.0], [0.0]])) * 0.5  # on [0, 1]
_GL_NODES_SQUARED: Final[NDArrayFloat] = _GL_NODES * _GL_NODES
_GRID: Final[int] = 128
_TAU: Final[NDArrayFloat] = np.linspace(0.0, 1.0, _GRID + 1)
_TAU_STEPS_T: Final = np.diff(np.power.outer(_TAU, np.arange(4)), axis=0).T.astype(np.complex128)  # (4, _GRID)
_PARAMETER_GRIDS: dict[int, NDArrayFloat] = {}
_COUNTING: list[NDArrayFloat] = [np.empty(0)]  # 1.0, 2.0, …: the one table of _counting

Piece = list[complex]  # power-basis coefficients [a, b, c, d] as x + iy: a + b·τ + c·τ² + d·τ³, τ ∈ [0, 1]


def _cross(ax: float, ay: float, bx: float, by: float) -> float:
    return ax * by - ay * bx


def _parameter_grid(n_pieces: int) -> NDArrayFloat:
    """Global parameter (piece index + τ) of the ``n_pieces·_GRID + 1`` grid nodes of joined pieces."""
    grid = _PARAMETER_GRIDS.get(n_pieces)
    if grid is None:
        grid = _PARAMETER_GRIDS[n_pieces] = np.arange(n_pieces * _GRID + 1) / _GRID
    return grid


def _counting(n: int) -> NDArrayFloat:
    """1.0, 2.0, …, n: a read-only slice of a table that grows on demand (no allocation per call)."""
    table = _COUNTING[0]
    if n > table.shape[0]:
        table = _COUNTING[0] = np.arange(1.0, 2.0 * n + 1.0)
        table.flags.writeable = False
    return table[:n]


def sample_pieces(pieces: Sequence[Sequence[Piece]], spacing_m: float) -> list[NDArrayFloat]:
    """Sample chains of cubic pieces by arc length; one ``(K, 2)`` array per chain.

    ``pieces[b]`` is the chain of border b: cubic pieces a + b·τ + c·τ² + d·τ³, τ ∈ [0, 1],
    joined end to start. All pieces are measured on one 128-step-per-piece grid (chord lengths
    from the differenced powers of τ, one running arc length over all pieces put end to end),
    then each chain is sampled at equal arc-length steps ≤ ``spacing_m`` strictly between its
    two ends (ends excluded), by evaluating the pieces exactly (Horner) at the interpolated
    parameters. All chains are processed in one vectorised pass, with points as complex
    numbers (x + iy).
    """
    flat = [piece for chain in pieces for piece in chain]
    if not flat:
        return [np.empty((0, 2)) for _ in pieces]
    coeffs = np.array(flat, dtype=np.complex128)
    n_pieces = coeffs.shape[0]
    s = np.empty(n_pieces * _GRID + 1)  # arc length at the grid nodes of the pieces joined end to end [m]
    s[0] = 0.0
    np.add.accumulate(np.abs(coeffs @ _TAU_STEPS_T).ravel(), out=s[1:])
    spans, first, offset = [], 0, 0  # per chain: (first target, target count, arc length at its start, step)
    for chain in pieces:
        count, start, step = 0, 0.0, 0.0
        if chain:
            start, end = s.item(first * _GRID), s.item((first + len(chain)) * _GRID)
            if end > start:
                n_steps = math.ceil((end - start) / spacing_m * (1.0 + 1e-3))
                count, step = n_steps - 1, (end - start) / n_steps
        spans.append((offset, count, start, step))
        first, offset = first + len(chain), offset + count
    if offset == 0:
        return [np.empty((0, 2)) for _ in pieces]
    k = np.concatenate([np.arange(start + step, start + (count + 0.5) * step, step)
                        for _, count, start, step in spans if count])
    q = np.interp(k, s, _parameter_grid(n_pieces))
    index = q.astype(np.intp)
    np.minimum(index, n_pieces - 1, out=index)
    tau = np.subtract(q, index, dtype=np.complex128)  # complex × complex: no cast inside each product
    a, b, c, d = coeffs.T.take(index, axis=1)
    z = d * tau
    z += c
    z *= tau
    z += b
    z *= tau
    z += a
    points = z.view(np.float64).reshape(-1, 2)
    return [points[offset:offset + count] for offset, count, _, _ in spans]


def estimate_apex(p_end: tuple[float, float], d_end: tuple[float, float], p_start: tuple[float, float],
                  d_start: tuple[float, float], ratio: float) -> tuple[float, float] | None:
    """Paper's apex estimate P_c = P_i + ratio·(P_j − P_i) (eq. 2).

    P_i is the intersection of the ego end tangent line (point ``p_end``, direction ``d_end``)
    with the coop start tangent line (``p_start``, ``d_start``); P_j is the foot of P_i on the
    chord ``p_end → p_start``. Returns ``None`` when the tangents are parallel or P_i does not
    lie ahead of the ego end and behind the coop start (no single curve between them).
    """
    cx, cy = p_start[0] - p_end[0], p_start[1] - p_end[1]
    denom = _cross(d_end[0], d_end[1], d_start[0], d_start[1])
    if abs(denom) < 1e-9:
        return None
    a = _cross(cx, cy, d_start[0], d_start[1]) / denom
    b = _cross(d_end[0], d_end[1], cx, cy) / denom
    if a <= 0.0 or b <= 0.0:
        return None
    ix, iy = p_end[0] + a * d_end[0], p_end[1] + a * d_end[1]
    t = ((ix - p_end[0]) * cx + (iy - p_end[1]) * cy) / (cx * cx + cy * cy)
    jx, jy = p_end[0] + t * cx, p_end[1] + t * cy
    return ix + ratio * (jx - ix), iy + ratio * (jy - iy)


def natural_spline_moments(h: Sequence[float], y: Sequence[complex]) -> list[complex]:
    """Second derivatives M of the natural cubic spline through ``y`` (knot steps ``h``).

    Solves the paper's tridiagonal system (eq. 4) with M_0 = M_n = 0 by the Thomas
    algorithm on Python numbers (a handful of knots: no numpy call overhead); ``y`` may be
    complex (x + iy: both coordinates at once).
    """
    n = len(h)
    moments: list[complex] = [0.0] * (n + 1)
    if n < 2:
        return moments
    slope = [(y[i + 1] - y[i]) / h[i] for i in range(n)]
    c: list[float] = [0.0] * (n - 1)
    d: list[complex] = [0.0] * (n - 1)
    for i in range(n - 1):
        diag = (h[i] + h[i + 1]) / 3.0
        rhs = slope[i + 1] - slope[i]
        if i > 0:
            sub = h[i] / 6.0
            diag -= sub * c[i - 1]
            rhs -= sub * d[i - 1]
        c[i] = h[i + 1] / 6.0 / diag
        d[i] = rhs / diag
    for i in range(n - 2, -1, -1):
        moments[i + 1] = d[i] - c[i] * moments[i + 2]
    return moments


def paper_pieces(ego: NDArrayFloat, coop: NDArrayFloat, apex_min_turn_rad: float, apex_ratio: float,
                 uniform: bool = False) -> list[Piece]:
    """Gap pieces of the paper's spline through ego[-3], ego[-1], (apex), coop[0], coop[2].

    The spline is parametric in cumulative chord length (a 90° curve is not a function
    y(x)), or in the knot index with ``uniform``, with natural boundary conditions. The apex
    P_c is added when the end directions ego[-3]→ego[-1] and coop[0]→coop[2] differ by more
    than ``apex_min_turn_rad``. Returns the power-basis pieces from ego[-1] to coop[0]; knots
    are complex numbers x + iy, so one tridiagonal solve serves both coordinates.
    """
    (ex0, ey0), *_, (ex1, ey1) = ego[-3:].tolist()
    (cx0, cy0), *_, (cx1, cy1) = coop[:3].tolist()
    e0, e1, c0, c1 = complex(ex0, ey0), complex(ex1, ey1), complex(cx0, cy0), complex(cx1, cy1)
    de = (e1 - e0) / (abs(e1 - e0) or 1.0)
    dc = (c1 - c0) / (abs(c1 - c0) or 1.0)
    knots = [e0, e1]
    turn = dc * de.conjugate()
    if abs(math.atan2(turn.imag, turn.real)) > apex_min_turn_rad:
        apex = estimate_apex((ex1, ey1), (de.real, de.imag), (cx0, cy0), (dc.real, dc.imag), apex_ratio)
        if apex is not None:
            knots.append(complex(*apex))
    knots += [c0, c1]
    kept, h = [e0], []
    for knot in knots[1:]:
        step = abs(knot - kept[-1])
        if step > _MIN_KNOT_STEP_M:
            kept.append(knot)
            h.append(1.0 if uniform else step)
    if e1 not in kept or c0 not in kept:
        return []
    m = natural_spline_moments(h, kept)
    pieces = []
    for i in range(kept.index(e1), kept.index(c0)):
        h2 = h[i] * h[i]
        pieces.append([kept[i], (kept[i + 1] - kept[i]) - h2 * (2.0 * m[i] + m[i + 1]) / 6.0, m[i] * h2 / 2.0,
                       (m[i + 1] - m[i]) * h2 / 6.0])
    return pieces


def _bezier_piece(p0: complex, d0: complex, p3: complex, d1: complex) -> Piece:
    """Power basis of the cubic Bézier with arms of a third of the chord (straight or S-shaped)."""
    arm = abs(p3 - p0) / 3.0
    c1, c2 = p0 + arm * d0, p3 - arm * d1
    return [p0, 3.0 * (c1 - p0), 3.0 * (c2 - 2.0 * c1 + p0), p3 - 3.0 * c2 + 3.0 * c1 - p0]


def _mean_dir(a: tuple[float, float], b: tuple[float, float]) -> complex:
    """Unit vector (x + iy) along the sum of two directions."""
    d = complex(a[0] + b[0], a[1] + b[1])
    return d / (abs(d) or 1.0)


def _straight(fit: EndFit) -> bool:
    """Whether a border end is straight within its noise: |κ| ≤ 2.5·σ_κ (σ_κ finite)."""
    return abs(fit.curvature) <= _STRAIGHT_SIGMAS * fit.curvature_sigma < math.inf


def hermite_lane(fits: Sequence[EndFit], spacing_m: float,
                 share: float | None = None) -> tuple[NDArrayFloat, NDArrayFloat]:
    """G1/G2 gap interpolation of both borders of a lane; returns the (left, right) gap points.

    ``fits`` are the least-squares end fits of (ego left, ego right, coop left, coop right)
    from :func:`lane_end_fits`; the end directions of the two borders are averaged (the
    borders of a lane are parallel), which halves the heading variance. Each border's gap
    is :func:`hermite_gap` between the fitted ends. When all four border ends are straight
    (zero curvature within noise), the turn lies wholly inside the gap and the arc, whose
    curvature would jump at the ends, gets clothoids (``share`` of the turn, default
    TRANSITION_SHARE; ``share`` given: used for every turn, 0 = the arc).
    """
    lane = _HermiteLane(fits, share)
    if lane.share is None:
        left, right = sample_pieces([[_bezier_piece(p0, lane.d0, p3, lane.d1)] for p0, p3 in lane.ends], spacing_m)
        return left, right
    left, right = (_hermite_points(p0, lane.d0, p3, lane.d1, triangle, lane.unit_tangent, spacing_m, lane.share)
                   for (p0, p3), triangle in zip(lane.ends, lane.triangles))
    return left, right


def hermite_turns(fits: Sequence[EndFit]) -> tuple[tuple[float, float], tuple[float, float]]:
    """Where :func:`hermite_lane` of ``fits`` turns, per border (left, right): the fractions
    (start, stop) of the border's gap curve, by arc length from the ego's end, between which
    it turns (arc, or clothoids and arc); before and after it runs straight along the end
    tangents. (0, 1) where the gap curve turns throughout (an arc, a cubic Bézier)."""
    lane = _HermiteLane(fits, None)
    spans = []
    for triangle in lane.triangles:
        if lane.share is None or triangle is None:
            spans.append((0.0, 1.0))
            continue
        lead, turn, tail = _turn_lengths(triangle, lane.unit_tangent, lane.share)
        total = lead + turn + tail
        spans.append((lead / total, (lead + turn) / total) if total > 0.0 else (0.0, 1.0))
    return spans[0], spans[1]


class _HermiteLane:
    """What :func:`hermite_lane` draws both borders' gaps from: the averaged end directions
    ``d0`` (ego) and ``d1`` (coop), the (ego, coop) end points per border ``ends``, their
    :func:`_tangent_triangle` ``triangles``, the clothoids' ``share`` (None when neither border
    has a triangle: cubic Béziers) and the turn's :func:`_unit_tangent`."""

    def __init__(self, fits: Sequence[EndFit], share: float | None):
        self.d0 = _mean_dir(fits[0].direction, fits[1].direction)
        self.d1 = _mean_dir(fits[2].direction, fits[3].direction)
        self.ends = [(complex(*fits[i].point), complex(*fits[i + 2].point)) for i in (0, 1)]
        self.triangles = [_tangent_triangle(p0, self.d0, p3, self.d1) for p0, p3 in self.ends]
        self.share: float | None = None
        self.unit_tangent = math.nan
        if self.triangles[0] is None and self.triangles[1] is None:
            return
        if share is None:
            share = TRANSITION_SHARE if all(_straight(fit) for fit in fits) else 0.0
        turn = (self.triangles[0] or self.triangles[1])[0]  # the same for both borders (same end directions)
        self.share, self.unit_tangent = share, _unit_tangent(turn, share)


def lane_end_fits(ego: tuple[NDArrayFloat, NDArrayFloat], coop: tuple[NDArrayFloat, NDArrayFloat],
                  window_m: float | None, sigmas: Sequence[NDArrayFloat | None] | None = None,
                  ) -> tuple[EndFit, EndFit, EndFit, EndFit]:
    """End fits of (ego left, ego right) at their ends and (coop left, coop right) at their starts.

    Windows: ``window_m``, or with ``None`` adaptive among 2–6 m from the noise σ estimated
    on the last/first 5 m of the four borders (:func:`fusion.geometry.fit_ends`); ``sigmas``
    (the four borders' per-point σ, or None) weight the fits by 1/σ².
    """
    windows = _WINDOWS_M if window_m is None else (window_m,)
    fits = fit_ends((ego[0], ego[1], coop[0], coop[1]), (True, True, False, False), windows, _NOISE_SAMPLE_M, sigmas)
    return fits[0], fits[1], fits[2], fits[3]


class EndFits:
    """:func:`lane_end_fits` of four ego-frame borders (ego left, ego right, coop left, coop
    right) with ``params.heading_window_m`` (weighted by 1/σ² with ``sigmas``, their per-point
    σ), computed once on the first call; :meth:`arcs`
    the same with the curvature of the whole detection where that is one arc."""

    def __init__(self, borders: tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat],
                 params: FusionParams, sigmas: Sequence[NDArrayFloat | None] | None = None):
        self._borders, self._params, self._sigmas = borders, params, sigmas
        self._fits: tuple[EndFit, EndFit, EndFit, EndFit] | None = None
        self._arcs: tuple[EndFit, ...] | None = None

    def __call__(self) -> tuple[EndFit, EndFit, EndFit, EndFit]:
        if self._fits is None:
            el, er, cl, cr = self._borders
            self._fits = lane_end_fits((el, er), (cl, cr), self._params.heading_window_m, self._sigmas)
        return self._fits

    def arcs(self) -> tuple[EndFit, ...]:
        """The end fits, or, when one of them does not resolve its curvature
        (:data:`_RESOLVED_SIGMAS`, :func:`fusion.fusibility.clearly_curved`; infinite σ_κ
        included), each with the
        direction, curvature and σ_κ of the fit over all of its border's points where that fit
        is an arc (:func:`fusion.geometry.fit_ends` with one window over the whole border: its
        cubic test says whether the whole detection is one arc), has the smaller σ_κ and
        agrees with the end's curvature within 3σ of their difference. Under detection noise
        a 2–6 m end window cannot tell a gentle curve (R 130 m) from a straight or pin down
        its heading; the ~30 m of a whole detection can, and its σ_κ comes from the same noise
        estimate. Four resolved ends (every noise-free arc, a tight corner) keep their
        fits, and so do all when every end's curvature turns its border by more than
        :data:`_WHOLE_MAX_TURN_RAD` (a curve beyond the fit's model), or an end whose whole
        detection is no single arc in the fit's model."""
        arcs = self._arcs
        if arcs is None:  # set once, when made: another thread may read it meanwhile
            arcs = fits = self()
            if _whole_fit_helps(fits, self._borders):
                whole = fit_ends(self._borders, (True, True, False, False), (_WHOLE_WINDOW_M,), _NOISE_SAMPLE_M,
                                 self._sigmas)
                arcs = tuple(_better_arc(end, fit) for end, fit in zip(fits, whole))
            self._arcs = arcs
        return arcs


def _whole_fit_helps(fits: Sequence[EndFit], borders: Sequence[NDArrayFloat]) -> bool:
    """Whether :meth:`EndFits.arcs` tries the fits over the whole borders: some end does not
    resolve its curvature (:data:`_RESOLVED_SIGMAS`, clearly curved), and the least turn of
    a border's chord at its end's curvature (ends with a finite σ_κ) is within
    :data:`_WHOLE_MAX_TURN_RAD`."""
    resolved = all(abs(fit.curvature) >= _RESOLVED_SIGMAS * fit.curvature_sigma
                   and clearly_curved(fit.curvature, fit.curvature_sigma) for fit in fits)
    if resolved:
        return False
    turns = (abs(fit.curvature) * math.dist(*border[::border.shape[0] - 1].tolist())
             for fit, border in zip(fits, borders) if fit.curvature_sigma < math.inf)
    return min(turns, default=0.0) <= _WHOLE_MAX_TURN_RAD


def _better_arc(end: EndFit, whole: EndFit) -> EndFit:
    """``end`` with the direction, curvature and σ_κ of the fit over its ``whole`` border when
    that has the smaller σ_κ and agrees within :data:`_AGREE_SIGMAS` σ of their difference."""
    agree = abs(whole.curvature - end.curvature) <= _AGREE_SIGMAS * math.hypot(whole.curvature_sigma,
                                                                               end.curvature_sigma)
    if whole.curvature_sigma < end.curvature_sigma and agree:
        return end._replace(direction=whole.direction, curvature=whole.curvature,
                            curvature_sigma=whole.curvature_sigma)
    return end


def transition_tangent(turn_rad: float, share: float) -> float:
    """Tangent length of the symmetric clothoid–arc–clothoid turn of arc radius 1 [m].

    The turn ``turn_rad`` is split into two clothoids (curvature linear between 0 and 1, each
    turning ``share``·|turn|/2, so each 2·that long) and an arc between them (the rest of
    the turn). By symmetry the end is H + e^{iθ}·conj(H) for the first half H (clothoid by
    16-point Gauss–Legendre, exact to 1e-12 for |θ| ≤ π, then half the arc in closed form);
    returns the distance from the start to where the end tangents meet.
    """
    theta = abs(turn_rad)
    spiral, arc = share * theta, (1.0 - share) * theta
    half = complex(spiral * np.dot(_GL_WEIGHTS, np.exp((0.5j * spiral) * _GL_NODES_SQUARED)))
    half += cmath.exp(0.5j * spiral) * (cmath.exp(0.5j * arc) - 1.0) / 1j
    end = half + cmath.exp(1j * theta) * half.conjugate()
    return end.real - end.imag / math.tan(theta)


def _tangent_triangle(p0: complex, d0: complex, p3: complex, d1: complex) -> tuple[float, float, float] | None:
    """``(turn, a, b)``: the signed turn [rad] from ``d0`` to ``d1`` and the distances [m] from ``p0``
    and from ``p3`` to where the two tangent lines meet; ``None`` when they meet behind either
    end, never meet (a turn of exactly π) or the turn is below 1 mrad (no circular arc:
    straight or S-shaped). Points and unit directions are x + iy."""
    ux, uy, vx, vy = d0.real, d0.imag, d1.real, d1.imag
    denom = _cross(ux, uy, vx, vy)
    turn = math.atan2(denom, ux * vx + uy * vy)
    if abs(turn) < _MIN_ARC_TURN_RAD or denom == 0.0:  # (anti-)parallel tangent lines never meet
        return None
    cx, cy = p3.real - p0.real, p3.imag - p0.imag
    a = _cross(cx, cy, vx, vy) / denom
    b = _cross(ux, uy, cx, cy) / denom
    return None if a <= 0.0 or b <= 0.0 else (turn, a, b)


def hermite_gap(p0: NDArrayFloat, d0: NDArrayFloat, p3: NDArrayFloat, d1: NDArrayFloat,
                spacing_m: float, share: float = 0.0) -> NDArrayFloat:
    """G1 Hermite interpolation from ``p0`` (direction ``d0``) to ``p3`` (``d1``).

    The two tangent lines meet at P_i, at distance a from p0 and b from p3. The curve is the
    largest circular arc tangent to both lines (tangent length m = min(a, b), radius
    m / tan(θ/2) for the turn θ) preceded or followed by a straight of length |a − b| on the
    longer side. A circular arc between the ends is therefore reproduced exactly (a = b),
    and so is a curve that starts or ends inside the gap; it is sampled in closed form every
    ≤ ``spacing_m``, ends excluded. (A cubic Bézier with arms (4/3)·R·tan(θ/4) would
    approximate the same arc to 3·10⁻⁴·R.) With ``share`` > 0 the arc is replaced by the
    symmetric clothoid–arc–clothoid turn of the same tangent length m whose clothoids take
    that share of the turn (:func:`transition_tangent`; 1 = a clothoid pair): a G2 turn
    between straight ends. Parallel or S-shaped end tangents (no triangle ahead of both ends) use a cubic
    Bézier with arms of a third of the chord.
    """
    p0c, d0c, p3c, d1c = (complex(*v.tolist()) for v in (p0, d0, p3, d1))
    triangle = _tangent_triangle(p0c, d0c, p3c, d1c)
    unit_tangent = _unit_tangent(triangle[0], share) if triangle is not None else math.nan
    return _hermite_points(p0c, d0c, p3c, d1c, triangle, unit_tangent, spacing_m, share)


def _unit_tangent(turn: float, share: float) -> float:
    """Tangent length [m] of the turn ``turn`` [rad] of arc radius 1: the arc, or with ``share`` > 0
    the clothoid–arc–clothoid turn (:func:`transition_tangent`)."""
    return transition_tangent(turn, share) if share > 0.0 else math.tan(abs(turn) / 2.0)


def _turn_lengths(triangle: tuple[float, float, float], unit_tangent: float, share: float) -> tuple[float, float, float]:
    """(lead, turn, tail) [m]: the lengths of :func:`_hermite_points`'s straight along the ego's
    end tangent, its turn (arc, or clothoids and arc with ``share`` > 0) and its straight into
    the coop's start, for the end points' :func:`_tangent_triangle` and the turn's
    :func:`_unit_tangent`."""
    turn, a, b = triangle
    m = min(a, b)
    radius = m / unit_tangent
    if share > 0.0:
        arc = 2.0 * (share * abs(turn) * radius) + (1.0 - share) * abs(turn) * radius
    else:
        arc = radius * abs(turn)
    return a - m, arc, b - m


def _hermite_points(p0: complex, d0: complex, p3: complex, d1: complex, triangle: tuple[float, float, float] | None,
                    unit_tangent: float, spacing_m: float, share: float) -> NDArrayFloat:
    """:func:`hermite_gap` on points and unit directions as x + iy, given their ``triangle`` and
    the :func:`_unit_tangent` of its turn (the same for both borders of a lane).

    The curve, by arc length u from ``p0``: the straight p0 + u·d0 up to the lead a − m, the
    turn (arc or clothoid–arc–clothoid), then the straight into ``p3`` along ``d1``; each
    stretch of the samples u = j·total/n is evaluated in closed form on its own slice.
    """
    if triangle is None:
        return sample_pieces([[_bezier_piece(p0, d0, p3, d1)]], spacing_m)[0]
    turn = triangle[0]
    radius = min(triangle[1:]) / unit_tangent
    spiral, arc_turn = share * abs(turn) * radius, (1.0 - share) * abs(turn)
    lead, arc, tail = _turn_lengths(triangle, unit_tangent, share)
    total = lead + arc + tail
    n_steps = math.ceil(total / spacing_m * (1.0 + 1e-9))
    if n_steps < 2:
        return np.empty((0, 2))
    step = total / n_steps
    j = _counting(n_steps - 1)  # sample j lies at arc length u = j·step
    n_lead = min(n_steps - 1, max(0, math.ceil(lead / step) - 1))  # samples before the turn
    n_turn = min(n_steps - 1, math.floor((lead + arc) / step))  # ... and up to its end
    z = np.empty(n_steps - 1, dtype=np.complex128)
    line, bend, straight = z[:n_lead], z[n_lead:n_turn], z[n_turn:]
    if n_lead > 0:
        np.multiply(j[:n_lead], step * d0, out=line)
        line += p0
    start = p0 + lead * d0
    if share > 0.0:  # midpoint rule on the steps of u (the first one from the start of the turn)
        first = j[n_lead] * step - lead if n_turn > n_lead else 0.0  # end of the first step [m into the turn]
        mid = j[n_lead:n_turn] * step
        mid -= lead + 0.5 * step
        mid[:1] = 0.5 * first
        along = arc_turn * radius
        i_arc, i_out = np.searchsorted(mid, (spiral, spiral + along)).tolist()
        turned = np.empty_like(mid)  # turned angle × radius [m]: clothoid in, arc, clothoid out
        rise, flat, fall = turned[:i_arc], turned[i_arc:i_out], turned[i_out:]
        np.multiply(mid[:i_arc], mid[:i_arc], out=rise)
        rise *= 0.5 / spiral
        np.subtract(mid[i_arc:i_out], 0.5 * spiral, out=flat)
        np.subtract(mid[i_out:], spiral + along, out=fall)
        fall *= 1.0 - (0.5 / spiral) * fall
        fall += 0.5 * spiral + along
        w = np.multiply(turned, 1j * math.copysign(1.0 / radius, turn))
        np.exp(w, out=w)
        w[:1] *= first
        w[1:] *= step
        np.add.accumulate(w, out=bend)
        bend *= d0
        bend += start
    else:
        kappa = math.copysign(abs(turn) / arc, turn)
        scale = d0 / (1j * kappa)  # bend = start + scale·(e^{iκ(u − lead)} − 1)
        np.multiply(j[n_lead:n_turn], 1j * kappa * step, out=bend)
        np.exp(bend, out=bend)
        bend *= scale * cmath.exp(-1j * kappa * lead)
        bend += start - scale
    if n_turn < n_steps - 1:
        np.multiply(j[n_turn:], step * d1, out=straight)  # p3 + (u − total)·d1
        straight += p3 - total * d1
    return z.view(np.float64).reshape(-1, 2)
