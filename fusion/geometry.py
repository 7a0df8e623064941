"""Small planar geometry kernels on ``(N, 2)`` polylines (numpy only, no validation)."""

from __future__ import annotations

import math

import numpy as np

from fusion.types import NDArrayFloat, Pose2D


def to_world(points: NDArrayFloat, pose: Pose2D) -> NDArrayFloat:
    """Vehicle-frame points of a vehicle at ``pose`` in the world frame."""
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    return points @ np.array([[c, s], [-s, c]]) + (pose.x, pose.y)


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
    """Closest point of ``polyline`` to ``point``.

    Returns ``(s, distance, segment)``: arc length of the foot point [m], its distance [m] and
    the index of the segment holding it.
    """
    seg = polyline[1:] - polyline[:-1]
    rel = point - polyline[:-1]
    seg_len2 = np.einsum("ij,ij->i", seg, seg)
    t = np.clip(np.einsum("ij,ij->i", rel, seg) / seg_len2, 0.0, 1.0)
    diff = rel - seg * t[:, None]
    dist2 = np.einsum("ij,ij->i", diff, diff)
    k = int(np.argmin(dist2))
    s = float(arclength[k] + t[k] * (arclength[k + 1] - arclength[k]))
    return s, math.sqrt(float(dist2[k])), k


def end_direction(points: NDArrayFloat, at_end: bool, window_m: float) -> tuple[float, float]:
    """Unit tangent ``(dx, dy)`` at the last (``at_end``) or first point, by a chord.

    The chord spans about ``window_m`` of the polyline (at least one segment); it points in
    driving direction.
    """
    n = points.shape[0]
    approx_step = float(np.hypot(*(points[-1] - points[0]))) / (n - 1) or 1.0
    k = min(n - 1, max(1, int(round(window_m / approx_step))))
    vec = points[-1] - points[-1 - k] if at_end else points[k] - points[0]
    norm = math.hypot(vec[0], vec[1])
    if norm == 0.0:
        vec = points[-1] - points[0]
        norm = math.hypot(vec[0], vec[1]) or 1.0
    return float(vec[0] / norm), float(vec[1] / norm)


def fit_end_tangent(points: NDArrayFloat, at_end: bool, window_m: float) -> tuple[float, float]:
    """Unit tangent at the last (``at_end``) or first point by least squares.

    Fits ``y = a + b·x + c·x²`` to the points within ``window_m`` of the end, in a frame whose
    x axis is the end chord, and returns the direction of the fitted curve at the end point
    (driving direction). The quadratic term removes the bias a straight-line fit would have
    on a curve; the fit averages detection noise. Falls back to the chord when the window
    holds fewer than four points.
    """
    cx, cy = end_direction(points, at_end, window_m)
    n = points.shape[0]
    approx_step = float(np.hypot(*(points[-1] - points[0]))) / (n - 1) or 1.0
    k = min(n, max(2, int(round(window_m / approx_step)) + 1))
    if k < 4:
        return cx, cy
    window = points[n - k:] if at_end else points[:k]
    origin = points[-1] if at_end else points[0]
    rel = window - origin
    x = rel[:, 0] * cx + rel[:, 1] * cy
    y = rel[:, 1] * cx - rel[:, 0] * cy
    x2 = x * x
    s1, s2, s3, s4 = float(x.sum()), float(x2.sum()), float(x2 @ x), float(x2 @ x2)
    t0, t1, t2 = float(y.sum()), float(y @ x), float(y @ x2)
    det = k * (s2 * s4 - s3 * s3) - s1 * (s1 * s4 - s3 * s2) + s2 * (s1 * s3 - s2 * s2)
    if abs(det) < 1e-12 * max(1.0, s4 * s4):
        return cx, cy
    slope = (k * (t1 * s4 - s3 * t2) - t0 * (s1 * s4 - s3 * s2) + s2 * (s1 * t2 - s2 * t1)) / det
    norm = math.hypot(1.0, slope)
    return (cx - slope * cy) / norm, (cy + slope * cx) / norm


def sample_curve(evaluate, t_start: float, t_end: float, length_hint_m: float, spacing_m: float,
                 oversample: int = 4) -> NDArrayFloat:
    """Points of a parametric curve strictly between its ends, at most ``spacing_m`` apart.

    ``evaluate`` maps an array of parameters in ``[t_start, t_end]`` to ``(M, 2)`` points.
    The curve is measured on a grid ``oversample`` times finer than the output step implied
    by ``length_hint_m`` (a rough curve length), then sampled at equal arc-length steps
    ``≤ spacing_m``; the two ends themselves are not returned.
    """
    n_grid = max(8, math.ceil(length_hint_m / spacing_m) * oversample)
    grid_t = np.linspace(t_start, t_end, n_grid + 1)
    grid_s = cumulative_length(evaluate(grid_t))
    total = float(grid_s[-1])
    n_steps = math.ceil(total / spacing_m * (1.0 + 1e-3))
    if n_steps < 2:
        return np.empty((0, 2))
    target = np.linspace(0.0, total, n_steps + 1)[1:-1]
    return evaluate(np.interp(target, grid_s, grid_t))
