"""A vehicle's detection message: the lane sensor on its track, then the error models.

``sense`` turns a vehicle's state into the ``fusion.LaneDetection`` it sends (borders in
its vehicle frame, ISO 8855, m; reported pose in the world frame); ``world_borders``
maps a detection back into the world frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Mapping, Sequence

import numpy as np

import fusion
from fusion.fusibility import lane_end
from fusion.types import clean_borders, stacked_arclengths
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


End = tuple[tuple[float, float], tuple[float, float]]
"""A lane's centre-line end: ``(point, unit tangent)``, world frame (m), driving direction."""


def read_ends(raw: Detection) -> tuple[End, End]:
    """The start and the end of the centre line of a sensor's lane, world frame, as the fusion
    reads them from detections (:func:`fusion.fusibility.lane_end` on the borders in the
    vehicle frame, then into the world frame)."""
    c, s = math.cos(raw.yaw), math.sin(raw.yaw)
    found = []
    for at_end in (False, True):
        (px, py), (tx, ty) = lane_end(raw.left, raw.right, at_end)
        found.append(((raw.x + c * px - s * py, raw.y + s * px + c * py), (c * tx - s * ty, s * tx + c * ty)))
    return found[0], found[1]


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
        read_ends: the start and the end of the centre line of the lane the sensor read,
            before any error model (:func:`read_ends`); None when the sensor saw no lane.
    """

    state: VehicleState
    detection: fusion.LaneDetection | None
    end_reason: str = ""
    seen: bool = True
    read_ends: tuple[End, End] | None = None

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
    None when the model is off (the ideal sensor). It states why the sensor's lane ended
    (``fusion.LaneDetection.end_reason``, the sensor's reason)."""
    raw, end_reason = sensor.read(state.track, state.station, obstacles)
    if raw is None:
        return Sensed(state, None, end_reason, seen=False)
    borders = errors.apply(raw.left, raw.right, rng)
    ends = read_ends(raw)
    if borders is None:
        return Sensed(state, None, end_reason, read_ends=ends)
    if lane_error is not None:
        borders = lane_error.perturb(state.name, stamp_s, *borders)
    borders = tuple(np.round(border, DETECTION_DECIMALS) for border in borders)
    params = None if lane_error is None else lane_error.params
    sigmas = lateral_sigmas(borders, errors, params)
    lanes, edges, branches = _beside(state, raw, sensor, errors, rng, neighbours)
    pose = _reported_pose(state, raw, errors, rng)
    return Sensed(state, fusion.LaneDetection(pose, borders[0], borders[1], stamp=stamp_s, sender=state.name,
                                              neighbours=lanes, road_edges=edges, branches=branches,
                                              left_sigma=sigmas[0], right_sigma=sigmas[1],
                                              pose_cov=pose_covariance(errors, state.role),
                                              end_reason=end_reason or None,
                                              lane_model_sigma=lane_model_sigma(params)),
                  end_reason, read_ends=ends)


def _beside(state: VehicleState, raw: Detection, sensor: LaneSensor | CameraSensor, errors: SensorErrorModel,
            rng: np.random.Generator, neighbours: NeighbourSensor | None
            ) -> tuple[tuple[fusion.NeighbourLane, ...], fusion.RoadEdges | None, tuple[fusion.LaneBranch, ...]]:
    """The neighbour lanes, road edges and branches ``neighbours`` sees with ``raw`` (each
    lane through ``errors``, a dropped one left out); nothing without ``neighbours``."""
    if neighbours is None:
        return (), None, ()
    lanes: list[fusion.NeighbourLane] = []
    branches: list[fusion.LaneBranch] = []
    readings, ends = neighbours.detect(state.track, state.station, sensor.range_m, sensor.step_m)
    for reading in readings:
        seen = _seen(reading.left, reading.right, raw, errors, rng)
        if seen is not None:
            lanes.append(fusion.NeighbourLane(reading.index, *seen, reading.at_start, reading.at_end))
    for left, right in neighbours.branches(state.track, state.station, sensor.range_m, sensor.step_m):
        seen = _seen(left, right, raw, errors, rng)
        if seen is not None:
            branches.append(fusion.LaneBranch(*seen))
    return tuple(lanes), fusion.RoadEdges(*ends), tuple(branches)


def _reported_pose(state: VehicleState, raw: Detection, errors: SensorErrorModel,
                   rng: np.random.Generator) -> fusion.Pose2D:
    """The pose the vehicle reports: the sensor's, with localisation error but for the ego's."""
    x, y, yaw = (raw.x, raw.y, raw.yaw) if state.role == "ego" else errors.perturb_pose(raw.x, raw.y, raw.yaw, rng)
    return fusion.Pose2D(x, y, yaw)


@dataclass
class _Pending:
    """A detection of :func:`sense_block` between its draws and its checks: where it is in
    the block, its state, why its lane ended, its borders (vehicle frame, m), the ends of the
    lane it read (:func:`read_ends`) and what comes with it."""

    frame: int
    state: VehicleState
    end_reason: str
    borders: tuple[NDArrayFloat, NDArrayFloat]
    ends: tuple[End, End]
    beside: tuple[tuple[fusion.NeighbourLane, ...], fusion.RoadEdges | None, tuple[fusion.LaneBranch, ...]]
    pose: fusion.Pose2D


def sense_block(frames: Sequence[Mapping[str, VehicleState]], sensor: LaneSensor | CameraSensor,
                errors: SensorErrorModel, rng: np.random.Generator, *, stamps_s: Sequence[float],
                neighbours: NeighbourSensor | None = None,
                lane_error: LaneModelErrorSampler | None = None) -> list[dict[str, Sensed]]:
    """:func:`sense` of every vehicle of every frame of a block (``frames``: each frame's
    states, as :meth:`Drive.states` gives them; ``stamps_s`` their times, s), frame by
    frame and vehicle by vehicle in that order, the obstacles of a camera being the other
    vehicles of the frame (:func:`obstacles_of`): the same results, the same draws from
    ``rng`` in the same order, but the sensor read as arrays over each vehicle's frames,
    the lane-model error drawn for each vehicle's frames at once and the borders rounded,
    given their σ and checked once for the whole block."""
    raws = _read_block(frames, sensor)
    out: list[dict[str, Sensed]] = [{} for _ in frames]
    pending: list[_Pending] = []
    identity = errors == SensorErrorModel()
    at_once = not identity and neighbours is None and errors.draws_known
    for frame, states in enumerate(frames):
        for name, state in states.items():
            raw, end_reason = raws[frame][name]
            if raw is None:
                out[frame][name] = Sensed(state, None, end_reason, seen=False)
                continue
            if identity or at_once:
                # Identity errors draw nothing; known draws come after the loop, all at once.
                pending.append(_Pending(frame, state, end_reason, (raw.left, raw.right),
                                        read_ends(raw), _beside(state, raw, sensor, errors, rng, neighbours),
                                        fusion.Pose2D(raw.x, raw.y, raw.yaw)))
                continue
            borders = errors.apply(raw.left, raw.right, rng)
            if borders is None:
                out[frame][name] = Sensed(state, None, end_reason, read_ends=read_ends(raw))
                continue
            beside = _beside(state, raw, sensor, errors, rng, neighbours)
            pending.append(_Pending(frame, state, end_reason, borders, read_ends(raw), beside,
                                    _reported_pose(state, raw, errors, rng)))
    if at_once:
        borders, poses = errors.apply_block(
            [item.borders for item in pending],
            [None if item.state.role == "ego" else (item.pose.x, item.pose.y, item.pose.yaw) for item in pending], rng)
        for item, pair, pose in zip(pending, borders, poses):
            item.borders = pair
            if pose is not None:
                item.pose = fusion.Pose2D(*pose)
    if lane_error is not None:
        by_vehicle: dict[str, list[_Pending]] = {}
        for item in pending:
            by_vehicle.setdefault(item.state.name, []).append(item)
        for name, items in by_vehicle.items():
            moved = lane_error.perturb_many(name, [stamps_s[item.frame] for item in items],
                                            [item.borders for item in items])
            for item, borders in zip(items, moved):
                item.borders = borders
    for item, detection in zip(pending, _detections(pending, errors, lane_error, stamps_s)):
        out[item.frame][item.state.name] = Sensed(item.state, detection, item.end_reason, read_ends=item.ends)
    return [{name: frame[name] for name in states} for frame, states in zip(out, frames)]


def _read_block(frames: Sequence[Mapping[str, VehicleState]],
                sensor: LaneSensor | CameraSensor) -> list[dict[str, tuple[Detection | None, str]]]:
    """Every vehicle's sensor reading in every frame (the camera's obstacles: the other
    vehicles of the frame), read as arrays over the frames of each vehicle and track."""
    groups: dict[tuple[str, int], list[int]] = {}
    for frame, states in enumerate(frames):
        for name, state in states.items():
            groups.setdefault((name, id(state.track)), []).append(frame)
    obstacles = _block_obstacles(frames, groups) if isinstance(sensor, CameraSensor) else None
    raws: list[dict[str, tuple[Detection | None, str]]] = [{} for _ in frames]
    for (name, _), indices in groups.items():
        track = frames[indices[0]][name].track
        stations = np.array([frames[frame][name].station for frame in indices])
        hidden_by = [NO_OBSTACLES if obstacles is None else obstacles[frame][name] for frame in indices]
        for frame, reading in zip(indices, sensor.read_many(track, stations, hidden_by)):
            raws[frame][name] = reading
    return raws


def _block_obstacles(frames: Sequence[Mapping[str, VehicleState]],
                     groups: Mapping[tuple[str, int], Sequence[int]]) -> list[dict[str, NDArrayFloat]]:
    """:func:`obstacles_of` of every frame, the poses of each vehicle's frames on a track
    taken at once (``LaneStrip.poses``: the same values)."""
    poses: list[dict[str, tuple[float, float, float]]] = [{} for _ in frames]
    for (name, _), indices in groups.items():
        strip = frames[indices[0]][name].track.strip
        x, y, yaw = strip.poses(np.array([frames[frame][name].station for frame in indices]))
        for frame, pose in zip(indices, zip(x.tolist(), y.tolist(), yaw.tolist())):
            poses[frame][name] = pose
    out = []
    for states, frame_poses in zip(frames, poses):
        table = np.array([frame_poses[name] for name in states]).reshape(-1, 3)
        everyone = np.arange(len(table))
        out.append({name: table[everyone != index] for index, name in enumerate(states)})
    return out


def _detections(pending: Sequence[_Pending], errors: SensorErrorModel, lane_error: LaneModelErrorSampler | None,
                stamps_s: Sequence[float]) -> list[fusion.LaneDetection]:
    """The detections of ``pending`` (borders rounded to 1 µm, with their σ), the borders
    checked as one block: a detection whose borders are not clean as they are (a repeated
    point) goes through the checking constructor instead."""
    if not pending:
        return []
    parts = [border for item in pending for border in item.borders]
    counts = np.array([len(border) for border in parts])
    offsets = np.concatenate(([0], np.cumsum(counts)))
    points = _frozen(np.round(np.concatenate(parts), DETECTION_DECIMALS))
    clean = clean_borders(points, offsets)
    arclength = _frozen(stacked_arclengths(points, offsets))
    params = None if lane_error is None else lane_error.params
    sigma = _point_sigmas(points[:, 0], errors, params)
    sigma = None if sigma is None else _frozen(sigma)
    covariances = {role: _frozen_or_none(pose_covariance(errors, role)) for role in ("ego", "coop")}
    model = lane_model_sigma(params)
    out = []
    for k, item in enumerate(pending):
        start, middle, stop = offsets[2 * k], offsets[2 * k + 1], offsets[2 * k + 2]
        sigmas = (None, None) if sigma is None else (sigma[start:middle], sigma[middle:stop])
        pose_cov = covariances["ego" if item.state.role == "ego" else "coop"]
        lanes, edges, branches = item.beside
        if clean[2 * k] and clean[2 * k + 1]:
            out.append(fusion.LaneDetection.trusted(
                item.pose, points[start:stop], int(middle - start), stamp=stamps_s[item.frame], sender=item.state.name,
                neighbours=lanes, road_edges=edges, branches=branches, left_sigma=sigmas[0], right_sigma=sigmas[1],
                pose_cov=pose_cov, arclength=arclength[start:stop], end_reason=item.end_reason or None,
                lane_model_sigma=model))
        else:
            out.append(fusion.LaneDetection(item.pose, points[start:middle], points[middle:stop],
                                            stamp=stamps_s[item.frame], sender=item.state.name, neighbours=lanes,
                                            road_edges=edges, branches=branches, left_sigma=sigmas[0],
                                            right_sigma=sigmas[1], pose_cov=pose_cov,
                                            end_reason=item.end_reason or None, lane_model_sigma=model))
    return out


def _frozen(array: NDArrayFloat) -> NDArrayFloat:
    array.flags.writeable = False
    return array


def _frozen_or_none(array: NDArrayFloat | None) -> NDArrayFloat | None:
    return None if array is None else _frozen(array)


def lateral_sigmas(borders: tuple[NDArrayFloat, NDArrayFloat], errors: SensorErrorModel,
                   lane_error: LaneModelErrorParams | None) -> tuple[NDArrayFloat | None, NDArrayFloat | None]:
    """Lateral 1σ (m) of every point of the ``(left, right)`` borders (vehicle frame, m):
    the lane model's closed form at the point's x and the per-point noise σ, independent,
    so their variances add; (None, None) when neither model is on. The constant offset and
    heading bias are systematic and the range jitter is along the lane: none adds to σ."""
    return _point_sigmas(borders[0][:, 0], errors, lane_error), _point_sigmas(borders[1][:, 0], errors, lane_error)


def _point_sigmas(x: NDArrayFloat, errors: SensorErrorModel,
                  lane_error: LaneModelErrorParams | None) -> NDArrayFloat | None:
    """Lateral 1σ (m) of border points at forward distances ``x`` (m, vehicle frame), as
    :func:`lateral_sigmas` states them; None when neither model is on."""
    noise = errors.noise_sigma_m
    if lane_error is None and noise == 0.0:
        return None
    if lane_error is None:
        return np.full(len(x), noise)
    out = lane_error.sigma_m(x)
    return np.hypot(out, noise) if noise > 0.0 else out


def lane_model_sigma(lane_error: LaneModelErrorParams | None) -> NDArrayFloat | None:
    """The coefficients' 1σ a detection states as its lane model
    (:attr:`fusion.LaneDetection.lane_model_sigma`, read-only), None without that model: the
    part of the stated σ (:func:`lateral_sigmas`) that each border's error shares over its points."""
    if lane_error is None or not lane_error.coefficient_sigmas.any():
        return None
    return _frozen(lane_error.coefficient_sigmas)


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
