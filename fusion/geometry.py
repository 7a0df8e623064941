"""Small planar geometry kernels on ``(N, 2)`` polylines (numpy only, no validation)."""

from __future__ import annotations

import cmath
import math
from dataclasses import dataclass
from typing import Final, NamedTuple, Sequence

import numpy as np

from fusion.types import NDArrayFloat, Pose2D

_SIGMA_FLOOR_M: Final[float] = 0.002
_CI_FACTOR: Final[float] = 2.5
_CURVATURE_CHANGE_SIGMAS: Final[float] = 3.0
_CUBIC_ARC_BIAS: Final[float] = 0.05
_STEP_SPAN: Final[int] = 20  # segments at a border end whose chord gives the point spacing


def transform(points: NDArrayFloat, x: float, y: float, yaw: float, *, in_place: bool = False) -> NDArrayFloat:
    """Points of a frame at ``(x, y, yaw)`` (relative to a parent frame) in the parent frame;
    ``in_place``: overwrite ``points`` (C-contiguous, writable) and return it.

    Read as complex numbers, the rigid motion is one multiply-add (half the time of a 2×2
    matmul on a few hundred points)."""
    rotation = complex(math.cos(yaw), math.sin(yaw))
    if in_place:
        z = points.view(np.complex128)[:, 0]
        z *= rotation
    else:
        z = np.ascontiguousarray(points).view(np.complex128)[:, 0] * rotation
    z += complex(x, y)
    return z.view(np.float64).reshape(-1, 2)


def to_world(points: NDArrayFloat, pose: Pose2D, *, in_place: bool = False) -> NDArrayFloat:
    """Vehicle-frame points of a vehicle at ``pose`` in the world frame (``in_place`` as
    :func:`transform`)."""
    return transform(points, pose.x, pose.y, pose.yaw, in_place=in_place)


def _points_in(length_m: float, step_m: float, limit: int) -> int:
    """round(length / step) capped at ``limit`` (``limit`` for a zero or tiny step)."""
    ratio = length_m / step_m if step_m > 0.0 else math.inf
    return limit if not ratio < limit else int(round(ratio))


def norms(vectors: NDArrayFloat) -> NDArrayFloat:
    """Euclidean lengths of ``(..., 2)`` vectors (read as complex numbers: one fast ufunc)."""
    return np.abs(np.ascontiguousarray(vectors).view(np.complex128))[..., 0]


def wrap_angle(angle: float) -> float:
    """Angle wrapped to [-π, π) [rad]."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def cumulative_length(points: NDArrayFloat) -> NDArrayFloat:
    """Arc length at every vertex of a polyline, starting at 0 [m]."""
    out = np.empty(points.shape[0])
    out[0] = 0.0
    np.cumsum(norms(points[1:] - points[:-1]), out=out[1:])
    return out


def segment_at(arclength: NDArrayFloat, s: NDArrayFloat) -> NDArrayFloat:
    """Index of the segment of a polyline (vertex arc lengths ``arclength`` [m]) that holds
    each arc length ``s`` [m]: the last vertex at or before it, the first or last segment
    for ``s`` before or past the line."""
    return np.clip(arclength.searchsorted(s, side="right") - 1, 0, arclength.shape[0] - 2)


def points_at(polyline: NDArrayFloat, arclength: NDArrayFloat, s: NDArrayFloat) -> NDArrayFloat:
    """``(len(s), 2)`` points of ``polyline`` (vertex arc lengths ``arclength`` [m]) at arc
    lengths ``s`` [m], linearly interpolated (its ends outside)."""
    return np.column_stack((np.interp(s, arclength, polyline[:, 0]), np.interp(s, arclength, polyline[:, 1])))


def _nearest_segment(point: NDArrayFloat, polyline: NDArrayFloat) -> tuple[float, int, float, float, float]:
    """``(distance, segment, t, x, y)`` of the closest point of ``polyline`` to ``point``: its
    distance [m], the index of the segment holding it, its fraction along that segment and
    its coordinates [m].
    Only the two segments at the nearest vertex are examined (exact for polylines sampled
    finer than their curvature radius)."""
    px, py = point.tolist()
    k = int(np.abs(np.ascontiguousarray(polyline).view(np.complex128)[:, 0] - complex(px, py)).argmin())
    return foot_near_vertex(px, py, polyline, k)


def foot_near_vertex(px: float, py: float, polyline: NDArrayFloat, k: int) -> tuple[float, int, float, float, float]:
    """:func:`_nearest_segment` of the point ``(px, py)`` [m] when ``polyline``'s vertex ``k``
    is already known to be its nearest: the two segments at that vertex are examined."""
    first = max(k - 1, 0)
    vertices = polyline[first:k + 2].tolist()  # the nearest vertex and its neighbours, as floats
    best = (math.inf, 0, 0.0, px, py)
    for j in range(len(vertices) - 1):
        (ax, ay), (bx, by) = vertices[j], vertices[j + 1]
        dx, dy = bx - ax, by - ay
        seg2 = dx * dx + dy * dy
        t = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / seg2)) if seg2 > 0.0 else 0.0
        fx, fy = ax + t * dx, ay + t * dy
        dist = math.hypot(fx - px, fy - py)
        if dist < best[0]:
            best = (dist, first + j, t, fx, fy)
    return best


def project_point(point: NDArrayFloat, polyline: NDArrayFloat, arclength: NDArrayFloat) -> tuple[float, float, int]:
    """Closest point of ``polyline`` to ``point`` (near its nearest vertex, see
    :func:`_nearest_segment`).

    Returns ``(s, distance, segment)``: arc length of the foot point [m], its distance [m] and
    the index of the segment holding it.
    """
    dist, i, t, _, _ = _nearest_segment(point, polyline)
    return float(arclength[i] + t * (arclength[i + 1] - arclength[i])), dist, i


def foot_point(point: NDArrayFloat, polyline: NDArrayFloat) -> tuple[float, float]:
    """The closest point ``(x, y)`` of ``polyline`` to ``point`` (near its nearest vertex, see
    :func:`_nearest_segment`), same frame [m]."""
    return _nearest_segment(point, polyline)[3:]


def end_direction(points: NDArrayFloat, at_end: bool, window_m: float) -> tuple[float, float]:
    """Unit tangent ``(dx, dy)`` at the last (``at_end``) or first point, by a chord.

    The chord spans about ``window_m`` of the polyline (at least one segment), assuming
    roughly even spacing; it points in driving direction. The whole polyline's chord when
    that one has zero length.
    """
    n = points.shape[0]
    (x0, y0), (x1, y1) = points[:: n - 1].tolist()
    k = max(1, _points_in(window_m, math.hypot(x1 - x0, y1 - y0) / (n - 1), n - 1))
    (ax, ay), (bx, by) = (points[-1 - k::k] if at_end else points[: k + 1: k]).tolist()
    vx, vy = bx - ax, by - ay
    norm = math.hypot(vx, vy)
    if norm == 0.0:
        vx, vy = x1 - x0, y1 - y0
        norm = math.hypot(vx, vy) or 1.0
    return vx / norm, vy / norm


class EndFit(NamedTuple):
    """Least-squares estimate at a border end (world frame); a named tuple, immutable and
    cheap to build (four per spline fusion).

    Fields: ``point`` fitted end point ``(x, y)`` [m]; ``direction`` unit tangent (driving direction);
    ``curvature`` [1/m] (positive turning left); ``curvature_sigma`` its standard deviation
    from the detection noise [1/m], infinite when the end is no single arc.
    """

    point: tuple[float, float]
    direction: tuple[float, float]
    curvature: float
    curvature_sigma: float


@dataclass(frozen=True)
class _EndDesign:
    """Constant least-squares filters of :func:`fit_ends` for one set of window sizes.

    Fields: ``rows`` ``(3·W + 1 + D, K)``, one filter per row: for each of the W windows
    (t = 0, 1, … the point index) the rows giving the quadratic coefficients p0, p1, p2; then
    the row giving the cubic coefficient p3 of a cubic fit over the longest window; then D
    second differences over the first noise points. ``enough_points``: whether the shortest
    window holds four points (the longer ones hold more). ``p1_gains``/``p2_gains`` per
    window the noise gains (row norms) of p1 and p2, ``p3_gain`` that of p3.
    ``cubic_leaks``/``quartic_leaks`` per window: t³/t⁴ projected onto the window's quadratic
    basis (how an arc's cubic and quartic terms bias p0…p2); ``p3_quartic_leak``: t⁴
    projected onto the longest window's p3.
    """

    rows: NDArrayFloat
    enough_points: bool
    p1_gains: tuple[float, ...]
    p2_gains: tuple[float, ...]
    p3_gain: float
    cubic_leaks: tuple[tuple[float, float, float], ...]
    quartic_leaks: tuple[tuple[float, float, float], ...]
    p3_quartic_leak: float


_DESIGNS: dict[tuple[tuple[int, ...], int, bytes | None], _EndDesign] = {}
_MAX_DESIGNS: Final[int] = 256


def _end_designs(counts: tuple[int, ...], n_noise: int,
                 weights: Sequence[NDArrayFloat | None]) -> list[_EndDesign]:
    """The filters of windows of ``counts`` points and of the noise over ``n_noise`` points,
    per border unweighted (``None``) or weighted by its ``weights`` (from the end inward,
    ≥ ``counts[-1]`` of them), memoised by sizes and weights: a detection's σ is fitted again
    with every partner and method. The designs not held are made in one :func:`_designs`
    call; each border's is its own pseudo-inverse, so it is the same bit for bit whichever
    borders share the call."""
    keys = [(counts, n_noise, None if w is None else w[: counts[-1]].tobytes()) for w in weights]
    found = [_DESIGNS.get(key) for key in keys]
    missing = {key: w for key, w, design in zip(keys, weights, found) if design is None}
    if not missing:
        return found  # type: ignore[return-value]  # every key was held
    made: dict[tuple[tuple[int, ...], int, bytes | None], _EndDesign] = {}
    if (counts, n_noise, None) in missing:
        made[counts, n_noise, None] = _designs(counts, n_noise, None)[0]
    weighted = [key for key in missing if key[2] is not None]
    if weighted:
        stacked = np.array([missing[key][: counts[-1]] for key in weighted])  # type: ignore[index]
        made.update(zip(weighted, _designs(counts, n_noise, stacked)))
    if len(_DESIGNS) + len(made) > _MAX_DESIGNS:
        _DESIGNS.clear()
    _DESIGNS.update(made)
    return [design or made[key] for key, design in zip(keys, found)]


def _designs(counts: tuple[int, ...], n_noise: int, weights: NDArrayFloat | None) -> list[_EndDesign]:
    """:func:`_end_design`, or with ``weights`` (``(B, ≥ counts[-1])``, per border one per
    point from the end inward) one weighted least-squares design per border: pinv(√W·V)·√W,
    each window's filters of all the borders from one stacked pseudo-inverse."""
    windows = [(count, 3) for count in counts] + ([(counts[-1], 4)] if counts[-1] >= 4 else [])
    filters = []
    for count, degree in windows:
        vander = np.vander(np.arange(count, dtype=np.float64), degree, increasing=True)
        if weights is None:
            filters.append(np.linalg.pinv(vander)[None])
            continue
        root = np.sqrt(weights[:, :count])
        filters.append(np.linalg.pinv(vander * root[:, :, None]) * root[:, None, :])
    n_windows = len(counts)
    rows = np.zeros((len(filters[0]), 3 * n_windows + 1 + max(0, n_noise - 2), max(counts[-1], n_noise)))
    gains, cubic_leaks, quartic_leaks = [], [], []
    for w, count in enumerate(counts):
        t = np.arange(count, dtype=np.float64)
        rows[:, 3 * w: 3 * w + 3, :count] = filters[w]
        gains.append(np.linalg.norm(filters[w], axis=-1).tolist())
        cubic_leaks.append((filters[w] @ t ** 3).tolist())
        quartic_leaks.append((filters[w] @ t ** 4).tolist())
    t = np.arange(counts[-1], dtype=np.float64)
    p3s = filters[-1][:, 3] if counts[-1] >= 4 else np.zeros((len(rows), counts[-1]))
    rows[:, 3 * n_windows, : counts[-1]] = p3s
    for i in range(n_noise - 2):
        rows[:, 3 * n_windows + 1 + i, i:i + 3] = (1.0, -2.0, 1.0)
    return [_EndDesign(rows[b], counts[0] >= 4, tuple(g[b][1] for g in gains), tuple(g[b][2] for g in gains),
                       float(np.linalg.norm(p3)), tuple(tuple(leak[b]) for leak in cubic_leaks),
                       tuple(tuple(leak[b]) for leak in quartic_leaks), float(p3 @ t ** 4))
            for b, p3 in enumerate(p3s)]


def fit_ends(borders: Sequence[NDArrayFloat], at_end: Sequence[bool], windows_m: tuple[float, ...],
             noise_window_m: float, sigmas: Sequence[NDArrayFloat | None] | None = None) -> list[EndFit]:
    """Least-squares end point, tangent and curvature of several borders at once.

    Each border is read from its last (``at_end``) or first point inward and fitted, in each
    of ``windows_m`` (increasing; point counts from the spacing over the end's first 20
    segments), by a parametric quadratic z(t) = p0 + p1·t + p2·t² with t the point index: a
    sensor samples a border at even steps along it, so the index is its arc length up to
    scale, noise enters both coordinates alike, and the fit of every window of every border
    is one constant linear filter (one matrix product for all). Tangent p1/|p1|, curvature
    Im(conj(p1)·2p2)/|p1|³. An arc's cubic (tangential, −κ²v³/6 at speed v per index) and
    quartic (normal, −κ³v⁴/24) terms bias p0…p2 by known multiples (their projections onto
    the window's basis); that bias is removed with the fitted κ and v (arcs of 8 m radius
    and more then come out within 1.2 % in κ and 0.06° in heading over 6 m windows).

    The window is chosen by the intersection-of-confidence-intervals rule: the longest
    window whose heading interval ψ ± 2.5·σ_ψ still intersects those of all shorter windows,
    with σ_ψ from the detection noise σ (estimated from second differences over
    ``noise_window_m`` of all borders, assuming ~0.1 m spacing; a smooth curve contributes
    < 1 mm; floor 2 mm). ``curvature_sigma`` is the chosen window's σ_κ, or infinite when the
    longest window is no single arc: the normal part of the p3 of a cubic fit over it
    (v³·κ'/6 for a curvature rate κ') differs from an arc's (its quartic leak, from the
    chosen κ) by more than 3σ plus 5 % of that leak; a clothoid or a junction of line and
    arc inside the window fails that test. A border whose shortest window holds fewer than
    four points gets its end point, the chord direction and zero curvature of infinite
    uncertainty. ``sigmas`` (per border its points' lateral 1σ [m], or None) weight each
    border's fits by 1/σ² (weighted least squares; a border with a σ of 0 is fitted unweighted).
    """
    weights = [_fit_weights(sigma, end) for sigma, end in zip(sigmas, at_end)] if sigmas else [None] * len(borders)
    groups: dict[tuple[tuple[int, ...], int], list[int]] = {}
    n_min = math.inf
    for e, points in enumerate(borders):
        n = points.shape[0]
        n_min = min(n_min, n)
        span = min(n - 1, _STEP_SPAN)
        (x0, y0), (x1, y1) = (points[-1 - span::span] if at_end[e] else points[: span + 1: span]).tolist()
        per_point = span / (math.hypot(x1 - x0, y1 - y0) or math.inf)
        counts = [int(w * per_point + 0.5) + 1 for w in windows_m]  # round(w / spacing) + 1 points
        if counts[-1] > n:
            counts = [min(n, count) for count in counts]
        groups.setdefault((tuple(counts), -1 if weights[e] is None else e), []).append(e)
    n_noise = min(n_min, max(3, int(round(noise_window_m / 0.1))))
    by_counts: dict[tuple[int, ...], list[int]] = {}
    for counts, weighted in groups:
        by_counts.setdefault(counts, []).append(weighted)
    designs = {(counts, e): design for counts, group in by_counts.items()
               for e, design in zip(group, _end_designs(counts, min(n_noise, counts[-1]),
                                                        [None if e < 0 else weights[e] for e in group]))}
    filtered, squares, n_squares = [], 0.0, 0
    for (counts, weighted), members in groups.items():
        design = designs[counts, weighted]
        k = design.rows.shape[1]
        window = np.concatenate([borders[e][:-k - 1:-1] if at_end[e] else borders[e][:k] for e in members])
        values = (design.rows @ window.reshape(len(members), k, 2)).view(np.complex128)[..., 0]
        n_fit = 3 * len(counts) + 1
        noise = values[:, n_fit:]
        squares += float(np.vdot(noise, noise).real)
        n_squares += noise.size
        filtered.append((members, design, values[:, :n_fit]))
    sigma = max(_SIGMA_FLOOR_M, math.sqrt(squares / (12.0 * n_squares))) if n_squares else _SIGMA_FLOOR_M
    fits: list[EndFit] = [None] * len(borders)  # type: ignore[list-item]  # every slot is filled below
    for members, design, values in filtered:
        for e, row in zip(members, values.tolist()):
            w = _chosen_window(row, design, sigma)
            fits[e] = _end_fit(row, design, w, at_end[e], sigma) if w >= 0 else _chord_fit(borders[e], at_end[e])
    return fits


def _fit_weights(sigma: NDArrayFloat | None, at_end: bool) -> NDArrayFloat | None:
    """Relative weights 1/σ² of a border's points from the fitted end inward (max 1); None
    without σ or with a σ of 0 (an exact point: equal weights)."""
    if sigma is None or not (sigma > 0.0).all():
        return None
    inverse = 1.0 / (sigma[::-1] if at_end else sigma) ** 2
    return inverse / inverse.max()


def _chosen_window(row: list[complex], design: _EndDesign, sigma: float) -> int:
    """Index of the longest window whose heading interval meets those of all shorter ones
    (−1 when the shortest has fewer than four points or no tangent)."""
    p1 = row[1]
    speed = abs(p1)
    if not design.enough_points or speed == 0.0:
        return -1
    reference, scale = p1.conjugate() / speed, _CI_FACTOR * sigma
    half = scale * design.p1_gains[0] / speed
    lo, hi = -half, half
    for w in range(1, len(design.p1_gains)):
        p1 = row[3 * w + 1]
        speed = abs(p1)
        if speed == 0.0:
            return w - 1
        heading, half = cmath.phase(p1 * reference), scale * design.p1_gains[w] / speed
        if heading - half > lo:
            lo = heading - half
        if heading + half < hi:
            hi = heading + half
        if lo > hi:
            return w - 1
    return len(design.p1_gains) - 1


def _chord_fit(points: NDArrayFloat, at_end: bool) -> EndFit:
    """The end point, the whole border's chord direction and zero curvature of infinite σ."""
    (x0, y0), (x1, y1) = points[0].tolist(), points[-1].tolist()
    norm = math.hypot(x1 - x0, y1 - y0) or 1.0
    return EndFit((x1, y1) if at_end else (x0, y0), ((x1 - x0) / norm, (y1 - y0) / norm), 0.0, math.inf)


def _end_fit(row: list[complex], design: _EndDesign, w: int, at_end: bool, sigma: float) -> EndFit:
    """One border's fit from its filtered coefficients ``row`` and chosen window ``w``."""
    p0, p1, p2 = row[3 * w: 3 * w + 3]
    speed = abs(p1)
    tangent = p1 / speed
    turn = (p1.conjugate() * p2).imag * 2.0 / (speed * speed)  # κ·v: curvature per point index
    along = turn * turn * speed / 6.0 * tangent  # minus the arc's cubic term, −κ²v³/6 along the tangent
    across = turn * turn * turn * speed / 24.0 * 1j * tangent  # minus its quartic term, −κ³v⁴/24 across
    (c0, c1, c2), (q0, q1, q2) = design.cubic_leaks[w], design.quartic_leaks[w]
    p0, p1, p2 = p0 + c0 * along + q0 * across, p1 + c1 * along + q1 * across, p2 + c2 * along + q2 * across
    speed = abs(p1)
    turn = (p1.conjugate() * p2).imag * 2.0 / (speed * speed)
    curvature, curvature_sigma = turn / speed, 2.0 * sigma * design.p2_gains[w] / (speed * speed)
    normal_p3 = (row[-1] * p1.conjugate()).imag / speed
    arc_p3 = -design.p3_quartic_leak * turn * turn * turn * speed / 24.0
    if abs(normal_p3 - arc_p3) > _CURVATURE_CHANGE_SIGMAS * sigma * design.p3_gain + _CUBIC_ARC_BIAS * abs(arc_p3):
        curvature_sigma = math.inf
    direction = (-p1 if at_end else p1) / speed
    return EndFit((p0.real, p0.imag), (direction.real, direction.imag),
                  -curvature if at_end else curvature, curvature_sigma)


def distance_to_polyline(points: NDArrayFloat, polyline: NDArrayFloat) -> NDArrayFloat:
    """Distance of every point to a dense ``polyline`` (closest vertex, then its segments)."""
    from scipy.spatial import cKDTree

    _, idx = cKDTree(polyline).query(points)
    best = np.full(points.shape[0], np.inf)
    for k in (-1, 0):
        i0 = np.clip(idx + k, 0, polyline.shape[0] - 2)
        a, b = polyline[i0], polyline[i0 + 1]
        seg = b - a
        t = np.clip(np.einsum("ij,ij->i", points - a, seg) / np.einsum("ij,ij->i", seg, seg), 0.0, 1.0)
        best = np.minimum(best, np.hypot(*(points - a - seg * t[:, None]).T))
    return best
