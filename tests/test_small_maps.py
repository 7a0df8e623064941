"""Issue 17 on maps built for it (``tests/small_maps.py``): a run on a map too short for
the whole plan evaluates what fits, a one-lane ring shorter than a spline scenario, and
links whose ``contactPoint`` contradicts the geometry."""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import bundled_map, carla_map
from hypothesis import given, settings
from hypothesis import strategies as st
from small_maps import (
    CONNECTING_ROAD_M,
    CONTRADICTING_ROAD_M,
    RING_REFERENCE_RADIUS_M,
    contradicting_links,
    ring_lap_m,
    small_ring,
    straight_road,
)

from cold_maps.cli import evaluate
from cold_maps.evaluation.fit import fit_plan
from cold_maps.evaluation.scenarios import MapPlan, scenarios_for
from cold_maps.groundtruth.meter import RANGE_ERROR_THRESHOLD_M, covered_length_m
from cold_maps.network.lane_graph import build_lane_graph
from cold_maps.network.routing import longest_route_lengths
from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.links import repair_contact_points
from cold_maps.opendrive.parser import load_opendrive, parse_opendrive
from cold_maps.simulation.drive import (
    DriveError,
    Track,
    ahead_in_ego_frame,
    build_drive,
    lane_relation,
)
from cold_maps.simulation.sensor import SENSOR_RANGE_M

GAPS_M = (20.0, 30.0, 50.0)
LANE_WIDTH_M = 3.5


def _plan(frames: int = 100, *, at_most: bool = True, distractors: bool = True) -> MapPlan:
    return MapPlan(Path("road.xodr"), scenarios_for(GAPS_M, ("paper",)), frames=frames, frames_at_most=at_most,
                   distractors=distractors)


# -- plans that fit the map ---------------------------------------------------------------

def test_whole_plan_that_fits_is_unchanged():
    plan = _plan()
    # 99 m of frames + 80 m coop + 30 m range + 5 m margin + 80 m behind
    fitted = fit_plan(plan, 294.0, where="road.xodr")
    assert fitted.plan is plan and fitted.notes == () and fitted.needed_m == pytest.approx(294.0)
    assert fitted.distractor_leads_m == (25.0, 50.0, 60.0, 80.0)


def test_200_m_road_keeps_the_gaps_that_fit_and_drops_distractors_first():
    fitted = fit_plan(_plan(), 200.0, where="road.xodr")
    # without distractors: 99 + lead + 35 <= 200 holds for leads 25, 50, 60 (d_s 20, 30) but not 80 (d_s 50)
    assert [s.label for s in fitted.plan.scenarios] == ["local", "convoy", "spline-paper-d20", "spline-paper-d30"]
    assert fitted.distractor_leads_m == () and not fitted.plan.distractors
    assert fitted.plan.frames == 100 and fitted.needed_m == pytest.approx(99 + 60 + 35)
    assert len(fitted.notes) == 2
    assert "no distractors 25, 50, 60, 80 m" in fitted.notes[0] and "the longest is 200 m" in fitted.notes[0]
    assert "dropped spline-paper-d50 (coops 80 m ahead)" in fitted.notes[1] and "214 m" in fitted.notes[1]


def test_distractors_that_fit_are_kept():
    # 30 frames: 29 + 80 + 35 = 144 m without distractors; a distractor lead b adds b behind
    fitted = fit_plan(_plan(30), 200.0, where="road.xodr")
    assert len(fitted.plan.scenarios) == 5 and fitted.distractor_leads_m == (25.0, 50.0)
    assert fitted.needed_m == pytest.approx(29 + 80 + 35 + 50)


def test_frames_shrink_to_the_local_scenario_on_a_60_m_road():
    fitted = fit_plan(_plan(), 60.0, where="road.xodr")
    assert fitted.plan.frames == 1 + round(60.0 - SENSOR_RANGE_M - 5.0)  # 1 m per frame
    assert [s.label for s in fitted.plan.scenarios] == ["local"]
    assert "26 frames per route instead of 100" in fitted.notes[0]


def test_explicit_frames_are_refused_with_what_fits():
    with pytest.raises(DriveError, match=r"no drivable route of 134 m for the local scenario \(longest 100 m\); "
                                         r"at most 66 --frames fit$"):
        fit_plan(_plan(at_most=False), 100.0, where="road.xodr")
    # every scenario: 80 m ahead, 80 m behind, 35 m: 250 - 195 m leave 55 more frames
    with pytest.raises(DriveError, match=r"of 1034 m .*at most 216 --frames fit \(56 with every scenario\)"):
        fit_plan(_plan(1000, at_most=False), 250.0, where="road.xodr")
    with pytest.raises(DriveError, match=r"longest 30 m\); even one frame needs 35 m"):
        fit_plan(_plan(), 30.0, where="road.xodr")


def test_endless_route_fits_everything():
    plan = _plan()
    assert fit_plan(plan, math.inf, where="ring.xodr").plan is plan


@pytest.fixture(scope="module")
def road_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("road200")
    path = folder / "road200.xodr"
    path.write_text(straight_road(200.0))
    status = evaluate.main(["--map", str(path), "--routes", "1", "--interpolation", "paper", "--no-plots",
                            "--no-mcap", "--out", str(folder / "out")])
    return status, folder / "out"


def test_cold_eval_on_a_200_m_road_evaluates_what_fits(road_run, capsys):
    status, out = road_run
    assert status == 0
    document = json.loads((out / "metrics.json").read_text())
    records = {(r["fusion"], r["d_s"], r["boundary"]): r for r in document["scenarios"]}
    assert {(f, d) for f, d, _ in records} == {("local", 0.0), ("convoy", 0.0), ("spline", 20.0), ("spline", 30.0)}
    for boundary in ("left", "right"):
        local = records[("local", 0.0, boundary)]
        assert local["frames"] == 100 and local["max_error_m"] <= 0.05
        assert local["perception_range_m"] == pytest.approx(SENSOR_RANGE_M, abs=0.01)
        assert records[("spline", 30.0, boundary)]["perception_range_m"] == pytest.approx(90.0, abs=0.1)
    summary = (out / "summary.md").read_text()
    assert "road200: dropped spline-paper-d50 (coops 80 m ahead)" in summary


# -- loops --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def ring_graph():
    return build_lane_graph(parse_opendrive(small_ring().encode(), path="ring.xodr"))


def test_ring_lap_is_under_40_m(ring_graph):
    lap = sum(ring_graph.lengths.values())
    assert lap == pytest.approx(ring_lap_m(), rel=1e-3) and lap < 40.0
    assert set(longest_route_lengths(ring_graph).values()) == {math.inf}


def test_track_wraps_only_on_a_stretch_longer_than_the_lap(ring_graph):
    lanes = sorted(ring_graph.lanes)
    track = Track.build(ring_graph, [lanes[i % 2] for i in range(8)])
    lap = track.shortest_loop_m
    assert lap == pytest.approx(ring_lap_m(), rel=1e-3)
    assert not track.wraps(3.0, 3.0 + lap - 0.01) and track.wraps(3.0, 3.0 + lap + 0.01)
    assert Track.build(ring_graph, lanes[:1]).shortest_loop_m == math.inf


def test_on_the_ring_behind_is_never_fusible_and_wrapping_coops_are_absent(ring_graph):
    lanes = sorted(ring_graph.lanes)
    route = [lanes[i % 2] for i in range(12)]
    drive = build_drive(ring_graph, route, 40, coop_leads_m=[5.0, 25.0], distractor_leads_m=[5.0],
                        rng=np.random.default_rng(0))
    lap = drive.ego.shortest_loop_m
    seen = set()
    for frame in range(drive.frames):
        states = drive.states(frame)
        ego = states["ego"]
        seen |= set(states)
        # 25 m + 30 m of sensor range circle the 38.6 m lap
        assert "coop25" not in states and lap < 25.0 + SENSOR_RANGE_M
        for name, state in states.items():
            if name == "ego":
                continue
            truth = lane_relation(ring_graph, ego, state, 85.0, SENSOR_RANGE_M)
            assert truth == (state.lead_m > 0 and ahead_in_ego_frame(ego, state))
    assert {"coop5", "behind5"} <= seen


def test_ahead_in_ego_frame_on_the_ring(ring_graph):
    lanes = sorted(ring_graph.lanes)
    drive = build_drive(ring_graph, [lanes[i % 2] for i in range(6)], 1, coop_leads_m=[], rng=np.random.default_rng(0))
    ego = drive.states(0)["ego"]
    radius = RING_REFERENCE_RADIUS_M + LANE_WIDTH_M / 2
    for arc in (5.0, 15.0, 25.0, 35.0):
        other = drive._state("other", "coop", drive.ego, ego.station + arc, arc)
        # on a circle, a point an arc a ahead lies at x = r sin(a / r) in the ego frame
        assert ahead_in_ego_frame(ego, other) == (math.sin(arc / radius) > 0)


@pytest.fixture(scope="module")
def ring_run(tmp_path_factory):
    folder = tmp_path_factory.mktemp("ring")
    path = folder / "ring.xodr"
    path.write_text(small_ring())
    status = evaluate.main(["--map", str(path), "--routes", "1", "--frames", "40", "--no-plots", "--no-mcap",
                            "--out", str(folder / "out")])
    return status, folder / "out"


def test_cold_eval_on_the_ring_measures_range_along_the_detection(ring_run):
    status, out = ring_run
    assert status == 0
    header, *rows = [line.split(",") for line in (out / "frames.csv").read_text().splitlines()]
    column = {name: i for i, name in enumerate(header)}
    ranges = [float(row[column["perception_range_m"]]) for row in rows if row[column["perception_range_m"]]]
    assert ranges and min(ranges) > 0.0
    # 30 m along the lane centre (radius r_c) is 30 r / r_c along a border of radius r
    centre = RING_REFERENCE_RADIUS_M + LANE_WIDTH_M / 2
    records = {(r["fusion"], r["boundary"]): r for r in json.loads((out / "metrics.json").read_text())["scenarios"]}
    for boundary, radius in (("left", RING_REFERENCE_RADIUS_M), ("right", centre + LANE_WIDTH_M / 2)):
        local = records[("local", boundary)]
        assert local["perception_range_m"] == pytest.approx(SENSOR_RANGE_M * radius / centre, rel=2e-3)
        assert local["max_error_m"] <= 0.05
    assert "circles a loop of 38.6 m" in (out / "summary.md").read_text()


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 3.0), min_size=2, max_size=40), st.floats(0.01, 2.0))
def test_covered_length_is_the_length_of_the_segments_within_the_threshold(errors, step):
    errors_m = np.array(errors)
    border = np.column_stack((np.arange(len(errors)) * step, np.zeros(len(errors))))
    within = errors_m <= RANGE_ERROR_THRESHOLD_M
    expected = step * np.count_nonzero(within[:-1] & within[1:])
    length = covered_length_m(border, errors_m)
    assert length == pytest.approx(expected) and 0.0 <= length <= step * (len(errors) - 1) + 1e-9


@pytest.mark.parametrize("radius_m", [np.inf, 6.0, 20.0])
def test_covered_length_is_not_lengthened_by_detection_noise(radius_m):
    """A 30 m border sampled every 0.1 m with σ = 5 cm lateral noise: its polyline is about
    25 % longer than the border, its covered length within 2 % (0.5 m chords)."""
    rng = np.random.default_rng(7)
    s = np.arange(0.0, 30.0 + 1e-9, 0.1)
    offset = rng.normal(0.0, 0.05, s.size)
    if np.isinf(radius_m):
        border = np.column_stack((s, offset))
    else:
        angle = s / radius_m
        border = (radius_m + offset)[:, None] * np.column_stack((np.sin(angle), 1.0 - np.cos(angle)))
        border[:, 1] -= offset
    polyline = float(np.sum(np.hypot(*np.diff(border, axis=0).T)))
    assert polyline > 1.15 * 30.0
    assert covered_length_m(border, np.abs(offset)) == pytest.approx(30.0, rel=0.02)
    # a noise-free arc loses only chord²/(24 R²) of its length
    exact = border - offset[:, None] * (np.column_stack((np.sin(s / radius_m), -np.cos(s / radius_m)))
                                        if np.isfinite(radius_m) else np.array([0.0, 1.0]))
    assert covered_length_m(exact, np.zeros(s.size)) == pytest.approx(30.0, rel=1e-3)


# -- contactPoints that contradict the geometry -------------------------------------------

def _contacts(odr_map):
    roads = {(road.id, end): getattr(road, end).contact_point for road in odr_map.roads.values()
             for end in ("predecessor", "successor") if getattr(road, end) is not None}
    connections = {(j.id, c.id): c.contact_point for j in odr_map.junctions.values() for c in j.connections}
    return roads, connections


def test_contradicting_contact_points_are_repaired_with_one_warning_and_an_info_each(caplog):
    with caplog.at_level(logging.INFO, logger="cold_maps.opendrive"):
        repaired = parse_opendrive(contradicting_links().encode(), path="bad.xodr")
    consistent = parse_opendrive(contradicting_links(contradict=False).encode(), path="good.xodr")
    assert _contacts(repaired) == _contacts(consistent)
    records = [r for r in caplog.records if r.name == "cold_maps.opendrive"]
    warnings = [r.getMessage() for r in records if r.levelno == logging.WARNING]
    each = [r.getMessage() for r in records if r.levelno == logging.INFO]
    assert len(warnings) == 1 and "bad.xodr: 3 road link(s) or junction connection(s)" in warnings[0]
    assert len(each) == 3
    assert any(f'road 1 successor road 2: contactPoint="start" is {CONTRADICTING_ROAD_M:.2f} m away' in w
               for w in each)
    assert any(f'connecting road 3): contactPoint="end" is {CONNECTING_ROAD_M:.2f} m away' in w for w in each)
    graph, expected = build_lane_graph(repaired), build_lane_graph(consistent)
    assert graph.successors == expected.successors
    assert max(longest_route_lengths(graph).values()) == pytest.approx(220.0)


def test_consistent_links_are_left_alone(caplog):
    consistent = parse_opendrive(contradicting_links(contradict=False).encode(), path="good.xodr", strict=True)
    with caplog.at_level(logging.WARNING, logger="cold_maps.opendrive"):
        assert repair_contact_points(consistent) is consistent
    assert not caplog.records


def test_strict_mode_refuses_contradicting_links():
    with pytest.raises(OpenDriveError, match=r'bad\.xodr: road 1 successor road 2: contactPoint="start" is 50\.00 m '
                                             r"away.*\(and 2 more\); strict mode refuses"):
        parse_opendrive(contradicting_links().encode(), path="bad.xodr", strict=True)


@pytest.mark.parametrize("name", ["straight", "curve90", "rural", "junction", "highway"])
def test_bundled_maps_have_no_contradicting_links(name):
    load_opendrive(bundled_map(name), strict=True)


@pytest.mark.parametrize("name", ["Town01", "Town04"])
def test_carla_towns_have_no_contradicting_links(name):
    load_opendrive(carla_map(name), strict=True)
