"""Convoy fusion (paper sec. III-A): overlap, weighted mean by arc length, blending, strategies."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusion
from fusion import FusionParams, LaneDetection, Pose2D, Source
from fusion.analytic import AnalyticRoad, Segment, detect, distance_to_polyline


def straight_lane(x_start: float, length: float, spacing: float, y_left: float, y_right: float) -> LaneDetection:
    """Vehicle at (x_start, 0) heading east; borders at y_left / y_right in the vehicle frame."""
    x = np.arange(0.0, length + 1e-9, spacing)
    return LaneDetection(Pose2D(x_start, 0.0, 0.0), np.column_stack((x, np.full_like(x, y_left))),
                         np.column_stack((x, np.full_like(x, y_right))))


def test_weighted_overlap_is_quarter_ego_three_quarters_coop() -> None:
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    coop = straight_lane(20.0, 30.0, 0.1, 2.1, -1.9)
    result = fusion.fuse(ego, coop)
    assert result.kind == "convoy"
    assert result.gap_m == pytest.approx(-math.hypot(10.0, 0.1))
    fused = result.left[result.left_source == Source.FUSED]
    assert fused.shape[0] == pytest.approx(100, abs=1)
    np.testing.assert_allclose(fused[:, 1], 0.25 * 2.0 + 0.75 * 2.1, atol=1e-12)
    assert fused[0, 0] == pytest.approx(20.0, abs=0.1)
    assert fused[-1, 0] == pytest.approx(30.0, abs=0.1)
    np.testing.assert_allclose(result.left[result.left_source == Source.EGO][:, 1], 2.0)
    coop_part = result.left[result.left_source == Source.COOP]
    np.testing.assert_allclose(coop_part[:, 1], 2.1)
    assert coop_part[-1, 0] == pytest.approx(50.0)
    assert result.left[-1, 0] == pytest.approx(50.0)


@pytest.mark.parametrize(("strategy", "y"), [("mean", 2.05), ("nearest", 2.1)])
def test_mean_and_nearest_strategies(strategy: str, y: float) -> None:
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    coop = straight_lane(15.0, 30.0, 0.1, 2.1, -1.9)
    result = fusion.fuse(ego, coop, params=FusionParams(convoy_strategy=strategy))
    np.testing.assert_allclose(result.left[result.left_source == Source.FUSED][:, 1], y, atol=1e-12)


def test_pairs_points_by_arc_length_not_index() -> None:
    # Coop sampled every 0.07 m along x with a lateral ramp y = 2 + 0.01·u: pairing by index
    # would take the coop point at 0.07·i instead of the one at the same arc length 0.1·i.
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    u = np.arange(0.0, 30.0, 0.07)
    ramp = np.column_stack((u, 0.01 * u))
    coop = LaneDetection(Pose2D(20.0, 0.0, 0.0), ramp + (0.0, 2.0), ramp + (0.0, -2.0))
    result = fusion.fuse(ego, coop, params=FusionParams(convoy_blend_offset_m=1.0))
    fused = result.left[result.left_source == Source.FUSED]
    # coop point paired with ego x lies at arc length s = (x − 20)·sqrt(1 + 1e-4) − tiny; y ≈ 2 + 0.01·(x − 20)
    s = fused[:, 0] - 20.0  # before weighting x is exact for the ego part
    expected_y = 0.25 * 2.0 + 0.75 * (2.0 + 0.01 * s / math.sqrt(1.0001))
    np.testing.assert_allclose(fused[:, 1], expected_y, atol=2e-4)


def test_large_offset_blends_linearly_without_jump() -> None:
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    coop = straight_lane(20.0, 30.0, 0.1, 2.5, -1.5)
    result = fusion.fuse(ego, coop, params=FusionParams(convoy_blend_offset_m=0.2))
    fused = result.left[result.left_source == Source.FUSED]
    w = (fused[:, 0] - 20.0) / 10.0
    np.testing.assert_allclose(fused[:, 1], 2.0 + 0.5 * w, atol=1e-9)
    steps = np.hypot(*np.diff(result.left, axis=0).T)
    assert steps.max() <= 0.1 * math.hypot(1, 0.05) + 1e-9
    # same offset below the threshold: fixed weights, hence a 0.375 m jump at the overlap start
    fixed = fusion.fuse(ego, coop, params=FusionParams(convoy_blend_offset_m=1.0))
    assert np.hypot(*np.diff(fixed.left, axis=0).T).max() == pytest.approx(math.hypot(0.1, 0.375), abs=0.01)


def test_convoy_on_curve_matches_truth_and_extends_range() -> None:
    road = AnalyticRoad([Segment(20.0), Segment(math.pi / 2 * 20.0, -1 / 20.0), Segment(40.0)])
    ego = detect(road, 5.0, 30.0, 0.0, -4.0)
    coop = detect(road, 22.0, 30.0, 0.0, -4.0)
    result = fusion.fuse(ego, coop)
    assert result.kind == "convoy"
    for border, offset in ((result.left, 0.0), (result.right, -4.0)):
        assert distance_to_polyline(border, road.border(offset)).max() < 0.005
    # ego covers s in [5, 35], coop [22, 52]: the fused right border (radius 16 in the curve)
    assert result.right.shape[0] > ego.right.shape[0] * 1.4


def test_adjacent_lane_and_opposite_direction_are_not_convoy() -> None:
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    adjacent = straight_lane(15.0, 30.0, 0.1, 6.0, 2.0)
    ok, reason = fusion.is_fusible(ego, adjacent)
    assert not ok and "no overlap on the same lane" in reason
    x = np.arange(0.0, 30.0, 0.1)
    opposite = LaneDetection(Pose2D(25.0, 0.0, math.pi), np.column_stack((x, np.full_like(x, -2.0))),
                             np.column_stack((x, np.full_like(x, 2.0))))
    result = fusion.fuse(ego, opposite, mode="convoy")
    assert result.kind == "none"
    assert "deg" in result.reason or "not ahead" in result.reason


def test_convoy_mode_with_a_gap_is_rejected_and_zero_gap_concatenates() -> None:
    ego = straight_lane(0.0, 30.0, 0.1, 2.0, -2.0)
    far = straight_lane(40.0, 30.0, 0.1, 2.0, -2.0)
    result = fusion.fuse(ego, far, mode="convoy")
    assert result.kind == "none" and "no overlap" in result.reason
    touching = straight_lane(30.0, 30.0, 0.1, 2.0, -2.0)
    joined = fusion.fuse(ego, touching)
    assert joined.kind == "convoy"
    assert np.isfinite(joined.left).all()
    assert np.diff(joined.left[:, 0]).min() > 0.0
    assert joined.left[-1, 0] == pytest.approx(60.0)


def test_coop_tail_kept_where_the_overlap_end_rounds_below_the_ego_end() -> None:
    """The coop continues past the ego's end even when s0 + (s_end − s0) rounds one ulp below s_end."""
    from fusion.convoy import OverlapStart, convoy_border
    x = np.linspace(0.0, 31.3, 314)
    ego = np.column_stack((x, np.full_like(x, 2.0)))
    s0 = 14.409121793547266
    assert s0 + (x[-1] - s0) < x[-1]
    coop = np.column_stack((s0 + x, np.full_like(x, 2.0)))
    parts = convoy_border(ego, coop, x, OverlapStart(x, s0, 0.0, 0.0), 0.75, 0.5)
    assert [source for _, source, _ in parts] == [Source.EGO, Source.FUSED, Source.COOP]
    border = np.concatenate([points for points, _, _ in parts])
    assert border[-1, 0] == pytest.approx(s0 + 31.3)
    assert np.all(np.diff(border[:, 0]) > 0.0)
