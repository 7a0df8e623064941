"""The correlated cubic lane-model error against its closed forms (issue 26, deliverable 2):
σ(x) at 10, 30 and 50 m, the AR(1) correlation exp(−Δt/τ), the per-point σ and pose
covariance a detection carries, seeding, and nothing drawn when the model is off."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from conftest import bundled_map

from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.scenarios import MapPlan, scenarios_for
from cold_maps.network.lane_graph import LaneKey, load_graph
from cold_maps.simulation.detection import sense
from cold_maps.simulation.drive import Track, VehicleState
from cold_maps.simulation.lane_model_error import (
    LaneModelErrorParams,
    LaneModelErrorSampler,
    evolve,
    lateral_error,
)
from cold_maps.simulation.sensor import LaneSensor
from cold_maps.simulation.sensor_errors import SensorErrorModel
from cold_maps.simulation.sensor_profile import CAMERA as CAMERA_PROFILE
from cold_maps.simulation.sensor_profile import IDEAL

CAMERA = CAMERA_PROFILE.lane_error
"""The urban camera profile's values."""
WITH_C3 = replace(CAMERA, sigma_c3_per_m2=2e-6)
"""The same with a curvature-rate error, so that every term of the closed form counts."""
CHAINS = 20_000
LANE = LaneKey("1", 0, -1)


def _closed_form(p: LaneModelErrorParams, x: np.ndarray) -> np.ndarray:
    """σ(x) written out term by term, independently of ``sigma_m``."""
    return np.sqrt(p.sigma_c0_m**2 + (p.sigma_c1_rad * x) ** 2 + (p.sigma_c2_per_m * x**2 / 2) ** 2
                   + (p.sigma_c3_per_m2 * x**3 / 6) ** 2 + p.white_m**2)


@pytest.mark.parametrize("params", [CAMERA, WITH_C3], ids=["camera", "with-c3"])
def test_empirical_sigma_at_10_30_50_m_is_the_closed_form_within_3_percent(params):
    x = np.array([10.0, 30.0, 50.0])
    rng = np.random.default_rng(1)
    expected = _closed_form(params, x)
    np.testing.assert_allclose(params.sigma_m(x), expected, rtol=1e-12)
    coefficients = evolve(None, params, 0.0, rng, (CHAINS,))
    for _ in range(3):  # stationary: the AR(1) steps keep the variance
        errors = lateral_error(coefficients, x, params, rng)
        assert errors.shape == (CHAINS, 3)
        np.testing.assert_allclose(errors.std(axis=0), expected, rtol=0.03)
        assert np.all(np.abs(errors.mean(axis=0)) < 4 * expected / math.sqrt(CHAINS))
        coefficients = evolve(coefficients, params, 0.1, rng)


@pytest.mark.parametrize("dt_s", [0.1, 0.3, 1.0])
def test_frame_to_frame_correlation_is_exp_minus_dt_over_tau(dt_s):
    params = replace(WITH_C3, tau_s=0.5)
    rng = np.random.default_rng(2)
    before = evolve(None, params, 0.0, rng, (CHAINS,))
    after = evolve(before, params, dt_s, rng)
    rho = math.exp(-dt_s / params.tau_s)
    for i, sigma in enumerate(params.coefficient_sigmas):
        assert np.corrcoef(before[:, i], after[:, i])[0, 1] == pytest.approx(rho, abs=0.02)
        assert after[:, i].std() == pytest.approx(sigma, rel=0.03)


def _straight_border(length_m: float = 50.0) -> np.ndarray:
    x = np.arange(0.0, length_m + 0.05, 0.1)
    return np.column_stack((x, np.full_like(x, 1.75)))


def test_the_sampler_persists_each_vehicles_error_over_its_stamps():
    # Only δc0: every point of a straight border moves by the same δc0, read off at x = 0.
    params = LaneModelErrorParams(sigma_c0_m=0.1, tau_s=0.5)
    sampler = LaneModelErrorSampler(params, seed=3, drive=0)
    border = _straight_border(1.0)
    frames = 20_000
    offsets = np.empty((frames, 2))
    for frame in range(frames):
        left, right = sampler.perturb("coop25", frame * 0.1, border, border - [0.0, 3.5])
        offsets[frame] = left[0, 1] - 1.75, right[0, 1] + 1.75
    np.testing.assert_array_equal(left[:, 0], border[:, 0])  # lateral only on a straight border
    np.testing.assert_allclose(left[:, 1] - left[0, 1], 0.0, atol=1e-12)
    for series in offsets.T:
        assert np.corrcoef(series[:-1], series[1:])[0, 1] == pytest.approx(math.exp(-0.1 / 0.5), abs=0.02)
        assert series.std() == pytest.approx(0.1, rel=0.03)
    assert abs(np.corrcoef(offsets[:, 0], offsets[:, 1])[0, 1]) < 0.05  # borders independent


def test_the_sampler_is_seeded_per_drive_and_vehicle_whatever_the_order():
    border = _straight_border()
    right = border - [0.0, 3.5]

    def run(seed, drive, order):
        sampler = LaneModelErrorSampler(CAMERA, seed=seed, drive=drive)
        out = {}
        for frame in range(3):
            for name in order:
                out[name, frame] = sampler.perturb(name, frame * 0.1, border, right)
        return out

    first = run(0, 0, ["ego", "coop25"])
    again = run(0, 0, ["coop25", "ego"])
    for key, (left, right_) in first.items():
        np.testing.assert_array_equal(left, again[key][0])
        np.testing.assert_array_equal(right_, again[key][1])
    for other in (run(1, 0, ["ego"]), run(0, 1, ["ego"])):
        assert not np.array_equal(other["ego", 0][0], first["ego", 0][0])
    assert not np.array_equal(first["ego", 0][0], first["coop25", 0][0])
    sampler = LaneModelErrorSampler(CAMERA, 0, 0)
    sampler.perturb("coop25", 1.0, border, right)
    with pytest.raises(ValueError, match="coop25 detects at 0.0 s, before its last detection at 1.0 s"):
        sampler.perturb("coop25", 0.0, border, right)


def test_all_zero_draws_nothing():
    rng = np.random.default_rng(4)
    state = rng.bit_generator.state
    zero = LaneModelErrorParams()
    assert zero.is_zero
    coefficients = evolve(evolve(None, zero, 0.0, rng, (2,)), zero, 0.1, rng)
    np.testing.assert_array_equal(coefficients, 0.0)
    np.testing.assert_array_equal(lateral_error(coefficients[0], np.array([0.0, 50.0]), zero, rng), 0.0)
    assert rng.bit_generator.state == state


@pytest.fixture(scope="module")
def straight_track():
    return Track.build(load_graph(bundled_map("straight")), [LANE])


def _state(track, name="ego", role="ego", station=10.0):
    index, offset = track.lane_at(station)
    return VehicleState(name, role, track, station, track.lanes[index], offset)


def test_the_detection_carries_the_closed_form_sigma_and_the_pose_covariance(straight_track):
    errors = SensorErrorModel(noise_sigma_m=0.03, pose_sigma_xy_m=0.2, pose_sigma_yaw_rad=0.01)
    sampler = LaneModelErrorSampler(WITH_C3, seed=0, drive=0)
    rng = np.random.default_rng(5)
    for role in ("ego", "coop"):
        detection = sense(_state(straight_track, role, role), LaneSensor(), errors, rng, stamp_s=0.0,
                          lane_error=sampler).detection
        for border, sigma in ((detection.left, detection.left_sigma), (detection.right, detection.right_sigma)):
            assert border[-1, 0] == pytest.approx(30.0, abs=0.2)
            expected = np.sqrt(_closed_form(WITH_C3, border[:, 0]) ** 2 + 0.03**2)  # independent: variances add
            np.testing.assert_allclose(sigma, expected, rtol=1e-12)
        expected_cov = np.zeros((3, 3)) if role == "ego" else np.diag([0.04, 0.04, 1e-4])
        np.testing.assert_allclose(detection.pose_cov, expected_cov, rtol=1e-12)


def test_the_noise_alone_gives_a_constant_sigma_and_the_ideal_sensor_none(straight_track):
    rng = np.random.default_rng(6)
    noisy = sense(_state(straight_track), LaneSensor(), SensorErrorModel(noise_sigma_m=0.03), rng).detection
    np.testing.assert_array_equal(noisy.left_sigma, np.full(len(noisy.left), 0.03))
    assert noisy.pose_cov is None
    ideal = sense(_state(straight_track), LaneSensor(), SensorErrorModel(), rng).detection
    assert (ideal.left_sigma, ideal.right_sigma, ideal.pose_cov) == (None, None, None)


def test_the_evaluator_applies_the_seeded_lane_error_to_every_frame():
    # Only δc0 with τ far above the drive: each border of the ego sits δc0 off its GT.
    params = LaneModelErrorParams(sigma_c0_m=0.2, tau_s=1e9)
    plan = MapPlan(bundled_map("straight"), scenarios_for([30.0], ["paper"]), frames=5, routes=1, start_lane=LANE,
                   distractors=False, seed=7, sensor=replace(IDEAL, lane_error=params))
    evaluator = MapEvaluator(plan)
    assert not evaluator.frames_independent
    assert MapEvaluator(replace(plan, sensor=IDEAL), graph=evaluator.graph).frames_independent
    collector = Collector()
    evaluator.run(collector)
    # the ego's chain: its own generator, drawn from the stationary N(0, σ²) at its first frame
    chain = np.random.default_rng([7, 13, 0, 0x46EC5170])  # zlib.crc32(b"ego")
    offsets = np.abs(chain.standard_normal((2, 4))[:, 0] * 0.2)
    for key, accumulator in collector.accumulators.items():
        if key.fusion != "local":
            continue
        side = 0 if key.boundary == "left" else 1
        assert len(accumulator.records) == 5
        for record in accumulator.records:
            np.testing.assert_allclose(record.errors_m, offsets[side], atol=1e-4)
