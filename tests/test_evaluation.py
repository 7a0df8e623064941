"""Evaluation: GT measurement with known offsets, error models wired through, fusion
decisions scored against the true lane relation, scenario set-up."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from conftest import bundled_map

import fusion
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.scenarios import MapPlan, Scenario, reason_category, scenarios_for
from cold_maps.network.lane_graph import LaneKey
from cold_maps.simulation.detection import sense, world_borders
from cold_maps.simulation.drive import build_drive
from cold_maps.simulation.sensor import LaneSensor
from cold_maps.simulation.sensor_errors import SensorErrorModel

LANE = LaneKey("1", 0, -1)


@pytest.fixture(scope="module")
def straight_plan():
    return MapPlan(bundled_map("straight"), scenarios_for([30.0], ["paper"]), frames=5, routes=1, start_lane=LANE)


@pytest.fixture(scope="module")
def straight_evaluator(straight_plan):
    evaluator = MapEvaluator(straight_plan)
    evaluator.prepare()
    return evaluator


def _run(evaluator, plan):
    """Runs ``plan`` re-using the evaluator's graph and ground truth."""
    other = MapEvaluator(plan, graph=evaluator.graph, ground_truth=evaluator.meter.ground_truth)
    collector = Collector()
    other.run(collector)
    return {(k.fusion, k.boundary): a.result() for k, a in collector.accumulators.items()}, collector


@pytest.fixture(scope="module")
def straight_results(straight_evaluator, straight_plan):
    return _run(straight_evaluator, straight_plan)


def test_scenarios_leads_and_bad_input():
    local, convoy, *splines = scenarios_for([20.0, 50.0], ["paper", "hermite"])
    assert (local.fusion, convoy.fusion, convoy.lead_m) == ("local", "convoy", 25.0)
    assert [(s.interpolation, s.d_s, s.lead_m) for s in splines] == [
        ("paper", 20.0, 50.0), ("paper", 50.0, 80.0), ("hermite", 20.0, 50.0), ("hermite", 50.0, 80.0)]
    assert Scenario("spline", "hermite", 20.0, 50.0).label == "spline-hermite-d20"
    assert len(scenarios_for([20.0, 20.0], ["paper", "paper"])) == 3
    with pytest.raises(ValueError, match="gap"):
        scenarios_for([0.0], ["paper"])
    with pytest.raises(ValueError, match="interpolation"):
        scenarios_for([20.0], ["linear"])


@pytest.mark.parametrize("offset", [0.0, 0.3, -0.45])
def test_meter_measures_a_known_lateral_offset(straight_evaluator, offset):
    drive = straight_evaluator.drives[0]
    state = drive.states(2)["ego"]
    errors = SensorErrorModel(lateral_offset_m=offset)
    sensed = sense(state, LaneSensor(), errors, np.random.default_rng(0))
    left, right = world_borders(sensed.detection)
    measured = straight_evaluator.meter.measure(left, right, (state.track.strip.pose(state.station)))
    # closest point to a GT resampled every 0.02 m: the offset, up to half a step along the border
    for errors_m in (measured.left_errors_m, measured.right_errors_m):
        assert errors_m.min() == pytest.approx(abs(offset), abs=1e-6)
        assert np.all(errors_m <= np.hypot(abs(offset), 0.01) + 1e-9)
        assert errors_m.size == 301  # 30 m every 0.10 m
    assert measured.left_range_m == pytest.approx(30.0, abs=0.02)
    assert measured.matched


def test_meter_reuses_the_match_of_a_reference_lane(straight_evaluator):
    """A reference lane matched again (equal borders and pose) gives the kept match; lanes
    measured against it get GroundTruth.errors' per-point distances and range."""
    meter = straight_evaluator.meter
    state = straight_evaluator.drives[0].states(3)["ego"]
    pose = state.track.strip.pose(state.station)
    truth = state.track.borders_between(state.station, state.station + 30.0)
    first = meter.match(*truth, pose)
    assert meter.match(truth[0].copy(), truth[1].copy(), tuple(pose)) is first
    moved = meter.match(truth[0] + 0.01, truth[1] + 0.01, pose)
    assert moved is not first and moved.lanelet_ids == first.lanelet_ids
    sensed = sense(state, LaneSensor(), SensorErrorModel(lateral_offset_m=0.3), np.random.default_rng(0))
    left, right = world_borders(sensed.detection)
    measured = meter.measure(left, right, pose, reference=truth)
    expected = meter.ground_truth.errors(left, right, first)
    np.testing.assert_array_equal(measured.left_errors_m, expected.left.distances_m)
    np.testing.assert_array_equal(measured.right_errors_m, expected.right.distances_m)
    # the range runs along the detection (everywhere 0.3 m < 1 m off): its own length, which
    # differs from the length along the GT border by less than the offset's effect on a curve
    assert measured.left_range_m == pytest.approx(float(np.sum(np.hypot(*np.diff(left, axis=0).T))), abs=1e-9)
    assert measured.left_range_m == pytest.approx(expected.left.metrics().length_m, abs=0.05)
    assert measured.left_errors_m.min() == pytest.approx(0.3, abs=1e-6)


def test_reason_categories_of_real_rejections(straight_evaluator):
    states = straight_evaluator.drives[0].states(0)
    sensor, rng, errors = LaneSensor(), np.random.default_rng(0), SensorErrorModel()
    ego = sense(states["ego"], sensor, errors, rng).detection
    coop = sense(states["coop60"], sensor, errors, rng).detection
    behind = sense(states["behind60"], sensor, errors, rng).detection
    opposite = sense(states["opposite60"], sensor, errors, rng).detection
    adjacent = sense(states["adjacent60"], sensor, errors, rng).detection
    assert reason_category(fusion.fuse(ego, behind, mode="spline").reason) == "coop_not_ahead"
    assert reason_category(fusion.fuse(ego, opposite, mode="spline").reason) == "opposite_direction"
    assert reason_category(fusion.fuse(ego, adjacent, mode="spline").reason) == "other_lane"
    assert reason_category(fusion.fuse(ego, coop, mode="convoy").reason) == "no_overlap"
    assert reason_category("something new") == "other"


def test_straight_run_ranges_errors_and_fusibility(straight_results):
    results, collector = straight_results
    for boundary in ("left", "right"):
        local, convoy, spline = (results[(f, boundary)] for f in ("local", "convoy", "spline"))
        assert local.max_error_m <= 0.0101 and convoy.max_error_m <= 0.0101 and spline.max_error_m <= 0.05
        assert local.perception_range_m == pytest.approx(30.0, abs=0.05)
        assert convoy.perception_range_m == pytest.approx(55.0, abs=0.05)
        assert spline.perception_range_m == pytest.approx(90.0, abs=0.05)
        # per frame: the coop is fused; behind, adjacent and opposite vehicles are rejected
        for result in (convoy, spline):
            assert (result.frames, result.fused_frames) == (4 * 5, 5)
            assert result.fusibility_precision == 1.0 and result.fusibility_recall == 1.0
            assert result.fusibility_recall_detected == 1.0  # the ideal sensor's detections reach its range
            assert sum(count for _, count in result.rejected) == 15
    assert set(collector.check_ms) == {("straight", "convoy"), ("straight", "spline-paper-d30")}
    assert all(len(v) == 5 for v in collector.check_ms.values())


def test_drop_model_rejects_every_local_frame(straight_evaluator, straight_plan):
    results, _ = _run(straight_evaluator, replace(straight_plan, errors=SensorErrorModel(drop_probability=1.0),
                                                  distractors=False))
    local = results[("local", "left")]
    assert (local.fused_frames, dict(local.rejected)) == (0, {"ego_dropped": 5})


def test_lateral_offset_model_shows_in_local_error(straight_evaluator, straight_plan):
    plan = replace(straight_plan, errors=SensorErrorModel(lateral_offset_m=0.2), distractors=False)
    results, _ = _run(straight_evaluator, plan)
    assert results[("local", "left")].mean_error_m == pytest.approx(0.2, abs=0.005)
    # both vehicles are shifted alike: the convoy lane keeps the offset
    assert results[("convoy", "right")].mean_error_m == pytest.approx(0.2, abs=0.005)


def test_pose_error_hits_only_the_senders(straight_evaluator, straight_plan):
    plan = replace(straight_plan, errors=SensorErrorModel(pose_sigma_xy_m=0.5), distractors=False, seed=4)
    results, _ = _run(straight_evaluator, plan)
    assert results[("local", "left")].max_error_m <= 0.0101
    assert results[("convoy", "left")].max_error_m > 0.05


def test_turning_coop_is_scored_against_its_own_lane():
    plan = MapPlan(bundled_map("junction"), scenarios_for([20.0], ["hermite"]), frames=60, routes=1,
                   start_lane=LaneKey("3", 0, -1))
    evaluator = MapEvaluator(plan)
    drive = evaluator.drives[0]
    assert any(v.role == "turn" for v in drive.vehicles)
    evaluator.prepare()
    collector = Collector()
    evaluator.run(collector)
    records = [r for k, a in collector.accumulators.items() if k.fusion == "spline" for r in a.records
               if r.coop.startswith("turn")]
    assert records and all(r.truly_fusible for r in records)
    fused = [r for r in records if r.fused]
    # a 20 m G1 gap into a 13/17 m radius turn: errors of decimetres, not of another branch (metres)
    assert fused and max(float(r.errors_m.max()) for r in fused) < 1.0


def test_build_drive_reuses_graph(straight_evaluator):
    drive = build_drive(straight_evaluator.graph, [LANE], 3, coop_leads_m=[25.0], rng=np.random.default_rng(0))
    assert [v.name for v in drive.vehicles] == ["coop25"]


def test_recall_given_detections_leaves_out_pairs_the_short_detection_cannot_fuse(straight_evaluator):
    """A camera seeing 20 m on the straight: its detection ends 20 m ahead, a coop's starts 3 m
    (the camera's near limit) ahead of the coop. The convoy coop at 25 m does not overlap it
    (28 > 20 m), the spline coop at 60 m leaves 43 m <= d_i = 50 m, the one at 80 m 63 m: the
    recall counts all three valid pairs, the recall given detections only the 60 m one."""
    from cold_maps.simulation.sensor_profile import CAMERA

    plan = MapPlan(bundled_map("straight"), scenarios_for([30.0, 50.0], ["paper"]), frames=5, routes=1,
                   start_lane=LANE, sensor=replace(CAMERA, max_range_m=20.0))
    evaluator = MapEvaluator(plan, graph=straight_evaluator.graph, ground_truth=straight_evaluator.meter.ground_truth)
    collector = Collector()
    evaluator.run(collector)
    convoy, near, far = sorted((a.result() for k, a in collector.accumulators.items()
                                if k.boundary == "left" and k.fusion != "local"), key=lambda r: r.key.d_s)
    assert (convoy.key.fusion, near.key.d_s, far.key.d_s) == ("convoy", 30.0, 50.0)
    assert convoy.fusibility_recall == 0.0 and dict(convoy.rejected)["no_overlap"] == 15
    assert np.isnan(convoy.fusibility_recall_detected)
    assert near.fusibility_recall == 1.0 and near.fusibility_recall_detected == 1.0
    assert far.fusibility_recall == 0.0 and dict(far.rejected)["gap_too_long"] == 15
    assert np.isnan(far.fusibility_recall_detected)


def test_read_ends_give_the_rules_gap_on_the_lanes_the_sensors_read(straight_evaluator):
    """The ideal sensor reads 30 m: on the straight the coop 60 m ahead starts 30 m after the
    ego's lane ends, the one 25 m ahead 5 m before it (negative: overlap). On curve90 (a
    90° right turn of radius 18 m on the lane centre from station 150) the ego at 110 ends at
    (140, -2) heading east, a coop 10 m past the turn starts at (168, -30) heading south: the
    gap is the chord, as the rule measures d_s, not the 48.3 m of lane."""
    from cold_maps.network.lane_graph import build_lane_graph
    from cold_maps.opendrive.parser import load_opendrive
    from cold_maps.simulation.drive import Track, VehicleState
    from fusion.fusibility import signed_gap_m

    sensor, rng, errors = LaneSensor(), np.random.default_rng(0), SensorErrorModel()
    states = straight_evaluator.drives[0].states(0)
    ego, coop, near = (sense(states[name], sensor, errors, rng).read_ends for name in ("ego", "coop60", "coop25"))
    (p_end, t_end) = ego[1]
    assert signed_gap_m(p_end, t_end, coop[0][0]) == pytest.approx(30.0, abs=1e-9)
    assert signed_gap_m(p_end, t_end, near[0][0]) == pytest.approx(-5.0, abs=1e-9)
    assert t_end == pytest.approx((1.0, 0.0), abs=1e-12)
    track = Track.build(build_lane_graph(load_opendrive(bundled_map("curve90"))), [LANE])
    station = 150.0 + 18.0 * np.pi / 2.0 + 10.0
    (_, _), (p_end, t_end) = sense(VehicleState("ego", "ego", track, 110.0, LANE, 110.0), sensor, errors,
                                   rng).read_ends
    (p_start, t_start), _ = sense(VehicleState("c", "coop", track, station, LANE, station, 70.0), sensor, errors,
                                  rng).read_ends
    assert p_end == pytest.approx((140.0, -2.0), abs=1e-4) and p_start == pytest.approx((168.0, -30.0), abs=1e-4)
    assert t_end == pytest.approx((1.0, 0.0), abs=1e-6) and t_start == pytest.approx((0.0, -1.0), abs=1e-6)
    assert signed_gap_m(p_end, t_end, p_start) == pytest.approx(np.hypot(28.0, 28.0), abs=1e-4)
