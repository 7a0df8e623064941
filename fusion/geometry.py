"""Small planar geometry kernels on ``(N, 2)`` polylines (numpy only, no validation)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np

from fusion.types import NDArrayFloat, Pose2D

_SIGMA_FLOOR_M: Final[float] = 0.002
_CI_FACTOR: Final[float] = 2.5
_CURVATURE_CHANGE_SIGMAS: Final[float] = 3.0
_CUBIC_ARC_BIAS: Final[float] = 0.05
_EYE4: Final[NDArrayFloat] = np.eye(4)
# Power sums of a window by slot: n, Σx … Σx⁶ (1–6), Σy, Σy·x, Σy·x², Σy·x³ (7–10).
_CUBIC_NORMAL: Final = np.add.outer(np.arange(4), np.arange(4))
_CUBIC_RHS: Final = np.arange(7, 11)


def transform(points: NDArrayFloat, x: float, y: float, yaw: float) -> NDArrayFloat:
    """Points of a frame at ``(x, y, yaw)`` (relative to a parent frame) in the parent frame.

    Read as complex numbers, the rigid motion is one multiply-add (half the time of a 2×2
    matmul on a few hundred points)."""
    z = np.ascontiguousarray(points).view(np.complex128)[:, 0] * complex(math.cos(yaw), math.sin(yaw))
    z += complex(x, y)
    return z.view(np.float64).reshape(-1, 2)


def to_world(points: NDArrayFloat, pose: Pose2D) -> NDArrayFloat:
    """Vehicle-frame points of a vehicle at ``pose`` in the world frame."""
    return transform(points, pose.x, pose.y, pose.yaw)


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


def project_point(point: NDArrayFloat, polyline: NDArrayFloat, arclength: NDArrayFloat) -> tuple[float, float, int]:
    """Closest point of ``polyline`` to ``point`` (near its nearest vertex).

    Returns ``(s, distance, segment)``: arc length of the foot point [m], its distance [m] and
    the index of the segment holding it. Only the two segments at the nearest vertex are
    examined, which is exact for polylines sampled finer than their curvature radius.
    """
    k = int(norms(polyline - point).argmin())
    px, py = float(point[0]), float(point[1])
    best = (math.inf, 0.0, 0)
    for i in (k - 1, k):
        if i < 0 or i + 1 >= polyline.shape[0]:
            continue
        ax, ay = float(polyline[i, 0]), float(polyline[i, 1])
        dx, dy = float(polyline[i + 1, 0]) - ax, float(polyline[i + 1, 1]) - ay
        seg2 = dx * dx + dy * dy
        t = min(1.0, max(0.0, ((px - ax) * dx + (py - ay) * dy) / seg2)) if seg2 > 0.0 else 0.0
        dist = math.hypot(ax + t * dx - px, ay + t * dy - py)
        if dist < best[0]:
            best = (dist, float(arclength[i] + t * (arclength[i + 1] - arclength[i])), i)
    return best[1], best[0], best[2]


def _chord(points: NDArrayFloat, at_end: bool, k: int, first: list[float], last: list[float]) -> tuple[float, float]:
    """Unit vector from the point ``k`` before the last one to the last (``at_end``), or from the
    first point to the point ``k`` after it; the whole polyline's chord when that is zero."""
    (x0, y0), (x1, y1) = first, last
    if at_end:
        px, py = points[-1 - k].tolist()
        vx, vy = x1 - px, y1 - py
    else:
        px, py = points[k].tolist()
        vx, vy = px - x0, py - y0
    norm = math.hypot(vx, vy)
    if norm == 0.0:
        vx, vy = x1 - x0, y1 - y0
        norm = math.hypot(vx, vy) or 1.0
    return vx / norm, vy / norm


def end_direction(points: NDArrayFloat, at_end: bool, window_m: float) -> tuple[float, float]:
    """Unit tangent ``(dx, dy)`` at the last (``at_end``) or first point, by a chord.

    The chord spans about ``window_m`` of the polyline (at least one segment), assuming
    roughly even spacing; it points in driving direction.
    """
    n = points.shape[0]
    first, last = points[0].tolist(), points[-1].tolist()
    k = max(1, _points_in(window_m, math.hypot(last[0] - first[0], last[1] - first[1]) / (n - 1), n - 1))
    return _chord(points, at_end, k, first, last)


@dataclass(frozen=True)
class EndFit:
    """Least-squares estimate at a border end (world frame).

    Fields: ``point`` fitted end point [m]; ``direction`` unit tangent (driving direction);
    ``curvature`` [1/m] (positive turning left); ``curvature_sigma`` its standard deviation
    from the detection noise [1/m].
    """

    point: NDArrayFloat
    direction: tuple[float, float]
    curvature: float
    curvature_sigma: float


def fit_ends(borders: Sequence[NDArrayFloat], at_end: Sequence[bool], windows_m: tuple[float, ...],
             noise_window_m: float) -> list[EndFit]:
    """Least-squares end point, tangent and curvature of several borders at once.

    For each border, fits ``y = a + b·x + c·x²`` to the points within each of ``windows_m``
    (increasing) of its last (``at_end``) or first point, in a frame whose x axis is the
    chord of the shortest window (driving direction) and whose origin is that point. The
    quadratic term removes most of the bias a line fit has on a curve; longer windows
    average the noise but are biased where the curvature changes. The window is chosen by
    the intersection-of-confidence-intervals rule: the longest window whose slope interval
    b ± 2.5·σ_b still intersects those of all shorter windows, with σ_b from the detection
    noise σ (estimated from second differences over ``noise_window_m`` of all borders,
    assuming ~0.1 m spacing; a smooth curve contributes < 1 mm). The curvature comes from the
    chosen window too (σ_κ falls with the window length to the power 2.5, so a long window
    tells a 1/500 m⁻¹ curve from a straight); ``curvature_sigma`` is its σ, or infinite when
    the longest window is no single arc: the cubic coefficient d of a cubic fit over it
    differs from an arc's, κ³·x_L/6 (x_L the far end of the window; measured on arcs of
    8–100 m radius), by more than 3σ_d + 0.05·|κ|³·L. A clothoid (d ≈ κ'/6 for a curvature
    rate κ') or a junction of line and arc inside the window fails that test. A border whose
    shortest window holds fewer than four points gets its end point, the chord direction and
    zero curvature of infinite uncertainty.

    The power sums of every window of every border come from one masked matrix product, the
    cubics of all borders from one batched solve; the windows' quadratics are solved by
    Cramer's rule on floats, stopping at the first window the rule rejects.
    """
    n_ends, n_windows = len(borders), len(windows_m)
    counts, chords, origins = [], [], []
    for points, end in zip(borders, at_end):
        n = points.shape[0]
        first, last = points[0].tolist(), points[-1].tolist()
        step = math.hypot(last[0] - first[0], last[1] - first[1]) / (n - 1)
        count = [_points_in(w, step, n - 1) + 1 for w in windows_m]
        counts.append(count)
        chords.append(complex(*_chord(points, end, max(1, count[0] - 1), first, last)))
        origins.append(last if end else first)
    k_max = max(c[-1] for c in counts)
    stacked = np.zeros((n_ends, k_max, 2))
    for e, (points, end) in enumerate(zip(borders, at_end)):
        m = min(k_max, points.shape[0])
        stacked[e, :m] = points[:-m - 1:-1] if end else points[:m]
    windows = stacked.view(np.complex128)[..., 0]
    n_noise = min(k_max, min(b.shape[0] for b in borders), max(3, int(round(noise_window_m / 0.1))))
    d2 = windows[:, : n_noise - 2] - 2.0 * windows[:, 1: n_noise - 1] + windows[:, 2:n_noise]
    sigma = max(_SIGMA_FLOOR_M, math.sqrt(float(np.vdot(d2, d2).real) / (12.0 * n_ends * max(1, n_noise - 2))))
    local = (windows - windows[:, :1]) * np.conj(chords)[:, None]
    x, y = local.real, local.imag
    powers = np.empty((n_ends, 11, k_max))
    powers[:, 0] = 1.0
    powers[:, 1] = x
    np.multiply(x, x, out=powers[:, 2])
    np.multiply(powers[:, 2], x, out=powers[:, 3])
    np.multiply(powers[:, 1:4], powers[:, 3:4], out=powers[:, 4:7])
    np.multiply(powers[:, :4], y[:, None], out=powers[:, 7:])
    count = np.array(counts)
    inside = (np.arange(k_max) < count[..., None]).astype(np.float64)
    sums = inside @ powers.transpose(0, 2, 1)
    cubic_normal = sums[:, -1, _CUBIC_NORMAL]
    rhs = np.zeros((n_ends, 4, 2))
    rhs[:, :, 0] = sums[:, -1, _CUBIC_RHS]
    rhs[:, 3, 1] = 1.0
    try:
        solution = np.linalg.solve(cubic_normal, rhs)[:, 3]
    except np.linalg.LinAlgError:  # fewer than four distinct x in a window: d = σ_d = 0 there
        solvable = np.linalg.det(cubic_normal) != 0.0
        solution = np.linalg.solve(np.where(solvable[:, None, None], cubic_normal, _EYE4), rhs)[:, 3]
        solution *= solvable[:, None]
    cubic, cubic_var = solution.T.tolist()
    x_far = x[np.arange(n_ends), count[:, -1] - 1].tolist()
    cells = sums[..., :10].tolist()
    fits = []
    for e in range(n_ends):
        direction = chords[e]
        chosen = None
        lo, hi = -math.inf, math.inf
        for k, s1, s2, s3, s4, _, _, t0, t1, t2 in cells[e]:
            m1 = s1 * s4 - s3 * s2
            det = k * (s2 * s4 - s3 * s3) - s1 * m1 + s2 * (s1 * s3 - s2 * s2)
            if k < 4.0 or abs(det) <= 1e-12 * max(1.0, s4 * s4):
                break
            b = (k * (t1 * s4 - s3 * t2) - t0 * m1 + s2 * (s1 * t2 - s2 * t1)) / det
            half = _CI_FACTOR * sigma * math.sqrt(abs((k * s4 - s2 * s2) / det))
            lo, hi = max(lo, b - half), min(hi, b + half)
            if lo > hi:
                break
            chosen = (k, s1, s2, s3, s4, t0, t1, t2, det, b)
        if chosen is None:
            fits.append(EndFit(np.array(origins[e]), (direction.real, direction.imag), 0.0, math.inf))
            continue
        k, s1, s2, s3, s4, t0, t1, t2, det, slope = chosen
        a = (t0 * (s2 * s4 - s3 * s3) - s1 * (t1 * s4 - s3 * t2) + s2 * (t1 * s3 - s2 * t2)) / det
        c = (k * (s2 * t2 - t1 * s3) - s1 * (s1 * t2 - t1 * s2) + t0 * (s1 * s3 - s2 * s2)) / det
        norm = math.hypot(1.0, slope)
        scale = 2.0 / norm ** 3
        curvature, curvature_sigma = scale * c, scale * sigma * math.sqrt(abs((k * s2 - s1 * s1) / det))
        arc_cubic = curvature ** 3 * x_far[e] / 6.0
        if abs(cubic[e] - arc_cubic) > (_CURVATURE_CHANGE_SIGMAS * sigma * math.sqrt(abs(cubic_var[e]))
                                        + _CUBIC_ARC_BIAS * abs(curvature) ** 3 * abs(x_far[e])):
            curvature_sigma = math.inf
        point = complex(*origins[e]) + a * 1j * direction
        tangent = direction * complex(1.0, slope) / norm
        fits.append(EndFit(np.array((point.real, point.imag)), (tangent.real, tangent.imag), curvature,
                           curvature_sigma))
    return fits


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
