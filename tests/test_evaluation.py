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
