"""What the engine's Lanelet2 ground truth needs beyond the lane geometry, read from the
OpenDRIVE file: road types (``<road><type>``) and the regulations of each lane
(``converters.regulatory.LaneletRegulations``): the road's lowest ``<speed max>``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Final

import numpy as np
from lxml import etree

from cold_maps.network.lane_graph import LaneGraph, LaneKey
from cold_maps.opendrive.model import OpenDriveMap
from cold_maps.opendrive.xml_safety import parse_xml
from converters.regulatory import LaneletRegulations

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
            lanes without any omitted.
    """

    road_types: Mapping[str, tuple[tuple[float, str], ...]] = field(default_factory=dict)
    speed_limits_mps: Mapping[str, float] = field(default_factory=dict)
    regulations: Mapping[LaneKey, LaneletRegulations] = field(default_factory=dict)


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


def read_road_rules(odr_map: OpenDriveMap, graph: LaneGraph) -> RoadRules:
    """The road types and regulations of ``odr_map`` (read again from its file; an
    in-memory map has none), for the lanes of ``graph``."""
    if not odr_map.path:
        return RoadRules()
    root = parse_xml(Path(odr_map.path).read_bytes(), path=odr_map.path)
    types, speeds = _types_and_speeds(root)
    regulations = {
        lane: LaneletRegulations(speed_limit_mps=speeds[lane.road_id]) for lane in graph.lanes if lane.road_id in speeds
    }
    return RoadRules(types, speeds, regulations)
