"""Lanelets ↔ OpenDRIVE lanes, and vehicle routing between OpenDRIVE lanes.

Every lanelet this converter writes carries the tag ``opendrive:lanes``: the OpenDRIVE
lanes it covers, as (road id, 0-based lane-section index, lane id). A lanelet may cover
several lanes (crdesigner joins lanes that continue each other). "Vehicle lanelets" are
the lanelets a vehicle may drive on under lanelet2's German vehicle traffic rules, the
rules of ``routing_graph``: walkways, crosswalks and emergency lanes are not among them.
lanelet2 is imported lazily.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from converters.osm import OPENDRIVE_TAG, parse_opendrive_lanes_tag

if TYPE_CHECKING:
    import lanelet2.core
    import lanelet2.routing
    import lanelet2.traffic_rules

OpenDriveLane = tuple[str, int, int]
"""(road id, 0-based lane-section index, lane id) of one OpenDRIVE lane."""


def opendrive_lanes(lanelet: lanelet2.core.Lanelet) -> tuple[OpenDriveLane, ...]:
    """The OpenDRIVE lanes a lanelet covers, in the order of its ``opendrive:lanes`` tag
    (empty when it has none: a lanelet not written by this converter)."""
    return parse_opendrive_lanes_tag(dict(lanelet.attributes).get(OPENDRIVE_TAG, ""))


def lanelets_by_opendrive_lane(lanelet_map: lanelet2.core.LaneletMap) -> dict[OpenDriveLane, tuple[int, ...]]:
    """OpenDRIVE lane → ids of the lanelets covering it (ascending), over the whole map."""
    index: dict[OpenDriveLane, list[int]] = {}
    for lanelet in lanelet_map.laneletLayer:
        for lane in opendrive_lanes(lanelet):
            index.setdefault(lane, []).append(int(lanelet.id))
    return {lane: tuple(sorted(ids)) for lane, ids in index.items()}


def vehicle_rules() -> lanelet2.traffic_rules.TrafficRules:
    """lanelet2's traffic rules for vehicles in Germany (its default set), as ``routing_graph`` uses."""
    import lanelet2.traffic_rules

    return lanelet2.traffic_rules.create(
        lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
    )


def vehicle_lanelets(lanelet_map: lanelet2.core.LaneletMap) -> list[lanelet2.core.Lanelet]:
    """The lanelets a vehicle may drive on (``vehicle_rules().canPass``), in the map's order."""
    rules = vehicle_rules()
    return [lanelet for lanelet in lanelet_map.laneletLayer if rules.canPass(lanelet)]


def routing_graph(lanelet_map: lanelet2.core.LaneletMap) -> lanelet2.routing.RoutingGraph:
    """lanelet2 routing graph for vehicles (``vehicle_rules``): it holds the vehicle lanelets only."""
    import lanelet2.routing
    import lanelet2.traffic_rules

    return lanelet2.routing.RoutingGraph(lanelet_map, vehicle_rules())


def route_between(
    lanelet_map: lanelet2.core.LaneletMap,
    start: OpenDriveLane,
    goal: OpenDriveLane,
    graph: lanelet2.routing.RoutingGraph | None = None,
) -> tuple[int, ...] | None:
    """Ids of the lanelets of the shortest vehicle route from OpenDRIVE lane ``start`` to
    ``goal`` (both lanelets included, lane changes allowed), or None when there is none.

    ``graph`` is the map's vehicle routing graph (built when None). Raises ValueError
    naming the lane when no vehicle lanelet covers ``start`` or ``goal``.
    """
    graph = graph if graph is not None else routing_graph(lanelet_map)
    index = lanelets_by_opendrive_lane(lanelet_map)
    passable = {int(lanelet.id) for lanelet in vehicle_lanelets(lanelet_map)}
    ends = []
    for name, (road, section, lane_id) in (("start", start), ("goal", goal)):
        covering = index.get((str(road), int(section), int(lane_id)), ())
        ids = [i for i in covering if i in passable]
        if not ids:
            raise ValueError(f"{name} lane (road {road}, section {section}, lane {lane_id}): no vehicle lanelet "
                             f"covers it (lanelets covering it: {list(covering) or 'none'})")
        ends.append([lanelet_map.laneletLayer[i] for i in ids])
    routes = [route for first in ends[0] for last in ends[1] if (route := graph.getRoute(first, last)) is not None]
    if not routes:
        return None
    shortest = min(routes, key=lambda route: route.length2d())
    return tuple(int(lanelet.id) for lanelet in shortest.shortestPath())
