"""Error models of the generic lane sensor (the paper's "offset or noise", sec. IV).

Every model is off by default and draws from a caller-owned ``numpy.random.Generator``,
so a run is reproducible from its seed. Detections are perturbed in the vehicle frame
(ISO 8855: x forward, y left); the sender's pose in the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Final, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.sensor import vehicle_to_world
from gt_matching.polyline import arc_lengths

MAX_ERROR_M: Final[float] = 1000.0
"""Largest lateral offset (either sign), noise σ, range jitter σ and pose σ the error
models accept (m): errors of a kilometre leave no lane to detect, and the bound keeps every
perturbed coordinate finite (a σ of 1e308 overflowed the detections to NaN mid-run)."""
MAX_ANGLE_RAD: Final[float] = math.pi
"""Largest heading bias (either sign) and yaw σ the error models accept (rad): beyond π a
rotation only wraps around."""
_SIGNED: Final[frozenset[str]] = frozenset({"lateral_offset_m", "heading_bias_rad"})
_ANGLES: Final[frozenset[str]] = frozenset({"heading_bias_rad", "pose_sigma_yaw_rad"})


def check_polyline(name: str, points: object, min_points: int = 2) -> NDArrayFloat:
    """``points`` as a finite ``(N, 2)`` float64 array with N >= ``min_points``.

    Raises ValueError naming ``name`` otherwise.
    """
    array = np.asarray(points, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"{name}: expected an (N, 2) polyline, got shape {array.shape}")
    if array.shape[0] < min_points:
        raise ValueError(f"{name}: expected at least {min_points} points, got {array.shape[0]}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name}: polyline contains NaN or infinite coordinates")
    return array


def left_normals(points: NDArrayFloat, name: str = "polyline") -> NDArrayFloat:
    """Unit normals pointing left of the driving direction at each vertex, ``(N, 2)``.

    Tangents are central differences (one-sided at the ends), so on a uniformly sampled
    circle the interior normals are exactly radial.
    """
    tangents = np.empty_like(points)
    tangents[1:-1] = (points[2:] - points[:-2]) / 2.0  # as np.gradient, at half its cost
    tangents[0] = points[1] - points[0]
    tangents[-1] = points[-1] - points[-2]
    norms = np.hypot(tangents[:, 0], tangents[:, 1])
    if np.any(norms == 0.0):
        raise ValueError(f"{name}: repeated or reversing points, normal undefined")
    tangents /= norms[:, None]
    return np.column_stack((-tangents[:, 1], tangents[:, 0]))


def left_normals_stacked(points: NDArrayFloat, offsets: npt.NDArray[np.intp],
                         names: Sequence[str]) -> NDArrayFloat:
    """:func:`left_normals` of every polyline of the stack ``points`` (polyline k is
    ``points[offsets[k]:offsets[k + 1]]``, at least 2 points, named ``names[k]``), in one
    pass: the same values; ValueError naming the first one with a repeated point."""
    first, last = offsets[:-1], offsets[1:] - 1
    tangents = np.empty_like(points)
    tangents[1:-1] = (points[2:] - points[:-2]) / 2.0
    tangents[first] = points[first + 1] - points[first]
    tangents[last] = points[last] - points[last - 1]
    norms = np.hypot(tangents[:, 0], tangents[:, 1])
    if np.any(norms == 0.0):
        broken = int(np.searchsorted(offsets, np.flatnonzero(norms == 0.0)[0], side="right")) - 1
        left_normals(points[first[broken]: last[broken] + 1], names[broken])
    tangents /= norms[:, None]
    return np.column_stack((-tangents[:, 1], tangents[:, 0]))


def truncate(points: NDArrayFloat, fraction: float) -> NDArrayFloat:
    """The first ``fraction`` (0..1] of a polyline's arc length; the end point is interpolated."""
    s = arc_lengths(points)
    end = fraction * s[-1]
    keep = int(np.searchsorted(s, end, side="right"))
    head = points[:keep]
    if keep < len(points) and end > s[keep - 1]:
        t = (end - s[keep - 1]) / (s[keep] - s[keep - 1])
        head = np.vstack((head, points[keep - 1] + t * (points[keep] - points[keep - 1])))
    return head


@dataclass(frozen=True, slots=True)
class SensorErrorModel:
    """Error models of the lane sensor; all zero (the default) is the exact identity.

    Fields:
        lateral_offset_m: constant shift of both borders along their local left normal
            (m, vehicle frame; positive = to the left).
        noise_sigma_m: σ of independent Gaussian noise on each point along its local
            normal (m).
        heading_bias_rad: rotation of the whole detection about the sensor origin
            (rad, counter-clockwise).
        range_jitter_sigma_m: σ of the detection's length error (m). Only truncates: the
            detection loses |N(0, σ)| of its mean border length; both borders keep the
            same fraction of their own arc length. A detection cut to nothing is dropped.
        drop_probability: probability that a frame's detection is lost (0..1).
        pose_sigma_xy_m: σ of the localisation error on the sender's x and y (m, world).
        pose_sigma_yaw_rad: σ of the localisation error on the sender's yaw (rad).

    Lengths lie within ``MAX_ERROR_M`` and angles within ``MAX_ANGLE_RAD``; anything else
    raises ValueError naming the field.
    """

    lateral_offset_m: float = 0.0
    noise_sigma_m: float = 0.0
    heading_bias_rad: float = 0.0
    range_jitter_sigma_m: float = 0.0
    drop_probability: float = 0.0
    pose_sigma_xy_m: float = 0.0
    pose_sigma_yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        for field in fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"SensorErrorModel.{field.name}: expected a finite number, got {value!r}")
            if field.name not in _SIGNED and value < 0:
                raise ValueError(f"SensorErrorModel.{field.name}: must be >= 0, got {value!r}")
            bound, unit = (MAX_ANGLE_RAD, "rad") if field.name in _ANGLES else (MAX_ERROR_M, "m")
            if field.name != "drop_probability" and abs(value) > bound:
                raise ValueError(f"SensorErrorModel.{field.name}: must be within ±{bound:g} {unit}, got {value!r}")
        if self.drop_probability > 1:
            raise ValueError(f"SensorErrorModel.drop_probability: must be <= 1, got {self.drop_probability!r}")

    def apply(
        self, left: NDArrayFloat, right: NDArrayFloat, rng: np.random.Generator
    ) -> tuple[NDArrayFloat, NDArrayFloat] | None:
        """The perturbed ``(left, right)`` borders (vehicle frame, m), or None when dropped.

        Order: drop, range truncation, lateral offset and noise along the normals of the
        truncated borders, heading rotation. Only enabled models draw from ``rng``.
        """
        borders = [check_polyline("left", left), check_polyline("right", right)]
        if self.drop_probability > 0 and rng.random() < self.drop_probability:
            return None
        if self.range_jitter_sigma_m > 0:
            cut = abs(rng.normal(0.0, self.range_jitter_sigma_m))
            mean_length = 0.5 * (arc_lengths(borders[0])[-1] + arc_lengths(borders[1])[-1])
            if mean_length <= 0:
                raise ValueError("left, right: detection has zero length")
            fraction = 1.0 - cut / mean_length
            if fraction <= 0:
                return None
            borders = [truncate(border, fraction) for border in borders]
            if min(len(border) for border in borders) < 2:
                return None
        if self.lateral_offset_m != 0 or self.noise_sigma_m > 0:
            shifted = []
            for name, border in zip(("left", "right"), borders):
                along = np.full(len(border), self.lateral_offset_m)
                if self.noise_sigma_m > 0:
                    along = along + rng.normal(0.0, self.noise_sigma_m, len(border))
                shifted.append(border + along[:, None] * left_normals(border, name))
            borders = shifted
        if self.heading_bias_rad != 0:
            borders = [vehicle_to_world(border, 0.0, 0.0, self.heading_bias_rad) for border in borders]
        return borders[0], borders[1]

    @property
    def draws_known(self) -> bool:
        """Whether a detection's number of draws is known before drawing (no drop, no range
        jitter): :meth:`apply_block` applies then."""
        return self.drop_probability == 0 and self.range_jitter_sigma_m == 0

    def apply_block(self, borders: Sequence[tuple[NDArrayFloat, NDArrayFloat]],
                    poses: Sequence[tuple[float, float, float] | None], rng: np.random.Generator
                    ) -> tuple[list[tuple[NDArrayFloat, NDArrayFloat]], list[tuple[float, float, float] | None]]:
        """:meth:`apply` then :meth:`perturb_pose` (where ``poses[k]`` is not None) of every
        detection in turn (borders checked by the sensor already), as arrays: all their
        normals drawn at once in that order, offset, noise and heading applied to all
        borders at once; the same values. Only when :attr:`draws_known`."""
        if not self.draws_known:
            raise ValueError("SensorErrorModel.apply_block: drops and range jitter draw as they go, use apply")
        counts = np.array([len(border) for pair in borders for border in pair], dtype=np.intp)
        noise = self.noise_sigma_m > 0
        pose_draws = (2 if self.pose_sigma_xy_m > 0 else 0) + (1 if self.pose_sigma_yaw_rad > 0 else 0)
        sizes = counts.reshape(-1, 2).sum(axis=1) * noise + np.array([pose is not None for pose in poses]) * pose_draws
        draws = rng.standard_normal(int(sizes.sum()))
        starts = np.concatenate(([0], np.cumsum(sizes)))
        out = [(left, right) for left, right in borders]
        if self.lateral_offset_m != 0 or noise or self.heading_bias_rad != 0:
            stacked = np.concatenate([border for pair in borders for border in pair])
            if self.lateral_offset_m != 0 or noise:
                along = np.full(len(stacked), self.lateral_offset_m)
                if noise:
                    picked = np.concatenate([draws[start: start + count] for start, count in
                                             zip(starts[:-1].tolist(), counts.reshape(-1, 2).sum(axis=1).tolist())])
                    along = along + (0.0 + self.noise_sigma_m * picked)
                offsets = np.concatenate(([0], np.cumsum(counts)))
                stacked = stacked + along[:, None] * left_normals_stacked(stacked, offsets,
                                                                          ("left", "right") * len(borders))
            if self.heading_bias_rad != 0:
                stacked = vehicle_to_world(stacked, 0.0, 0.0, self.heading_bias_rad)
            parts = np.split(stacked, np.cumsum(counts)[:-1])
            out = [(parts[2 * k], parts[2 * k + 1]) for k in range(len(borders))]
        moved: list[tuple[float, float, float] | None] = []
        for pose, start, size in zip(poses, starts[:-1].tolist(), sizes.tolist()):
            if pose is None:
                moved.append(None)
                continue
            x, y, yaw = pose
            at = start + size - pose_draws
            if self.pose_sigma_xy_m > 0:
                dx, dy = 0.0 + self.pose_sigma_xy_m * draws[at: at + 2]
                x, y, at = x + float(dx), y + float(dy), at + 2
            if self.pose_sigma_yaw_rad > 0:
                yaw = yaw + float(0.0 + self.pose_sigma_yaw_rad * draws[at])
            moved.append((x, y, yaw))
        return out, moved

    def perturb_pose(self, x: float, y: float, yaw: float, rng: np.random.Generator) -> tuple[float, float, float]:
        """The sender's pose ``(x m, y m, yaw rad)`` (world frame) with localisation error."""
        if self.pose_sigma_xy_m > 0:
            dx, dy = rng.normal(0.0, self.pose_sigma_xy_m, 2)
            x, y = x + float(dx), y + float(dy)
        if self.pose_sigma_yaw_rad > 0:
            yaw = yaw + float(rng.normal(0.0, self.pose_sigma_yaw_rad))
        return x, y, yaw
