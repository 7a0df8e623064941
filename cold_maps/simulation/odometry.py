"""Lane history: the lane a vehicle perceived over its last metres, registered with its odometry.

A vehicle keeps what its lane sensor saw behind it. Each history point was last seen from
the vehicle's pose when it passed that cross-section (the sensor's best view, 0 m ahead),
and is carried into the current vehicle frame by dead reckoning over the distance driven
since. The odometry's errors (:class:`OdometryModel`) are separate from the map-frame pose
error of :class:`~cold_maps.simulation.sensor_errors.SensorErrorModel`: that one moves the
whole message (detection and history alike), drift bends the history relative to the
detection.

Dead reckoning back from the current pose (station s₀) to a past one at distance u behind:
each centreline step is rotated by the heading error k·u and scaled by 1 + e, so the past
pose is estimated at ĉ(u) = Σ (1 + e)·R(k·u)·Δc with heading error k·u; a point seen from
there at offset p − c(u) lands at ĉ(u) + R(k·u)·(p − c(u)). On a straight this is a lateral
error k·u²/2 and an along-track error e·u.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final

import numpy as np

import fusion
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.drive import Track
from cold_maps.simulation.sensor import SENSOR_STEP_M, LaneSensor, world_to_vehicle
from cold_maps.simulation.sensor_errors import SensorErrorModel
from gt_matching.polyline import arc_lengths

DEFAULT_HISTORY_M: Final[float] = 100.0
"""Lane history length (m) of ``cold-eval --history`` without a value."""
TYPICAL_HEADING_DRIFT_RAD_PER_M: Final[float] = 1.0e-4
"""σ of the heading drift rate (rad/m) of ``--drift``: 0.57° per 100 m, a yaw-rate gyro bias
of ~0.06°/s at 10 m/s (automotive MEMS class)."""
TYPICAL_SCALE_ERROR: Final[float] = 0.005
"""σ of the odometry scale error (fraction) of ``--drift``: 0.5 %, wheel odometry with a
calibrated tyre radius."""
DECIMALS: Final[int] = 6
"""History points are rounded to 1 µm like the detections."""


@dataclass(frozen=True, slots=True)
class OdometryModel:
    """Errors of a vehicle's dead reckoning; all zero (the default) is exact.

    Fields:
        heading_drift_rad_per_m: σ of the heading drift rate k (rad per m driven); each
            history draws its k from N(0, σ).
        scale_error: σ of the distance scale error e (fraction); each history draws e.
    """

    heading_drift_rad_per_m: float = 0.0
    scale_error: float = 0.0

    def __post_init__(self) -> None:
        for name in ("heading_drift_rad_per_m", "scale_error"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"OdometryModel.{name}: expected a finite number >= 0, got {value!r}")

    def draw(self, rng: np.random.Generator) -> tuple[float, float]:
        """``(k rad/m, e)`` of one history; only enabled errors draw from ``rng``."""
        k = float(rng.normal(0.0, self.heading_drift_rad_per_m)) if self.heading_drift_rad_per_m > 0 else 0.0
        e = float(rng.normal(0.0, self.scale_error)) if self.scale_error > 0 else 0.0
        return k, e


def dead_reckoned(points: NDArrayFloat, observed_at: NDArrayFloat, track: Track, station: float, k: float,
                  e: float) -> NDArrayFloat:
    """World points ``(N, 2)`` seen from the track's stations ``observed_at`` (m), as dead
    reckoning back from ``station`` with drift rate ``k`` (rad/m) and scale error ``e``
    places them (world frame, the current pose exact; see the module docstring)."""
    if k == 0.0 and e == 0.0:
        return points
    grid = np.unique(np.concatenate((np.arange(station, float(observed_at.min()), -SENSOR_STEP_M),
                                     [float(observed_at.min()), station])))[::-1]
    centre = track.strip.interpolate(grid)[0].view(np.complex128)[:, 0]
    back = station - grid
    steps = np.diff(centre) * (1.0 + e) * np.exp(1j * k * 0.5 * (back[1:] + back[:-1]))
    estimated = centre[0] + np.concatenate(([0.0], np.cumsum(steps)))
    u = station - observed_at
    true_c = np.interp(u, back, centre.real) + 1j * np.interp(u, back, centre.imag)
    est_c = np.interp(u, back, estimated.real) + 1j * np.interp(u, back, estimated.imag)
    z = np.ascontiguousarray(points).view(np.complex128)[:, 0]
    moved = est_c + np.exp(1j * k * u) * (z - true_c)
    return moved.view(np.float64).reshape(-1, 2)


def lane_history(track: Track, station: float, history_m: float, errors: SensorErrorModel,
                 odometry: OdometryModel, rng: np.random.Generator, *,
                 step_m: float = SENSOR_STEP_M) -> fusion.LaneHistory | None:
    """The lane history of a vehicle at ``station`` on ``track``: its borders over the last
    ``history_m`` (m, less at the track start) every ``step_m``, with the sensor's lateral
    offset and noise, registered by dead reckoning, in the vehicle frame (true current pose)
    and rounded to 1 µm; None when less than two steps were driven."""
    start = max(0.0, station - history_m)
    if station - start < 2.0 * step_m:
        return None
    raw = LaneSensor(range_m=station - start, step_m=step_m).detect(track.strip, start)
    if raw is None:
        return None
    shape_only = replace(errors, drop_probability=0.0, range_jitter_sigma_m=0.0, heading_bias_rad=0.0,
                         pose_sigma_xy_m=0.0, pose_sigma_yaw_rad=0.0)
    borders = shape_only.apply(*raw.to_world(), rng)
    assert borders is not None  # nothing that drops is enabled
    k, e = odometry.draw(rng)
    x, y, yaw = track.strip.pose(station)
    out = []
    for border in borders:
        s = arc_lengths(border)
        observed_at = start + (station - start) * s / s[-1]
        out.append(np.round(world_to_vehicle(dead_reckoned(border, observed_at, track, station, k, e), x, y, yaw),
                            DECIMALS))
    return fusion.LaneHistory(out[0], out[1])
