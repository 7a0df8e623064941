"""Bézier exchange format for lane detections (paper sec. III-C).

Each border is sent as cubic Bézier segments, 4 control points of 3 float32 coordinates
(x, y, z; z = 0 for our planar borders) in the sender's vehicle frame [m], so one lane with
one segment per border costs 2 × 4 × 3 × 4 = 96 bytes of payload, independent of its length
(the sampled lane costs 12 bytes per point: 7200 bytes for 2 × 300 points). A border that
one cubic does not approximate within the tolerance is split into more segments of equal
arc length. The sender's pose is sent separately.

Byte layout, version 1 (little-endian)::

    offset  size  field
    0       2     magic b"CB"
    2       1     version = 1
    3       1     flags = 0 (reserved)
    4       2     uint16 number of left-border segments  K_l ≥ 1
    6       2     uint16 number of right-border segments K_r ≥ 1
    8       48·K  float32 control points, segment by segment, left border first:
                  P0.x P0.y P0.z P1.x … P3.z

Total size 8 + 48·(K_l + K_r) bytes: 104 bytes for one segment per border.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from typing import Final

import numpy as np

from fusion.errors import BezierDecodeError, InvalidParameterError
from fusion.geometry import cumulative_length, distance_to_polyline
from fusion.types import NDArrayFloat, validated_border

MAGIC: Final[bytes] = b"CB"
VERSION: Final[int] = 1
HEADER: Final[struct.Struct] = struct.Struct("<2sBBHH")
SEGMENT_BYTES: Final[int] = 4 * 3 * 4
SAMPLED_POINT_BYTES: Final[int] = 3 * 4
DEFAULT_TOLERANCE_M: Final[float] = 0.05
_MAX_SEGMENTS: Final[int] = 0xFFFF
_REPARAM_ROUNDS: Final[int] = 4


@dataclass(frozen=True)
class ExchangeStats:
    """Cost and accuracy of the Bézier encoding of one lane.

    Fields: ``bezier_bytes`` size of the message [B]; ``payload_bytes`` its control points
    only [B] (96 for one segment per border); ``sampled_bytes`` the same lane as sampled
    points, 3 float32 per point [B]; ``segments`` (left, right) segment counts;
    ``max_error_m`` largest distance of an input point from the decoded curve [m].
    """

    bezier_bytes: int
    payload_bytes: int
    sampled_bytes: int
    segments: tuple[int, int]
    max_error_m: float


def _basis(t: NDArrayFloat) -> NDArrayFloat:
    v = 1.0 - t
    return np.stack((v**3, 3.0 * v * v * t, 3.0 * v * t * t, t**3), axis=1)


def _fit_cubic(points: NDArrayFloat) -> tuple[NDArrayFloat, float]:
    """Least-squares cubic Bézier through the end points of ``points``; (4, 2) control, error.

    Inner control points by linear least squares with chord-length parameters, then a few
    rounds of Newton re-parametrisation (each point's parameter moves to its closest curve
    point). The error is the largest distance of a point from the curve at its parameter,
    an upper bound of the distance to the curve.
    """
    p0, p3 = points[0], points[-1]
    s = cumulative_length(points)
    t = s / s[-1]
    ctrl = np.array([p0, p0 + (p3 - p0) / 3.0, p3 - (p3 - p0) / 3.0, p3])
    for _ in range(_REPARAM_ROUNDS):
        b = _basis(t)
        rhs = points - np.outer(b[:, 0], p0) - np.outer(b[:, 3], p3)
        a11, a12, a22 = b[:, 1] @ b[:, 1], b[:, 1] @ b[:, 2], b[:, 2] @ b[:, 2]
        det = a11 * a22 - a12 * a12
        if abs(det) > 1e-12:
            r1, r2 = b[:, 1] @ rhs, b[:, 2] @ rhs
            ctrl[1] = (a22 * r1 - a12 * r2) / det
            ctrl[2] = (a11 * r2 - a12 * r1) / det
        d1 = 3.0 * np.diff(ctrl, axis=0)
        d2 = 2.0 * np.diff(d1, axis=0)
        v = 1.0 - t
        diff = _basis(t) @ ctrl - points
        first = np.outer(v * v, d1[0]) + np.outer(2 * v * t, d1[1]) + np.outer(t * t, d1[2])
        second = np.outer(v, d2[0]) + np.outer(t, d2[1])
        num = np.einsum("ij,ij->i", diff, first)
        den = np.einsum("ij,ij->i", first, first) + np.einsum("ij,ij->i", diff, second)
        step = np.divide(num, den, out=np.zeros_like(num), where=np.abs(den) > 1e-12)
        t = np.clip(t - step, 0.0, 1.0)
        t[0], t[-1] = 0.0, 1.0
    error = float(np.hypot(*(_basis(t) @ ctrl - points).T).max())
    return ctrl, error


def fit_border(points: NDArrayFloat, tolerance_m: float) -> tuple[NDArrayFloat, float]:
    """Fewest equal-arc-length cubic segments within ``tolerance_m``; ``(K, 4, 2)``, error [m]."""
    n = points.shape[0]
    s = cumulative_length(points)
    best: tuple[NDArrayFloat, float] | None = None
    for k in range(1, max(1, (n - 1) // 3) + 1):
        cuts = np.searchsorted(s, np.linspace(0.0, s[-1], k + 1)[1:-1])
        bounds = np.unique(np.concatenate(([0], cuts, [n - 1])))
        fits = [_fit_cubic(points[i:j + 1]) for i, j in zip(bounds[:-1], bounds[1:])]
        error = max(e for _, e in fits)
        best = (np.stack([c for c, _ in fits]), error)
        if error <= tolerance_m:
            break
    assert best is not None
    return best


def encode(left: NDArrayFloat, right: NDArrayFloat, *, tolerance_m: float = DEFAULT_TOLERANCE_M) -> bytes:
    """Version-1 message of a lane's borders (``(N, 2)``, sender vehicle frame [m])."""
    if not math.isfinite(tolerance_m) or tolerance_m <= 0.0:
        raise InvalidParameterError(f"bezier.encode tolerance_m must be finite and > 0, got {tolerance_m!r}")
    ctrls = [fit_border(validated_border(name, b), tolerance_m)[0] for name, b in (("left", left), ("right", right))]
    if any(c.shape[0] > _MAX_SEGMENTS for c in ctrls):
        raise InvalidParameterError("bezier.encode: more than 65535 segments per border")
    body = np.concatenate([np.concatenate((c, np.zeros(c.shape[:2] + (1,))), axis=2).reshape(-1) for c in ctrls])
    return HEADER.pack(MAGIC, VERSION, 0, ctrls[0].shape[0], ctrls[1].shape[0]) + body.astype("<f4").tobytes()


def decode_controls(data: bytes) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Control points ``(K, 4, 3)`` float64 of the (left, right) borders of a message."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise BezierDecodeError(f"Bézier message must be bytes, got {type(data).__name__}")
    if len(data) < HEADER.size:
        raise BezierDecodeError(f"Bézier message truncated: {len(data)} bytes, header needs {HEADER.size}")
    magic, version, _, n_left, n_right = HEADER.unpack_from(data)
    if magic != MAGIC:
        raise BezierDecodeError(f"Bézier message has magic {magic!r}, expected {MAGIC!r}")
    if version != VERSION:
        raise BezierDecodeError(f"Bézier message version {version} unsupported (this decoder reads {VERSION})")
    if n_left == 0 or n_right == 0:
        raise BezierDecodeError(f"Bézier message has {n_left} left and {n_right} right segments; each needs >= 1")
    expected = HEADER.size + SEGMENT_BYTES * (n_left + n_right)
    if len(data) != expected:
        raise BezierDecodeError(f"Bézier message is {len(data)} bytes, its header announces {expected}")
    values = np.frombuffer(bytes(data), dtype="<f4", offset=HEADER.size).astype(np.float64).reshape(-1, 4, 3)
    if not np.isfinite(values).all():
        raise BezierDecodeError("Bézier message contains NaN or inf control points")
    return values[:n_left], values[n_left:]


def sample_controls(ctrl: NDArrayFloat, spacing_m: float) -> NDArrayFloat:
    """Points ``(N, 2)`` of Bézier segments ``(K, 4, ≥2)``, ends included, ≤ ``spacing_m`` apart."""
    parts = []
    for seg in ctrl[:, :, :2]:
        fine = _basis(np.linspace(0.0, 1.0, 257)) @ seg
        s = cumulative_length(fine)
        n = max(1, math.ceil(s[-1] / spacing_m * (1.0 + 1e-3)))
        t = np.interp(np.linspace(0.0, s[-1], n + 1), s, np.linspace(0.0, 1.0, 257))
        pts = _basis(t) @ seg
        parts.append(pts if not parts else pts[1:])
    return np.concatenate(parts)


def decode(data: bytes, *, spacing_m: float = 0.10) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(left, right) borders ``(N, 2)`` [m, sender vehicle frame] sampled every ≤ ``spacing_m``."""
    if not math.isfinite(spacing_m) or spacing_m <= 0.0:
        raise InvalidParameterError(f"bezier.decode spacing_m must be finite and > 0, got {spacing_m!r}")
    left, right = decode_controls(data)
    return sample_controls(left, spacing_m), sample_controls(right, spacing_m)


def exchange_stats(left: NDArrayFloat, right: NDArrayFloat, *, tolerance_m: float = DEFAULT_TOLERANCE_M) -> ExchangeStats:
    """Encode, decode and measure a lane (see :class:`ExchangeStats`)."""
    message = encode(left, right, tolerance_m=tolerance_m)
    ctrl_left, ctrl_right = decode_controls(message)
    error = 0.0
    for border, ctrl in ((left, ctrl_left), (right, ctrl_right)):
        dense = sample_controls(ctrl, 0.01)
        error = max(error, float(distance_to_polyline(np.asarray(border, dtype=np.float64), dense).max()))
    n_points = len(left) + len(right)
    return ExchangeStats(len(message), len(message) - HEADER.size, SAMPLED_POINT_BYTES * n_points,
                         (ctrl_left.shape[0], ctrl_right.shape[0]), error)
