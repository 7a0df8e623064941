"""Property tests (hypothesis): finiteness, order, gap spacing, convoy between inputs, no stray errors."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import fusion
from fusion import FusionError, LaneDetection, Pose2D, Source
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.geometry import distance_to_polyline

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])

MAX_TURN_RAD = math.pi / 2  # the fusion refuses a coop heading over 90° + t_psi from the ego's


def turn_road(k: float, turn: float, entry: float) -> AnalyticRoad:
    """Straight, clothoid of length ``entry`` into curvature ``k`` (1/m), arc, clothoid out, straight.
    The two clothoids turn |k|·entry together, so the arc turns the rest of ``turn`` (rad), at least
    1 m: the whole road turns max(turn, |k|·(entry + 1)) ≤ ``MAX_TURN_RAD`` for the strategy's ranges."""
    arc_m = max(1.0, (turn - abs(k) * entry) / abs(k))
    return AnalyticRoad([Segment(80.0), Segment(entry, 0.0, k), Segment(arc_m, k),
                         Segment(entry, k, 0.0), Segment(120.0)])  # ≥ s_end + gap + 30 m


roads = st.builds(
    turn_road,
    k=st.floats(1 / 60.0, 1 / 18.0).flatmap(lambda k: st.sampled_from([k, -k])),
    turn=st.floats(0.05, MAX_TURN_RAD),
    entry=st.floats(0.5, 15.0),
)


@SETTINGS
@given(road=roads)
def test_generated_roads_turn_at_most_a_right_angle(road: AnalyticRoad) -> None:
    assert abs(road.heading[-1] - road.heading[0]) <= MAX_TURN_RAD + 1e-9


def along(points: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Index of the nearest truth vertex (5 mm apart) of every point."""
    from scipy.spatial import cKDTree

    return cKDTree(truth).query(points)[1]


@SETTINGS
@given(road=roads, s_end=st.floats(40.0, 120.0), gap=st.floats(-25.0, 45.0),
       interpolation=st.sampled_from(["paper", "hermite"]))
def test_fused_lane_is_finite_ordered_and_densely_sampled(road: AnalyticRoad, s_end: float, gap: float,
                                                         interpolation: str) -> None:
    ego = detect(road, s_end - 30.0, 30.0, 0.0, -4.0)
    coop = detect(road, s_end + gap, 30.0, 0.0, -4.0)
    result = fusion.fuse(ego, coop, interpolation=interpolation)
    if abs(gap) > 0.5:
        assert result.kind == ("convoy" if gap < 0 else "spline"), result.reason
    for border, source, offset in ((result.left, result.left_source, 0.0), (result.right, result.right_source, -4.0)):
        assert np.isfinite(border).all()
        assert border.shape[0] == source.shape[0]
        idx = along(border, road.border(offset))
        assert np.diff(idx).min() >= 0, "points not ordered in driving direction"
        inside = source == Source.INTERPOLATED
        if inside.any():
            around = inside | np.roll(inside, 1) | np.roll(inside, -1)
            assert np.hypot(*np.diff(border[around], axis=0).T).max() <= 0.10 + 1e-3


@SETTINGS
@given(road=roads, s_end=st.floats(40.0, 120.0), overlap=st.floats(1.0, 25.0), shift=st.floats(-0.15, 0.15),
       strategy=st.sampled_from(["weighted", "mean", "nearest"]))
def test_convoy_overlap_lies_between_its_inputs(road: AnalyticRoad, s_end: float, overlap: float, shift: float,
                                                strategy: str) -> None:
    ego = detect(road, s_end - 30.0, 30.0, 0.0, -4.0)
    coop = detect(road, s_end - overlap, 30.0, shift, -4.0 + shift)  # same lane, borders shifted laterally
    result = fusion.fuse(ego, coop, params=fusion.FusionParams(convoy_strategy=strategy))
    assert result.kind == "convoy", result.reason
    for border, source, offset in ((result.left, result.left_source, 0.0), (result.right, result.right_source, -4.0)):
        fused = border[source == Source.FUSED]
        assert fused.shape[0] > 0
        d_ego = distance_to_polyline(fused, road.border(offset))
        d_coop = distance_to_polyline(fused, road.border(offset + shift))
        assert (d_ego + d_coop).max() <= abs(shift) + 2.5e-4  # + twice the chord sagitta 0.1²/(8·14 m)


finite = st.floats(-60.0, 60.0, allow_nan=False, allow_infinity=False)
borders = st.integers(2, 40).flatmap(lambda n: arrays(np.float64, (n, 2), elements=finite))
poses = st.builds(Pose2D, finite, finite, st.floats(-math.pi, math.pi))


@SETTINGS
@given(ego_pose=poses, coop_pose=poses, el=borders, er=borders, cl=borders, cr=borders,
       mode=st.sampled_from(["auto", "convoy", "spline"]), interpolation=st.sampled_from(["paper", "hermite"]),
       fusibility=st.sampled_from(["geometric", "paper"]))
def test_arbitrary_input_gives_finite_output_or_a_fusion_error(ego_pose, coop_pose, el, er, cl, cr, mode,
                                                               interpolation, fusibility) -> None:
    try:
        ego, coop = LaneDetection(ego_pose, el, er), LaneDetection(coop_pose, cl, cr)
        loose = fusion.FusionParams(fusibility=fusibility, d_i_m=500.0, t_pos_m=50.0, t_psi_rad=3.0)
        result = fusion.fuse(ego, coop, mode=mode, interpolation=interpolation, params=loose)
        ok, reason = fusion.is_fusible(ego, coop, fusion.FusionParams(fusibility=fusibility), mode=mode)
    except FusionError:
        return
    assert ok == (not reason)
    assert result.kind in ("convoy", "spline", "none")
    assert (result.kind == "none") == bool(result.reason)
    for array in (result.left, result.right):
        assert np.isfinite(array).all()
    assert np.isfinite(result.gap_m)
