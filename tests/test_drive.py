"""Drives: vehicle placement by closed forms on the bundled maps, branches, the true lane
relation, route lengths and bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import bundled_map, junction_fork_reach_m
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.network.lane_graph import LaneKey, build_lane_graph
from cold_maps.opendrive.parser import load_opendrive
from cold_maps.simulation.drive import (
    MAX_SPEED_MPS,
    ROUTE_MARGIN_M,
    DriveError,
    Track,
    build_drive,
    covering_routes,
    lane_relation,
    required_route_length,
)

LANE = LaneKey("1", 0, -1)


@pytest.fixture(scope="module")
def straight():
    return build_lane_graph(load_opendrive(bundled_map("straight")))


@pytest.fixture(scope="module")
def curve90():
    return build_lane_graph(load_opendrive(bundled_map("curve90")))


@pytest.fixture(scope="module")
def junction():
    return build_lane_graph(load_opendrive(bundled_map("junction")))


@pytest.fixture(scope="module")
def straight_drive(straight):
    return build_drive(straight, [LANE], 20, coop_leads_m=[25.0, 60.0], distractor_leads_m=[60.0],
                       rng=np.random.default_rng(0))


def _xy(state):
    return np.array(state.track.strip.pose(state.station)[:2])


def test_track_length_and_lanes_on_straight(straight):
    track = Track.build(straight, [LANE])
    assert track.length == pytest.approx(1000.0, abs=1e-6)
    assert track.lane_at(500.0) == (0, pytest.approx(500.0))
    left, right = track.borders_between(100.0, 130.0)
    # lane -1: borders at t = 0 and t = -4 of an eastward reference line at y = 0
    np.testing.assert_allclose(left[[0, -1]], [[100.0, 0.0], [130.0, 0.0]], atol=1e-9)
    np.testing.assert_allclose(right[[0, -1]], [[100.0, -4.0], [130.0, -4.0]], atol=1e-9)


def test_coops_lead_the_ego_by_their_headway(straight_drive):
    states = straight_drive.states(7)
    ego = states["ego"]
    assert ego.station == pytest.approx(60.0 + 7 * 1.0)  # room for the 60 m 'behind' vehicle
    for name, lead in (("coop25", 25.0), ("coop60", 60.0), ("behind60", -60.0)):
        np.testing.assert_allclose(_xy(states[name]) - _xy(ego), [lead, 0.0], atol=1e-9)


def test_distractors_stand_beside_the_lane_ahead(straight_drive):
    states = straight_drive.states(3)
    ego = _xy(states["ego"])
    # adjacent lane -2 is one lane width (4 m) right, opposite lane 1 one lane width left
    np.testing.assert_allclose(_xy(states["adjacent60"]) - ego, [60.0, -4.0], atol=0.06)
    np.testing.assert_allclose(_xy(states["opposite60"]) - ego, [60.0, 4.0], atol=0.06)
    assert states["opposite60"].track.strip.pose(states["opposite60"].station)[2] == pytest.approx(math.pi, abs=1e-6)
    assert states["adjacent60"].lane == LaneKey("1", 0, -2)
    assert states["opposite60"].lane == LaneKey("1", 0, 1)


def test_lane_relation_separates_coops_from_distractors(straight, straight_drive):
    states = straight_drive.states(5)
    truth = {name: lane_relation(straight, states["ego"], state, 85.0)
             for name, state in states.items() if name != "ego"}
    assert truth == {"coop25": True, "coop60": True, "behind60": False, "adjacent60": False, "opposite60": False}
    assert not lane_relation(straight, states["ego"], states["coop60"], 59.0)  # farther than allowed


def test_turning_coops_on_junction_branches(junction):
    lanes = [LaneKey("3", 0, -1)]
    nxt = junction.successors[lanes[0]]
    assert len(nxt) == 3  # left, straight, right
    straight_on = next(k for k in nxt if junction.successors[k] and junction.successors[k][0].road_id == "1")
    lanes += [straight_on, junction.successors[straight_on][0]]
    drive = build_drive(junction, lanes, 100, coop_leads_m=[50.0], distractor_leads_m=[50.0],
                        rng=np.random.default_rng(1))
    branch = float(drive.ego.lane_starts[1])
    assert branch == pytest.approx(junction.lengths[lanes[0]], rel=1e-3)
    turns = [v for v in drive.vehicles if v.role == "turn"]
    assert len(turns) == 2 and all(v.branch_station_m == pytest.approx(branch) for v in turns)
    seen = related = 0
    for frame in range(drive.frames):
        states = drive.states(frame)
        ego_station = states["ego"].station
        for vehicle in turns:
            present = vehicle.name in states
            assert present == (ego_station < branch < ego_station + 50.0)
            if present:
                seen += 1
                state = states[vehicle.name]
                assert state.lane != states["coop50"].lane
                assert lane_relation(junction, states["ego"], state, 85.0)
                # with a 30 m detection, the turning coop continues the detected lane while
                # that detection ends before the fork or still inside the turning lane past
                # it; beyond, the ego saw only the straight branch, which the turning coop's
                # lane does not continue
                past_m, reach_m = ego_station + 30.0 - branch, junction_fork_reach_m(junction, state.track.lanes[1])
                still_inside = past_m < reach_m
                if abs(past_m - reach_m) > 0.2:  # sampled borders
                    assert lane_relation(junction, states["ego"], state, 85.0, 30.0) == still_inside
                related += still_inside
    assert seen > related > 0


def test_branch_strips_end_past_where_their_turning_vehicles_read(junction):
    """A turning vehicle is present only while the ego has not reached the branch, so its
    track is read at most its lead plus the sensor's reach past the branch: the strip ends
    there (cut), and every state and detection is the one on the whole track."""
    from cold_maps.simulation.sensor import LaneSensor

    lanes = [LaneKey("3", 0, -1)]
    straight_on = next(k for k in junction.successors[lanes[0]]
                       if junction.successors[k] and junction.successors[k][0].road_id == "1")
    lanes += [straight_on, junction.successors[straight_on][0]]
    kwargs = dict(coop_leads_m=[50.0], distractor_leads_m=[20.0, 50.0])
    cut = build_drive(junction, lanes, 100, rng=np.random.default_rng(1), reach_m=40.0, **kwargs)
    whole = build_drive(junction, lanes, 100, rng=np.random.default_rng(1), reach_m=1e9, **kwargs)
    turns = [(a, b) for a, b in zip(cut.vehicles, whole.vehicles, strict=True) if a.role == "turn"]
    assert turns
    for a, b in turns:
        assert a.name == b.name and a.branch_station_m == b.branch_station_m
        assert a.track.lanes == b.track.lanes and np.array_equal(a.track.lane_starts, b.track.lane_starts)
        station = a.track.strip.station
        assert a.branch_station_m + 50.0 + 40.0 + ROUTE_MARGIN_M <= a.track.length < b.track.length
        assert station[-2] < a.branch_station_m + 50.0 + 40.0 + ROUTE_MARGIN_M  # the first cross-section past it
        for name in ("station", "centerline", "left", "right", "left_distance", "right_distance", "heading"):
            assert np.array_equal(getattr(a.track.strip, name), getattr(b.track.strip, name)[:len(station)]), name
    sensor = LaneSensor(range_m=40.0)
    for frame, (mine, theirs) in enumerate(zip(cut.states_block(range(100)), whole.states_block(range(100)))):
        assert list(mine) == list(theirs), frame
        for name, state in mine.items():
            other = theirs[name]
            assert (state.station, state.lane, state.lane_offset_m) == (other.station, other.lane, other.lane_offset_m)
            if state.role == "turn":
                seen, expected = sensor.detect(state.track.strip, state.station), sensor.detect(
                    other.track.strip, other.station)
                assert seen is not None and expected is not None and seen.end_reason == expected.end_reason
                assert np.array_equal(seen.left, expected.left) and np.array_equal(seen.right, expected.right)


def test_track_cut_beyond_its_strip_is_the_track(straight):
    track = Track.build(straight, [LANE])
    assert track.cut(track.length) is track and track.cut(float(track.strip.station[-2]) + 1e-9) is track
    shorter = track.cut(10.0)
    assert 10.0 <= shorter.length < 10.0 + 0.11 and shorter.lanes == track.lanes


def test_required_route_length_closed_form():
    assert required_route_length(11, [25.0, 80.0], behind_m=50.0) == pytest.approx(50 + 10 + 80 + 30 + ROUTE_MARGIN_M)
    with pytest.raises(ValueError, match="frames"):
        required_route_length(0, [])


@pytest.mark.parametrize("speed", [0.0, -1.0, float("nan"), float("inf"), 1e308, MAX_SPEED_MPS * (1 + 1e-12)])
def test_a_speed_out_of_range_is_refused_before_any_length_is_computed(speed):
    """1e308 m/s used to give an infinite route length that reached the error message."""
    with pytest.raises(ValueError, match=rf"speed must be > 0 and <= {MAX_SPEED_MPS:g} m/s"):
        required_route_length(5, [], speed_mps=speed)
    assert required_route_length(5, [], speed_mps=MAX_SPEED_MPS) == pytest.approx(
        4 * MAX_SPEED_MPS / 10.0 + 30.0 + ROUTE_MARGIN_M)


def test_too_short_route_and_too_long_drive_raise(curve90):
    with pytest.raises(DriveError, match=r"curve90.*shorter than"):
        build_drive(curve90, [LANE], 1000, coop_leads_m=[50.0], rng=np.random.default_rng(0))
    with pytest.raises(DriveError, match=r"curve90.*no drivable route"):
        covering_routes(curve90, 1, 10_000.0, np.random.default_rng(0))


def test_covering_routes_start_on_uncovered_lanes(junction):
    routes = covering_routes(junction, 4, 120.0, np.random.default_rng(3))
    firsts = [route[0] for route in routes]
    assert len(set(firsts)) == 4
    for route in routes:
        assert sum(junction.lengths[k] for k in route) >= 120.0
        assert all(b in junction.successors[a] for a, b in zip(route, route[1:]))


@settings(max_examples=25, deadline=None)
@given(lead=st.floats(1.0, 100.0), frame=st.integers(0, 9))
def test_coop_station_lead_and_chord_on_the_curve(curve90, lead, frame):
    drive = build_drive(curve90, [LANE], 10, coop_leads_m=[lead], rng=np.random.default_rng(0))
    states = drive.states(frame)
    ego, coop = states["ego"], states[f"coop{lead:g}"]
    assert coop.station - ego.station == pytest.approx(lead)
    assert np.hypot(*(_xy(coop) - _xy(ego))) <= lead + 1e-9  # a chord is never longer than its arc


def test_covering_routes_start_on_a_lane_short_by_round_off_only(curve90):
    """A lane whose longest route falls short of the length by less than
    ``LENGTH_TOLERANCE_M`` (the same road's lanes sampled in opposite directions) is a
    start: two routes of the inner lane's length cover both lanes, not the outer twice."""
    from cold_maps.network.routing import LENGTH_TOLERANCE_M, longest_route_lengths

    longest = longest_route_lengths(curve90)
    inner = min(curve90.lanes, key=longest.__getitem__)
    routes = covering_routes(curve90, 2, longest[inner] + 0.5 * LENGTH_TOLERANCE_M, np.random.default_rng(0))
    assert {route[0] for route in routes} == set(curve90.lanes)


def test_covering_routes_until_every_startable_lane_is_covered(junction):
    from cold_maps.network.routing import longest_route_lengths

    routes = covering_routes(junction, None, 120.0, np.random.default_rng(5))
    longest = longest_route_lengths(junction)
    startable = {lane for lane in junction.lanes if longest[lane] >= 120.0}
    assert startable <= {lane for route in routes for lane in route}
    assert len(routes) <= len(startable)


def test_tracks_beside_the_lanes_built_again_are_the_same(monkeypatch):
    """A drive keeps only the latest ``BESIDE_TRACKS_KEPT`` tracks beside its lanes built:
    with one kept (each built again when asked for after another), every frame's vehicles
    stand on the same lanes at the same stations and points as with all of them kept."""
    from cold_maps.cli.evaluate import _plans, build_parser
    from cold_maps.evaluation.evaluator import MapEvaluator
    from cold_maps.simulation import drive as drive_module

    def drives():
        args = build_parser().parse_args(["--map", str(bundled_map("highway")), "--frames", "300", "--routes", "1"])
        return MapEvaluator(_plans(args)[0]).drives

    (everything,) = drives()
    monkeypatch.setattr(drive_module, "BESIDE_TRACKS_KEPT", 1)
    (one,) = drives()
    beside = 0
    for frame in range(0, one.frames, 7):
        kept, rebuilt = everything.states(frame), one.states(frame)
        assert list(kept) == list(rebuilt)
        for name, state in kept.items():
            other = rebuilt[name]
            assert (state.role, state.station, state.lane, state.lane_offset_m, state.lead_m, state.track.lanes) == (
                other.role, other.station, other.lane, other.lane_offset_m, other.lead_m, other.track.lanes)
            assert np.array_equal(state.track.strip.centerline, other.track.strip.centerline)
            beside += state.role in ("adjacent", "opposite")
    assert beside > 0
    assert len(one.beside._built) == 1 and len({track.lanes for lanes in one.beside.values() for _, track in lanes}) > 1
