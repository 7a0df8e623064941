"""What the engine's Lanelet2 ground truth needs beyond the lane geometry, read from the
OpenDRIVE file: road types (``<road><type>``) and the regulations of each lane
(``converters.regulatory.LaneletRegulations``, written by ``converters.regulatory``):

- speed limit: a ``<signal type="274">`` (German speed-limit sign, its ``value`` in its
  ``unit``, km/h when absent) on the lanes of its road section driving in its
  ``orientation`` ("+" along s, "-" against, else both) wins; else the road's lowest
  ``<type><speed max>``;
- traffic lights: every ``<signal>`` of a traffic-light type (``TRAFFIC_LIGHT_TYPES``)
  controls the vehicle lanes that lead into a junction and
  whose exit lies within ``converters.regulatory.LIGHT_REACH_M`` of the light and nearer
  than their entry (the rule the crdesigner path applies to crdesigner's assignment;
  ``orientation``, ``<validity>`` and ``<signalReference>`` are not read);
- stop and yield signs (``<signal type="206">`` / ``"205"``): the same lanes near the
  sign yield; the other lanes leading into the same junction without such a sign have
  the right of way.

Signal positions are the engine's road → world transform of (s, t).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from lxml import etree

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.lanes import section_borders
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, OpenDriveMap
from cold_maps.opendrive.xml_safety import parse_xml
from converters.regulatory import LIGHT_REACH_M, LaneletRegulations

MPS_PER_SPEED_UNIT: Final[dict[str, float]] = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}
"""OpenDRIVE speed units (``e_unitSpeed``) in m/s; m/s when absent."""


@dataclass(frozen=True)
class RoadRules:
    """Road types and lane regulations of a map.

    Fields:
        road_types: road id → its ``<type>`` records as (s in m, type), ordered by s.
        speed_limits_mps: road id → lowest ``<speed max>`` of its types (m/s); roads
            without a numeric one are omitted.
        regulations: per lane (of the lane graph) the regulations the writer adds;
            lanes without any omitted (their ``priority_lanelets`` empty: see ``priority``).
        priority: per lane with a stop or yield sign, the other lanes into its junction
            without one (they have the right of way; lanelet ids are given by the builder).
    """

    road_types: Mapping[str, tuple[tuple[float, str], ...]] = field(default_factory=dict)
    speed_limits_mps: Mapping[str, float] = field(default_factory=dict)
    regulations: Mapping[LaneKey, LaneletRegulations] = field(default_factory=dict)
    priority: Mapping[LaneKey, tuple[LaneKey, ...]] = field(default_factory=dict)


def _number(text: str | None) -> float:
    """A finite float from an attribute, NaN when absent or not a number."""
    try:
        value = float(text or "nan")
    except ValueError:
        return float("nan")
    return value if np.isfinite(value) else float("nan")


def _types_and_speeds(root: etree._Element) -> tuple[dict[str, tuple[tuple[float, str], ...]], dict[str, float]]:
    types: dict[str, tuple[tuple[float, str], ...]] = {}
    speeds: dict[str, float] = {}
    for road in root.iterfind("{*}road"):
        road_id = road.get("id", "")
        records = []
        limits = []
        for element in road.iterfind("{*}type"):
            start = _number(element.get("s"))
            records.append((0.0 if np.isnan(start) else start, element.get("type", "")))
            speed = element.find("{*}speed")
            if speed is not None:
                value = _number(speed.get("max")) * MPS_PER_SPEED_UNIT.get(speed.get("unit", "m/s"), 1.0)
                if value > 0.0:
                    limits.append(value)
        types[road_id] = tuple(sorted(records))
        if limits:
            speeds[road_id] = min(limits)
    return types, speeds


TRAFFIC_LIGHT_TYPES: Final[frozenset[str]] = frozenset({"1000001", "1000002", "1000007", "1000008", "1000009",
                                                       "1000010", "1000011", "1000012", "1000013"})
"""``<signal type>`` values of traffic lights (German catalogue, as ASAM's OpenDRIVE
signal examples and the CARLA towns use them)."""

RIGHT_OF_WAY_SIGNS: Final[dict[str, str]] = {"206": "de206", "205": "de205"}
"""``<signal type>`` of stop and yield signs → Lanelet2 sign subtype."""

SPEED_SIGN_TYPE: Final[str] = "274"
"""``<signal type>`` of a speed-limit sign."""


@dataclass(frozen=True)
class Signal:
    """One ``<signal>`` the ground truth uses.

    Fields:
        road_id: its road.
        s: station along the road (m).
        xy: (x, y) position (m, inertial frame).
        type: the ``type`` attribute.
        orientation: "+", "-" or "none".
        speed_mps: the limit of a speed sign (m/s), None otherwise.
    """

    road_id: str
    s: float
    xy: tuple[float, float]
    type: str
    orientation: str
    speed_mps: float | None = None


def _signals(root: etree._Element, odr_map: OpenDriveMap) -> list[Signal]:
    """The signals of known roads with finite s and t (clamped onto their road)."""
    from cold_maps.opendrive.sampling import road_to_world

    found = []
    for road_element in root.iterfind("{*}road"):
        road = odr_map.roads.get(road_element.get("id", ""))
        if road is None:
            continue
        for element in road_element.iterfind("{*}signals/{*}signal"):
            s, t = _number(element.get("s")), _number(element.get("t"))
            if np.isnan(s) or np.isnan(t):
                continue
            s = min(max(s, 0.0), road.length)
            x, y = road_to_world(road, np.array([s]), np.array([t]))
            kind = element.get("type", "")
            speed = None
            if kind == SPEED_SIGN_TYPE:
                value = _number(element.get("value")) * MPS_PER_SPEED_UNIT.get(element.get("unit", "km/h"), 1.0 / 3.6)
                speed = value if value > 0.0 else None
            found.append(Signal(road.id, s, (float(x[0]), float(y[0])), kind, element.get("orientation", "none"), speed))
    return found


def _lane_ends(graph: LaneGraph, lane: LaneKey) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(x, y) of the lane's centre at its entry and at its exit (m)."""
    from cold_maps.opendrive.sampling import road_to_world

    road = graph.odr_map.roads[lane.road_id]
    section = road.lane_sections[lane.section]
    entry, exit_ = graph.entry_s(lane), graph.exit_s(lane)
    stations = np.array([entry, exit_])
    borders = section_borders(road, lane.section, np.clip(stations, section.s, section.s_end))[lane.lane_id]
    x, y = road_to_world(road, stations, 0.5 * (borders[0] + borders[1]))
    return np.array([x[0], y[0]]), np.array([x[1], y[1]])


def _junction_entries(graph: LaneGraph) -> dict[LaneKey, str]:
    """Vehicle lanes outside junctions whose successors lie in a junction → that junction's id."""
    roads = graph.odr_map.roads
    entries = {}
    for lane, nexts in graph.successors.items():
        road = roads[lane.road_id]
        if road.junction != "-1" or road.lane_sections[lane.section].lane(lane.lane_id).type not in VEHICLE_LANE_TYPES:
            continue
        junctions = {roads[n.road_id].junction for n in nexts} - {"-1"}
        if junctions:
            entries[lane] = min(junctions)
    return entries


def _controlled(at: tuple[float, float], entries: Mapping[LaneKey, str],
                ends: Mapping[LaneKey, tuple[NDArrayFloat, NDArrayFloat]]) -> list[LaneKey]:
    """The junction entries whose exit lies within ``LIGHT_REACH_M`` of ``at`` and nearer than their entry."""
    point = np.asarray(at)
    return [lane for lane in entries
            if np.hypot(*(ends[lane][1] - point)) <= min(LIGHT_REACH_M, float(np.hypot(*(ends[lane][0] - point))))]


def _sign_lanes(graph: LaneGraph, signal: Signal) -> list[LaneKey]:
    """The lanes of the signal's road section at its s driving in its orientation."""
    road = graph.odr_map.roads[signal.road_id]
    lanes = []
    for lane in graph.lanes:
        section = road.lane_sections[lane.section] if lane.road_id == road.id else None
        if section is None or not section.s <= signal.s <= section.s_end:
            continue
        along = road.drives_along_s(lane.lane_id, lane.section)
        if signal.orientation == "none" or along == (signal.orientation == "+"):
            lanes.append(lane)
    return lanes


def read_road_rules(odr_map: OpenDriveMap, graph: LaneGraph) -> RoadRules:
    """The road types and regulations of ``odr_map`` (read again from its file; an
    in-memory map has none), for the lanes of ``graph`` (module docstring)."""
    if not odr_map.path:
        return RoadRules()
    root = parse_xml(Path(odr_map.path).read_bytes(), path=odr_map.path)
    types, speeds = _types_and_speeds(root)
    signals = _signals(root, odr_map)
    entries = _junction_entries(graph)
    ends = {lane: _lane_ends(graph, lane) for lane in entries} if signals else {}
    limits: dict[LaneKey, tuple[float, tuple[float, float] | None]] = {
        lane: (speeds[lane.road_id], None) for lane in graph.lanes if lane.road_id in speeds}
    lights: dict[LaneKey, list[tuple[float, float]]] = {}
    yielding: dict[LaneKey, tuple[str, tuple[float, float]]] = {}
    signed: dict[LaneKey, float] = {}
    for signal in signals:
        if signal.speed_mps is not None:
            for lane in _sign_lanes(graph, signal):
                if lane not in signed or signal.speed_mps < signed[lane]:
                    signed[lane] = signal.speed_mps
                    limits[lane] = (signal.speed_mps, signal.xy)
        elif signal.type in TRAFFIC_LIGHT_TYPES:
            for lane in _controlled(signal.xy, entries, ends):
                lights.setdefault(lane, []).append(signal.xy)
        elif signal.type in RIGHT_OF_WAY_SIGNS:
            for lane in _controlled(signal.xy, entries, ends):
                yielding[lane] = (RIGHT_OF_WAY_SIGNS[signal.type], signal.xy)
    regulations = {}
    for lane in graph.lanes:
        limit, limit_at = limits.get(lane, (None, None))
        sign, sign_at = yielding.get(lane, ("", None))
        rules = LaneletRegulations(limit, limit_at, tuple(lights.get(lane, ())), sign, sign_at)
        if rules != LaneletRegulations():
            regulations[lane] = rules
    priorities = {lane: tuple(other for other, junction in entries.items()
                              if junction == entries[lane] and other != lane and other not in yielding)
                  for lane in yielding if lane in entries}
    return RoadRules(types, speeds, regulations, priorities)
