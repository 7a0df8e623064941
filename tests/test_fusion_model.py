"""Data model of fusion: validation of poses, detections and parameters; bad input."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusion
from fusion import FusionError, FusionParams, InvalidDetectionError, InvalidParameterError, LaneDetection, Pose2D
from fusion.geometry import to_world

STRAIGHT = np.column_stack((np.arange(0.0, 30.0, 0.1), np.full(300, 2.0)))


def lane(x0: float = 0.0, pose: Pose2D = Pose2D(0.0, 0.0, 0.0)) -> LaneDetection:
    return LaneDetection(pose, STRAIGHT + (x0, 0.0), STRAIGHT + (x0, -4.0))


@pytest.mark.parametrize("value", [math.nan, math.inf, "1", None])
def test_pose_rejects_non_finite_or_non_numeric(value: object) -> None:
    with pytest.raises(InvalidDetectionError, match="Pose2D.yaw"):
        Pose2D(0.0, 0.0, value)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("border", "message"),
    [
        (np.empty((0, 2)), "at least 2 distinct points"),
        (np.array([[1.0, 2.0]]), "at least 2 distinct points"),
        (np.array([[1.0, 2.0], [1.0, 2.0], [1.0, 2.0]]), "at least 2 distinct points"),
        (np.array([[0.0, 0.0], [np.nan, 1.0]]), "NaN or inf"),
        (np.array([[0.0, 0.0], [np.inf, 1.0]]), "NaN or inf"),
        (np.zeros((4, 3)), r"shape \(N, 2\)"),
        (np.zeros(4), r"shape \(N, 2\)"),
        ([["a", "b"], ["c", "d"]], "not numeric"),
    ],
)
def test_detection_rejects_malformed_border_naming_it(border: object, message: str) -> None:
    with pytest.raises(InvalidDetectionError, match=f"LaneDetection.left.*{message}|{message}") as info:
        LaneDetection(Pose2D(0, 0, 0), border, STRAIGHT)  # type: ignore[arg-type]
    assert "LaneDetection.left" in str(info.value)
    assert isinstance(info.value, FusionError)


def test_detection_drops_consecutive_duplicates_and_freezes_arrays() -> None:
    doubled = np.repeat(STRAIGHT, 2, axis=0)
    det = LaneDetection(Pose2D(0, 0, 0), doubled, STRAIGHT[:100])
    assert det.left.shape == STRAIGHT.shape
    np.testing.assert_array_equal(det.left, STRAIGHT)
    assert det.right.shape == (100, 2)
    with pytest.raises(ValueError):
        det.left[0, 0] = 5.0
    doubled[0, 0] = 99.0
    assert det.left[0, 0] == 0.0


def test_detection_requires_pose() -> None:
    with pytest.raises(InvalidDetectionError, match="LaneDetection.pose"):
        LaneDetection((0, 0, 0), STRAIGHT, STRAIGHT)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("field", "value"),
    [("t_pos_m", 0.0), ("d_i_m", -1.0), ("spacing_m", math.nan), ("w_coop", 1.5), ("apex_ratio", -0.1),
     ("convoy_strategy", "median"), ("fusibility", "loose"), ("heading_window_m", 0.0)],
)
def test_params_reject_out_of_range_naming_field(field: str, value: object) -> None:
    with pytest.raises(InvalidParameterError, match=f"FusionParams.{field}"):
        FusionParams(**{field: value})


def test_coop_weight_per_strategy() -> None:
    assert FusionParams().coop_weight == 0.75
    assert FusionParams(convoy_strategy="mean").coop_weight == 0.5
    assert FusionParams(convoy_strategy="nearest").coop_weight == 1.0


def test_fuse_rejects_unknown_mode_interpolation_and_types() -> None:
    ego, coop = lane(), lane(40.0)
    with pytest.raises(InvalidParameterError, match="mode"):
        fusion.fuse(ego, coop, mode="merge")
    with pytest.raises(InvalidParameterError, match="interpolation"):
        fusion.fuse(ego, coop, interpolation="linear")
    with pytest.raises(InvalidDetectionError, match="coop must be a LaneDetection"):
        fusion.fuse(ego, STRAIGHT)  # type: ignore[arg-type]
    with pytest.raises(InvalidParameterError, match="params"):
        fusion.fuse(ego, coop, params={"d_i_m": 10})  # type: ignore[arg-type]


def test_to_world_rotates_counter_clockwise_and_translates() -> None:
    pts = np.array([[1.0, 0.0], [0.0, 1.0]])
    out = to_world(pts, Pose2D(10.0, 5.0, math.pi / 2))
    np.testing.assert_allclose(out, [[10.0, 6.0], [9.0, 5.0]], atol=1e-12)


def test_unfusible_result_is_the_ego_lane_in_world_frame() -> None:
    pose = Pose2D(100.0, 50.0, 0.3)
    ego = lane(pose=pose)
    behind = lane(pose=Pose2D(90.0, 50.0, 0.3))
    result = fusion.fuse(ego, behind)
    assert result.kind == "none"
    assert "not ahead" in result.reason
    np.testing.assert_allclose(result.left, to_world(ego.left, pose))
    assert (result.left_source == fusion.Source.EGO).all()
    assert np.isfinite(result.gap_m)


def test_detection_sigma_follows_the_points_it_keeps_and_is_validated() -> None:
    left = np.array([[0.0, 1.0], [0.0, 1.0], [1.0, 1.0], [2.0, 1.0]])  # a duplicate, dropped
    right = np.array([[0.0, -1.0], [1.0, -1.0]])
    detection = LaneDetection(Pose2D(0.0, 0.0, 0.0), left, right, left_sigma=[0.1, 0.2, 0.3, 0.4],
                              right_sigma=np.zeros(2), pose_cov=np.diag([0.01, 0.01, 1e-4]))
    assert detection.left_sigma.tolist() == [0.1, 0.3, 0.4]
    assert detection.left_sigma.shape[0] == detection.left.shape[0]
    model = LaneDetection(Pose2D(0.0, 0.0, 0.0), left, right, lane_model_sigma=(0.05, 0.002, 4e-5, 0.0))
    assert model.lane_model_sigma.tolist() == [0.05, 0.002, 4e-5, 0.0] and not model.lane_model_sigma.flags.writeable
    for bad in ({"left_sigma": [0.1]}, {"right_sigma": [0.1, -0.1]}, {"right_sigma": [0.1, np.nan]},
                {"pose_cov": np.eye(2)}, {"pose_cov": np.array([[1.0, 2, 0], [0, 1, 0], [0, 0, 1]])},
                {"pose_cov": -np.eye(3)}, {"lane_model_sigma": [0.05, 0.002, 4e-5]},
                {"lane_model_sigma": [0.05, -0.002, 0.0, 0.0]}, {"lane_model_sigma": [np.inf, 0.0, 0.0, 0.0]}):
        with pytest.raises(InvalidDetectionError, match="LaneDetection"):
            LaneDetection(Pose2D(0.0, 0.0, 0.0), left, right, **bad)


def test_detection_end_reason_is_one_of_the_known_reasons_or_none() -> None:
    """``end_reason`` defaults to None; a known reason is kept (also by ``trusted``); anything
    else is refused with an error naming the field."""
    base = lane()
    assert base.end_reason is None
    for reason in fusion.types.END_REASONS:
        assert LaneDetection(base.pose, base.left, base.right, end_reason=reason).end_reason == reason
        trusted = LaneDetection.trusted(base.pose, base.points, base.left.shape[0], end_reason=reason)
        assert trusted.end_reason == reason
    assert set(fusion.types.END_REACHED) | set(fusion.types.END_EARLY) == set(fusion.types.END_REASONS)
    assert not set(fusion.types.END_REACHED) & set(fusion.types.END_EARLY)
    for bad in ("", "Range", "unmarked ", 3):
        with pytest.raises(InvalidDetectionError, match="LaneDetection.end_reason"):
            LaneDetection(base.pose, base.left, base.right, end_reason=bad)
