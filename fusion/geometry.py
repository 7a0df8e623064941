"""Small planar geometry kernels on ``(N, 2)`` polylines (numpy only, no validation)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.types import NDArrayFloat, Pose2D

_SIGMA_FLOOR_M = 0.002
_CI_FACTOR = 2.5


def transform(points: NDArrayFloat, x: float, y: float, yaw: float) -> NDArrayFloat:
    """Points of a frame at ``(x, y, yaw)`` (relative to a parent frame) in the parent frame."""
    c, s = math.cos(yaw), math.sin(yaw)
    return points @ np.array(((c, s), (-s, c))) + (x, y)


def to_world(points: NDArrayFloat, pose: Pose2D) -> NDArrayFloat:
    """Vehicle-frame points of a vehicle at ``pose`` in the world frame."""
    return transform(points, pose.x, pose.y, pose.yaw)


def wrap_angle(angle: float) -> float:
    """Angle wrapped to [-π, π) [rad]."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def cumulative_length(points: NDArrayFloat) -> NDArrayFloat:
    """Arc length at every vertex of a polyline, starting at 0 [m]."""
    step = np.diff(points, axis=0)
    out = np.empty(points.shape[0])
    out[0] = 0.0
    np.cumsum(np.hypot(step[:, 0], step[:, 1]), out=out[1:])
    return out


def project_point(point: NDArrayFloat, polyline: NDArrayFloat, arclength: NDArrayFloat) -> tuple[float, float, int]:
    """Closest point of ``polyline`` to ``point`` (near its nearest vertex).

    Returns ``(s, distance, segment)``: arc length of the foot point [m], its distance [m] and
    the index of the segment holding it. Only the two segments at the nearest vertex are
    examined, which is exact for polylines sampled finer than their curvature radius.
    """
    rel = polyline - point
    k = int(np.einsum("ij,ij->i", rel, rel).argmin())
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


def end_direction(points: NDArrayFloat, at_end: bool, window_m: float) -> tuple[float, float]:
    """Unit tangent ``(dx, dy)`` at the last (``at_end``) or first point, by a chord.

    The chord spans about ``window_m`` of the polyline (at least one segment), assuming
    roughly even spacing; it points in driving direction.
    """
    n = points.shape[0]
    x0, y0, x1, y1 = float(points[0, 0]), float(points[0, 1]), float(points[-1, 0]), float(points[-1, 1])
    approx_step = math.hypot(x1 - x0, y1 - y0) / (n - 1) or 1.0
    k = min(n - 1, max(1, int(round(window_m / approx_step))))
    if at_end:
        vx, vy = x1 - float(points[-1 - k, 0]), y1 - float(points[-1 - k, 1])
    else:
        vx, vy = float(points[k, 0]) - x0, float(points[k, 1]) - y0
    norm = math.hypot(vx, vy)
    if norm == 0.0:
        vx, vy = x1 - x0, y1 - y0
        norm = math.hypot(vx, vy) or 1.0
    return vx / norm, vy / norm


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


def fit_end(points: NDArrayFloat, at_end: bool, windows_m: tuple[float, ...], sigma_m: float) -> EndFit:
    """End point and unit tangent of a border by least-squares quadratics, adaptive window.

    Fits ``y = a + b·x + c·x²`` to the points within each of ``windows_m`` (increasing) of
    the last (``at_end``) or first point, in a frame whose x axis is the chord of the shortest
    window and whose origin is that point. The quadratic term removes most of the bias a
    line fit has on a curve, and longer windows average the noise but are biased where the
    curvature changes. The window is chosen by the intersection-of-confidence-intervals
    rule: the longest window whose slope interval b ± 2.5·σ_b (σ_b from the detection noise
    ``sigma_m``) still intersects those of all shorter windows. The curvature comes from the
    shortest window (least biased by a curvature change, so with noise it is uncertain and
    ``curvature_sigma`` says so). With fewer than four points
    in the shortest window: the end point, the chord direction and zero curvature of
    infinite uncertainty.
    """
    cx, cy = end_direction(points, at_end, windows_m[0])
    n = points.shape[0]
    origin = points[-1] if at_end else points[0]
    approx_step = float(np.hypot(*(points[-1] - points[0]))) / (n - 1) or 1.0
    counts = np.minimum(n, np.rint(np.asarray(windows_m) / approx_step).astype(np.intp) + 1)
    counts = counts[counts >= 4]
    if counts.shape[0] == 0:
        return EndFit(origin, (cx, cy), 0.0, math.inf)
    k_max = int(counts[-1])
    rel = (points[n - k_max:][::-1] if at_end else points[:k_max]) - origin
    x = rel[:, 0] * cx + rel[:, 1] * cy
    y = rel[:, 1] * cx - rel[:, 0] * cy
    x2 = x * x
    sums = np.cumsum(np.stack((x, x2, x2 * x, x2 * x2, y, y * x, y * x2)), axis=1)[:, counts - 1]
    s1, s2, s3, s4, t0, t1, t2 = sums
    k = counts.astype(np.float64)
    m0, m1, m2 = s2 * s4 - s3 * s3, s1 * s4 - s3 * s2, s1 * s3 - s2 * s2
    det = k * m0 - s1 * m1 + s2 * m2
    ok = np.abs(det) > 1e-12 * np.maximum(1.0, s4 * s4)
    if not ok[0]:
        return EndFit(origin, (cx, cy), 0.0, math.inf)
    det = np.where(ok, det, 1.0)
    a = (t0 * m0 - s1 * (t1 * s4 - s3 * t2) + s2 * (t1 * s3 - s2 * t2)) / det
    b = (k * (t1 * s4 - s3 * t2) - t0 * m1 + s2 * (s1 * t2 - s2 * t1)) / det
    c = (k * (s2 * t2 - t1 * s3) - s1 * (s1 * t2 - t1 * s2) + t0 * m2) / det
    sigma = max(sigma_m, _SIGMA_FLOOR_M)
    half = _CI_FACTOR * sigma * np.sqrt(np.abs((k * s4 - s2 * s2) / det))
    lo = np.maximum.accumulate(b - half)
    hi = np.minimum.accumulate(b + half)
    valid = (lo <= hi) & ok
    j = int(np.argmin(valid)) - 1 if not valid.all() else valid.shape[0] - 1
    j = max(j, 0)
    slope = float(b[j])
    norm = math.hypot(1.0, slope)
    point = origin + float(a[j]) * np.array((-cy, cx))
    scale = 2.0 / math.hypot(1.0, float(b[0])) ** 3
    c_sigma = sigma * math.sqrt(abs(float((k[0] * s2[0] - s1[0] * s1[0]) / det[0])))
    return EndFit(point, ((cx - slope * cy) / norm, (cy + slope * cx) / norm), scale * float(c[0]), scale * c_sigma)


def noise_level(points: NDArrayFloat, count: int) -> float:
    """Detection noise σ per coordinate [m] estimated from second differences of ``count``
    points at the end of ``points`` (a smooth curve sampled every 0.1 m contributes < 1 mm)."""
    tail = points[-count:]
    if tail.shape[0] < 3:
        return 0.0
    d2 = tail[:-2] - 2.0 * tail[1:-1] + tail[2:]
    return math.sqrt(float(np.einsum("ij,ij->", d2, d2)) / (12.0 * d2.shape[0]))


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
