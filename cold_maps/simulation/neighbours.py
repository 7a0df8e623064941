"""Multi-lane sensing: the lanes beside a track, and where the road edge lies.

The k-th lane to the left (``+k``) or right (``-k``, driving direction) of a track lane is
the lane k positions over in the same lane section when it and every lane between are
driving lanes of the lane graph driven the same way; the first lane that is not (a
shoulder, a sidewalk, the opposite direction, nothing) ends the side, and the outer border
of the last lane before it is the *road edge*. A *branch* is a lane that leaves the track's
lane at a fork inside the detection window (another successor than the track's), seen
from the fork to the end of the window. Neighbour borders are sampled on the same
s grid as the track's own lane (0.1 m of s), so every sample carries the track station of
its cross-section; detections are resampled every ``step_m`` of their own arc length,
world frame (OpenDRIVE inertial), m.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.network.lane_strip import NDArrayFloat, resample_polyline
from cold_maps.network.route import borders_in_driving_direction
from cold_maps.opendrive.sampling import sample_lane_borders
from gt_matching.polyline import arc_lengths

from cold_maps.simulation.drive import Track


def neighbour_key(graph: LaneGraph, lane: LaneKey, offset: int) -> LaneKey | None:
    """The lane ``offset`` positions left (> 0) or right (< 0) of ``lane`` in its lane
    section, driving direction, or None when a lane on the way (or that one) is not a
    driving lane of ``graph`` driven the same way."""
    road = graph.odr_map.roads[lane.road_id]
    own = road.drives_along_s(lane.lane_id, lane.section)
    step = (1 if own else -1) * (1 if offset > 0 else -1)
    lane_id = lane.lane_id
    for _ in range(abs(offset)):
        lane_id += step
        if lane_id == 0:
            lane_id += step
        key = LaneKey(lane.road_id, lane.section, lane_id)
        if key not in graph.lengths or road.drives_along_s(lane_id, lane.section) != own:
            return None
    return key


@dataclass(frozen=True)
class SideLane:
    """The lanes at one offset beside a track, concatenated in driving order.

    Fields:
        station: (M,) track station of each sample's cross-section (m).
        left, right: (M, 2) the neighbour's borders, world frame (m).
        lane_index: (M,) index of the track lane each sample lies beside.
        joined: (M,) whether a sample continues the one before it on the same neighbour
            lane or its graph successor (False at the first sample of every run).
    """

    station: NDArrayFloat
    left: NDArrayFloat
    right: NDArrayFloat
    lane_index: np.ndarray
    joined: np.ndarray


@dataclass(frozen=True)
class NeighbourReading:
    """One neighbour lane seen in one detection window (world frame, m).

    Fields: ``index`` (+k left, -k right); ``left``, ``right`` its borders every ``step_m``;
    ``at_start``, ``at_end`` whether it exists at the window's first / last cross-section.
    """

    index: int
    left: NDArrayFloat
    right: NDArrayFloat
    at_start: bool
    at_end: bool


class NeighbourSensor:
    """The neighbour lanes of tracks of one lane graph, up to ``count`` on each side.

    Side lanes are built once per track (cached by its lanes).
    """

    def __init__(self, graph: LaneGraph, count: int) -> None:
        if count < 1:
            raise ValueError(f"neighbour lanes: expected at least 1 per side, got {count!r}")
        self.graph, self.count = graph, count
        self._cache: dict[tuple[LaneKey, ...], tuple[dict[int, tuple[LaneKey | None, ...]], dict[int, SideLane]]] = {}
        self._branch_tracks: dict[LaneKey, Track] = {}

    def _sides(self, track: Track) -> tuple[dict[int, tuple[LaneKey | None, ...]], dict[int, SideLane]]:
        cached = self._cache.get(track.lanes)
        if cached is not None:
            return cached
        graph = self.graph
        offsets = [k for n in range(1, self.count + 2) for k in (n, -n)]
        keys = {k: tuple(neighbour_key(graph, lane, k) for lane in track.lanes) for k in offsets}
        sides = {}
        for k in offsets:
            if abs(k) <= self.count and any(key is not None for key in keys[k]):
                sides[k] = self._side(track, keys[k])
        self._cache[track.lanes] = (keys, sides)
        return keys, sides

    def _side(self, track: Track, keys: tuple[LaneKey | None, ...]) -> SideLane:
        parts: list[tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]] = []
        previous: LaneKey | None = None
        for index, (own, key) in enumerate(zip(track.lanes, keys)):
            if key is None:
                previous = None
                continue
            road = self.graph.odr_map.roads[own.road_id]
            _, own_left, own_right = borders_in_driving_direction(road, sample_lane_borders(road, own.section,
                                                                                          own.lane_id))
            _, left, right = borders_in_driving_direction(road, sample_lane_borders(road, key.section, key.lane_id))
            centre = arc_lengths(0.5 * (own_left[:, :2] + own_right[:, :2]))
            start, end = track.lane_starts[index], track.lane_starts[index + 1]
            station = start + centre * ((end - start) / centre[-1])
            joined = np.ones(len(station), dtype=bool)
            joined[0] = previous is not None and key in self.graph.successors[previous]
            parts.append((station, left[:, :2], right[:, :2], np.full(len(station), index), joined))
            previous = key
        station, left, right, lane_index, joined = (np.concatenate(column) for column in zip(*parts))
        return SideLane(station, left, right, lane_index, joined)

    def _edge(self, keys: dict[int, tuple[LaneKey | None, ...]], lane_index: int, sign: int) -> int | None:
        """Index of the lane whose outer border on side ``sign`` is the road edge beside track
        lane ``lane_index``; None when it lies beyond the ``count`` lanes the sensor sees."""
        edge = 0
        while keys[sign * (edge + 1)][lane_index] is not None:
            edge += 1
            if edge > self.count:
                return None
        return sign * edge

    def _branch_track(self, lane: LaneKey, length_m: float) -> Track:
        """A track from ``lane`` on along first successors, at least ``length_m`` long where
        the graph allows (cached per lane)."""
        track = self._branch_tracks.get(lane)
        if track is None:
            lanes, total = [lane], self.graph.lengths[lane]
            while total < length_m and self.graph.successors[lanes[-1]] and len(lanes) < len(self.graph.lengths):
                lanes.append(self.graph.successors[lanes[-1]][0])
                total += self.graph.lengths[lanes[-1]]
            track = self._branch_tracks[lane] = Track.build(self.graph, lanes)
        return track

    def branches(self, track: Track, station: float, range_m: float, step_m: float) -> list[tuple[NDArrayFloat, NDArrayFloat]]:
        """Left and right borders (world frame, m, every ``step_m``) of the lanes that leave
        the track's lane at a fork between ``station`` and ``range_m`` ahead, from the fork to
        the end of that window."""
        end = min(station + range_m, track.length)
        found = []
        for index, (lane, following) in enumerate(zip(track.lanes, track.lanes[1:])):
            fork = float(track.lane_starts[index + 1])
            if not station < fork < end - step_m:
                continue
            for other in self.graph.successors[lane]:
                if other == following:
                    continue
                branch = self._branch_track(other, range_m)
                left, right = branch.borders_between(0.0, min(end - fork, branch.length))
                found.append((_resampled(left, step_m), _resampled(right, step_m)))
        return found

    def detect(self, track: Track, station: float, range_m: float,
               step_m: float) -> tuple[list[NeighbourReading], tuple[int | None, int | None, int | None, int | None]]:
        """The neighbour lanes seen from ``station`` (m) over ``range_m`` ahead of the track,
        and the road edges ``(start_left, start_right, end_left, end_right)`` (lane index, see
        :class:`fusion.RoadEdges`). A neighbour that comes and goes in the window is its
        longest unbroken stretch."""
        keys, sides = self._sides(track)
        end = min(station + range_m, track.length)
        first, last = track.lane_at(station)[0], track.lane_at(max(end - 1e-6, station))[0]
        readings = []
        for k, side in sides.items():
            inside = np.flatnonzero((side.station >= station) & (side.station <= end))
            if inside.size < 2:
                continue
            breaks = np.flatnonzero((np.diff(inside) != 1) | ~side.joined[inside[1:]]) + 1
            run = max(np.split(inside, breaks), key=len)
            if run.size < 2:
                continue
            borders = [_resampled(points, step_m) for points in (side.left[run], side.right[run])]
            lanes = set(side.lane_index[run].tolist())
            readings.append(NeighbourReading(k, borders[0], borders[1], first in lanes and keys[k][first] is not None,
                                             last in lanes and keys[k][last] is not None))
        edges = (self._edge(keys, first, 1), self._edge(keys, first, -1), self._edge(keys, last, 1),
                 self._edge(keys, last, -1))
        return readings, edges


def _resampled(points: NDArrayFloat, step_m: float) -> NDArrayFloat:
    """A polyline resampled every ``step_m`` of its own arc length (m), both ends kept."""
    distance = arc_lengths(points)
    return resample_polyline(points, distance, 0.0, float(distance[-1]), step_m)
