"""A vehicle's detection message: the lane sensor on its track, then the error models.

``sense`` turns a vehicle's state into the ``fusion.LaneDetection`` it sends (borders in
its vehicle frame, ISO 8855, m; reported pose in the world frame); ``world_borders``
maps a detection back into the world frame.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Mapping

import numpy as np

import fusion
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.camera import CameraSensor
from cold_maps.simulation.drive import VehicleState
from cold_maps.simulation.lane_model_error import LaneModelErrorParams, LaneModelErrorSampler
from cold_maps.simulation.neighbours import NeighbourSensor
from cold_maps.simulation.sensor import Detection, LaneSensor, vehicle_to_world, world_to_vehicle
from cold_maps.simulation.sensor_errors import SensorErrorModel

DETECTION_DECIMALS: Final[int] = 6
"""Detected border points are rounded to 1 µm (the sensor's resolution): the recorded
``cold.LaneDetection`` JSON is then short and exactly what was fused."""
NO_OBSTACLES: Final[NDArrayFloat] = np.empty((0, 3))
"""No other vehicle (x, y m, yaw rad rows)."""


@dataclass(frozen=True)
class Sensed:
    """One vehicle's detection in one frame.

    Fields:
        state: where the vehicle is.
        detection: what it sends (reported pose with localisation error, borders in its
            vehicle frame with the sensor errors), or None when the frame was dropped or
            the sensor saw no lane.
        end_reason: why the sensor's lane ended (``sensor.Detection.end_reason``); ""
            when unknown.
        seen: False when the sensor saw no lane (the detection is None), True otherwise.
    """

    state: VehicleState
    detection: fusion.LaneDetection | None
    end_reason: str = ""
    seen: bool = True

    def missing(self, who: str) -> str:
        """Why ``who`` (``ego``/``coop``) sent no detection: ``WHO_not_seen`` (the sensor
        saw no lane) or ``WHO_dropped`` (an error model dropped it)."""
        return f"{who}_dropped" if self.seen else f"{who}_not_seen"


def sense(state: VehicleState, sensor: LaneSensor | CameraSensor, errors: SensorErrorModel,
          rng: np.random.Generator, *, stamp_s: float = 0.0, neighbours: NeighbourSensor | None = None,
          obstacles: NDArrayFloat = NO_OBSTACLES, lane_error: LaneModelErrorSampler | None = None) -> Sensed:
    """The detection of a vehicle: the sensor on its track (the other vehicles at
    ``obstacles``, (M, 3) x, y m, yaw rad, world frame, may hide the lane from a camera),
    then the error models (``errors``, then the drive's ``lane_error`` on the borders of its
    own lane), points rounded to 1 µm; the ego's pose carries no localisation error (it is
    the reference). With ``neighbours`` the lanes beside its own (same range and sampling,
    each through ``errors``, a dropped one left out) and the road edges come with it.

    The detection states its uncertainty when an error model has one: per-point lateral
    1σ of both borders (:func:`lateral_sigmas`) and the pose covariance (:func:`pose_covariance`);
    None when the model is off (the ideal sensor)."""
    raw, end_reason = sensor.read(state.track, state.station, obstacles)
    if raw is None:
        return Sensed(state, None, end_reason, seen=False)
    borders = errors.apply(raw.left, raw.right, rng)
    if borders is None:
        return Sensed(state, None, end_reason)
    if lane_error is not None:
        borders = lane_error.perturb(state.name, stamp_s, *borders)
    borders = tuple(np.round(border, DETECTION_DECIMALS) for border in borders)
    sigmas = lateral_sigmas(borders, errors, None if lane_error is None else lane_error.params)
    lanes: list[fusion.NeighbourLane] = []
    branches: list[fusion.LaneBranch] = []
    edges = None
    if neighbours is not None:
        readings, ends = neighbours.detect(state.track, state.station, sensor.range_m, sensor.step_m)
        edges = fusion.RoadEdges(*ends)
        for reading in readings:
            seen = _seen(reading.left, reading.right, raw, errors, rng)
            if seen is not None:
                lanes.append(fusion.NeighbourLane(reading.index, *seen, reading.at_start, reading.at_end))
        for left, right in neighbours.branches(state.track, state.station, sensor.range_m, sensor.step_m):
            seen = _seen(left, right, raw, errors, rng)
            if seen is not None:
                branches.append(fusion.LaneBranch(*seen))
    x, y, yaw = (raw.x, raw.y, raw.yaw) if state.role == "ego" else errors.perturb_pose(raw.x, raw.y, raw.yaw, rng)
    pose = fusion.Pose2D(x, y, yaw)
    return Sensed(state, fusion.LaneDetection(pose, borders[0], borders[1], stamp=stamp_s, sender=state.name,
                                              neighbours=tuple(lanes), road_edges=edges, branches=tuple(branches),
                                              left_sigma=sigmas[0], right_sigma=sigmas[1],
                                              pose_cov=pose_covariance(errors, state.role)),
                  end_reason)


def lateral_sigmas(borders: tuple[NDArrayFloat, NDArrayFloat], errors: SensorErrorModel,
                   lane_error: LaneModelErrorParams | None) -> tuple[NDArrayFloat | None, NDArrayFloat | None]:
    """Lateral 1σ (m) of every point of the ``(left, right)`` borders (vehicle frame, m):
    the lane model's closed form at the point's x and the per-point noise σ, independent,
    so their variances add; (None, None) when neither model is on. The constant offset and
    heading bias are systematic and the range jitter is along the lane: none adds to σ."""
    noise = errors.noise_sigma_m
    if lane_error is None and noise == 0.0:
        return None, None
    if lane_error is None:
        return np.full(len(borders[0]), noise), np.full(len(borders[1]), noise)
    out = [lane_error.sigma_m(border[:, 0]) for border in borders]
    return (np.hypot(out[0], noise), np.hypot(out[1], noise)) if noise > 0.0 else (out[0], out[1])


def pose_covariance(errors: SensorErrorModel, role: str) -> NDArrayFloat | None:
    """Covariance of the reported pose's error in (x m, y m, yaw rad), world frame, from the
    localisation error model (diagonal: independent draws); zero for the ego, whose pose is
    exact; None when the model is off."""
    if errors.pose_sigma_xy_m == 0.0 and errors.pose_sigma_yaw_rad == 0.0:
        return None
    if role == "ego":
        return np.zeros((3, 3))
    return np.diag([errors.pose_sigma_xy_m**2, errors.pose_sigma_xy_m**2, errors.pose_sigma_yaw_rad**2])


def _seen(left: NDArrayFloat, right: NDArrayFloat, raw: Detection, errors: SensorErrorModel,
          rng: np.random.Generator) -> tuple[NDArrayFloat, NDArrayFloat] | None:
    """World borders of another lane seen by the sensor at ``raw``'s pose: in the vehicle
    frame, through the error models, rounded to 1 µm; None when dropped."""
    seen = errors.apply(world_to_vehicle(left, raw.x, raw.y, raw.yaw), world_to_vehicle(right, raw.x, raw.y, raw.yaw),
                        rng)
    return None if seen is None else (np.round(seen[0], DETECTION_DECIMALS), np.round(seen[1], DETECTION_DECIMALS))


def obstacles_of(states: Mapping[str, VehicleState]) -> dict[str, NDArrayFloat]:
    """Per vehicle of a frame, the poses of all the others: (M, 3) x, y (m), yaw (rad), world
    frame, at their true positions on their tracks' centrelines."""
    poses = {name: state.track.strip.pose(state.station) for name, state in states.items()}
    return {name: np.array([pose for other, pose in poses.items() if other != name]).reshape(-1, 3) for name in poses}


def world_borders(detection: fusion.LaneDetection) -> tuple[NDArrayFloat, NDArrayFloat]:
    """The detection's borders in the world frame (m), from its reported pose."""
    p = detection.pose
    return vehicle_to_world(detection.left, p.x, p.y, p.yaw), vehicle_to_world(detection.right, p.x, p.y, p.yaw)


def detection_pose(detection: fusion.LaneDetection) -> tuple[float, float, float]:
    """The detection's reported pose as (x m, y m, yaw rad), world frame."""
    return detection.pose.x, detection.pose.y, detection.pose.yaw
