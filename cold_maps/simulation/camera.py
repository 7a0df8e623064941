"""The camera lane sensor: the current lane's borders as far as a camera sees them.

The candidate border points are the lane's two borders on cross-sections every
``step_m`` of centreline station from the vehicle on (as the ideal sensor's). The camera
sits at the vehicle's pose on its lane centreline, ``camera_height_m`` above the road. A
border point is *visible* (:func:`hidden_by`, vectorised over points) when it is

1. between ``min_range_m`` and ``max_range_m`` from the camera (plane distance);
2. inside the horizontal field of view: the angle between the heading and the line of
   sight at most ``fov_half_angle_rad``;
3. over the road surface: its elevation angle seen from the camera is at least that of
   every nearer point of the same border (a viewshed along the border's own height
   profile; crests hide what lies behind them, dips what lies in them);
4. not behind another vehicle: the line of sight in the plane does not cross the
   footprint (``vehicle_length_m`` × ``vehicle_width_m``, centred on its pose, taller than
   the camera) of another vehicle of the drive;
5. painted or a physical edge (``opendrive.road_marks.classify_border``).

A hidden point records every rule it fails. The reported lane (:func:`detection_window`)
starts at the first cross-section whose two points are both at least ``min_range_m`` away
and ends where either border is hidden over more than ``gap_tolerance_m`` along it
(measured between the visible points around the gap), or hidden up to the last
candidate: at the last visible cross-section before that gap. Shorter gaps are bridged (a
dashed mark is detectable over its whole length, so dashes never end it). The lane ended
for the rule that hides most points of the gap's first ``gap_tolerance_m`` (ties: the
earlier rule above), so a border that leaves the view behind an occluding vehicle ends
for the occlusion, not for the range a few metres farther. A lane whose candidates run
out first ends for ``map_end`` (the track ends) or ``range`` (the search window ends).
The reported borders are the map's between the start and the end, sampled like the ideal
sensor's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.network.route import route_from_lanes
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.opendrive.road_marks import classify_border
from cold_maps.simulation.drive import Track
from cold_maps.simulation.sensor import Detection, LaneSensor, detection_between, detections_between
from cold_maps.simulation.sensor_profile import SensorProfile

NDArrayBool = npt.NDArray[np.bool_]
NDArrayInt = npt.NDArray[np.int64]

END_REASONS: Final[tuple[str, ...]] = ("range", "field_of_view", "crest", "occlusion", "unmarked", "map_end")
"""Why a camera detection ended; bit i of a :func:`hidden_by` mask is rule END_REASONS[i]."""
RULES: Final[int] = 5
"""The visibility rules: the first five :data:`END_REASONS`."""
VISIBLE: Final[int] = 0
"""The :func:`hidden_by` mask of a point that fails no rule."""
SEARCH_MARGIN_M: Final[float] = 5.0
"""Centreline length (m) searched beyond the farthest station a point in range and view can
have on a circle through the camera, for the lane's half width."""
_RULE_BITS: Final[NDArrayInt] = 1 << np.arange(RULES)
"""Bit i of a mask: rule END_REASONS[i], i < :data:`RULES`."""
ANGLE_TOLERANCE_RAD: Final[float] = 1e-9
"""A point this much below the horizon of the nearer points still counts as over it."""
WEDGE_MARGIN_M: Final[float] = 1e-3
"""A footprint is grown by this much (m) for the bearings it may hide (:func:`behind_footprints`):
far more than rounding, so no point its exact clipping hides is left out."""
_CORNERS: Final[NDArrayFloat] = np.array([[-1.0, -1.0], [-1.0, 1.0], [1.0, -1.0], [1.0, 1.0]])
"""A footprint's corners in its frame, in half lengths and half widths."""


@dataclass(frozen=True)
class BorderSurface:
    """A track's two borders at the cross-sections of the route through its lanes
    (``route_from_lanes``, index-aligned with it).

    Fields:
        station: (N,) centreline station (m), non-decreasing.
        z: (2, N) height (m, inertial frame) of the left and right border points.
        detectable: (2, N) whether the left and right border is painted or a physical
            edge there (``classify_border``).
    """

    station: NDArrayFloat
    z: NDArrayFloat
    detectable: NDArrayBool

    def at(self, stations: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayBool]:
        """(2, K) heights (interpolated) and detectability (of the cross-section at or
        before) at ``stations`` (m)."""
        z = np.stack([np.interp(stations, self.station, side) for side in self.z])
        index = np.clip(np.searchsorted(self.station, stations, side="right") - 1, 0, len(self.station) - 1)
        return z, self.detectable[:, index]


def border_surface(graph: LaneGraph, track: Track) -> BorderSurface:
    """The :class:`BorderSurface` of ``track`` (ValueError when it has no lanes), from the
    route through its lanes (``route_from_lanes``, the one ``Track.build`` made its strip of)."""
    if not track.lanes:
        raise ValueError("the camera sensor needs a track built from lanes (Track.build)")
    route = route_from_lanes(graph, track.lanes)
    detectable = np.zeros((2, len(route.s)), dtype=bool)
    for index, piece in enumerate(route.pieces):
        road = graph.odr_map.roads[piece.road_id]
        here = route.piece == index
        # Seen in driving direction the left border is the inner one in right-hand traffic.
        sides = ("inner", "outer") if road.rule == "RHT" else ("outer", "inner")
        for row, side in enumerate(sides):
            marking = classify_border(road, piece.section, piece.lane_id, side, route.s[here])
            detectable[row, here] = marking.detectable
    return BorderSurface(route.distance, np.stack((route.left_z, route.right_z)), detectable)


def hidden_by(points: NDArrayFloat, z: NDArrayFloat, detectable: NDArrayBool, cameras: NDArrayFloat,
              obstacles: Sequence[NDArrayFloat], profile: SensorProfile) -> NDArrayInt:
    """Why each border point of F frames is hidden: a mask of the rules it fails (bit i:
    rule ``END_REASONS[i]``; ``VISIBLE`` when none), shape (F, B, K).

    Args:
        points: (F, B, K, 2) world x, y (m) of each frame's border points, each border's
            nearest first.
        z: (F, B, K) their heights (m).
        detectable: (F, B, K) painted or a physical edge.
        cameras: (F, 4) each frame's camera x, y (m), yaw (rad) and height z (m), world frame.
        obstacles: per frame, (M, 3) x, y (m), yaw (rad) of the other vehicles.
    """
    x, y, yaw, camera_z = (cameras[:, k, None, None] for k in range(4))
    c, s = np.cos(yaw), np.sin(yaw)
    dx, dy = points[..., 0] - x, points[..., 1] - y
    local = np.stack((c * dx + s * dy, -s * dx + c * dy), axis=-1)  # world_to_vehicle of each frame's camera
    distance = np.hypot(local[..., 0], local[..., 1])
    signed = np.arctan2(local[..., 1], local[..., 0])
    elevation = np.arctan2(z - camera_z, distance)
    horizon = np.maximum.accumulate(elevation, axis=-1)
    below = np.zeros(points.shape[:-1], dtype=bool)
    below[..., 1:] = elevation[..., 1:] < horizon[..., :-1] - ANGLE_TOLERANCE_RAD
    frames, size = len(points), points[0, ..., 0].size
    occluded = behind_footprints(points.reshape(-1, 2), distance.ravel(), signed.ravel(), size * np.arange(frames + 1),
                                 cameras[:, :3], obstacles, profile.vehicle_length_m, profile.vehicle_width_m
                                 ).reshape(points.shape[:-1])
    failed = ((distance < profile.min_range_m) | (distance > profile.max_range_m),
              np.abs(signed) > profile.fov_half_angle_rad, below, occluded, ~detectable)
    return sum((rule.astype(np.int64) << bit for bit, rule in enumerate(failed)), np.zeros(points.shape[:-1], np.int64))


def behind_footprints(points: NDArrayFloat, distance: NDArrayFloat, bearing: NDArrayFloat, offsets: NDArrayInt,
                      cameras: NDArrayFloat, obstacles: Sequence[NDArrayFloat], length_m: float,
                      width_m: float) -> NDArrayBool:
    """(P,) whether the segment from its frame's camera to each point crosses a ``length_m``
    × ``width_m`` footprint centred on one of that frame's obstacles, world frame, m: frame
    f's points (at least one) are ``points[offsets[f]:offsets[f + 1]]`` (P, 2; ``distance``
    and ``bearing``: their distance, m, and signed bearing, rad, from the camera in its
    frame), its camera ``cameras[f]`` (x, y m, yaw rad), its obstacles ``obstacles[f]`` (M,
    3: x, y m, yaw rad). A footprint that contains the camera is ignored (the vehicle's own).

    Exact Liang–Barsky clipping in each footprint's frame, run only on the point and
    footprint pairs that can cross: the point's bearing inside the footprint's (grown by
    :data:`WEDGE_MARGIN_M`; a footprint across the bearing ±π as its two sides), the
    footprint not beyond the frame's farthest point nor beside all its bearings."""
    hidden = np.zeros(len(points), dtype=bool)
    counts = np.diff(offsets)
    tables = [np.asarray(table, dtype=np.float64).reshape(-1, 3) for table in obstacles]
    jobs = np.repeat(np.arange(len(tables)), [len(table) for table in tables])  # each footprint's frame
    if len(jobs) == 0 or len(points) == 0 or length_m <= 0.0 or width_m <= 0.0:
        return hidden
    footprints = np.concatenate(tables)
    half = np.array([0.5 * length_m, 0.5 * width_m])
    grown = half + WEDGE_MARGIN_M
    heading_cos, heading_sin = np.cos(cameras[:, 2]), np.sin(cameras[:, 2])
    cos, sin = np.cos(footprints[:, 2]), np.sin(footprints[:, 2])
    offset = cameras[jobs, :2] - footprints[:, :2]
    start = np.stack((cos * offset[:, 0] + sin * offset[:, 1], -sin * offset[:, 0] + cos * offset[:, 1]), axis=-1)
    corner_x = -offset[:, :1] + cos[:, None] * _CORNERS[:, 0] * grown[0] - sin[:, None] * _CORNERS[:, 1] * grown[1]
    corner_y = -offset[:, 1:] + sin[:, None] * _CORNERS[:, 0] * grown[0] + cos[:, None] * _CORNERS[:, 1] * grown[1]
    angle = np.arctan2(heading_cos[jobs, None] * corner_y - heading_sin[jobs, None] * corner_x,
                       heading_cos[jobs, None] * corner_x + heading_sin[jobs, None] * corner_y)
    low, high = angle.min(axis=1), angle.max(axis=1)
    # A wedge across the bearing ±π behind the camera: its two parts, each a footprint's.
    across = np.flatnonzero(high - low > math.pi)
    low[across] = np.where(angle[across] > 0.0, angle[across], np.inf).min(axis=1)
    high[across] = np.inf
    order = np.argsort(np.concatenate((jobs, jobs[across])), kind="stable")
    jobs, index = np.concatenate((jobs, jobs[across]))[order], np.concatenate((np.arange(len(jobs)), across))[order]
    low = np.concatenate((low, np.full(len(across), -np.inf)))[order]
    high = np.concatenate((high, np.where(angle[across] < 0.0, angle[across], -np.inf).max(axis=1)))[order]
    inside = np.all(np.abs(start[index]) <= grown, axis=1)  # the camera in a grown footprint: every bearing
    low[inside], high[inside] = -np.inf, np.inf
    first = offsets[:-1]
    farthest, leftmost, rightmost = (reduce.reduceat(values, first)[jobs] for reduce, values in (
        (np.maximum, distance), (np.maximum, bearing), (np.minimum, bearing)))
    kept = (np.any(np.abs(start[index]) > half, axis=1) & (high >= rightmost) & (low <= leftmost)
            & (np.hypot(offset[index, 0], offset[index, 1]) - float(np.hypot(*grown)) <= farthest))
    jobs, index, low, high = jobs[kept], index[kept], low[kept], high[kept]
    if len(jobs) == 0:
        return hidden
    # The pairs to clip: each frame's kept footprints against its points, as a padded table.
    slot = np.arange(len(jobs)) - np.searchsorted(jobs, jobs)
    table = np.full((len(counts), int(slot.max()) + 1, 2), (np.inf, -np.inf))
    table[jobs, slot] = np.column_stack((low, high))
    which = np.full(table.shape[:2], -1)
    which[jobs, slot] = index
    width = int(counts.max())
    bearings = np.full((len(counts), width), np.nan)
    bearings.ravel()[np.arange(len(points)) + np.repeat(np.arange(len(counts)) * width - first, counts)] = bearing
    pair, column = np.divmod(np.flatnonzero((bearings[:, None, :] >= table[:, :, None, 0])
                                            & (bearings[:, None, :] <= table[:, :, None, 1])), width)
    frame = pair // which.shape[1]
    job, point = which.ravel()[pair], offsets[frame] + column
    ray_x, ray_y = points[point, 0] - cameras[frame, 0], points[point, 1] - cameras[frame, 1]
    d = np.stack((cos[job] * ray_x + sin[job] * ray_y, -sin[job] * ray_x + cos[job] * ray_y), axis=-1)
    enter, leave = np.zeros(len(job)), np.ones(len(job))
    for axis in range(2):
        step = d[:, axis]
        origin = start[job, axis]
        moving = np.abs(step) > 1e-12
        safe = np.where(moving, step, 1.0)
        t1, t2 = (-half[axis] - origin) / safe, (half[axis] - origin) / safe
        inside = np.abs(origin) <= half[axis]
        enter = np.where(moving, np.maximum(enter, np.minimum(t1, t2)), np.where(inside, enter, np.inf))
        leave = np.where(moving, np.minimum(leave, np.maximum(t1, t2)), leave)
    hidden[point[enter <= leave]] = True
    return hidden


def detection_window(hidden: NDArrayInt, along: NDArrayFloat, start: int, gap_tolerance_m: float) -> tuple[int, int]:
    """(last candidate reported, index into :data:`END_REASONS` of why the lane ended) from
    candidate ``start`` on (see the module).

    ``hidden``: (B, K) :func:`hidden_by` masks; ``along``: (B, K) arc length (m) along each
    border. The reason is -1 when no gap ends the lane (the candidates run out). The last
    candidate is ``start - 1`` when a border is hidden from ``start`` on.
    """
    end, why = detection_windows(hidden[None], along[None], np.array([hidden.shape[1]]), np.array([start]),
                                 gap_tolerance_m)
    return int(end[0]), int(why[0])


def detection_windows(hidden: NDArrayInt, along: NDArrayFloat, counts: NDArrayInt, starts: NDArrayInt,
                      gap_tolerance_m: float) -> tuple[NDArrayInt, NDArrayInt]:
    """:func:`detection_window` of F frames at once: frame f's (B, K) masks and arc lengths
    are ``hidden[f, :, :counts[f]]`` and ``along[f, :, :counts[f]]`` (the rest padding), read
    from candidate ``starts[f]`` on; (F,) last candidates and reasons.

    The lane ends at the first gap of any border that ends it (the earliest, the first
    border on ties)."""
    frames, borders, width = hidden.shape
    column = np.arange(width)
    off = np.zeros((frames, borders, width + 2), dtype=np.int8)
    off[:, :, 1:-1] = (hidden != VISIBLE) & ((column >= starts[:, None]) & (column < counts[:, None]))[:, None, :]
    change = np.diff(off, axis=2)
    row, first = np.divmod(np.flatnonzero(change == 1), width + 1)  # each gap: its first hidden candidate ...
    after = np.flatnonzero(change == -1) % (width + 1)  # ... and the first visible one after it, in the same order
    frame, border = np.divmod(row, borders)
    before = np.maximum(first - 1, starts[frame])
    last = counts[frame] - 1
    span = along[frame, border, np.minimum(after, last)] - along[frame, border, before]
    ending = np.flatnonzero((after > last) | (span > gap_tolerance_m))
    earliest = np.full((frames, borders), width)
    gap = np.full((frames, borders), -1)
    lead = ending[np.diff(row[ending], prepend=-1) != 0]  # each border's first ending gap
    earliest[frame[lead], border[lead]] = first[lead]
    gap[frame[lead], border[lead]] = lead
    chosen = gap[np.arange(frames), np.argmin(earliest, axis=1)]
    end, why = counts - 1, np.full(frames, -1)
    ended = np.flatnonzero(chosen >= 0)
    if len(ended) == 0:
        return end, why
    pick = chosen[ended]
    f, b, lo = frame[pick], border[pick], first[pick]
    target = along[f, b, before[pick]] + gap_tolerance_m
    reach = np.count_nonzero((along[f, b] <= target[:, None]) & (column < counts[f, None]), axis=1)
    size = np.maximum(np.minimum(reach, after[pick]), lo + 1) - lo
    offsets = np.concatenate(([0], np.cumsum(size)[:-1]))
    inside = np.repeat(lo - offsets, size) + np.arange(int(size.sum()))
    window = hidden[np.repeat(f, size), np.repeat(b, size), inside]
    rules = np.add.reduceat((window[:, None] & _RULE_BITS) != 0, offsets, axis=0)
    end[ended], why[ended] = lo - 1, np.argmax(rules, axis=1)
    return end, why


class CameraSensor:
    """A lane sensor of kind ``camera`` (see the module) on one lane graph; caches each
    track's :class:`BorderSurface`.

    Attributes:
        profile: its parameters.
        range_m: the farthest a detection reaches (m, plane distance).
        step_m: spacing of the reported border points (m).
    """

    def __init__(self, profile: SensorProfile, graph: LaneGraph) -> None:
        if profile.kind != "camera":
            raise ValueError(f"sensor profile {profile.name}: a camera sensor needs kind 'camera', "
                             f"got {profile.kind!r}")
        self.profile = profile
        self.graph = graph
        self.range_m = profile.max_range_m
        self.step_m = profile.step_m
        angle = min(profile.fov_half_angle_rad, 0.5 * math.pi)
        self.search_m = profile.max_range_m * angle / math.sin(angle) + SEARCH_MARGIN_M
        self._surfaces: dict[tuple[LaneKey, ...], BorderSurface] = {}

    @property
    def reach_m(self) -> float:
        """The farthest (m) a reading looks along a track past the vehicle's station."""
        return self.search_m

    def surface(self, track: Track) -> BorderSurface:
        """The track's :class:`BorderSurface`, computed once per lane sequence."""
        found = self._surfaces.get(track.lanes)
        if found is None:
            found = self._surfaces[track.lanes] = border_surface(self.graph, track)
        return found

    def read(self, track: Track, station: float, obstacles: NDArrayFloat) -> tuple[Detection | None, str]:
        """The detection of a vehicle centred in its lane at ``station`` (m) with the other
        vehicles at ``obstacles`` (M, 3: x, y m, yaw rad, world), or None when nothing is
        seen, and why it ended (:data:`END_REASONS`)."""
        strip = track.strip
        profile = self.profile
        last_station = min(station + self.search_m, strip.length)
        count = max(int(math.ceil((last_station - station) / self.step_m - 1e-9)), 1)
        stations = np.minimum(station + self.step_m * np.arange(count + 1), last_station)
        left, right = strip.borders_at(stations)
        points = np.stack((left, right))
        surface = self.surface(track)
        z, detectable = surface.at(stations)
        x, y, yaw = strip.pose(station)
        camera_z = float(np.interp(station, surface.station, 0.5 * (surface.z[0] + surface.z[1])))
        camera = np.array([[x, y, yaw, camera_z + profile.camera_height_m]])
        hidden = hidden_by(points[None], z[None], detectable[None], camera, [obstacles], profile)[0]
        near = np.hypot(points[..., 0] - x, points[..., 1] - y) >= profile.min_range_m
        started = np.flatnonzero(near.all(axis=0))
        if started.size == 0:
            return None, "map_end" if last_station >= strip.length else "range"
        start = int(started[0])
        along = np.stack([np.interp(stations, strip.station, d) for d in (strip.left_distance, strip.right_distance)])
        end, why = detection_window(hidden, along, start, profile.gap_tolerance_m)
        reason = END_REASONS[why] if why >= 0 else "map_end" if last_station >= strip.length else "range"
        if end <= start or stations[end] - stations[start] < self.step_m:
            return None, reason
        return detection_between(strip, x, y, yaw, float(stations[start]), float(stations[end]), self.step_m,
                                 reason), reason

    def read_many(self, track: Track, stations: NDArrayFloat,
                  obstacles: Sequence[NDArrayFloat]) -> list[tuple[Detection | None, str]]:
        """:meth:`read` at every station (m) of ``stations`` with the other vehicles at
        ``obstacles[k]``: the candidates of all stations as (F, 2, K) tables (a station with
        fewer repeats its last), the same readings."""
        strip = track.strip
        profile = self.profile
        stations = np.asarray(stations, dtype=np.float64)
        if len(stations) == 0:
            return []
        last = np.minimum(stations + self.search_m, strip.length)
        counts = np.maximum(np.ceil((last - stations) / self.step_m - 1e-9).astype(np.intp), 1) + 1
        frames, width = len(stations), int(counts.max())
        candidates = np.minimum(stations[:, None] + self.step_m * np.arange(width), last[:, None])
        left, right = strip.borders_at(candidates.ravel())
        points = np.stack((left.reshape(frames, width, 2), right.reshape(frames, width, 2)), axis=1)
        surface = self.surface(track)
        z, detectable = surface.at(candidates.ravel())
        x, y, yaw = strip.poses(stations)
        camera_z = np.interp(stations, surface.station, 0.5 * (surface.z[0] + surface.z[1])) + profile.camera_height_m
        hidden = hidden_by(points, z.reshape(2, frames, width).swapaxes(0, 1),
                           detectable.reshape(2, frames, width).swapaxes(0, 1), np.column_stack((x, y, yaw, camera_z)),
                           obstacles, profile)
        near = np.hypot(points[..., 0] - x[:, None, None], points[..., 1] - y[:, None, None]) >= profile.min_range_m
        both = near.all(axis=1) & (np.arange(width) < counts[:, None])
        along = np.stack([np.interp(candidates, strip.station, d) for d in (strip.left_distance, strip.right_distance)],
                         axis=1)
        started = both.any(axis=1)
        first = np.where(started, np.argmax(both, axis=1), counts)
        ends, whys = detection_windows(hidden, along, counts, first, profile.gap_tolerance_m)
        out: list[tuple[Detection | None, str]] = []
        windows: list[tuple[int, float, float, str]] = []
        for f, (here, start, end, why) in enumerate(zip(candidates, first.tolist(), ends.tolist(), whys.tolist())):
            ran_out = "map_end" if last[f] >= strip.length else "range"
            if not started[f]:
                out.append((None, ran_out))
                continue
            reason = END_REASONS[why] if why >= 0 else ran_out
            if end <= start or here[end] - here[start] < self.step_m:
                out.append((None, reason))
                continue
            windows.append((f, float(here[start]), float(here[end]), reason))
            out.append((None, reason))
        if windows:
            index = np.array([w[0] for w in windows])
            found = detections_between(strip, x[index], y[index], yaw[index], np.array([w[1] for w in windows]),
                                       np.array([w[2] for w in windows]), self.step_m, [w[3] for w in windows])
            for (f, _, _, reason), detection in zip(windows, found):
                out[f] = (detection, reason)
        return out


def lane_sensor(profile: SensorProfile, graph: LaneGraph) -> LaneSensor | CameraSensor:
    """The sensor of ``profile``: the ideal ``LaneSensor`` (range and step of the profile)
    or a :class:`CameraSensor` on ``graph``."""
    if profile.kind == "ideal":
        return LaneSensor(range_m=profile.max_range_m, step_m=profile.step_m)
    return CameraSensor(profile, graph)
