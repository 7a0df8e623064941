"""Ramp lanes (OpenDRIVE types offRamp, connectingRamp, ...) are vehicle lanes: the lane
graph drives them, the converter gives them ground truth and ``check`` compares them."""

from __future__ import annotations

from typing import Final

import pytest
from adversarial_maps import LANE_WIDTH_M, LaneSpec, RoadSpec, SectionSpec, _arc_end, document, geometry, road_link

from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.opendrive.model import VEHICLE_LANE_TYPES
from cold_maps.opendrive.parser import parse_opendrive

ROADS: Final[tuple[tuple[str, str], ...]] = (("1", "driving"), ("2", "offRamp"), ("3", "connectingRamp"))
"""Road id and the type of its one lane (-1), chained 1 → 2 → 3."""
LENGTH_M: Final[float] = 60.0
CURVATURE_PER_M: Final[float] = 0.01


def ramp_map() -> str:
    """A straight 60 m driving road, then a 60 m offRamp arc, then a 60 m connectingRamp line."""
    roads, x, y, hdg = [], 0.0, 0.0, 0.0
    for index, (road_id, lane_type) in enumerate(ROADS):
        curvature = CURVATURE_PER_M if index == 1 else 0.0
        shape = f'<arc curvature="{curvature!r}"/>' if curvature else "<line/>"
        links = (road_link("predecessor", "road", ROADS[index - 1][0], "end") if index else "",
                 road_link("successor", "road", ROADS[index + 1][0], "start") if index + 1 < len(ROADS) else "")
        lane = LaneSpec(-1, type=lane_type, predecessor=-1 if index else None,
                        successor=-1 if index + 1 < len(ROADS) else None)
        roads.append(RoadSpec(road_id, (geometry(0.0, x, y, hdg, LENGTH_M, shape),), LENGTH_M,
                              (SectionSpec(0.0, (lane,)),), predecessor=links[0], successor=links[1]))
        x, y, hdg = _arc_end(x, y, hdg, LENGTH_M, curvature)
    return document(roads, name="ramps")


def _lanes() -> list[LaneKey]:
    return [LaneKey(road_id, 0, -1) for road_id, _ in ROADS]


def test_the_lane_graph_drives_from_a_driving_lane_onto_the_ramps() -> None:
    graph = build_lane_graph(parse_opendrive(ramp_map().encode()))
    lanes = _lanes()
    assert set(graph.lanes) == set(lanes)
    assert sorted(graph.edges()) == [(lanes[0], lanes[1]), (lanes[1], lanes[2])]
    outer_arc_m = LENGTH_M * (1.0 + CURVATURE_PER_M * LANE_WIDTH_M / 2.0)  # the right lane's centre, outside
    assert sum(graph.lengths.values()) == pytest.approx(2 * LENGTH_M + outer_arc_m, abs=0.01)
    driving_only = build_lane_graph(parse_opendrive(ramp_map().encode()), ("driving",))
    assert driving_only.lanes == (lanes[0],) and not list(driving_only.edges())
    assert {"offRamp", "connectingRamp"} <= set(VEHICLE_LANE_TYPES)


def test_ramps_get_ground_truth_that_matches_the_engine(tmp_path) -> None:
    from cold_maps.groundtruth.check import check_map

    path = tmp_path / "ramps.xodr"
    path.write_text(ramp_map())
    report = check_map(path, cache=False, converter="crdesigner")
    assert report.trustworthy
    assert sorted((lane.road_id, lane.lane_id) for lane in report.lanes) == [(road_id, -1) for road_id, _ in ROADS]
    assert all(lane.matched_by == "id" for lane in report.lanes)


def test_a_map_without_vehicle_lanes_names_the_types_it_looked_for() -> None:
    import numpy as np

    from cold_maps.simulation.drive import DriveError, covering_routes

    sidewalks = ramp_map()
    for _, lane_type in ROADS:
        sidewalks = sidewalks.replace(f'type="{lane_type}"', 'type="sidewalk"')
    graph = build_lane_graph(parse_opendrive(sidewalks.encode()))
    with pytest.raises(DriveError, match=r"no driving lanes \(of types driving, entry, exit, onRamp, offRamp, "
                                         r"connectingRamp, slipLane\)"):
        covering_routes(graph, 1, 10.0, np.random.default_rng(0))
