"""The Lanelet2 ground truth built from the map engine (``groundtruth.lanelet2_from_engine``):
borders equal to ``cold-maps export`` within the chord tolerance, every lane-graph edge a
routing successor, adjacency, heights, line types, cache and the converter option."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.groundtruth.check import check_lanelet_map, check_map
from cold_maps.groundtruth.lanelet2_from_engine import (
    CHORD_TOLERANCE_M,
    END_VERTEX_M,
    adaptive_section_samples,
    engine_converter,
)
from cold_maps.network.lane_graph import build_lane_graph
from cold_maps.opendrive.parser import load_opendrive, parse_opendrive
from converters import load_lanelet2
from converters.osm import SIMPLIFY_TOLERANCE_M
from tests.conftest import bundled_map, carla_map, load_tool
from tests.gap_maps import branch_gap_map

AGREEMENT_M = 1e-3
"""The issue's bound: the engine's Lanelet2 borders agree with the export within 1 mm."""


def _engine_gt(path: Path):
    odr_map = load_opendrive(path)
    lanelet_map, routing = load_lanelet2(path, cache=False, converter=engine_converter(odr_map))
    return odr_map, lanelet_map, routing


@pytest.mark.parametrize("name", ["straight", "curve90", "rural", "junction", "highway"])
def test_engine_borders_agree_with_the_export_and_every_edge_is_a_successor(name) -> None:
    odr_map, lanelet_map, routing = _engine_gt(bundled_map(name))
    report = check_lanelet_map(odr_map, lanelet_map, routing_graph=routing)
    assert report.lanes and all(lane.matched_by == "id" for lane in report.lanes)
    # exact closest-point distances of the export's points (every 0.1 m and record ends)
    assert max(lane.max_m for lane in report.lanes) <= CHORD_TOLERANCE_M + SIMPLIFY_TOLERANCE_M < AGREEMENT_M
    assert report.disconnected == () and report.edges == sum(1 for _ in build_lane_graph(odr_map).edges())


ARC_RADIUS_M = 25.0
LANE_WIDTH_M = 3.5


def _arc_map(radius: float, elevation: str = "") -> str:
    length = 0.5 * math.pi * radius
    return (
        '<?xml version="1.0"?><OpenDRIVE><header revMajor="1" revMinor="6"/>'
        f'<road id="7" length="{length!r}" junction="-1"><link/>'
        f'<planView><geometry s="0" x="0" y="0" hdg="0" length="{length!r}"><arc curvature="{1.0 / radius!r}"/>'
        f"</geometry></planView>{elevation}"
        '<lanes><laneSection s="0"><left><lane id="1" type="driving">'
        f'<width sOffset="0" a="{LANE_WIDTH_M}" b="0" c="0" d="0"/>'
        '<roadMark sOffset="0" type="solid" weight="bold"/></lane></left>'
        '<center><lane id="0" type="none"><roadMark sOffset="0" type="solid broken"/></lane></center><right>'
        f'<lane id="-1" type="driving"><width sOffset="0" a="{LANE_WIDTH_M}" b="0" c="0" d="0"/>'
        '<roadMark sOffset="0" type="broken"/></lane>'
        f'<lane id="-2" type="driving"><width sOffset="0" a="{LANE_WIDTH_M}" b="0" c="0" d="0"/></lane>'
        "</right></laneSection></lanes></road></OpenDRIVE>"
    )


def test_arc_borders_lie_on_their_circles_within_the_chord_tolerance(tmp_path) -> None:
    path = tmp_path / "arc.xodr"
    path.write_text(_arc_map(ARC_RADIUS_M))
    _, lanelet_map, _ = _engine_gt(path)
    centre = np.array([0.0, ARC_RADIUS_M])
    radii = {ARC_RADIUS_M - LANE_WIDTH_M, ARC_RADIUS_M, ARC_RADIUS_M + LANE_WIDTH_M, ARC_RADIUS_M + 2 * LANE_WIDTH_M}
    for line in lanelet_map.lineStringLayer:
        xy = np.array([(p.x, p.y) for p in line])
        distance = np.hypot(*(xy - centre).T)
        radius = min(radii, key=lambda r: abs(r - distance[0]))
        np.testing.assert_allclose(distance, radius, atol=1e-9)  # every vertex on the border
        angles = np.abs(np.diff(np.unwrap(np.arctan2(*(xy - centre).T[::-1]))))
        sagitta = radius * (1.0 - np.cos(0.5 * angles))  # chord error of each segment, closed form
        assert sagitta.max() <= CHORD_TOLERANCE_M + SIMPLIFY_TOLERANCE_M
        # adaptive, not dense: a chord of the tolerance's length, within a factor four
        assert len(xy) - 1 <= 4 * math.ceil(0.5 * math.pi / (2.0 * math.acos(1.0 - CHORD_TOLERANCE_M / radius)))


def test_neighbours_share_one_way_and_are_adjacent_for_routing(tmp_path) -> None:
    path = tmp_path / "arc.xodr"
    path.write_text(_arc_map(ARC_RADIUS_M))
    _, lanelet_map, routing = _engine_gt(path)
    by_lane = {dict(ll.attributes)["opendrive:lanes"]: ll for ll in lanelet_map.laneletLayer}
    inner, outer = by_lane["7:0:-1"], by_lane["7:0:-2"]
    assert inner.rightBound.id == outer.leftBound.id
    assert routing.right(inner).id == outer.id  # a broken line: lane change allowed
    opposite = by_lane["7:0:1"]
    assert opposite.leftBound.id == inner.leftBound.id  # the centre line, shared in reverse


def test_road_marks_become_lanelet2_line_types(tmp_path) -> None:
    path = tmp_path / "arc.xodr"
    path.write_text(_arc_map(ARC_RADIUS_M))
    _, lanelet_map, _ = _engine_gt(path)
    by_lane = {dict(ll.attributes)["opendrive:lanes"]: ll for ll in lanelet_map.laneletLayer}

    def tags(line) -> tuple[str, str]:
        attributes = dict(line.attributes)
        return attributes["type"], attributes.get("subtype", "")

    lane_m1, lane_m2, lane_1 = by_lane["7:0:-1"], by_lane["7:0:-2"], by_lane["7:0:1"]
    assert tags(lane_m1.rightBound) == ("line_thin", "dashed")
    assert tags(lane_1.rightBound) == ("line_thick", "solid")  # bold; lane 1 drives against s
    # "solid broken": solid nearer the reference line, i.e. on the left of lane -1 (along +s)
    centre = lane_m1.leftBound
    subtype = tags(centre)[1]
    assert subtype == ("dashed_solid" if centre.inverted() else "solid_dashed")
    # lane -2's outer border is unpainted with no lane beyond: the road's edge
    assert tags(lane_m2.rightBound) == ("road_border", "")


def test_nodes_carry_the_engines_heights(tmp_path) -> None:
    path = tmp_path / "arc.xodr"
    path.write_text(_arc_map(ARC_RADIUS_M, '<elevationProfile><elevation s="0" a="2" b="0.05" c="0" d="0"/>'
                                           "</elevationProfile>"))
    _, lanelet_map, _ = _engine_gt(path)
    for point in lanelet_map.pointLayer:
        # z = 2 + 0.05 s, and s along the reference circle is the angle about the centre times R
        s = ARC_RADIUS_M * math.atan2(point.x, ARC_RADIUS_M - point.y)
        assert point.z == pytest.approx(2.0 + 0.05 * s, abs=1e-4)


@pytest.mark.parametrize("gap_m", [0.02, 0.8])
def test_linked_ends_across_a_gap_become_successors_and_the_snap_fades_at_the_end_vertex(tmp_path, gap_m) -> None:
    path = tmp_path / "branch.xodr"
    path.write_text(branch_gap_map(gap_m))
    odr_map, lanelet_map, routing = _engine_gt(path)
    report = check_lanelet_map(odr_map, lanelet_map, routing_graph=routing)
    assert report.disconnected == () and report.edges == 3
    named = {dict(ll.attributes)["opendrive:lanes"]: ll for ll in lanelet_map.laneletLayer}
    incoming, straight, arc = named["1:0:-1"], named["2:0:-1"], named["3:0:-1"]
    # roads 1 and 3 end / start on one node (y = 0 and -3.5), road 2 gap_m higher: joined midway
    for side, y in (("leftBound", 0.0), ("rightBound", -LANE_WIDTH_M)):
        end = getattr(incoming, side)[-1]
        assert getattr(straight, side)[0].id == getattr(arc, side)[0].id == end.id
        assert (end.x, end.y) == pytest.approx((40.0, y + gap_m / 2.0), abs=1e-9)
    assert max(lane.max_m for lane in report.lanes) <= gap_m / 2.0 + 1e-9
    # past END_VERTEX_M from the joined end the straight's borders are exact again
    for bound, y in ((straight.leftBound, gap_m), (straight.rightBound, gap_m - LANE_WIDTH_M)):
        xy = np.array([(p.x, p.y) for p in bound])
        beyond = xy[:, 0] >= 40.0 + END_VERTEX_M - 1e-9
        assert beyond.sum() >= 2 and np.allclose(xy[beyond, 1], y, atol=1e-9)


def test_adaptive_sampling_refines_where_the_chord_leaves_the_border() -> None:
    odr_map = parse_opendrive(_arc_map(ARC_RADIUS_M).encode())
    road = odr_map.roads["7"]
    coarse = adaptive_section_samples(road, 0, [-1], tolerance_m=0.05)[0]
    fine = adaptive_section_samples(road, 0, [-1], tolerance_m=CHORD_TOLERANCE_M)[0]
    assert len(fine.s) > 4 * len(coarse.s)  # sagitta ~ step²: 100x tighter → ~10x more stations
    assert np.all(np.diff(fine.s) > 0)


def test_engine_and_crdesigner_are_cached_apart(tmp_path) -> None:
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named

    cache = tmp_path / "cache"
    path = bundled_map("straight")
    for name in ("engine", "crdesigner"):
        load_lanelet2(path, cache_dir=cache, converter=converter_named(name))
    names = sorted(entry.name for entry in cache.iterdir())
    assert len(names) == 2 and any("-engine" in n for n in names) and any("-crdesigner" in n for n in names)
    with pytest.raises(ValueError, match="unknown ground-truth converter 'lanelet'"):
        converter_named("lanelet")


def test_check_defaults_to_the_engine_and_cross_checks_crdesigner(tmp_path) -> None:
    from cold_maps.groundtruth.check import cross_check, format_cross_check

    path = bundled_map("junction")
    engine = check_map(path, cache=False)
    assert engine.trustworthy and max(lane.max_m for lane in engine.lanes) < AGREEMENT_M
    result = cross_check(path, cache=False)
    assert result.crdesigner is not None and result.exit_code == 0
    assert len(result.between) == len(engine.lanes) and all(lane.lanelet_id is not None for lane in result.between)
    # both measure the same borders: crdesigner's distance to ours bounds the two maps' distance
    worst = max(lane.max_m for lane in result.between)
    assert worst <= max(lane.max_m for lane in result.crdesigner.lanes) + CHORD_TOLERANCE_M + 0.1**2 / 8.0
    assert "engine and crdesigner: AGREE" in format_cross_check(result)


def test_routing_and_matching_work_on_the_engine_gt() -> None:
    from lanelet2.matching import Object2d, Pose2d, getDeterministicMatches

    odr_map, lanelet_map, routing = _engine_gt(bundled_map("junction"))
    graph = build_lane_graph(odr_map)
    (a, b), *_ = list(graph.edges())
    named = {dict(ll.attributes)["opendrive:lanes"]: ll for ll in lanelet_map.laneletLayer}
    start, goal = named[f"{a.road_id}:{a.section}:{a.lane_id}"], named[f"{b.road_id}:{b.section}:{b.lane_id}"]
    route = routing.getRoute(start, goal)
    assert route is not None and route.shortestPath()[-1].id == goal.id
    centre = np.array([(p.x, p.y) for p in start.centerline])[len(start.centerline) // 2]
    heading = math.atan2(*(np.array([(p.y, p.x) for p in start.centerline])[-1] - [centre[1], centre[0]]))
    obj = Object2d()
    obj.pose = Pose2d(float(centre[0]), float(centre[1]), heading)
    matches = getDeterministicMatches(lanelet_map, obj, 0.5)
    assert start.id in {m.lanelet.id for m in matches}


def _with_signals(text: str, road_id: str, signals: str) -> str:
    """``text`` with ``signals`` (``<signal>`` elements) added to road ``road_id``."""
    from lxml import etree

    root = etree.fromstring(text.encode())
    road = next(r for r in root.iter("road") if r.get("id") == road_id)
    holder = etree.SubElement(road, "signals")
    for signal in etree.fromstring(f"<s>{signals}</s>"):
        holder.append(signal)
    return etree.tostring(root).decode()


def test_signals_become_regulatory_elements_on_the_lanes_they_govern(tmp_path) -> None:
    import lanelet2.traffic_rules as tr
    from lanelet2.core import RightOfWay, SpeedLimit, TrafficLight

    text = bundled_map("junction").read_text()
    # road 1's lane 1 and road 3's lane -1 drive into the junction (road 1 leaves it along +s)
    text = _with_signals(text, "1", '<signal id="s1" s="1" t="5" type="1000001" dynamic="yes" orientation="-"/>')
    text = _with_signals(text, "3", '<signal id="s2" s="149" t="-5" type="206" dynamic="no" orientation="+"/>')
    text = _with_signals(text, "2", '<signal id="s3" s="80" t="-5" type="274" value="30" unit="km/h" '
                                    'dynamic="no" orientation="-"/>')
    path = tmp_path / "signals.xodr"
    path.write_text(text)
    _, lanelet_map, _ = _engine_gt(path)
    named = {dict(ll.attributes)["opendrive:lanes"]: ll for ll in lanelet_map.laneletLayer}

    def elements(lane: str, kind: type) -> list:
        return [r for r in named[lane].regulatoryElements if isinstance(r, kind)]

    (light,) = elements("1:0:1", TrafficLight)
    stop_line = [(p.x, p.y) for p in light.stopLine]
    exit_ = [(b[-1].x, b[-1].y) for b in (named["1:0:1"].leftBound, named["1:0:1"].rightBound)]
    assert sorted(stop_line) == sorted(exit_)
    assert all(not elements(lane, TrafficLight) for lane in named if lane != "1:0:1")
    (right_of_way,) = elements("3:0:-1", RightOfWay)
    assert [ll.id for ll in right_of_way.yieldLanelets()] == [named["3:0:-1"].id]
    assert {ll.id for ll in right_of_way.rightOfWayLanelets()} == {named[k].id for k in ("1:0:1", "2:0:1", "4:0:-1")}
    german = tr.create(tr.Locations.Germany, tr.Participants.Vehicle)
    assert german.speedLimit(named["2:0:1"]).speedLimit == pytest.approx(30.0)
    # the sign governs the lanes driving against s only: the other keeps the road's <speed>
    assert german.speedLimit(named["2:0:-1"]).speedLimit == pytest.approx(50.0)
    assert all(not r.parameters for r in elements("2:0:-1", SpeedLimit))


def test_evaluations_over_a_broken_link_are_unscored_and_the_rest_exact(tmp_path, monkeypatch, capsys) -> None:
    import json

    from cold_maps.cli.evaluate import main
    from cold_maps.evaluation.trust import MAP_BROKEN

    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "far.xodr"
    path.write_text(branch_gap_map(0.8))  # road 1 -> road 2 misses by 0.8 m
    out = tmp_path / "out"
    assert main(["--map", str(path), "--routes", "1", "--out", str(out), "--frames", "60", "--gaps", "20",
                 "--interpolation", "paper", "--no-distractors", "--no-mcap", "--no-plots", "--no-progress"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    notes = (out / "summary.md").read_text()
    assert "broken at 1 place(s)" in notes and "misses by 0.800 m" in notes
    local = [s for s in json.loads((out / "metrics.json").read_text())["scenarios"] if s["fusion"] == "local"]
    for scenario in local:
        unscored = scenario["gt_unmatched"][MAP_BROKEN]
        assert 0 < unscored < scenario["frames"] and scenario["fused_frames"] + unscored == scenario["frames"]
        assert scenario["max_error_m"] <= 0.02  # everywhere else the GT is the engine's border
    # many of the 60 frames see the joint: more than 1 % unscored flags the run
    assert "GROUND TRUTH NOT TRUSTWORTHY" in line and "map is broken" in line


def _sections(odr_map):
    return [(road, index, [lane.id for lane in section.lanes])
            for road in odr_map.roads.values() for index, section in enumerate(road.lane_sections)
            if section.lanes and section.s_end > section.s]


@pytest.mark.parametrize("name", ["junction", "highway", "rural"])
def test_sections_refined_together_equal_the_section_by_section_sampling_bit_for_bit(name) -> None:
    from cold_maps.groundtruth.lanelet2_from_engine import adaptive_samples

    sections = _sections(load_opendrive(bundled_map(name)))
    together = adaptive_samples(sections)
    for (road, index, lane_ids), samples in zip(sections, together):
        alone = adaptive_section_samples(road, index, lane_ids)
        assert [(s.lane_id, s.s.tobytes(), s.inner.tobytes(), s.outer.tobytes()) for s in samples] == [
            (s.lane_id, s.s.tobytes(), s.inner.tobytes(), s.outer.tobytes()) for s in alone]


def test_crossing_connections_evaluated_together_equal_one_by_one_bit_for_bit() -> None:
    from cold_maps.opendrive.sampling import batchable, section_points, stacked_section_points

    sections = _sections(parse_opendrive("".join(load_tool("big_maps").junction(4, 3)).encode()))
    assert all(batchable(*section) for section in sections)
    rng = np.random.default_rng(0)
    stations = [rng.uniform(road.lane_sections[index].s, road.lane_sections[index].s_end, size=int(rng.integers(0, 40)))
                for road, index, _ in sections]  # unordered, some sections without a station
    values, starts = stacked_section_points(sections, np.concatenate(stations), np.array([len(s) for s in stations]))
    for (road, index, lane_ids), s, first, end in zip(sections, stations, starts[:-1], starts[1:]):
        assert values[first:end].tobytes() == section_points(road, index, s, lane_ids)[1].tobytes()


@pytest.mark.parametrize("name", ["junction", "highway", "rural", "Town04"])
def test_a_uniform_marking_is_the_classification_at_every_mark_station(name) -> None:
    """Where ``uniform_marking`` answers, ``classify_border`` at every mark station of the
    section gives that type, owner and mark; it answers for some borders and leaves others
    (a mark changing inside the section, an unpainted border with a lane beyond) to it."""
    from cold_maps.groundtruth.lanelet2_from_engine import mark_stations
    from cold_maps.opendrive.road_marks import classify_border, uniform_marking

    odr_map = load_opendrive(carla_map(name) if name.startswith("Town") else bundled_map(name))
    answered = left = 0
    for road in odr_map.roads.values():
        for index, section in enumerate(road.lane_sections):
            s = mark_stations(road, index)
            for lane in section.lanes:
                for side in ("inner", "outer"):
                    uniform = uniform_marking(road, index, lane.id, side)
                    if uniform is None:
                        left += 1
                        continue
                    answered += 1
                    marking = classify_border(road, index, lane.id, side, s)
                    for field in ("type", "owner", "mark_index"):
                        assert (getattr(marking, field) == getattr(uniform, field)).all(), (road.id, lane.id, side)
    assert answered and (left > 0) == name.startswith("Town")  # the bundled maps: all painted or outermost
