"""The generic lane sensor (paper sec. IV): the current lane's borders ahead of a vehicle.

Like the paper's sensor in the RESIST framework, it reads the lane from the OpenDRIVE map
(through a route's ``LaneStrip``), not from the Lanelet2 ground truth: each border is
sampled every ``step_m`` of its own arc length, from the cross-section at the vehicle to
the cross-section ``range_m`` ahead along the lane centreline, and returned in the
vehicle frame (ISO 8855: x forward, y left).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final, Protocol, Sequence

import numpy as np

from cold_maps.network.lane_strip import LaneStrip, NDArrayFloat, resample_polyline, resample_polylines


class OnStrip(Protocol):
    """Anything driven along a lane strip (a ``drive.Track``)."""

    @property
    def strip(self) -> LaneStrip: ...

SENSOR_RANGE_M: Final[float] = 30.0
SENSOR_STEP_M: Final[float] = 0.10
END_RANGE: Final[str] = "range"
"""``Detection.end_reason``: the detection reached the sensor's range."""
END_MAP: Final[str] = "map_end"
"""``Detection.end_reason``: the vehicle's track ended first (the drives' routes run on
until the lanes end or past every detection, so: where the mapped lanes end)."""


@dataclass(frozen=True)
class Detection:
    """One lane detection of one vehicle in one frame.

    Fields:
        x, y, yaw: the sensor pose in the world frame (m, m, rad).
        left, right: (N, 2) borders in the vehicle frame (ISO 8855, m), driving order.
        start_station, end_station: the route stations the detection spans (m).
        end_reason: why it ended (``END_RANGE``, ``END_MAP`` or one of
            ``simulation.camera.END_REASONS``); "" when unknown.
    """

    x: float
    y: float
    yaw: float
    left: NDArrayFloat
    right: NDArrayFloat
    start_station: float
    end_station: float
    end_reason: str = ""

    def to_world(self) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Left and right borders in the world frame (m)."""
        return vehicle_to_world(self.left, self.x, self.y, self.yaw), vehicle_to_world(self.right, self.x, self.y, self.yaw)


def world_to_vehicle(points: NDArrayFloat, x: float | NDArrayFloat, y: float | NDArrayFloat,
                     yaw: float | NDArrayFloat) -> NDArrayFloat:
    """World points (m) into the frame of a vehicle at (x, y, yaw); with (N,) arrays, point
    k into the frame of the vehicle at (x[k], y[k], yaw[k])."""
    return _into_frame(points, x, y, np.cos(yaw), np.sin(yaw))


def _into_frame(points: NDArrayFloat, x: float | NDArrayFloat, y: float | NDArrayFloat, c: float | NDArrayFloat,
                s: float | NDArrayFloat) -> NDArrayFloat:
    """:func:`world_to_vehicle` with the heading's cosine ``c`` and sine ``s`` given."""
    dx, dy = points[:, 0] - x, points[:, 1] - y
    return np.column_stack((c * dx + s * dy, -s * dx + c * dy))


def vehicle_to_world(points: NDArrayFloat, x: float, y: float, yaw: float) -> NDArrayFloat:
    """Vehicle-frame points (m) of a vehicle at (x, y, yaw) into the world frame."""
    c, s = np.cos(yaw), np.sin(yaw)
    return np.column_stack((x + c * points[:, 0] - s * points[:, 1], y + s * points[:, 0] + c * points[:, 1]))


@dataclass(frozen=True)
class LaneSensor:
    """Generic lane sensor.

    Fields:
        range_m: perception range along the lane centreline (m); the paper's r_lane.
        step_m: spacing of the border points along each border (m).
    """

    range_m: float = SENSOR_RANGE_M
    step_m: float = SENSOR_STEP_M

    @property
    def reach_m(self) -> float:
        """The farthest (m) a reading looks along a track past the vehicle's station."""
        return self.range_m

    def detect(self, strip: LaneStrip, station: float) -> Detection | None:
        """The detection of a vehicle centred in the lane at ``station`` (m), or None
        when less than one step of lane is left ahead on the strip."""
        end = min(station + self.range_m, strip.length)
        if end - station < self.step_m:
            return None
        x, y, yaw = strip.pose(station)
        reason = END_RANGE if station + self.range_m <= strip.length else END_MAP
        return detection_between(strip, x, y, yaw, station, end, self.step_m, reason)

    def read(self, track: OnStrip, station: float, obstacles: NDArrayFloat) -> tuple[Detection | None, str]:
        """:meth:`detect` on the track's strip (the other vehicles ``obstacles`` hide
        nothing from the ideal sensor) and its end reason ("" when it sees nothing)."""
        detection = self.detect(track.strip, station)
        return detection, "" if detection is None else detection.end_reason

    def read_many(self, track: OnStrip, stations: NDArrayFloat,
                  obstacles: Sequence[NDArrayFloat]) -> list[tuple[Detection | None, str]]:
        """:meth:`read` at every station (m) of ``stations``, as arrays over them (the same
        detections); ``obstacles`` (one (M, 3) array per station) hide nothing."""
        strip = track.strip
        stations = np.asarray(stations, dtype=np.float64)
        ends = np.minimum(stations + self.range_m, strip.length)
        seen = ~(ends - stations < self.step_m)
        reasons = np.where(stations + self.range_m <= strip.length, END_RANGE, END_MAP)
        kept = np.flatnonzero(seen)
        detections = detections_between(strip, *strip.poses(stations[kept]), stations[kept], ends[kept], self.step_m,
                                         reasons[kept].tolist())
        out: list[tuple[Detection | None, str]] = [(None, "")] * len(stations)
        for index, detection in zip(kept.tolist(), detections):
            out[index] = (detection, detection.end_reason)
        return out


def detections_between(strip: LaneStrip, x: NDArrayFloat, y: NDArrayFloat, yaw: NDArrayFloat, start: NDArrayFloat,
                       end: NDArrayFloat, step_m: float, end_reasons: Sequence[str]) -> list[Detection]:
    """:func:`detection_between` for every k of the (K,) arrays (vehicle poses, world frame,
    and station windows, m), evaluated over all of them at once: the same detections."""
    if len(start) == 0:
        return []
    borders = []
    cos, sin = np.cos(yaw), np.sin(yaw)
    for points, distance in ((strip.left, strip.left_distance), (strip.right, strip.right_distance)):
        ends = np.interp(np.concatenate((start, end)), strip.station, distance)
        world, offsets = resample_polylines(points, distance, ends[: len(start)], ends[len(start):], step_m)
        counts = np.diff(offsets)
        local = _into_frame(world, np.repeat(x, counts), np.repeat(y, counts), np.repeat(cos, counts),
                            np.repeat(sin, counts))
        borders.append(np.split(local, offsets[1:-1]))
    return [Detection(x=px, y=py, yaw=pyaw, left=left, right=right, start_station=first, end_station=last,
                      end_reason=reason)
            for px, py, pyaw, left, right, first, last, reason in zip(
                x.tolist(), y.tolist(), yaw.tolist(), borders[0], borders[1], start.tolist(), end.tolist(),
                end_reasons)]


def detection_between(strip: LaneStrip, x: float, y: float, yaw: float, start: float, end: float, step_m: float,
                      end_reason: str = "") -> Detection:
    """The strip's borders from station ``start`` to ``end`` (m), each sampled every
    ``step_m`` of its own arc length, in the frame of a vehicle at (x, y, yaw)."""
    window = np.array([start, end])
    borders = []
    for points, distance in ((strip.left, strip.left_distance), (strip.right, strip.right_distance)):
        start_d, end_d = np.interp(window, strip.station, distance)
        world = resample_polyline(points, distance, float(start_d), float(end_d), step_m)
        borders.append(world_to_vehicle(world, x, y, yaw))
    return Detection(x=x, y=y, yaw=yaw, left=borders[0], right=borders[1], start_station=start, end_station=end,
                     end_reason=end_reason)
