"""Lanelet2 output per the tagging specification: regulatory elements that plain lanelet2
traffic rules read, ele on nodes, two-way walkways, consistent location, validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from converters import frame
from converters.api import convert
from converters.crdesigner_bridge import SourceLanelet
from converters.osm import build_osm
from converters.regulatory import LaneletRegulations, sign_subtype
from converters.validation import outside_namespaces, validate_osm

LENGTH_M, WIDTH_M = 20.0, 3.5


def straight(lanelet_id: int, x0: float, y0: float, **fields: object) -> SourceLanelet:
    """A straight lanelet along +x from (x0, y0), 3.5 m wide, on a crest: z = 2 + 0.1·x·(1 - x / 40) m."""
    x = np.linspace(x0, x0 + LENGTH_M, 5)
    z = 2.0 + 0.1 * (x - x0) * (1.0 - (x - x0) / (2 * LENGTH_M))
    left = np.column_stack((x, np.full_like(x, y0 + WIDTH_M / 2)))
    right = np.column_stack((x, np.full_like(x, y0 - WIDTH_M / 2)))
    return SourceLanelet(lanelet_id, left, right, frozenset({"urban"}), left_z=z, right_z=z, **fields)  # type: ignore[arg-type]


def rules(participant: str):
    import lanelet2.traffic_rules as tr

    return tr.create(tr.Locations.Germany, getattr(tr.Participants, participant))


def load(path: Path):
    import lanelet2.io

    return lanelet2.io.load(str(path), frame.projector())


@pytest.mark.parametrize(("speed_kmh", "subtype"), [(50.0, "de274-50"), (30.0, "de274-30"), (40.2336, "40.2336km/h")])
def test_speed_limit_sign_type_is_read_by_the_german_rules(tmp_path: Path, speed_kmh: float, subtype: str) -> None:
    assert sign_subtype(speed_kmh / 3.6) == subtype
    regulations = LaneletRegulations(speed_limit_mps=speed_kmh / 3.6, speed_sign=(5.0, -3.0))
    path = tmp_path / "speed.osm"
    path.write_bytes(build_osm([straight(1, 0.0, 0.0, regulations=regulations)]))
    lanelet = load(path).laneletLayer[1]
    assert rules("Vehicle").speedLimit(lanelet).speedLimit == pytest.approx(speed_kmh, abs=1e-6)


def test_traffic_light_stop_line_and_right_of_way(tmp_path: Path) -> None:
    light = LaneletRegulations(traffic_lights=((LENGTH_M + 1.0, -3.0),))
    sign = LaneletRegulations(yield_sign="de206", yield_sign_at=(LENGTH_M, 8.0), priority_lanelets=(1,))
    path = tmp_path / "junction.osm"
    path.write_bytes(build_osm([straight(1, 0.0, 0.0, regulations=light), straight(2, 0.0, 10.0, regulations=sign)]))
    lanelet_map = load(path)
    (traffic_light,) = lanelet_map.laneletLayer[1].trafficLights()
    stop_line = traffic_light.stopLine
    ends = sorted((round(p.x, 6), round(p.y, 6), round(p.z, 6)) for p in stop_line)
    assert ends == [(LENGTH_M, -WIDTH_M / 2, 3.0), (LENGTH_M, WIDTH_M / 2, 3.0)]  # across the lanelet's exit
    (bulb,) = traffic_light.trafficLights
    centre = np.mean([(p.x, p.y) for p in bulb], axis=0)
    np.testing.assert_allclose(centre, (LENGTH_M + 1.0, -3.0), atol=1e-6)
    (right_of_way,) = lanelet_map.laneletLayer[2].rightOfWay()
    assert [ll.id for ll in right_of_way.yieldLanelets()] == [2]
    assert [ll.id for ll in right_of_way.rightOfWayLanelets()] == [1]
    assert right_of_way.parameters["refers"][0].attributes["subtype"] == "de206"
    bounds = lanelet_map.laneletLayer[2].leftBound, lanelet_map.laneletLayer[2].rightBound
    exit_ids = [bound[len(bound) - 1].id for bound in bounds]
    assert [p.id for p in right_of_way.stopLine] == exit_ids
    assert outside_namespaces(validate_osm(path)) == []


def test_nodes_carry_ele_and_walkways_are_two_way(tmp_path: Path) -> None:
    walk = SourceLanelet(
        3, straight(3, 0, 0).left, straight(3, 0, 0).right, frozenset({"sidewalk"}),
        left_z=np.full(5, 1.25), right_z=np.full(5, 1.25),
    )  # fmt: skip
    path = tmp_path / "walk.osm"
    path.write_bytes(build_osm([walk, straight(4, 0.0, 10.0)]))
    root = etree.parse(str(path)).getroot()
    nodes = root.findall("node")
    assert all(node.find("tag[@k='ele']") is not None for node in nodes)
    lanelet_map = load(path)
    sidewalk, road = lanelet_map.laneletLayer[3], lanelet_map.laneletLayer[4]
    assert {p.z for p in sidewalk.leftBound} == {1.25}
    assert [round(p.z, 6) for p in road.leftBound] == [2.0, 2.4375, 2.75, 2.9375, 3.0]
    pedestrian, vehicle = rules("Pedestrian"), rules("Vehicle")
    assert pedestrian.canPass(sidewalk) and pedestrian.canPass(sidewalk.invert())
    assert vehicle.canPass(road) and not vehicle.canPass(road.invert()) and not vehicle.canPass(sidewalk)


# -- CARLA towns -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def town01_osm(town01_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("town01") / "Town01.osm"
    convert(town01_path, out)
    return out


def _speed_roads(xodr: Path) -> dict[str, float]:
    """Road id → max speed (km/h) of the roads whose <type> carries a <speed>."""
    speeds = {}
    for road in etree.parse(str(xodr)).getroot().iter("road"):
        speed = road.find("type/speed")
        if speed is not None:
            factor = {"mph": 1.609344, "km/h": 1.0, "m/s": 3.6}[speed.get("unit", "m/s")]
            speeds[road.get("id")] = float(speed.get("max")) * factor
    return speeds


def test_town01_validates_and_tags_per_specification(town01_osm: Path) -> None:
    issues = validate_osm(town01_osm)
    assert issues  # the namespaced extension tags are reported as unknown, and nothing else
    assert outside_namespaces(issues) == []
    lanelet_map = load(town01_osm)
    walkways = [ll for ll in lanelet_map.laneletLayer if ll.attributes["subtype"] == "walkway"]
    assert walkways and all(ll.attributes["one_way"] == "no" for ll in walkways)
    pedestrian = rules("Pedestrian")
    assert all(pedestrian.canPass(ll) and pedestrian.canPass(ll.invert()) for ll in walkways)
    assert {ll.attributes["location"] for ll in lanelet_map.laneletLayer} == {"urban"}


def test_town01_speed_limits_traffic_lights_and_routing_across_junctions(town01_path: Path, town01_osm: Path) -> None:
    import lanelet2.routing

    lanelet_map = load(town01_osm)
    vehicle = rules("Vehicle")
    speeds = _speed_roads(town01_path)
    checked = 0
    for lanelet in lanelet_map.laneletLayer:
        roads = {item.split(":")[0] for item in lanelet.attributes["opendrive:lanes"].split(";")} if "opendrive:lanes" in lanelet.attributes else set()
        if lanelet.attributes["subtype"] == "road" and roads and roads <= set(speeds):
            expected = min(speeds[r] for r in roads)  # crdesigner truncates to mm/s: 0.0036 km/h
            assert vehicle.speedLimit(lanelet).speedLimit == pytest.approx(expected, abs=0.004)
            checked += 1
    assert checked > 0
    lit = [ll for ll in lanelet_map.laneletLayer if ll.trafficLights()]
    assert len(lit) >= 30
    graph = lanelet2.routing.RoutingGraph(lanelet_map, vehicle)
    crossed = 0
    for lanelet in lit:
        for inside in graph.following(lanelet):
            assert "intersection" in inside.attributes["commonroad:types"]
            for beyond in graph.following(inside):
                route = graph.shortestPath(lanelet, beyond)
                assert [ll.id for ll in route] == [lanelet.id, inside.id, beyond.id]
                crossed += 1
    assert crossed >= len(lit)


def test_town04_every_node_carries_the_map_elevation(town04_path: Path, tmp_path: Path) -> None:
    from cold_maps.opendrive.parser import load_opendrive
    from cold_maps.opendrive.sampling import sample_road
    from scipy.spatial import cKDTree

    out = tmp_path / "Town04.osm"
    convert(town04_path, out)
    nodes = etree.parse(str(out)).getroot().findall("node")
    ele = [node.find("tag[@k='ele']") for node in nodes]
    assert all(tag is not None for tag in ele)
    heights = np.array([float(tag.get("v")) for tag in ele])
    assert np.ptp(heights) > 1.0  # Town04 is not flat
    lanelet_map = load(out)
    odr_map = load_opendrive(town04_path)
    ours = np.vstack([
        border for road in odr_map.roads.values() for samples in sample_road(road, step=0.2, lane_types=None)
        for border in (samples.inner, samples.outer)
    ])  # fmt: skip
    points = np.array([(p.x, p.y, p.z) for p in lanelet_map.pointLayer if "ele" not in p.attributes])
    distance, index = cKDTree(ours[:, :2]).query(points[:, :2])
    near = distance < 0.15  # on a border, within 0.1 m along it of one of our samples
    dz = np.abs(points[near, 2] - ours[index[near], 2])
    assert near.mean() > 0.9
    assert np.percentile(dz, 99) < 0.02  # measured 6.2 mm (the rest: bridges over other roads)


def test_yield_sign_without_a_priority_lanelet_is_a_plain_traffic_sign(tmp_path: Path) -> None:
    sign = LaneletRegulations(yield_sign="de205", yield_sign_at=(LENGTH_M, 3.0))
    path = tmp_path / "alone.osm"
    path.write_bytes(build_osm([straight(1, 0.0, 0.0, regulations=sign)]))
    (element,) = load(path).laneletLayer[1].regulatoryElements
    assert element.attributes["subtype"] == "traffic_sign"
    assert element.parameters["refers"][0].attributes["subtype"] == "de205"
    assert outside_namespaces(validate_osm(path)) == []
