"""Lane-level graph of an OpenDRIVE map, directed in the driving direction.

A node is one lane of one lane section (``LaneKey``). An edge ``a → b`` means a vehicle
driving along lane ``a`` continues into lane ``b``. Edges come from three sources, each
read as an undirected contact between two lane *ends* (the end at the section start or
at the section end):

- lane links between successive sections of one road (falling back to the same lane id
  when neither side names a link);
- road-to-road links (``<predecessor>``/``<successor>`` with a contact point) and their
  lane links, read from both roads, so a link written on one side only still counts;
- junction connections: incoming road lane → connecting-road lane at the connection's
  contact point (the connecting road then leaves through its own road link).

A contact becomes an edge from the lane whose *exit* end touches it (the section end when
the lane drives along s, see ``Road.drives_along_s``) to the lane whose *entry* end
touches it. This one rule covers both orientations of a linked road, both sides of a road
and right- and left-hand traffic. Contacts joining two exits or two entries, and links
that name missing roads, junctions or lanes, are reported in ``LaneGraph.issues``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Final, Iterator, Literal, Mapping, NamedTuple, Sequence

import numpy as np

from cold_maps.opendrive.model import VEHICLE_LANE_TYPES, ContactPoint, OpenDriveMap, Road, RoadLink

LENGTH_STEP_M: Final[float] = 0.5
"""Sampling step (m) of the lane centrelines whose polyline lengths weigh the graph."""

_End = Literal["start", "end"]


class LaneKey(NamedTuple):
    """One lane of one lane section.

    Fields:
        road_id: id of the road.
        section: 0-based index of the lane section in the road.
        lane_id: OpenDRIVE lane id (> 0 left of the reference line, < 0 right).
    """

    road_id: str
    section: int
    lane_id: int


class _LaneEnd(NamedTuple):
    """One end of a lane: at its section's start or at its section's end."""

    lane: LaneKey
    end: _End


@dataclass(frozen=True)
class LaneGraph:
    """Directed lane graph in the driving direction.

    Fields:
        odr_map: the map the graph was built from.
        lane_types: OpenDRIVE lane types included as nodes.
        lengths: node → length of the lane's centreline polyline (m, world frame; NaN when
            built without measuring them, ``build_lane_graph(length_step=None)``).
        successors: node → lanes a vehicle can drive into from its end, sorted.
        predecessors: node → lanes from which a vehicle drives into it, sorted.
        issues: human-readable reports of links that name missing roads, junctions or
            lanes, and of contacts that join two lane exits or two lane entries.
    """

    odr_map: OpenDriveMap
    lane_types: tuple[str, ...]
    lengths: Mapping[LaneKey, float]
    successors: Mapping[LaneKey, tuple[LaneKey, ...]]
    predecessors: Mapping[LaneKey, tuple[LaneKey, ...]]
    issues: tuple[str, ...]

    def __repr__(self) -> str:
        return (
            f"LaneGraph({self.odr_map.path or '<input>'}: {len(self.lengths)} lanes of types "
            f"{self.lane_types}, {sum(map(len, self.successors.values()))} edges, "
            f"{len(self.issues)} issues)"
        )

    @property
    def lanes(self) -> tuple[LaneKey, ...]:
        """All nodes, in map order (roads in file order, sections, lanes left to right)."""
        return tuple(self.lengths)

    def edges(self) -> Iterator[tuple[LaneKey, LaneKey]]:
        """Every edge (from, to)."""
        for lane, nexts in self.successors.items():
            for nxt in nexts:
                yield lane, nxt

    def entry_s(self, lane: LaneKey) -> float:
        """Road s (m) where traffic enters the lane."""
        return self._section_ends(lane)[0]

    def exit_s(self, lane: LaneKey) -> float:
        """Road s (m) where traffic leaves the lane."""
        return self._section_ends(lane)[1]

    def _section_ends(self, lane: LaneKey) -> tuple[float, float]:
        road = self.odr_map.roads[lane.road_id]
        section = road.lane_sections[lane.section]
        if road.drives_along_s(lane.lane_id, lane.section):
            return section.s, section.s_end
        return section.s_end, section.s


def build_lane_graph(
    odr_map: OpenDriveMap,
    lane_types: Sequence[str] | None = VEHICLE_LANE_TYPES,
    *,
    length_step: float | None = LENGTH_STEP_M,
) -> LaneGraph:
    """Build the lane graph of ``odr_map`` over the lanes of ``lane_types`` (None → all).

    Lane lengths are the lengths of the centreline polylines sampled every
    ``length_step`` metres (the chord error on a curve of radius R is about
    L·step²/(24·R²)); ``length_step`` None: not measured (every length NaN), for a
    caller that needs the lanes and their links only.
    """
    if length_step is not None and not length_step > 0:
        raise ValueError(f"length_step must be > 0 m, got {length_step!r}")
    types = None if lane_types is None else tuple(lane_types)
    nodes = _nodes(odr_map, types)
    issues: list[str] = []
    contacts = _section_contacts(odr_map, nodes, issues)
    contacts |= _road_link_contacts(odr_map, nodes, issues)
    contacts |= _junction_contacts(odr_map, nodes, issues)
    successors: dict[LaneKey, set[LaneKey]] = {lane: set() for lane in nodes}
    predecessors: dict[LaneKey, set[LaneKey]] = {lane: set() for lane in nodes}
    for a, b in sorted(contacts):
        a_exit, b_exit = _is_exit(odr_map, a), _is_exit(odr_map, b)
        if a_exit == b_exit:
            kind = "exits" if a_exit else "entries"
            issues.append(f"contact joins two lane {kind}: {_describe(a)} and {_describe(b)}")
            continue
        src, dst = (a.lane, b.lane) if a_exit else (b.lane, a.lane)
        successors[src].add(dst)
        predecessors[dst].add(src)
    return LaneGraph(
        odr_map=odr_map,
        lane_types=types if types is not None else tuple(sorted(set(nodes.values()))),
        lengths=MappingProxyType(dict.fromkeys(nodes, math.nan) if length_step is None
                                 else _lane_lengths(odr_map, nodes, types, length_step)),
        successors=MappingProxyType({k: tuple(sorted(v)) for k, v in successors.items()}),
        predecessors=MappingProxyType({k: tuple(sorted(v)) for k, v in predecessors.items()}),
        issues=tuple(issues),
    )


def _nodes(odr_map: OpenDriveMap, types: tuple[str, ...] | None) -> dict[LaneKey, str]:
    """Lane key → lane type of every included lane, in map order."""
    nodes: dict[LaneKey, str] = {}
    for road in odr_map.roads.values():
        for index, section in enumerate(road.lane_sections):
            for lane in section.lanes:
                if types is None or lane.type in types:
                    nodes[LaneKey(road.id, index, lane.id)] = lane.type
    return nodes


def _is_exit(odr_map: OpenDriveMap, lane_end: _LaneEnd) -> bool:
    forward = odr_map.roads[lane_end.lane.road_id].drives_along_s(lane_end.lane.lane_id, lane_end.lane.section)
    return (lane_end.end == "end") == forward


def _describe(lane_end: _LaneEnd) -> str:
    road_id, section, lane_id = lane_end.lane
    return f"road {road_id} section {section} lane {lane_id} ({lane_end.end})"


def _contact(a: _LaneEnd, b: _LaneEnd) -> tuple[_LaneEnd, _LaneEnd]:
    """Contacts are undirected: store each pair in one canonical order."""
    return (a, b) if a <= b else (b, a)


def _section_contacts(
    odr_map: OpenDriveMap, nodes: Mapping[LaneKey, str], issues: list[str]
) -> set[tuple[_LaneEnd, _LaneEnd]]:
    """Contacts between successive lane sections of each road; a lane link naming a lane
    the other section lacks is reported in ``issues`` (and the lanes fall back to same-id
    contacts)."""
    contacts: set[tuple[_LaneEnd, _LaneEnd]] = set()
    for road in odr_map.roads.values():
        for index in range(len(road.lane_sections) - 1):
            before, after = road.lane_sections[index], road.lane_sections[index + 1]
            before_ids = {lane.id for lane in before.lanes}
            after_ids = {lane.id for lane in after.lanes}
            pairs = {(lane.id, to) for lane in before.lanes for to in lane.successors}
            pairs |= {(frm, lane.id) for lane in after.lanes for frm in lane.predecessors}
            for a, b in sorted(pairs):
                if b not in after_ids:
                    issues.append(f"road {road.id} section {index} lane {a}: successor lane {b} is not in section "
                                  f"{index + 1}")
                elif a not in before_ids:
                    issues.append(f"road {road.id} section {index + 1} lane {b}: predecessor lane {a} is not in "
                                  f"section {index}")
            pairs = {(a, b) for a, b in pairs if a in before_ids and b in after_ids}
            linked_before = {a for a, _ in pairs}
            linked_after = {b for _, b in pairs}
            pairs |= {
                (lane_id, lane_id)
                for lane_id in before_ids & after_ids
                if lane_id not in linked_before and lane_id not in linked_after
            }
            for a, b in pairs:
                key_a, key_b = LaneKey(road.id, index, a), LaneKey(road.id, index + 1, b)
                if key_a in nodes and key_b in nodes:
                    contacts.add(_contact(_LaneEnd(key_a, "end"), _LaneEnd(key_b, "start")))
    return contacts


def _section_at(road: Road, end: ContactPoint) -> int:
    return 0 if end == "start" else len(road.lane_sections) - 1


def _road_link_contacts(
    odr_map: OpenDriveMap, nodes: Mapping[LaneKey, str], issues: list[str]
) -> set[tuple[_LaneEnd, _LaneEnd]]:
    """Contacts of road-to-road links and their lane links."""
    contacts: set[tuple[_LaneEnd, _LaneEnd]] = set()
    for road in odr_map.roads.values():
        for own_end, link in (("start", road.predecessor), ("end", road.successor)):
            if link is None or link.element_type != "road" or not road.lane_sections:
                continue
            where = f"road {road.id} {'predecessor' if own_end == 'start' else 'successor'}"
            other = odr_map.roads.get(link.element_id)
            if other is None:
                issues.append(f"{where}: road {link.element_id} does not exist")
                continue
            if link.contact_point is None or not other.lane_sections:
                issues.append(f"{where}: road {link.element_id} has no contact point or lanes")
                continue
            own_index = _section_at(road, own_end)
            other_index = _section_at(other, link.contact_point)
            other_section = other.lane_sections[other_index]
            for lane in road.lane_sections[own_index].lanes:
                linked = lane.predecessors if own_end == "start" else lane.successors
                for to in linked:
                    try:
                        other_section.lane(to)
                    except KeyError:
                        issues.append(
                            f"{where}: lane {lane.id} links to lane {to}, which road "
                            f"{other.id} does not have at its {link.contact_point}"
                        )
                        continue
                    key_a = LaneKey(road.id, own_index, lane.id)
                    key_b = LaneKey(other.id, other_index, to)
                    if key_a in nodes and key_b in nodes:
                        contacts.add(
                            _contact(
                                _LaneEnd(key_a, own_end), _LaneEnd(key_b, link.contact_point)
                            )
                        )
    return contacts


def _incoming_end(
    junction_id: str, incoming: Road, connecting: Road, contact: str
) -> ContactPoint | None:
    """End of the incoming road that touches the junction, or None when unknown.

    The connecting road's own link at ``contact`` names it best; otherwise the incoming
    road's link to the junction (only when exactly one of its ends links there).
    """
    link = connecting.predecessor if contact == "start" else connecting.successor
    if link is not None and link.element_type == "road" and link.element_id == incoming.id:
        return link.contact_point
    ends: list[ContactPoint] = []
    if _links_junction(incoming.predecessor, junction_id):
        ends.append("start")
    if _links_junction(incoming.successor, junction_id):
        ends.append("end")
    return ends[0] if len(ends) == 1 else None


def _links_junction(link: RoadLink | None, junction_id: str) -> bool:
    return link is not None and link.element_type == "junction" and link.element_id == junction_id


def _junction_contacts(
    odr_map: OpenDriveMap, nodes: Mapping[LaneKey, str], issues: list[str]
) -> set[tuple[_LaneEnd, _LaneEnd]]:
    """Contacts of junction connections: incoming lane ↔ connecting-road lane."""
    contacts: set[tuple[_LaneEnd, _LaneEnd]] = set()
    for road in odr_map.roads.values():
        for link in (road.predecessor, road.successor):
            if link is not None and link.element_type == "junction":
                if link.element_id not in odr_map.junctions:
                    issues.append(f"road {road.id}: junction {link.element_id} does not exist")
    for junction in odr_map.junctions.values():
        for conn in junction.connections:
            where = f"junction {junction.id} connection {conn.id}"
            incoming = odr_map.roads.get(conn.incoming_road)
            connecting = odr_map.roads.get(conn.connecting_road)
            if incoming is None or connecting is None:
                missing = conn.incoming_road if incoming is None else conn.connecting_road
                issues.append(f"{where}: road {missing} does not exist")
                continue
            if not incoming.lane_sections or not connecting.lane_sections:
                issues.append(f"{where}: a road without lane sections")
                continue
            in_end = _incoming_end(junction.id, incoming, connecting, conn.contact_point)
            if in_end is None:
                issues.append(
                    f"{where}: cannot tell which end of road {incoming.id} meets the junction"
                )
                continue
            in_index = _section_at(incoming, in_end)
            conn_index = _section_at(connecting, conn.contact_point)
            for lane_link in conn.lane_links:
                key_a = LaneKey(incoming.id, in_index, lane_link.from_lane)
                key_b = LaneKey(connecting.id, conn_index, lane_link.to_lane)
                missing_lanes = [
                    key
                    for key, road in ((key_a, incoming), (key_b, connecting))
                    if not _has_lane(road, key)
                ]
                if missing_lanes:
                    issues.append(
                        f"{where}: lane link {lane_link.from_lane} → {lane_link.to_lane}: "
                        + ", ".join(f"road {k.road_id} has no lane {k.lane_id}" for k in missing_lanes)
                    )
                    continue
                if key_a in nodes and key_b in nodes:
                    contacts.add(
                        _contact(_LaneEnd(key_a, in_end), _LaneEnd(key_b, conn.contact_point))
                    )
    return contacts


def _has_lane(road: Road, key: LaneKey) -> bool:
    try:
        road.lane_sections[key.section].lane(key.lane_id)
    except KeyError:
        return False
    return key.lane_id != 0


def _lane_lengths(
    odr_map: OpenDriveMap,
    nodes: Mapping[LaneKey, str],
    types: tuple[str, ...] | None,
    step: float,
) -> dict[LaneKey, float]:
    """Centreline polyline length (m) of every node, sampled every ``step`` metres."""
    from cold_maps.opendrive.sampling import sample_road

    lengths: dict[LaneKey, float] = {}
    for road in odr_map.roads.values():
        for samples in sample_road(road, step=step, lane_types=types):
            key = LaneKey(road.id, samples.section, samples.lane_id)
            if key in nodes:
                centre = 0.5 * (samples.inner[:, :2] + samples.outer[:, :2])
                lengths[key] = float(np.linalg.norm(np.diff(centre, axis=0), axis=1).sum())
    return {key: lengths[key] for key in nodes}


def load_graph(path: Path) -> LaneGraph:
    """The driving-lane graph of an OpenDRIVE file (OpenDriveError when unreadable)."""
    from cold_maps.opendrive.parser import load_opendrive

    return build_lane_graph(load_opendrive(path))
