"""fusion.fuse_history: the coop's lane history bridges the gap (observed, not interpolated),
seams without a jump, the checks, and a history short of the gap."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

import fusion
from fusion.analytic import AnalyticRoad, Segment, bend_segments, detect, detect_lanes, with_history
from fusion.fusibility import relative_pose
from fusion.geometry import distance_to_polyline, transform

LANE = (0.0, -3.5)
CORNER = AnalyticRoad([Segment(80.0), *bend_segments(-1.0 / 12.0, math.pi / 2), Segment(200.0)])
CORNER_END_M = 80.0 + math.pi / 2 * 12.0  # the turn lies wholly inside [75, 75 + d_s] for d_s >= 24
STRAIGHT = AnalyticRoad([Segment(400.0)])


def _pair(road, s_end, d_s, history_m, noise_m=0.0, seed=0, lane=LANE):
    rng = np.random.default_rng(seed)
    ego = detect(road, s_end - 30.0, 30.0, *LANE, noise_m=noise_m, rng=rng)
    s_coop = s_end + d_s
    coop = detect(road, s_coop, 30.0, *lane, noise_m=noise_m, rng=rng)
    return ego, with_history(road, coop, s_coop, history_m, *lane)


def _errors(road, result, source=None):
    out = []
    for border, labels, offset in ((result.left, result.left_source, LANE[0]),
                                   (result.right, result.right_source, LANE[1])):
        points = border if source is None else border[labels == source]
        out.append(distance_to_polyline(points, road.border(offset)))
    return np.concatenate(out)


@pytest.mark.parametrize("d_s", [30.0, 40.0])
def test_history_covering_the_gap_reproduces_a_corner_inside_it(d_s):
    ego, coop = _pair(CORNER, 75.0, d_s, 100.0)
    result = fusion.fuse_history(ego, coop, interpolation="hermite")
    assert result.kind == "history" and not result.reason
    assert set(np.unique(result.left_source)) == {fusion.Source.EGO, fusion.Source.COOP_HISTORY, fusion.Source.COOP}
    assert _errors(CORNER, result).max() < 1e-3  # exact history: the lane to rounding
    # the same pair without history: the turn inside the gap is interpolated, off by decimetres
    plain = fusion.fuse(ego, coop, interpolation="hermite")
    assert plain.kind == "spline" and _errors(CORNER, plain).max() > 0.3


def test_noisy_history_keeps_the_detection_error():
    sigma = 0.05
    worst = []
    for seed in range(5):
        ego, coop = _pair(CORNER, 75.0, 30.0, 100.0, noise_m=sigma, seed=seed)
        noisy = np.random.default_rng(100 + seed)
        history = fusion.LaneHistory(*(b + noisy.normal(0.0, sigma, b.shape) for b in (coop.history.left,
                                                                                       coop.history.right)))
        result = fusion.fuse_history(ego, replace(coop, history=history))
        assert result.kind == "history"
        worst.append(_errors(CORNER, result, fusion.Source.COOP_HISTORY).max())
    # per-coordinate noise σ: a point is off by |N(0, σ)²| (≤ 5σ), plus the seam offsets (≤ 2·5σ·(1-w)...)
    assert max(worst) < 6 * sigma


def test_seams_have_no_jump_under_a_coop_pose_error():
    ego, coop = _pair(STRAIGHT, 100.0, 30.0, 100.0)
    shift = 0.4  # the coop believes it stands 0.4 m further left: its whole message moves
    p = coop.pose
    moved = replace(coop, pose=fusion.Pose2D(p.x - shift * math.sin(p.yaw), p.y + shift * math.cos(p.yaw), p.yaw))
    result = fusion.fuse_history(ego, moved)
    assert result.kind == "history"
    for border, labels, offset in ((result.left, result.left_source, LANE[0]),
                                   (result.right, result.right_source, LANE[1])):
        steps = np.hypot(*np.diff(border, axis=0).T)
        assert steps.max() < 0.1 * math.hypot(1.0, shift / 30.0) + 1e-9  # no jump, seams included
        gap = border[labels == fusion.Source.COOP_HISTORY]
        # closed form (road along x from the origin): the history lies 0.4 m left; the ego seam
        # offset −0.4 m fades linearly to 0 at the coop seam (x = 130), so the error grows
        # linearly from 0 at the ego end (x = 100) to the coop's own 0.4 m
        np.testing.assert_allclose(gap[:, 1] - offset, shift * (gap[:, 0] - 100.0) / 30.0, atol=1e-6)


def test_adjacent_lane_history_is_rejected_like_the_pair():
    ego, coop = _pair(STRAIGHT, 100.0, 30.0, 100.0, lane=(3.5, 0.0))
    result = fusion.fuse_history(ego, coop)
    pair = fusion.fuse(ego, replace(coop, history=None))
    assert result.kind == pair.kind == "none" and "another lane" in result.reason
    assert result.reason == pair.reason  # the pair's own check decides, not the history's
    np.testing.assert_array_equal(result.left, pair.left)


def _fork(d_s):
    """Ego on a straight main road whose 30 m detection passes a fork 15 m ahead (right turn,
    R 25 m, reported as a branch); coops ``d_s`` after the ego's end, each with 100 m of history."""
    main = AnalyticRoad([Segment(200.0)])
    branch = AnalyticRoad([Segment(15.0), Segment(25.0 * math.pi / 2, -1 / 25.0), Segment(100.0)])
    ego = detect(main, 0.0, 30.0, *LANE)
    seen = detect(branch, 15.0, 15.0, *LANE)
    fork = fusion.LaneBranch(*(transform(b, *relative_pose(ego.pose, seen.pose)) for b in (seen.left, seen.right)))
    ego = replace(ego, branches=(fork,))
    turning, straight = (with_history(road, detect(road, 30.0 + d_s, 30.0, *LANE), 30.0 + d_s, 100.0, *LANE)
                         for road in (branch, main))
    return ego, turning, straight


@pytest.mark.parametrize("d_s", [20.0, 30.0])
def test_a_coop_on_the_other_branch_is_rejected_like_the_pair(d_s):
    ego, turning, straight = _fork(d_s)
    result = fusion.fuse_history(ego, turning)
    pair = fusion.fuse(ego, replace(turning, history=None))
    assert result.kind == "none" and "other branch" in result.reason and result.reason == pair.reason
    fused = fusion.fuse_history(ego, straight)
    assert fused.kind == "history" and fused.confidence == fusion.fuse(ego, straight).confidence > 0.0


@pytest.mark.parametrize("past_m", [2.5, 3.0])
def test_ego_points_past_a_fork_give_way_to_the_history_of_the_branch(past_m):
    """The ego's detection ends ``past_m`` into a fork on its own straight lane; the coop took
    the right turn (reference radius 12 m, so the right border turns at 8.5 m) and its history
    covers the gap. Closed form: a border turning at radius r leaves the straight one by
    x²/(2r) at x metres past the fork. Those last ego points are not the coop's lane: they are
    dropped where they leave the history, and the fused lane follows the branch."""
    radius = 12.0
    main = AnalyticRoad([Segment(200.0)])
    branch = AnalyticRoad([Segment(60.0), Segment(radius * math.pi / 2, -1 / radius), Segment(100.0)])
    end = 60.0 + past_m
    ego = detect(main, end - 30.0, 30.0, *LANE)
    coop = with_history(branch, detect(branch, end + 20.0, 30.0, *LANE), end + 20.0, 100.0, *LANE)
    result = fusion.fuse_history(ego, coop, interpolation="hermite")
    assert result.kind == "history"
    ego_end = transform(ego.right[-1:], ego.pose.x, ego.pose.y, ego.pose.yaw)
    parting = distance_to_polyline(ego_end, branch.border(LANE[1]))[0]
    assert parting == pytest.approx(past_m**2 / (2 * (radius + LANE[1])), rel=0.1) and parting > 0.35
    assert int((result.right_source == fusion.Source.EGO).sum()) < ego.right.shape[0]  # those points are gone
    for border, offset in ((result.left, LANE[0]), (result.right, LANE[1])):
        assert distance_to_polyline(border, branch.border(offset)).max() < 0.26  # below the fork threshold
    assert distance_to_polyline(result.right, branch.border(LANE[1])).max() < 0.12


def test_noise_alone_never_cuts_the_ego_border():
    """σ = 5 cm on every detected and history point, coop on the ego's own straight lane:
    the fork test's five-point average stays far below its threshold, all ego points stay."""
    for seed in range(20):
        ego, coop = _pair(STRAIGHT, 100.0, 20.0, 100.0, noise_m=0.05, seed=seed)
        noisy = np.random.default_rng(200 + seed)
        history = fusion.LaneHistory(*(b + noisy.normal(0.0, 0.05, b.shape) for b in (coop.history.left,
                                                                                      coop.history.right)))
        result = fusion.fuse_history(ego, replace(coop, history=history))
        assert result.kind == "history"
        assert [int((src == fusion.Source.EGO).sum()) for src in (result.left_source, result.right_source)] == \
            [ego.left.shape[0], ego.right.shape[0]]


@pytest.mark.parametrize("k", [1e-4, 2e-3])
def test_a_history_bent_away_from_the_ego_lane_is_rejected(k):
    """Heading drift k (rad/m) bends the history sideways by k·u²/2 at u metres behind the coop
    (closed form on a straight). With d_s 20 m the ego's detection spans u = 20 … 50 m, so its
    offset from the history changes by k·(50² − 20²)/2 along their overlap: 0.105 m for a
    typical drift (fused), 2.1 m for k = 2·10⁻³ (more than half the 3.5 m lane: rejected,
    although the history joins the ego's end within 0.4 m)."""
    ego, coop = _pair(STRAIGHT, 100.0, 20.0, 100.0)
    bent = fusion.LaneHistory(*(b + np.column_stack((np.zeros(len(b)), k * b[:, 0] ** 2 / 2.0))
                                for b in (coop.history.left, coop.history.right)))
    result = fusion.fuse_history(ego, replace(coop, history=bent))
    change = k * (50.0**2 - 20.0**2) / 2.0
    if change < 1.75:
        assert result.kind == "history"
        return
    assert result.kind == "none" and "another lane" in result.reason and "half the lane width" in result.reason
    measured = float(re.search(r"by (\d+\.\d+) m", result.reason).group(1))
    # measured across the bent history, whose slope at the ego's start is k·50 m
    assert measured == pytest.approx(change * math.cos(math.atan(k * 50.0)), abs=0.006)


def test_neighbour_lanes_and_road_edges_survive_history_fusion():
    """Multi-lane detections (left lane of two, right neighbour and both road edges seen):
    the history bridges the gap, the association is the pair's (both edges agree: confidence
    1) and the matched neighbour lane is fused as well."""
    road = AnalyticRoad([Segment(300.0, 1 / 200.0)])
    ego = detect_lanes(road, 70.0, 30.0, 1, 2, 3.5)
    coop = detect_lanes(road, 130.0, 30.0, 1, 2, 3.5)
    coop = with_history(road, coop, 130.0, 100.0, 7.0, 3.5)
    assert coop.neighbours and coop.road_edges is not None  # with_history keeps them
    result = fusion.fuse_history(ego, coop, interpolation="hermite")
    pair = fusion.fuse(ego, coop, interpolation="hermite")
    assert result.kind == "history" and result.confidence == pair.confidence == 1.0
    (index, left, right), = result.lanes
    (_, pair_left, pair_right), = pair.lanes
    assert index == -1
    np.testing.assert_array_equal(left, pair_left)
    np.testing.assert_array_equal(right, pair_right)
    assert distance_to_polyline(left, road.border(3.5)).max() < 0.01


def test_history_short_of_the_gap_is_interpolated_only_where_missing():
    ego, coop = _pair(CORNER, 75.0, 30.0, 12.0)  # covers the last 12 m of the 30 m gap
    result = fusion.fuse_history(ego, coop, interpolation="hermite")
    assert result.kind == "spline"
    labels = set(np.unique(result.left_source))
    assert {fusion.Source.INTERPOLATED, fusion.Source.COOP_HISTORY} <= labels
    n_hist = int(np.count_nonzero(result.left_source == fusion.Source.COOP_HISTORY))
    assert abs(n_hist - 120) <= 2  # 12 m every 0.10 m
    assert _errors(CORNER, result, fusion.Source.COOP_HISTORY).max() < 1e-3
    labels = result.left_source
    runs = [int(v) for i, v in enumerate(labels) if i == 0 or labels[i - 1] != v]
    S = fusion.Source
    assert runs == [S.EGO, S.INTERPOLATED, S.COOP_HISTORY, S.COOP]


def test_without_history_it_is_fuse():
    ego = detect(CORNER, 45.0, 30.0, *LANE)
    coop = detect(CORNER, 105.0, 30.0, *LANE)
    a, b = fusion.fuse_history(ego, coop), fusion.fuse(ego, coop)
    np.testing.assert_array_equal(a.left, b.left)
    np.testing.assert_array_equal(a.right_source, b.right_source)


def test_history_must_be_a_lane_history():
    ego = detect(STRAIGHT, 0.0, 30.0, *LANE)
    with pytest.raises(fusion.InvalidDetectionError, match="history"):
        fusion.LaneDetection(ego.pose, ego.left, ego.right, history=(ego.left, ego.right))
    with pytest.raises(fusion.InvalidDetectionError, match="LaneHistory.left"):
        fusion.LaneHistory(np.full((3, 2), np.nan), ego.right)
