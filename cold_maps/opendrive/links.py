"""Road links and junction connections checked against the geometry (``contactPoint``).

A ``contactPoint`` names the end of the linked (or connecting) road that touches this
road. Some exporters write the wrong end: road 21's successor is road 22 at
``contactPoint="start"`` although road 21's end meets road 22's *end*. A link whose named
end lies farther than ``CONTACT_FAR_M`` from the end it should touch while the other end
lies within ``CONTACT_TOUCH_TOLERANCE_M`` contradicts the geometry: it is repaired (the
other end) with one logged warning per map (-v: one per link), or refused in strict mode.
Links where neither end or both ends touch are left as written.

Ends are reference-line points (inertial frame, m): a road link joins the reference lines
of the two roads; a junction connection joins the connecting road's named end to the end
of the incoming road that links to the junction.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, replace
from typing import Final, Iterable, Mapping

import numpy as np

from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.model import (
    ContactPoint,
    Junction,
    OpenDriveMap,
    Road,
    RoadLink,
)
from cold_maps.opendrive.reference_line import reference_pose

LOG = logging.getLogger("cold_maps.opendrive")

CONTACT_TOUCH_TOLERANCE_M: Final[float] = 0.5
"""The end a link is repaired to must lie this close (m) to the end it joins."""
CONTACT_FAR_M: Final[float] = 2.0
"""The end a link names must lie farther than this (m) for the link to be repaired."""

_OTHER: Final[Mapping[str, ContactPoint]] = {"start": "end", "end": "start"}

Point = tuple[float, float]


@dataclass(frozen=True)
class Contradiction:
    """One link whose ``contactPoint`` contradicts the geometry.

    Fields:
        what: the link, e.g. ``road 21 successor road 22`` or ``junction 9 connection 3
            (incoming road 2, connecting road 30)``.
        written: the contact point in the file.
        named_m: distance (m) from the written end to the end it should touch.
        other_m: distance (m) from the other end to it.
    """

    what: str
    written: ContactPoint
    named_m: float
    other_m: float

    @property
    def repaired(self) -> ContactPoint:
        """The contact point the geometry says."""
        return _OTHER[self.written]

    def describe(self) -> str:
        """One line: the link, what it says and what the geometry says."""
        return (f"{self.what}: contactPoint=\"{self.written}\" is {self.named_m:.2f} m away, the road's "
                f"{self.repaired} touches ({self.other_m:.2f} m)")


def _road_ends(road: Road) -> dict[str, Point]:
    """The reference line's start and end points (inertial frame, m)."""
    x, y, _ = reference_pose(road, np.array([0.0, road.length]))
    return {"start": (float(x[0]), float(y[0])), "end": (float(x[1]), float(y[1]))}


def _check(what: str, written: ContactPoint, targets: Iterable[Point],
           ends: Mapping[str, Point]) -> Contradiction | None:
    """The contradiction when the ``written`` end of a road (``ends``) is far from every
    point of ``targets`` and its other end touches one of them; None otherwise."""
    points = list(targets)
    if not points:
        return None

    def distance(end: str) -> float:
        return min(math.dist(ends[end], point) for point in points)

    named, other = distance(written), distance(_OTHER[written])
    if named > CONTACT_FAR_M and other <= CONTACT_TOUCH_TOLERANCE_M:
        return Contradiction(what, written, named, other)
    return None


def _road_link_contradictions(odr_map: OpenDriveMap, ends: Mapping[str, dict[str, Point]]
                              ) -> dict[tuple[str, str], Contradiction]:
    found = {}
    for road in odr_map.roads.values():
        for side, own_end, link in (("predecessor", "start", road.predecessor), ("successor", "end", road.successor)):
            if link is None or link.element_type != "road" or link.contact_point is None:
                continue
            what = f"road {road.id} {side} road {link.element_id}"
            contradiction = _check(what, link.contact_point, [ends[road.id][own_end]], ends[link.element_id])
            if contradiction is not None:
                found[(road.id, side)] = contradiction
    return found


def _junction_ends(odr_map: OpenDriveMap, ends: Mapping[str, dict[str, Point]], road_id: str,
                   junction_id: str) -> list[Point]:
    """The ends of road ``road_id`` whose road link names junction ``junction_id``."""
    road = odr_map.roads[road_id]
    return [ends[road_id][end] for end, link in (("start", road.predecessor), ("end", road.successor))
            if link is not None and link.element_type == "junction" and link.element_id == junction_id]


def _connection_contradictions(odr_map: OpenDriveMap, ends: Mapping[str, dict[str, Point]]
                               ) -> dict[tuple[str, int], Contradiction]:
    found = {}
    for junction in odr_map.junctions.values():
        for index, connection in enumerate(junction.connections):
            what = (f"junction {junction.id} connection {connection.id} (incoming road {connection.incoming_road}, "
                    f"connecting road {connection.connecting_road})")
            targets = _junction_ends(odr_map, ends, connection.incoming_road, junction.id)
            contradiction = _check(what, connection.contact_point, targets, ends[connection.connecting_road])
            if contradiction is not None:
                found[(junction.id, index)] = contradiction
    return found


def _repaired_junction(junction: Junction, repairs: Mapping[int, Contradiction]) -> Junction:
    connections = tuple(replace(c, contact_point=repairs[i].repaired) if i in repairs else c
                        for i, c in enumerate(junction.connections))
    return replace(junction, connections=connections)


def _repaired_link(link: RoadLink | None, contradiction: Contradiction | None) -> RoadLink | None:
    return link if link is None or contradiction is None else replace(link, contact_point=contradiction.repaired)


def repair_contact_points(odr_map: OpenDriveMap, *, strict: bool = False) -> OpenDriveMap:
    """``odr_map`` with every road link and junction connection whose ``contactPoint``
    contradicts the geometry repaired (one warning with their count on the
    ``cold_maps.opendrive`` logger, an info record each); the same map when none does.
    ``strict``: raises ``OpenDriveError`` naming the first contradicting link (and how many
    there are) instead."""
    ends = {road_id: _road_ends(road) for road_id, road in odr_map.roads.items()}
    road_links = _road_link_contradictions(odr_map, ends)
    connections = _connection_contradictions(odr_map, ends)
    found = [*road_links.values(), *connections.values()]
    if not found:
        return odr_map
    if strict:
        more = f" (and {len(found) - 1} more)" if len(found) > 1 else ""
        raise OpenDriveError(f"{found[0].describe()}{more}; strict mode refuses links that contradict the geometry",
                             path=odr_map.path)
    name = odr_map.path or "<input>"
    for contradiction in found:
        LOG.info("%s: %s; repaired to contactPoint=\"%s\"", name, contradiction.describe(), contradiction.repaired)
    LOG.warning("%s: %d road link(s) or junction connection(s) name a contactPoint the geometry contradicts, "
                "repaired (first: %s; -v lists each)", name, len(found), found[0].describe())
    roads = {road_id: replace(road,
                              predecessor=_repaired_link(road.predecessor, road_links.get((road_id, "predecessor"))),
                              successor=_repaired_link(road.successor, road_links.get((road_id, "successor"))))
             for road_id, road in odr_map.roads.items()}
    junctions = {junction_id: _repaired_junction(junction, {i: c for (j, i), c in connections.items()
                                                            if j == junction_id})
                 for junction_id, junction in odr_map.junctions.items()}
    return replace(odr_map, roads=roads, junctions=junctions)
