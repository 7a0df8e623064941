"""Sensor error models against closed forms and statistical bounds."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.simulation.sensor_errors import MAX_ERROR_M, SensorErrorModel, check_polyline
from gt_matching.polyline import arc_lengths as arc_length

STEP_M = 0.10


def straight_lane(heading: float = 0.0, length: float = 30.0, half_width: float = 1.75):
    """Borders of a straight lane from the origin along ``heading`` (vehicle frame)."""
    s = np.arange(0.0, length + STEP_M / 2, STEP_M)
    direction = np.array([math.cos(heading), math.sin(heading)])
    normal = np.array([-direction[1], direction[0]])
    centre = s[:, None] * direction
    return centre + half_width * normal, centre - half_width * normal, normal


def left_curve(radius: float, half_width: float = 1.75, length: float = 30.0):
    """Borders of a left curve centred at (0, radius), starting at the origin heading +x."""
    theta = np.arange(0.0, length / radius, STEP_M / radius)
    centre = np.array([0.0, radius])

    def ring(r):
        return centre + r * np.column_stack((np.sin(theta), -np.cos(theta)))

    return ring(radius - half_width), ring(radius + half_width), centre


@settings(max_examples=40, deadline=None)
@given(
    heading=st.floats(-math.pi, math.pi),
    offset=st.floats(-2.0, 2.0).filter(lambda d: abs(d) > 1e-3),
)
def test_offset_moves_every_point_by_d_along_the_normal_of_a_straight_lane(heading, offset):
    left, right, normal = straight_lane(heading)
    new_left, new_right = SensorErrorModel(lateral_offset_m=offset).apply(left, right, np.random.default_rng(0))
    np.testing.assert_allclose(new_left - left, np.broadcast_to(offset * normal, left.shape), atol=1e-9)
    np.testing.assert_allclose(new_right - right, np.broadcast_to(offset * normal, right.shape), atol=1e-9)


def test_offset_on_a_left_curve_changes_each_border_radius_by_d():
    radius, offset = 40.0, 0.5
    left, right, centre = left_curve(radius)
    new_left, new_right = SensorErrorModel(lateral_offset_m=offset).apply(left, right, np.random.default_rng(0))
    # A shift to the left moves towards the centre of a left curve.
    np.testing.assert_allclose(np.hypot(*(new_left - centre).T), radius - 1.75 - offset, atol=1e-5)
    np.testing.assert_allclose(np.hypot(*(new_right - centre).T), radius + 1.75 - offset, atol=1e-5)


def test_noise_is_along_the_normal_with_the_configured_sigma():
    sigma = 0.2
    left, right, _ = straight_lane(length=400.0)  # 4001 points per border
    new_left, new_right = SensorErrorModel(noise_sigma_m=sigma).apply(left, right, np.random.default_rng(7))
    residual = np.concatenate((new_left[:, 1] - left[:, 1], new_right[:, 1] - right[:, 1]))
    n = residual.size
    np.testing.assert_array_equal(new_left[:, 0], left[:, 0])  # nothing along the lane
    assert abs(residual.mean()) < 5 * sigma / math.sqrt(n)
    assert abs(residual.std(ddof=1) / sigma - 1) < 5 / math.sqrt(2 * n)
    # independent per point: neighbouring residuals are uncorrelated
    assert abs(np.corrcoef(residual[:-1], residual[1:])[0, 1]) < 5 / math.sqrt(n)


@settings(max_examples=40, deadline=None)
@given(angle=st.floats(-0.5, 0.5).filter(lambda a: abs(a) > 1e-6))
def test_heading_bias_rotates_about_the_sensor_origin(angle):
    left, right, _ = straight_lane()
    new_left, new_right = SensorErrorModel(heading_bias_rad=angle).apply(left, right, np.random.default_rng(0))
    for old, new in ((left, new_left), (right, new_right)):
        np.testing.assert_allclose(np.hypot(*new.T), np.hypot(*old.T), atol=1e-9)
        turned = np.arctan2(old[:, 0] * new[:, 1] - old[:, 1] * new[:, 0], (old * new).sum(axis=1))
        np.testing.assert_allclose(turned, angle, atol=1e-9)
    np.testing.assert_allclose(new_left[-1], [30 * math.cos(angle) - 1.75 * math.sin(angle),
                                              30 * math.sin(angle) + 1.75 * math.cos(angle)], atol=1e-9)


def test_range_jitter_only_truncates_with_half_normal_mean():
    sigma = 2.0
    left, right, centre = left_curve(60.0)
    model = SensorErrorModel(range_jitter_sigma_m=sigma)
    rng = np.random.default_rng(3)
    full = 0.5 * (arc_length(left)[-1] + arc_length(right)[-1])
    cuts = []
    for _ in range(2000):
        new_left, new_right = model.apply(left, right, rng)
        kept_left = arc_length(new_left)[-1] / arc_length(left)[-1]
        kept_right = arc_length(new_right)[-1] / arc_length(right)[-1]
        assert kept_left <= 1 + 1e-12 and kept_left == pytest.approx(kept_right, abs=1e-9)
        np.testing.assert_array_equal(new_left[:-1], left[: len(new_left) - 1])  # a prefix
        assert np.hypot(*(new_left[-1] - centre)) == pytest.approx(60.0 - 1.75, abs=1e-4)  # on the border
        cuts.append(full * (1 - kept_left))
    half_normal_mean = sigma * math.sqrt(2 / math.pi)
    half_normal_std = sigma * math.sqrt(1 - 2 / math.pi)
    assert abs(np.mean(cuts) - half_normal_mean) < 5 * half_normal_std / math.sqrt(len(cuts))


def test_range_jitter_longer_than_the_detection_drops_it():
    left, right, _ = straight_lane(length=0.5)
    model = SensorErrorModel(range_jitter_sigma_m=1000.0)
    results = [model.apply(left, right, np.random.default_rng(seed)) for seed in range(50)]
    assert sum(r is None for r in results) >= 45  # P(|N(0, 1000)| < 0.5) is 0.04 %


def test_drop_probability_is_respected():
    left, right, _ = straight_lane(length=1.0)
    rng = np.random.default_rng(11)
    model = SensorErrorModel(drop_probability=0.3)
    dropped = sum(model.apply(left, right, rng) is None for _ in range(4000))
    assert abs(dropped / 4000 - 0.3) < 5 * math.sqrt(0.3 * 0.7 / 4000)
    assert SensorErrorModel(drop_probability=1.0).apply(left, right, rng) is None


def test_same_seed_reproduces_and_other_seed_differs():
    left, right, _ = straight_lane()
    model = SensorErrorModel(lateral_offset_m=0.1, noise_sigma_m=0.05, heading_bias_rad=0.01,
                             range_jitter_sigma_m=1.0, drop_probability=0.1,
                             pose_sigma_xy_m=0.2, pose_sigma_yaw_rad=0.01)

    def run(seed):
        rng = np.random.default_rng(seed)
        out = []
        for _ in range(20):
            det = model.apply(left, right, rng)
            out.append(None if det is None else np.concatenate(det))
            out.append(np.array(model.perturb_pose(1.0, 2.0, 0.3, rng)))
        return out

    first, again, other = run(5), run(5), run(6)
    assert all((a is None and b is None) or np.array_equal(a, b) for a, b in zip(first, again))
    assert not all((a is None and b is None) or (a is not None and b is not None and a.shape == b.shape
                                                  and np.array_equal(a, b)) for a, b in zip(first, other))


def test_all_zero_model_is_the_identity_and_draws_nothing():
    left, right, _ = left_curve(30.0)
    rng = np.random.default_rng(1)
    state = rng.bit_generator.state
    new_left, new_right = SensorErrorModel().apply(left, right, rng)
    np.testing.assert_array_equal(new_left, left)
    np.testing.assert_array_equal(new_right, right)
    assert SensorErrorModel().perturb_pose(3.0, -4.0, 0.25, rng) == (3.0, -4.0, 0.25)
    assert rng.bit_generator.state == state


def test_pose_error_has_the_configured_sigmas():
    model = SensorErrorModel(pose_sigma_xy_m=0.5, pose_sigma_yaw_rad=0.02)
    rng = np.random.default_rng(9)
    poses = np.array([model.perturb_pose(10.0, 20.0, 1.0, rng) for _ in range(3000)])
    errors = poses - [10.0, 20.0, 1.0]
    bound = 5 / math.sqrt(2 * len(errors))
    for column, sigma in ((0, 0.5), (1, 0.5), (2, 0.02)):
        assert abs(errors[:, column].std(ddof=1) / sigma - 1) < bound
    assert abs(np.corrcoef(errors[:, 0], errors[:, 1])[0, 1]) < 5 / math.sqrt(len(errors))


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"noise_sigma_m": -0.1}, "noise_sigma_m: must be >= 0"),
        ({"drop_probability": 1.5}, "drop_probability: must be <= 1"),
        ({"lateral_offset_m": float("nan")}, "lateral_offset_m: expected a finite number"),
        ({"pose_sigma_yaw_rad": "0.1"}, "pose_sigma_yaw_rad: expected a finite number"),
        ({"noise_sigma_m": 1e308}, "noise_sigma_m: must be within ±1000 m"),
        ({"lateral_offset_m": -1000.5}, "lateral_offset_m: must be within ±1000 m"),
        ({"pose_sigma_xy_m": 1e4}, "pose_sigma_xy_m: must be within ±1000 m"),
        ({"range_jitter_sigma_m": 1e300}, "range_jitter_sigma_m: must be within ±1000 m"),
        ({"heading_bias_rad": -3.2}, "heading_bias_rad: must be within ±3.14159 rad"),
        ({"pose_sigma_yaw_rad": 7.0}, "pose_sigma_yaw_rad: must be within ±3.14159 rad"),
    ],
)
def test_invalid_model_parameters_are_named(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SensorErrorModel(**kwargs)


def test_invalid_detections_are_named():
    left, right, _ = straight_lane()
    model = SensorErrorModel(lateral_offset_m=0.1)
    bad = left.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="left: polyline contains NaN"):
        model.apply(bad, right, np.random.default_rng(0))
    with pytest.raises(ValueError, match=r"right: expected an \(N, 2\) polyline"):
        model.apply(left, right[:, 0], np.random.default_rng(0))
    stuck = np.array([[1.0, -1.75], [1.0, -1.75], [2.0, -1.75]])
    with pytest.raises(ValueError, match="right: repeated or reversing points"):
        model.apply(left, stuck, np.random.default_rng(0))
    with pytest.raises(ValueError, match="right: expected at least 2 points, got 0"):
        check_polyline("right", np.empty((0, 2)))


@pytest.mark.parametrize("field", ["lateral_offset_m", "noise_sigma_m", "range_jitter_sigma_m", "pose_sigma_xy_m"])
def test_the_largest_accepted_error_keeps_detections_finite(field):
    """At ``MAX_ERROR_M`` (the sign that is allowed, the pose σ too) every perturbed border
    point and pose stays finite: the bound is what keeps a σ of 1e308 from reaching the
    fusion as NaN."""
    model = SensorErrorModel(**{field: MAX_ERROR_M, "heading_bias_rad": -math.pi, "pose_sigma_yaw_rad": math.pi})
    rng = np.random.default_rng(4)
    x = np.linspace(0.0, 30.0, 301)
    left, right = np.column_stack((x, np.full_like(x, 1.75))), np.column_stack((x, np.full_like(x, -1.75)))
    for _ in range(50):
        borders = model.apply(left, right, rng)
        assert borders is None or all(np.isfinite(border).all() for border in borders)
        assert np.isfinite(model.perturb_pose(3.0e5, -2.0e6, 3.0, rng)).all()
