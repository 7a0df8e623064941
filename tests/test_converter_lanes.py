"""converters.lanes: lanelet ↔ OpenDRIVE lane, vehicle lanelets, vehicle routes between
OpenDRIVE lanes, checked against the map engine (bundled junction; the small 1.8 map
for a walkway and an emergency lane)."""

from __future__ import annotations

from itertools import product
from pathlib import Path

import numpy as np
import pytest
from conftest import bundled_map

import converters
from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.network.route import lane_borders
from cold_maps.opendrive import load_opendrive

SMALL_MAP = Path(__file__).parent / "data" / "small_1_8.xodr"
ARMS = ("1", "2", "3", "4")
"""Roads of the junction's four arms (the others are its connecting roads)."""


@pytest.fixture(scope="module")
def junction():
    path = bundled_map("junction")
    lanelet_map, graph = converters.load_lanelet2(path)
    return build_lane_graph(load_opendrive(path)), lanelet_map, graph


@pytest.fixture(scope="module")
def small():
    return converters.load_lanelet2(SMALL_MAP)


def test_every_junction_lanelet_is_one_engine_lane_with_its_borders(junction) -> None:
    lane_graph, lanelet_map, _ = junction
    index = converters.lanelets_by_opendrive_lane(lanelet_map)
    assert set(index) == set(lane_graph.lengths)  # every driving lane, nothing else
    for lane, ids in index.items():
        assert len(ids) == 1
        lanelet = lanelet_map.laneletLayer[ids[0]]
        assert converters.opendrive_lanes(lanelet) == (lane,)
        borders = lane_borders(lane_graph.odr_map, lane)
        for bound, points in ((lanelet.leftBound, borders.left), (lanelet.rightBound, borders.right)):
            ends = np.array([[bound[0].x, bound[0].y], [bound[-1].x, bound[-1].y]])
            np.testing.assert_allclose(ends, points[[0, -1], :2], atol=1e-3)


def test_vehicle_lanelets_leave_out_the_walkway_and_the_emergency_lane(small) -> None:
    lanelet_map, graph = small
    vehicle = {int(lanelet.id) for lanelet in converters.vehicle_lanelets(lanelet_map)}
    index = converters.lanelets_by_opendrive_lane(lanelet_map)
    left_out = {converters.opendrive_lanes(lanelet_map.laneletLayer[i])[0]: lanelet_map.laneletLayer[i]
                for i in {int(lanelet.id) for lanelet in lanelet_map.laneletLayer} - vehicle}
    assert sorted(left_out) == [("1", 1, -2), ("1", 1, 2)]
    assert {dict(lanelet.attributes)["subtype"] for lanelet in left_out.values()} == {"walkway", "emergency_lane"}
    assert vehicle == {index[lane][0] for lane in (("1", 1, 1), ("1", 1, -1), ("2", 0, -1), ("3", 0, -1))}
    # the routing graph load_lanelet2 returns is the vehicles' graph: it holds these lanelets only
    assert {int(lanelet.id) for lanelet in graph.passableLaneletSubmap().laneletLayer} == vehicle


def _engine_reaches(lane_graph, start: LaneKey, goal: LaneKey) -> bool:
    seen, todo = {start}, [start]
    while todo:
        lane = todo.pop()
        for after in lane_graph.successors[lane]:
            if after not in seen:
                seen.add(after)
                todo.append(after)
    return goal in seen


def test_routes_between_the_arms_follow_the_engine_lane_graph(junction) -> None:
    lane_graph, lanelet_map, graph = junction
    arms = [lane for lane in lane_graph.lengths if lane.road_id in ARMS]
    assert len(arms) == 8
    routes = 0
    for start, goal in product(arms, arms):
        ids = converters.route_between(lanelet_map, start, goal, graph)
        assert (ids is not None) == (start == goal or _engine_reaches(lane_graph, start, goal)), (start, goal)
        if ids is None:
            continue
        routes += 1
        lanes = [LaneKey(*converters.opendrive_lanes(lanelet_map.laneletLayer[i])[0]) for i in ids]
        assert lanes[0] == start and lanes[-1] == goal
        assert all(after in lane_graph.successors[before] for before, after in zip(lanes, lanes[1:]))
    assert routes == 8 + 4 * 3  # itself, and from each of the four lanes entering to the three other arms


def test_a_route_without_a_vehicle_lanelet_at_an_end_is_refused(small) -> None:
    lanelet_map, _ = small
    with pytest.raises(ValueError, match=r"start lane \(road 1, section 1, lane 2\): no vehicle lanelet"):
        converters.route_between(lanelet_map, ("1", 1, 2), ("1", 1, -1))
    with pytest.raises(ValueError, match=r"goal lane \(road 9, section 0, lane -1\): .*covering it: none"):
        converters.route_between(lanelet_map, ("1", 1, -1), ("9", 0, -1))
