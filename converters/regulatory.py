"""Regulatory elements of a converted map, per the Lanelet2 tagging specification
(lanelet2_core/doc/RegulatoryElementTagging.md, LinestringTagging.md).

crdesigner turns OpenDRIVE ``<signal>``s into CommonRoad traffic signs, traffic lights
and intersections and assigns them to lanelets; ``regulations_of`` reads that assignment
into one ``LaneletRegulations`` per lanelet and ``append_regulatory_elements`` writes them:

- speed limit: a real speed sign on the lanelet wins; else the lowest road ``<type>
  <speed>`` of the roads the lanelet covers (``road_speed_limits``; crdesigner's own
  virtual signs for them reach only some lanelets of a road, Town01: 36 of 124, and are
  truncated to mm/s); else a virtual crdesigner sign. Written as ``subtype=speed_limit``
  referring to a ``type=traffic_sign`` line at a real sign, or with the ``sign_type``
  tag when there is no sign (road type); the sign type is the German sign (``de274-50``)
  when the limit is one, else the speed in km/h (``40.2336km/h``), which lanelet2's
  traffic rules read as a velocity;
- traffic light: ``subtype=traffic_light`` referring to ``type=traffic_light``
  (``subtype=red_yellow_green``) lines at the lights, with the lanelet's stop line as
  ``ref_line``. crdesigner also attaches lights of far-away junctions (Town01: 7 of 43
  assignments, 18-267 m from the lanelet's end); a light is kept only within
  ``LIGHT_REACH_M`` of the lanelet's exit and nearer its exit than its entry;
- stop and yield signs: ``subtype=right_of_way`` with the sign (``de206``/``de205``) as
  ``refers``, the lanelet as ``yield``, the other incoming lanelets of its intersection
  that carry no such sign as ``right_of_way``, and the stop line as ``ref_line``; when
  no such lanelet is known (lanelet2 refuses a right_of_way without one), a plain
  ``subtype=traffic_sign`` element with the sign and the stop line.

A stop line is a ``type=stop_line`` way across the lanelet's exit (its last left and
right border nodes).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any, Final

import numpy as np
import numpy.typing as npt
from lxml import etree

NDArrayFloat = npt.NDArray[np.float64]

LIGHT_REACH_M: Final[float] = 10.0
"""A traffic light farther than this (m) from a lanelet's exit does not control it."""

LIGHT_WIDTH_M: Final[float] = 0.5
"""Length (m) of the ``traffic_light`` line drawn at a light, parallel to the stop line."""

SIGN_WIDTH_M: Final[float] = 0.6
"""Length (m) of the ``traffic_sign`` line drawn at a sign, parallel to the stop line."""

KMH_PER_MPS: Final[float] = 3.6

_MPS_PER_UNIT: Final[dict[str, float]] = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}
"""OpenDRIVE speed units (``e_unitSpeed``) in m/s; m/s is the default."""

_GERMAN_LIMITS_KMH: Final[frozenset[int]] = frozenset({5, 10, 15, 20, 30, 40, 50, 60, 70, 80, 90, 100, 110, 120, 130})
"""Speeds with a ``de274-<v>`` sign type in lanelet2's German traffic rules."""

_RIGHT_OF_WAY_SIGNS: Final[dict[str, str]] = {"STOP": "de206", "YIELD": "de205"}
"""CommonRoad sign name → Lanelet2 sign subtype of the signs that make a lanelet yield."""


@dataclass(frozen=True)
class LaneletRegulations:
    """The regulations crdesigner assigned to one lanelet.

    Fields:
        speed_limit_mps: lowest speed limit on the lanelet (m/s), None when none.
        speed_sign: (x, y) of that limit's sign (m, inertial frame), None when the limit
            has no physical sign (road type, virtual sign).
        traffic_lights: (x, y) of each light controlling the lanelet's exit (m).
        yield_sign: "de206" (stop) or "de205" (yield) when the lanelet must give way, "".
        yield_sign_at: (x, y) of that sign (m), None when none.
        priority_lanelets: other incoming lanelets of the lanelet's intersection that
            carry no stop or yield sign (they have the right of way).
    """

    speed_limit_mps: float | None = None
    speed_sign: tuple[float, float] | None = None
    traffic_lights: tuple[tuple[float, float], ...] = ()
    yield_sign: str = ""
    yield_sign_at: tuple[float, float] | None = None
    priority_lanelets: tuple[int, ...] = ()


def road_speed_limits(opendrive: Any) -> dict[str, float]:
    """Road id → lowest ``<type><speed max>`` (m/s) of crdesigner's parsed OpenDRIVE roads
    (roads without a numeric one omitted)."""
    limits = {}
    for road in opendrive.roads:
        speeds = []
        for road_type in road.types:
            speed = road_type.speed
            try:
                value = float(speed.max) * _MPS_PER_UNIT.get(str(speed.unit or "m/s"), 1.0)
            except (AttributeError, TypeError, ValueError):
                continue  # no speed, "no limit", "undefined"
            if np.isfinite(value) and value > 0:
                speeds.append(value)
        if speeds:
            limits[str(road.id)] = min(speeds)
    return limits


def regulations_of(network: Any, road_limits: Mapping[int, float]) -> dict[int, LaneletRegulations]:
    """Per lanelet id, the regulations of a CommonRoad ``LaneletNetwork``, with
    ``road_limits`` the road-type speed limit (m/s) per lanelet id (lanelets without any
    regulation omitted)."""
    signs = {sign.traffic_sign_id: sign for sign in network.traffic_signs}
    lights = {light.traffic_light_id: light for light in network.traffic_lights}
    yielding: dict[int, tuple[str, tuple[float, float]]] = {}
    limits: dict[int, list[tuple[bool, float, tuple[float, float] | None]]] = {}
    for lanelet in network.lanelets:
        for sign_id in sorted(lanelet.traffic_signs):
            sign = signs.get(sign_id)
            if sign is None:
                continue
            position = (float(sign.position[0]), float(sign.position[1]))
            for element in sign.traffic_sign_elements:
                name = element.traffic_sign_element_id.name
                if name == "MAX_SPEED" and element.additional_values and float(element.additional_values[0]) > 0:
                    real = not sign.virtual  # (virtual, speed): real signs sort first, then the lowest
                    entry = (not real, float(element.additional_values[0]), position if real else None)
                    limits.setdefault(lanelet.lanelet_id, []).append(entry)
                elif name in _RIGHT_OF_WAY_SIGNS:
                    yielding[lanelet.lanelet_id] = (_RIGHT_OF_WAY_SIGNS[name], position)
    incoming_groups: dict[int, tuple[int, ...]] = {}
    for intersection in network.intersections:
        incoming = tuple(sorted(i for element in intersection.incomings for i in element.incoming_lanelets))
        for lanelet_id in incoming:
            incoming_groups[lanelet_id] = incoming
    result = {}
    for lanelet in network.lanelets:
        lanelet_id = lanelet.lanelet_id
        centre = np.asarray(lanelet.center_vertices, dtype=np.float64)[:, :2]
        controlling = tuple(
            (float(p[0]), float(p[1]))
            for p in (np.asarray(lights[i].position, dtype=np.float64)[:2] for i in sorted(lanelet.traffic_lights) if i in lights)
            if np.hypot(*(p - centre[-1])) <= min(LIGHT_REACH_M, float(np.hypot(*(p - centre[0]))))
        )
        sign, sign_at = yielding.get(lanelet_id, ("", None))
        priority = tuple(i for i in incoming_groups.get(lanelet_id, ()) if i != lanelet_id and i not in yielding) if sign else ()
        virtual, limit, limit_at = min(limits.get(lanelet_id, [(True, None, None)]), key=lambda e: (e[0], e[1] or 0.0))
        if virtual and lanelet_id in road_limits:
            limit, limit_at = road_limits[lanelet_id], None
        regulations = LaneletRegulations(limit, limit_at, controlling, sign, sign_at, priority)
        if regulations != LaneletRegulations():
            result[lanelet_id] = regulations
    return result


def sign_subtype(speed_mps: float) -> str:
    """Lanelet2 traffic-sign subtype of a speed limit (m/s): ``de274-<v>`` for a German
    limit, else the speed in km/h with its unit (read by lanelet2 as a velocity)."""
    kmh = speed_mps * KMH_PER_MPS
    rounded = round(kmh)
    if abs(kmh - rounded) < 1e-6 and rounded in _GERMAN_LIMITS_KMH:
        return f"de274-{rounded}"
    return f"{kmh:.4f}km/h"


@dataclass(frozen=True)
class LaneletExit:
    """Where a written lanelet ends: its relation and its last border nodes.

    Fields:
        relation: the lanelet's ``<relation>`` element (regulatory members are added to it).
        left_node, right_node: OSM ids of the last node of its left and right border.
        left, right: (3,) x, y, z (m, inertial frame) of those nodes.
    """

    relation: etree._Element
    left_node: int
    right_node: int
    left: NDArrayFloat
    right: NDArrayFloat


NewNode = Callable[[NDArrayFloat], int]
"""Writes a node at (3,) x, y, z (m) and returns its id."""


class _Writer:
    """Appends ways and relations to the OSM root with fresh ids."""

    def __init__(self, root: etree._Element, new_node: NewNode, ids: Iterator[int]) -> None:
        self.root, self.new_node, self.ids = root, new_node, ids

    def way(self, nodes: list[int], tags: Mapping[str, str]) -> int:
        way_id = next(self.ids)
        element = etree.SubElement(self.root, "way", id=str(way_id))
        for node in nodes:
            etree.SubElement(element, "nd", ref=str(node))
        for key, value in tags.items():
            etree.SubElement(element, "tag", k=key, v=value)
        return way_id

    def line_at(self, at: tuple[float, float], exit_: LaneletExit, width: float, tags: Mapping[str, str]) -> int:
        """A short way centred at ``at``, parallel to the lanelet's stop line, at its height."""
        across = exit_.left[:2] - exit_.right[:2]
        direction = across / max(float(np.hypot(*across)), 1e-9)
        z = 0.5 * (exit_.left[2] + exit_.right[2])
        centre = np.array([at[0], at[1]])
        ends = [np.append(centre + sign * 0.5 * width * direction, z) for sign in (-1.0, 1.0)]
        return self.way([self.new_node(end) for end in ends], tags)

    def regulatory_element(self, members: list[tuple[str, str, int]], tags: Mapping[str, str]) -> int:
        relation_id = next(self.ids)
        element = etree.SubElement(self.root, "relation", id=str(relation_id))
        for kind, role, ref in members:
            etree.SubElement(element, "member", type=kind, role=role, ref=str(ref))
        etree.SubElement(element, "tag", k="type", v="regulatory_element")
        for key, value in tags.items():
            etree.SubElement(element, "tag", k=key, v=value)
        return relation_id


def append_regulatory_elements(
    root: etree._Element,
    regulations: Mapping[int, LaneletRegulations],
    exits: Mapping[int, LaneletExit],
    new_node: NewNode,
    ids: Iterator[int],
) -> None:
    """Write the regulatory elements of every lanelet in ``regulations`` that was written
    (``exits``), their signs, lights and stop lines, and reference them from the lanelets."""
    writer = _Writer(root, new_node, ids)
    for lanelet_id, rules in regulations.items():
        exit_ = exits.get(lanelet_id)
        if exit_ is None:
            continue
        elements = []
        if rules.speed_limit_mps is not None:
            sign_type = sign_subtype(rules.speed_limit_mps)
            if rules.speed_sign is None:
                elements.append(writer.regulatory_element([], {"subtype": "speed_limit", "sign_type": sign_type}))
            else:
                sign_tags = {"type": "traffic_sign", "subtype": sign_type}
                sign = writer.line_at(rules.speed_sign, exit_, SIGN_WIDTH_M, sign_tags)
                elements.append(writer.regulatory_element([("way", "refers", sign)], {"subtype": "speed_limit"}))
        stop_line = None
        if rules.traffic_lights or rules.yield_sign:
            stop_line = writer.way([exit_.left_node, exit_.right_node], {"type": "stop_line"})
        if rules.traffic_lights and stop_line is not None:
            light_tags = {"type": "traffic_light", "subtype": "red_yellow_green"}
            members = [("way", "refers", writer.line_at(at, exit_, LIGHT_WIDTH_M, light_tags)) for at in rules.traffic_lights]
            members.append(("way", "ref_line", stop_line))
            elements.append(writer.regulatory_element(members, {"subtype": "traffic_light"}))
        if rules.yield_sign and rules.yield_sign_at is not None and stop_line is not None:
            sign = writer.line_at(rules.yield_sign_at, exit_, SIGN_WIDTH_M, {"type": "traffic_sign", "subtype": rules.yield_sign})
            members = [("way", "refers", sign), ("way", "ref_line", stop_line)]
            priority = [("relation", "right_of_way", other) for other in rules.priority_lanelets if other in exits]
            if priority:
                members += [("relation", "yield", lanelet_id), *priority]
            elements.append(writer.regulatory_element(members, {"subtype": "right_of_way" if priority else "traffic_sign"}))
        for element in elements:
            etree.SubElement(exit_.relation, "member", type="relation", role="regulatory_element", ref=str(element))
