"""Drives: an ego and cooperative vehicles following routes of the lane graph.

A drive is one ego ``Track`` (a lane sequence and its ``LaneStrip``) plus vehicles placed
relative to the ego in every frame (10 Hz, 10 m/s by default):

- ``coop``: ahead on the ego's own lanes, ``lead_m`` metres of station ahead. The paper's
  presets: convoy headway d_v = 25 m (detections overlap), spline gap d_s between the
  ego's detection end and the coop's detection start (lead = r_lane + d_s).
- ``turn``: ahead on a branch that shares the ego's lanes up to a junction and turns off
  there (present only once past the branch point): a lane the ego could drive, fusible.
- ``adjacent`` / ``opposite``: distractors on the lane beside the ego's lane ahead, in the
  same or the opposite direction, placed at the point of their lane nearest to the ego's
  lane ``lead_m`` ahead; the fusion must reject them.
- ``behind``: on the ego's lanes, ``lead_m`` behind; must be rejected.

Stations are centreline arc lengths (m) from the start of a track. The true lane relation
(:func:`lane_relation`) is read from the lane graph, never from the fusion.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Iterator
from dataclasses import dataclass, field, fields
from functools import cached_property
from typing import Any, Final, Literal, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.network.lane_area import offset_inside
from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.network.lane_strip import LaneStrip, NDArrayFloat
from cold_maps.network.route import route_from_lanes
from cold_maps.network.routing import (
    LENGTH_TOLERANCE_M,
    longest_route_lengths,
    random_route,
)
from cold_maps.simulation.sensor import SENSOR_RANGE_M
from gt_matching.lru import lru_get

FRAME_RATE_HZ: Final[float] = 10.0
DEFAULT_SPEED_MPS: Final[float] = 10.0
MAX_SPEED_MPS: Final[float] = 1000.0
"""Fastest ego a drive accepts (m/s): 100 m per frame at 10 Hz, more than three sensor
ranges, so consecutive frames share nothing beyond it; the bound keeps drive lengths finite
(1e308 m/s made the needed route length inf)."""
CONVOY_HEADWAY_M: Final[float] = 25.0
"""The paper's convoy headway d_v (m)."""
PAPER_GAPS_M: Final[tuple[float, ...]] = (20.0, 30.0, 50.0)
"""The paper's spline gaps d_s (m)."""
BESIDE_MAX_DISTANCE_M: Final[float] = 8.0
"""A distractor farther than this (m) from the ego's lane point it is placed beside is absent."""
ROUTE_MARGIN_M: Final[float] = 5.0
"""Extra route length (m) beyond what the vehicles and their sensors need."""
MAX_BRANCHES: Final[int] = 2
"""Branch (turning) tracks built per drive at most."""
BESIDE_TRACKS_KEPT: Final[int] = 16
"""Tracks of the lanes beside the ego's that a drive keeps built (:class:`BesideTracks`,
latest used; a block of frames asks for those of a few lanes)."""
MAX_COVER_ROUTES: Final[int] = 1000
"""Most routes drawn to cover a map's lanes."""

Role = Literal["ego", "coop", "turn", "adjacent", "opposite", "behind"]
SHARED_STATION_ROLES: Final[tuple[str, ...]] = ("coop", "turn", "behind")
"""Roles whose track shares the ego's stations (up to a branch point): their ``lead_m``
is their distance along the drive from the ego."""


class DriveError(ValueError):
    """A drive that cannot be built (no drivable route, a route too short); names the map.

    ``longest_m`` is the longest route there was (m), or None when unknown.
    """

    def __init__(self, message: str, *, longest_m: float | None = None) -> None:
        super().__init__(message)
        self.longest_m = longest_m


@dataclass(frozen=True)
class Track:
    """A path of whole lanes, world frame (OpenDRIVE inertial), in driving direction.

    Fields:
        lanes: the lanes in driving order.
        strip: their centreline and borders by station (m).
        lane_starts: (L + 1,) station (m) where each lane begins; the last entry is the
            end of the last lane (the track length unless the strip is cut, :meth:`cut`).
            From the graph's lane lengths scaled to the length of the whole strip.

    A track built from lanes (:meth:`build`) keeps only its strip: the route it came from
    (road s, heights, ``route_from_lanes(graph, lanes)``) is made again where needed (the
    camera's road surface), so a long drive holds one copy of its geometry.
    """

    lanes: tuple[LaneKey, ...]
    strip: LaneStrip
    lane_starts: NDArrayFloat

    @classmethod
    def build(cls, graph: LaneGraph, lanes: Sequence[LaneKey]) -> Track:
        """The track through ``lanes`` (ValueError when they do not follow each other)."""
        route = route_from_lanes(graph, lanes)
        strip = LaneStrip.from_borders(route.left, route.right)
        cumulative = np.concatenate(([0.0], np.cumsum([graph.lengths[lane] for lane in lanes])))
        return cls(tuple(lanes), strip, cumulative * (strip.length / cumulative[-1]))

    def cut(self, station: float) -> Track:
        """This track with its strip ending at its first cross-section at or past ``station``
        (m), lanes and lane starts unchanged: up to there every station, lane, offset, point
        and heading is this track's (itself when ``station`` lies beyond its strip's second
        to last cross-section)."""
        strip = self.strip
        end = int(np.searchsorted(strip.station, station, side="left")) + 1
        if end >= len(strip.station):
            return self
        kept = LaneStrip(**{part.name: getattr(strip, part.name)[:end].copy() for part in fields(strip)})
        return Track(self.lanes, kept, self.lane_starts)

    @property
    def length(self) -> float:
        """Track length (m)."""
        return self.strip.length

    def borders_between(self, start: float, end: float) -> tuple[NDArrayFloat, NDArrayFloat]:
        """Left and right borders (world frame, m) from station ``start`` to ``end``,
        the strip's own points plus both ends."""
        strip = self.strip
        first = int(np.searchsorted(strip.station, start, side="right"))
        last = int(np.searchsorted(strip.station, end, side="left"))
        left_ends, right_ends = strip.borders_at(np.array([start, end]))
        return (np.concatenate((left_ends[:1], strip.left[first:last], left_ends[1:])),
                np.concatenate((right_ends[:1], strip.right[first:last], right_ends[1:])))

    def _repeats(self) -> list[tuple[int, int]]:
        """Index pairs (i, j), i < j, of the same lane passed twice."""
        seen: dict[LaneKey, list[int]] = {}
        for index, lane in enumerate(self.lanes):
            seen.setdefault(lane, []).append(index)
        return [(first, again) for indices in seen.values() for n, first in enumerate(indices)
                for again in indices[n + 1:]]

    @property
    def shortest_loop_m(self) -> float:
        """Length (m) of the shortest loop the track circles; inf when it passes no lane twice."""
        return min((float(self.lane_starts[j] - self.lane_starts[i]) for i, j in self._repeats()), default=math.inf)

    def wraps(self, start: float, end: float) -> bool:
        """True when the stretch of stations [``start``, ``end``] (m) passes some point of a
        lane twice: the track circles a loop shorter than the stretch."""
        starts = self.lane_starts
        return any(max(starts[i], start) <= min(starts[i + 1], end - (starts[j] - starts[i]))
                   for i, j in self._repeats())

    def wraps_all(self, start: NDArrayFloat, end: NDArrayFloat) -> npt.NDArray[np.bool_]:
        """:meth:`wraps` of every stretch [``start[k]``, ``end[k]``] (m)."""
        starts = self.lane_starts
        out = np.zeros(np.shape(start), dtype=bool)
        for i, j in self._repeats():
            out |= np.maximum(starts[i], start) <= np.minimum(starts[i + 1], end - (starts[j] - starts[i]))
        return out

    def nearest_within(self, points: NDArrayFloat, radius_m: float) -> npt.NDArray[np.intp]:
        """Per point of ``points`` (K, 2, world frame, m), the index of its nearest centreline
        point as ``np.argmin`` of the ``np.hypot`` distances to all of them finds it (the first
        of equals) when that distance is at most ``radius_m``, else -1; only the points a
        k-d tree finds within a slightly larger radius are measured."""
        centre = self.strip.centerline
        found = self._centre_tree.query_ball_point(points, radius_m * (1.0 + 1e-9) + 1e-9, return_sorted=True)
        counts = np.array([len(near) for near in found], dtype=np.intp)
        out = np.full(len(points), -1, dtype=np.intp)
        if not counts.any():
            return out
        index = np.concatenate([near for near in found if near]).astype(np.intp)
        rows = np.repeat(np.arange(len(points)), counts)
        distance = np.hypot(centre[index, 0] - points[rows, 0], centre[index, 1] - points[rows, 1])
        starts = np.concatenate(([0], np.cumsum(counts)))[:-1][counts > 0]
        least = np.minimum.reduceat(distance, starts)
        row_least = np.repeat(least, counts[counts > 0])
        first = np.flatnonzero(distance == row_least)
        first = first[np.concatenate(([True], rows[first][1:] != rows[first][:-1]))]
        within = distance[first] <= radius_m
        out[rows[first][within]] = index[first][within]
        return out

    @cached_property
    def _centre_tree(self) -> Any:
        """A k-d tree of the centreline points (scipy ``cKDTree``)."""
        from scipy.spatial import cKDTree

        return cKDTree(self.strip.centerline)

    def lane_at(self, station: float) -> tuple[int, float]:
        """Index of the lane at ``station`` and the distance (m) driven in it."""
        index = min(max(int(np.searchsorted(self.lane_starts, station, side="right")) - 1, 0), len(self.lanes) - 1)
        return index, float(station - self.lane_starts[index])


@dataclass(frozen=True)
class Vehicle:
    """A vehicle of a drive other than the ego.

    Fields:
        name: unique id (letters, digits, '_' or '-'), e.g. ``coop50``.
        role: ``coop``, ``turn``, ``adjacent``, ``opposite`` or ``behind`` (see the module).
        lead_m: station distance ahead of the ego (m; negative behind).
        track: the vehicle's track; ``coop``, ``turn`` and ``behind`` share the ego's
            stations up to their branch point. None for ``adjacent``/``opposite``, whose
            tracks are the drive's ``beside`` tracks.
        branch_station_m: for ``turn``, the station where its track leaves the ego's; the
            vehicle is present only while it is past it and the ego is not. 0 otherwise.
    """

    name: str
    role: Role
    lead_m: float
    track: Track | None = None
    branch_station_m: float = 0.0


@dataclass(frozen=True)
class VehicleState:
    """One vehicle in one frame.

    Fields:
        name, role: as in :class:`Vehicle` (``ego`` for the ego).
        track: the track it drives on.
        station: its station on the track (m).
        lane: the lane it is in.
        lane_offset_m: distance driven in that lane (m).
        lead_m: its station distance ahead of the ego (m; negative behind, 0 for the ego).
    """

    name: str
    role: str
    track: Track
    station: float
    lane: LaneKey
    lane_offset_m: float
    lead_m: float = 0.0


@dataclass(frozen=True)
class Drive:
    """The ego and its vehicles on one route.

    Fields:
        graph: the lane graph.
        ego: the ego's track.
        vehicles: the other vehicles.
        beside: lane → tracks starting at the lanes beside it (role ``adjacent`` or
            ``opposite``, track), for the lanes of the ego's track.
        frames: number of frames.
        speed_mps: ego speed (m/s).
        rate_hz: frame rate (Hz).
        sensor_range_m: detection range every vehicle needs ahead of it (m).
        start_station_m: the ego's station in frame 0 (m), room for vehicles behind it.
    """

    graph: LaneGraph
    ego: Track
    vehicles: tuple[Vehicle, ...]
    beside: Mapping[LaneKey, tuple[tuple[str, Track], ...]] = field(repr=False)
    frames: int
    speed_mps: float = DEFAULT_SPEED_MPS
    rate_hz: float = FRAME_RATE_HZ
    sensor_range_m: float = SENSOR_RANGE_M
    start_station_m: float = 0.0

    def stamp(self, frame: int) -> float:
        """Time of a frame (s) from the start of the drive."""
        return frame / self.rate_hz

    def ego_station(self, frame: int) -> float:
        """The ego's station (m) in a frame."""
        return self.start_station_m + frame * self.speed_mps / self.rate_hz

    def states(self, frame: int) -> dict[str, VehicleState]:
        """Every vehicle present in ``frame`` (ego first), by name. A vehicle is present
        when it stands on its track with a full sensor range of lane ahead of it, and (on
        a track through a loop) the stretch from the ego, or the vehicle behind it, to the
        end of the farther one's detection does not circle the loop (``Track.wraps``)."""
        if not 0 <= frame < self.frames:
            raise ValueError(f"frame {frame} outside the drive's 0..{self.frames - 1}")
        ego_station = self.ego_station(frame)
        states = {"ego": self._state("ego", "ego", self.ego, ego_station)}
        for vehicle in self.vehicles:
            state = self._vehicle_state(vehicle, ego_station)
            if state is not None:
                states[vehicle.name] = state
        return states

    def states_block(self, frames: range) -> list[dict[str, VehicleState]]:
        """:meth:`states` of every frame of ``frames`` (a step-1 range inside the drive),
        computed as arrays over the frames, vehicle by vehicle: the same states, same order."""
        if frames.step != 1 or (len(frames) and not 0 <= frames.start <= frames.stop - 1 < self.frames):
            raise ValueError(f"frames {frames} outside the drive's 0..{self.frames - 1} (or not consecutive)")
        ego_stations = self.start_station_m + np.arange(frames.start, frames.stop) * self.speed_mps / self.rate_hz
        blocks: list[dict[str, VehicleState]] = [{} for _ in frames]
        self._fill(blocks, "ego", "ego", self.ego, ego_stations, np.ones(len(frames), dtype=bool), 0.0)
        for vehicle in self.vehicles:
            self._vehicle_states(blocks, vehicle, ego_stations)
        return blocks

    def _fill(self, blocks: list[dict[str, VehicleState]], name: str, role: str, track: Track, stations: NDArrayFloat,
              present: npt.NDArray[np.bool_], lead_m: float) -> None:
        """Adds the state at ``stations`` (m, one per frame) to the frames where ``present``."""
        frames = np.flatnonzero(present)
        kept = stations[frames]
        index = np.clip(np.searchsorted(track.lane_starts, kept, side="right") - 1, 0, len(track.lanes) - 1)
        offsets = kept - track.lane_starts[index]
        for frame, station, lane, offset in zip(frames.tolist(), kept.tolist(), index.tolist(), offsets.tolist()):
            blocks[frame][name] = VehicleState(name, role, track, station, track.lanes[lane], offset, lead_m)

    def _vehicle_states(self, blocks: list[dict[str, VehicleState]], vehicle: Vehicle,
                        ego_stations: NDArrayFloat) -> None:
        """:meth:`_vehicle_state` over the frames of ``blocks`` (ego at ``ego_stations``)."""
        targets = ego_stations + vehicle.lead_m
        if vehicle.track is not None:
            track = vehicle.track
            present = self._fits_all(track, targets)
            if vehicle.role == "turn":
                present &= (ego_stations < vehicle.branch_station_m) & (vehicle.branch_station_m < targets)
            present &= ~track.wraps_all(np.minimum(ego_stations, targets),
                                        np.maximum(ego_stations, targets) + self.sensor_range_m)
            self._fill(blocks, vehicle.name, vehicle.role, track, targets, present, vehicle.lead_m)
            return
        fits = self._fits_all(self.ego, targets)
        if not fits.any():
            return
        lanes = np.clip(np.searchsorted(self.ego.lane_starts, targets, side="right") - 1, 0, len(self.ego.lanes) - 1)
        points = self.ego.strip.interpolate(targets)[0]
        placed = np.zeros(len(targets), dtype=bool)
        for lane_index in np.unique(lanes[fits]).tolist():
            for role, track in self.beside.get(self.ego.lanes[lane_index], ()):
                if role != vehicle.role:
                    continue
                frames = np.flatnonzero(fits & (lanes == lane_index) & ~placed)
                if frames.size == 0:
                    break
                nearest = track.nearest_within(points[frames], BESIDE_MAX_DISTANCE_M)
                station = track.strip.station[nearest]
                ok = (nearest >= 0) & self._fits_all(track, station)
                for frame, at in zip(frames[ok].tolist(), station[ok].tolist()):
                    blocks[frame][vehicle.name] = self._state(vehicle.name, vehicle.role, track, at, vehicle.lead_m)
                placed[frames[ok]] = True

    def _fits_all(self, track: Track, stations: NDArrayFloat) -> npt.NDArray[np.bool_]:
        """:meth:`_fits` of every station (m)."""
        return (0.0 <= stations) & (stations <= track.length - self.sensor_range_m)

    def _state(self, name: str, role: str, track: Track, station: float, lead_m: float = 0.0) -> VehicleState:
        index, offset = track.lane_at(station)
        return VehicleState(name, role, track, station, track.lanes[index], offset, lead_m)

    def _fits(self, track: Track, station: float) -> bool:
        return 0.0 <= station <= track.length - self.sensor_range_m

    def _vehicle_state(self, vehicle: Vehicle, ego_station: float) -> VehicleState | None:
        target = ego_station + vehicle.lead_m
        if vehicle.track is not None:
            if vehicle.role == "turn" and not ego_station < vehicle.branch_station_m < target:
                return None
            if not self._fits(vehicle.track, target):
                return None
            if vehicle.track.wraps(min(ego_station, target), max(ego_station, target) + self.sensor_range_m):
                return None
            return self._state(vehicle.name, vehicle.role, vehicle.track, target, vehicle.lead_m)
        if not self._fits(self.ego, target):
            return None
        lane = self.ego.lanes[self.ego.lane_at(target)[0]]
        point = self.ego.strip.interpolate(np.array([target]))[0][0]
        for role, track in self.beside.get(lane, ()):
            if role != vehicle.role:
                continue
            distances = np.hypot(*(track.strip.centerline - point).T)
            nearest = int(np.argmin(distances))
            station = float(track.strip.station[nearest])
            if distances[nearest] <= BESIDE_MAX_DISTANCE_M and self._fits(track, station):
                return self._state(vehicle.name, vehicle.role, track, station, vehicle.lead_m)
        return None


def required_route_length(frames: int, leads_m: Sequence[float], *, behind_m: float = 0.0,
                          speed_mps: float = DEFAULT_SPEED_MPS, rate_hz: float = FRAME_RATE_HZ,
                          sensor_range_m: float = SENSOR_RANGE_M) -> float:
    """Route length (m) an ego needs for ``frames`` frames with vehicles ``leads_m`` ahead
    and room for one ``behind_m`` behind it."""
    if frames < 1:
        raise ValueError(f"frames: expected at least 1, got {frames!r}")
    if not (0 < speed_mps <= MAX_SPEED_MPS and math.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"speed must be > 0 and <= {MAX_SPEED_MPS:g} m/s and the frame rate finite and > 0, "
                         f"got {speed_mps!r} m/s, {rate_hz!r} Hz")
    ahead = max([0.0, *leads_m])
    return behind_m + (frames - 1) * speed_mps / rate_hz + ahead + sensor_range_m + ROUTE_MARGIN_M


def _map_name(graph: LaneGraph) -> str:
    return str(graph.odr_map.path or "<map>")


def require_driving_lanes(graph: LaneGraph) -> None:
    """DriveError naming the map and the lane types looked for when the graph has no lane."""
    if not graph.lanes:
        raise DriveError(f"{_map_name(graph)}: the map has no driving lanes (of types {', '.join(graph.lane_types)})")


def covering_routes(graph: LaneGraph, count: int | None, length_m: float,
                    rng: np.random.Generator) -> list[tuple[LaneKey, ...]]:
    """Random routes of at least ``length_m``, each starting, where it can, on a lane no
    earlier route covers, so the routes spread over the map's driving lanes: ``count`` of
    them, or (``count`` None) as many as it takes to cover every lane a route of that
    length can start on (at most ``MAX_COVER_ROUTES``).

    Raises DriveError naming the map when no route is that long.
    """
    if count is not None and count < 1:
        raise ValueError(f"routes: expected at least 1, got {count!r}")
    require_driving_lanes(graph)
    longest = longest_route_lengths(graph)
    startable = [lane for lane in graph.lanes if longest[lane] >= length_m - LENGTH_TOLERANCE_M]
    if not startable:
        best = max(longest.values())
        raise DriveError(f"{_map_name(graph)}: no drivable route of {length_m:.0f} m (longest {best:.0f} m)",
                         longest_m=best)
    covered: set[LaneKey] = set()
    routes: list[tuple[LaneKey, ...]] = []
    while len(routes) < (MAX_COVER_ROUTES if count is None else count):
        pool = [lane for lane in startable if lane not in covered]
        if not pool and count is None:
            break
        pool = pool or startable
        start = pool[int(rng.integers(len(pool)))]
        lanes = random_route(graph, length_m, rng, start=start, longest=longest)
        assert lanes is not None  # start is drivable for length_m
        routes.append(lanes)
        covered.update(lanes)
    return routes


def route_from_start(graph: LaneGraph, start: LaneKey, length_m: float,
                     rng: np.random.Generator) -> tuple[LaneKey, ...]:
    """A random route of at least ``length_m`` from ``start``; DriveError when none exists."""
    lanes = random_route(graph, length_m, rng, start=start)
    if lanes is None:
        longest = longest_route_lengths(graph)[start]
        raise DriveError(f"{_map_name(graph)}: no route of {length_m:.0f} m from lane {tuple(start)} "
                         f"(longest {longest:.0f} m)", longest_m=longest)
    return lanes


def lanes_beside(graph: LaneGraph, lane: LaneKey) -> list[tuple[str, LaneKey]]:
    """The graph lanes next to ``lane`` in its lane section: ``adjacent`` (same direction,
    the next lane outwards or inwards, across the centre lane too: lanes 1 and -1 when one
    has ``direction="reversed"``) and ``opposite`` (the nearest lane driven the other way)."""
    road = graph.odr_map.roads[lane.road_id]
    own = road.drives_along_s(lane.lane_id, lane.section)
    same_section = [k for k in graph.lanes if k.road_id == lane.road_id and k.section == lane.section and k != lane]
    beside_ids = {lane.lane_id + 1 or 1, lane.lane_id - 1 or -1}
    found: list[tuple[str, LaneKey]] = []
    for other in same_section:
        if road.drives_along_s(other.lane_id, other.section) == own and other.lane_id in beside_ids:
            found.append(("adjacent", other))
    opposite = [k for k in same_section if road.drives_along_s(k.lane_id, k.section) != own]
    if opposite:
        found.append(("opposite", min(opposite, key=lambda k: (abs(k.lane_id - lane.lane_id), k.lane_id))))
    return found


def _forward(graph: LaneGraph, lanes: list[LaneKey], length_m: float, rng: np.random.Generator) -> list[LaneKey]:
    """``lanes`` extended by random successors until they are ``length_m`` long (or end)."""
    total = sum(graph.lengths[lane] for lane in lanes)
    while total < length_m and graph.successors[lanes[-1]]:
        nexts = graph.successors[lanes[-1]]
        lanes.append(nexts[int(rng.integers(len(nexts)))])
        total += graph.lengths[lanes[-1]]
    return lanes


def build_drive(graph: LaneGraph, lanes: Sequence[LaneKey], frames: int, *, coop_leads_m: Sequence[float],
                distractor_leads_m: Sequence[float] = (), rng: np.random.Generator,
                speed_mps: float = DEFAULT_SPEED_MPS, rate_hz: float = FRAME_RATE_HZ,
                sensor_range_m: float = SENSOR_RANGE_M, reach_m: float | None = None) -> Drive:
    """A drive of ``frames`` frames on the route ``lanes``: a ``coop`` at each of
    ``coop_leads_m`` and, for each of ``distractor_leads_m``, ``turn`` vehicles on branches
    of the route, ``adjacent``/``opposite`` distractors and one ``behind``. A branch's strip
    is cut (:meth:`Track.cut`) past where its turning vehicles can be plus ``reach_m`` (m),
    the farthest a sensor reads a track ahead of a vehicle, or ``sensor_range_m`` if farther.

    Raises DriveError when the route is shorter than the drive needs.
    """
    behind = max(distractor_leads_m, default=0.0)
    needed = required_route_length(frames, [*coop_leads_m, *distractor_leads_m], behind_m=behind,
                                   speed_mps=speed_mps, rate_hz=rate_hz, sensor_range_m=sensor_range_m)
    ego = Track.build(graph, lanes)
    if ego.length < needed - ROUTE_MARGIN_M:
        raise DriveError(f"{_map_name(graph)}: route of {ego.length:.0f} m is shorter than the {needed:.0f} m "
                         f"{frames} frames need; use fewer --frames")
    vehicles = [Vehicle(f"coop{lead:g}", "coop", lead, ego) for lead in coop_leads_m]
    beside: Mapping[LaneKey, tuple[tuple[str, Track], ...]] = {}
    if distractor_leads_m:
        ahead_m = max(distractor_leads_m) + max(sensor_range_m, reach_m or 0.0) + ROUTE_MARGIN_M
        branches = _branches(graph, ego, needed, ahead_m, rng)
        for lead in distractor_leads_m:
            vehicles += [Vehicle(f"turn{lead:g}-{i}", "turn", lead, track, station)
                         for i, (track, station) in enumerate(branches)]
            vehicles += [Vehicle(f"{role}{lead:g}", role, lead) for role in ("adjacent", "opposite")]
            vehicles.append(Vehicle(f"behind{lead:g}", "behind", -lead, ego))
        reach = 2.0 * sensor_range_m + max(distractor_leads_m) + ROUTE_MARGIN_M
        routes: dict[LaneKey, tuple[LaneKey, ...]] = {}
        roles: dict[LaneKey, tuple[tuple[str, LaneKey], ...]] = {}
        for lane in dict.fromkeys(ego.lanes):
            roles[lane] = tuple(lanes_beside(graph, lane))
            for _, other in roles[lane]:
                if other not in routes:
                    routes[other] = tuple(_forward(graph, [other], reach, rng))
        beside = BesideTracks(graph, roles, routes)
    return Drive(graph, ego, tuple(vehicles), beside, frames, speed_mps, rate_hz, sensor_range_m, behind)


class BesideTracks(Mapping[LaneKey, tuple[tuple[str, Track], ...]]):
    """A drive's ``beside``: lane → (role, track) of each lane beside it, the tracks built
    from their lanes when asked for and the latest ``BESIDE_TRACKS_KEPT`` kept (a long
    drive passes many lanes; a track built again is the same, :meth:`Track.build`)."""

    def __init__(self, graph: LaneGraph, roles: Mapping[LaneKey, tuple[tuple[str, LaneKey], ...]],
                 routes: Mapping[LaneKey, tuple[LaneKey, ...]]) -> None:
        """``roles``: per lane of the ego, the role and first lane of each lane beside it;
        ``routes``: per such first lane, the lanes of its track."""
        self._graph = graph
        self._roles = roles
        self._routes = routes
        self._built: OrderedDict[LaneKey, Track] = OrderedDict()

    def __getitem__(self, lane: LaneKey) -> tuple[tuple[str, Track], ...]:
        return tuple((role, lru_get(self._built, other, lambda: Track.build(self._graph, self._routes[other]),
                                    BESIDE_TRACKS_KEPT))
                     for role, other in self._roles[lane])

    def __iter__(self) -> Iterator[LaneKey]:
        return iter(self._roles)

    def __len__(self) -> int:
        return len(self._roles)


def _branches(graph: LaneGraph, ego: Track, length_m: float, ahead_m: float,
              rng: np.random.Generator) -> list[tuple[Track, float]]:
    """Up to MAX_BRANCHES tracks that follow the ego's lanes to a lane with several
    successors and turn into another one there, their lanes drawn to ``length_m`` (m) and
    their strips cut ``ahead_m`` past the branch; each with its branch station (m)."""
    branches = []
    for index, (lane, following) in enumerate(zip(ego.lanes, ego.lanes[1:])):
        for other in graph.successors[lane]:
            if other == following or len(branches) >= MAX_BRANCHES:
                continue
            lanes = _forward(graph, [*ego.lanes[: index + 1], other], length_m, rng)
            station = float(ego.lane_starts[index + 1])
            branches.append((Track.build(graph, lanes).cut(station + ahead_m), station))
    return branches


def _reachable(graph: LaneGraph, lane: LaneKey, offset_m: float, coop: VehicleState, max_distance_m: float) -> bool:
    """True when ``coop`` is ahead of the point ``offset_m`` into ``lane`` along the lane
    graph, by at most ``max_distance_m`` (m) of lane."""
    if coop.lane == lane and coop.lane_offset_m > offset_m:
        return coop.lane_offset_m - offset_m <= max_distance_m
    best: dict[LaneKey, float] = {}
    frontier = [(nxt, graph.lengths[lane] - offset_m) for nxt in graph.successors[lane]]
    while frontier:
        nxt, entry = frontier.pop()
        if entry > max_distance_m or best.get(nxt, math.inf) <= entry:
            continue
        best[nxt] = entry
        frontier += [(after, entry + graph.lengths[nxt]) for after in graph.successors[nxt]]
    entry = best.get(coop.lane)
    return entry is not None and 0.0 < entry + coop.lane_offset_m <= max_distance_m


def ahead_in_ego_frame(ego: VehicleState, other: VehicleState) -> bool:
    """True when ``other`` stands ahead of the ego in the ego's vehicle frame (x > 0),
    both at their true positions on their tracks' centrelines."""
    x, y, yaw = ego.track.strip.pose(ego.station)
    other_x, other_y, _ = other.track.strip.pose(other.station)
    return (other_x - x) * math.cos(yaw) + (other_y - y) * math.sin(yaw) > 0.0


def lane_relation(graph: LaneGraph, ego: VehicleState, coop: VehicleState, max_distance_m: float,
                  detection_m: float = 0.0) -> bool:
    """True when ``coop`` is on a possible trajectory of the ego (the paper's validity rule,
    sec. III-B): ahead of the ego in the ego's vehicle frame and along the lane graph by at
    most ``max_distance_m`` (m) of lane, and either on the stretch of the ego's track its
    detection covers (``detection_m`` ahead) or on a lane reachable from where that
    detection ends, along successors on any branch, by at most ``max_distance_m -
    detection_m`` of lane (the length of lane between the two detections matches a gap the
    fusion may bridge). A vehicle sharing the ego's stations (``coop``, ``turn``,
    ``behind``) must also be ahead on the drive itself (``0 < lead_m`` relative to ``ego``,
    itself a chain's coop or the ego), so that on a loop a vehicle behind does not count as
    reachable ahead around it. Adjacent and opposite lanes, vehicles behind, and a coop on
    another branch of a fork the ego's detection has passed and left are not. Where the
    detection ends is every lane its end point lies in: the track's lane, and a lane that
    left the track at a fork inside the detection but has not yet drifted half its width
    away from that point (branches of a junction overlap past their common entry; the
    detection lies on each of them from the fork to its end)."""
    if coop.role in SHARED_STATION_ROLES and not 0.0 < coop.lead_m - ego.lead_m <= max_distance_m:
        return False
    if not ahead_in_ego_frame(ego, coop) or not _reachable(graph, ego.lane, ego.lane_offset_m, coop, max_distance_m):
        return False
    track = ego.track
    first, _ = track.lane_at(ego.station)
    last, last_offset_m = track.lane_at(min(ego.station + detection_m, track.length))
    if coop.lane in track.lanes[first: last + 1]:
        return True
    budget_m = max_distance_m - detection_m
    if _reachable(graph, track.lanes[last], last_offset_m, coop, budget_m):
        return True
    end = min(ego.station + detection_m, track.length)
    return any(coop.lane in lanes or _reachable(graph, lanes[-1], offset_m, coop, budget_m)
               for lanes, offset_m in _fork_lanes_at(graph, track, first, last, end))


def _fork_lanes_at(graph: LaneGraph, track: Track, first: int, last: int,
                   station: float) -> list[tuple[tuple[LaneKey, ...], float]]:
    """The lanes from a fork of ``track`` between its lanes ``first`` and ``last`` to a lane
    that contains the track's centre point at ``station`` (the detection lies on all of
    them), each with the distance (m) along that last lane to the point's cross-section
    (:func:`cold_maps.network.lane_area.offset_inside`)."""
    x, y, _ = track.strip.pose(station)
    found = []
    for index in range(first, last):
        past_fork_m = station - float(track.lane_starts[index + 1])
        stack = [((lane,), 0.0) for lane in graph.successors[track.lanes[index]] if lane != track.lanes[index + 1]]
        while stack:
            lanes, entry_m = stack.pop()
            offset_m = offset_inside(graph, lanes[-1], (x, y))
            if offset_m is not None:
                found.append((lanes, offset_m))
            exit_m = entry_m + graph.lengths[lanes[-1]]
            if exit_m < past_fork_m:
                stack += [((*lanes, after), exit_m) for after in graph.successors[lanes[-1]] if after not in lanes]
    return found


RELATION_KINDS: Final[tuple[str, ...]] = ("own", "branch", "adjacent", "opposite", "other_branch", "behind", "other")
"""Kinds of a pair: ``own`` (valid, the coop's lane is on the ego's route), ``branch`` (valid,
on another branch of a fork inside the gap), and the kinds of invalid pairs: ``adjacent``
lane, ``opposite`` direction, ``other_branch`` (a fork the ego's detection has passed),
``behind``, ``other`` (valid by role but farther along the graph than a gap allows)."""

_FALSE_KINDS: Final[Mapping[str, str]] = {"adjacent": "adjacent", "opposite": "opposite", "turn": "other_branch",
                                          "behind": "behind"}


def relation_kind(ego: VehicleState, coop: VehicleState, valid: bool) -> str:
    """The :data:`RELATION_KINDS` entry of a pair whose validity (:func:`lane_relation`) is
    ``valid``: for a valid pair whether the coop's lane is on the ego's route, for an invalid
    one what the coop is (from its role)."""
    if valid:
        return "own" if coop.lane in ego.track.lanes else "branch"
    return _FALSE_KINDS.get(coop.role, "other")
