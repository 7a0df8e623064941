"""Fusibility: the paper's pose cases (in our right-handed frame) and the curve-aware default."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusion
from fusion import FusionParams, LaneDetection, Pose2D
from fusion.analytic import AnalyticRoad, Segment, detect

PAPER = FusionParams(fusibility="paper")


def straight_detection(pose: Pose2D, length: float = 30.0) -> LaneDetection:
    x = np.arange(0.0, length + 1e-9, 0.1)
    return LaneDetection(pose, np.column_stack((x, np.full_like(x, 2.0))), np.column_stack((x, np.full_like(x, -2.0))))


EGO = straight_detection(Pose2D(0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    "coop_pose",
    [Pose2D(45.0, 0.3, math.radians(8.0)),       # ahead, same direction
     Pose2D(48.0, -15.0, math.radians(-95.0)),   # ahead-right turning right: y_rel < 0, Ψ_rel ≈ −90°
     Pose2D(48.0, 15.0, math.radians(85.0))],    # ahead-left turning left: y_rel > 0, Ψ_rel ≈ +90°
    ids=["ahead", "ahead-right", "ahead-left"],
)
def test_paper_cases_accepted(coop_pose: Pose2D) -> None:
    assert fusion.is_fusible(EGO, straight_detection(coop_pose), PAPER) == (True, "")


@pytest.mark.parametrize(
    ("coop_pose", "reason"),
    [(Pose2D(45.0, 0.5, 0.0), "matches none"),                       # |y_rel| > t_pos
     (Pose2D(45.0, 0.0, math.radians(11.0)), "matches none"),         # |Ψ_rel| > t_Ψ
     (Pose2D(48.0, 15.0, math.radians(-90.0)), "matches none"),       # the paper's left-handed "right"
     (Pose2D(48.0, -15.0, math.radians(90.0)), "matches none"),
     (Pose2D(-10.0, 0.0, 0.0), "not ahead"),
     (Pose2D(90.0, 0.0, 0.0), "exceeds d_i"),
     (Pose2D(30.0, 0.0, 0.0), "d_s must be > 0")],
    ids=["lateral", "heading", "mirrored-right", "mirrored-left", "behind", "beyond-d_i", "zero-gap"],
)
def test_paper_rejections(coop_pose: Pose2D, reason: str) -> None:
    ok, why = fusion.is_fusible(EGO, straight_detection(coop_pose), PAPER, mode="spline")
    assert not ok
    assert reason in why


@pytest.fixture(scope="module")
def curve() -> AnalyticRoad:
    """90° right curve, reference radius 20 m; lanes: right (0, −4), left/oncoming (4, 0)."""
    return AnalyticRoad([Segment(60.0), Segment(math.pi / 2 * 20.0, -1 / 20.0), Segment(60.0)])


APEX = 60.0 + math.pi / 4 * 20.0


def test_same_lane_mid_curve_geometric_accepts_where_paper_rejects(curve: AnalyticRoad) -> None:
    ego = detect(curve, APEX - 40.0, 30.0, 0.0, -4.0)
    coop = detect(curve, APEX + 10.0, 30.0, 0.0, -4.0)
    assert fusion.is_fusible(ego, coop) == (True, "")
    ok, reason = fusion.is_fusible(ego, coop, PAPER)
    assert not ok and "matches none" in reason
    assert fusion.fuse(ego, coop).kind == "spline"


@pytest.mark.parametrize("s_end", [40.0, 55.0, 60.0, 65.0, 70.0, 80.0, 90.0])
@pytest.mark.parametrize("gap", [10.0, 20.0, 40.0])
def test_geometric_accepts_the_same_lane_along_the_curve(curve: AnalyticRoad, s_end: float, gap: float) -> None:
    ego = detect(curve, s_end - 30.0, 30.0, 0.0, -4.0)
    coop = detect(curve, s_end + gap, 30.0, 0.0, -4.0)
    assert fusion.is_fusible(ego, coop) == (True, "")


@pytest.mark.parametrize(
    ("s_end", "gap"),
    [(30.0, 10.0), (30.0, 20.0), (35.0, 15.0), (95.0, 10.0), (100.0, 20.0),   # straight before / after
     (65.0, 10.0), (70.0, 10.0), (75.0, 10.0), (80.0, 10.0)],                 # both ends in the curve
)
def test_geometric_rejects_the_adjacent_lane(curve: AnalyticRoad, s_end: float, gap: float) -> None:
    ego = detect(curve, s_end - 30.0, 30.0, 0.0, -4.0)
    for offsets in ((4.0, 0.0), (-4.0, -8.0)):
        coop = detect(curve, s_end + gap, 30.0, *offsets)
        ok, reason = fusion.is_fusible(ego, coop)
        assert not ok and "another lane" in reason, offsets


def test_geometric_rejects_opposite_direction_behind_and_beyond(curve: AnalyticRoad) -> None:
    ego = detect(curve, 10.0, 30.0, 0.0, -4.0)
    road_back = AnalyticRoad([Segment(200.0)], x0=200.0, yaw0=math.pi)
    oncoming = detect(road_back, 150.0, 30.0, -4.0, 0.0)  # other direction, starts 10 m ahead
    ok, reason = fusion.is_fusible(ego, oncoming)
    assert not ok and "not the same direction" in reason
    behind = detect(curve, 0.0, 5.0, 0.0, -4.0)
    ok, reason = fusion.is_fusible(ego, behind)
    assert not ok and "not ahead" in reason
    far = detect(curve, 120.0, 30.0, 0.0, -4.0)  # centre-line gap 60 m
    ok, reason = fusion.is_fusible(ego, far)
    assert not ok and "exceeds d_i" in reason
    assert fusion.fuse(ego, far).kind == "none"


def test_geometric_rejects_lateral_offset_on_a_straight() -> None:
    ok, reason = fusion.is_fusible(EGO, straight_detection(Pose2D(45.0, 3.5, 0.0)))
    assert not ok and "another lane" in reason
    assert fusion.is_fusible(EGO, straight_detection(Pose2D(45.0, 0.5, 0.0))) == (True, "")
