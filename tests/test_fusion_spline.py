"""Spline fusion (paper sec. III-B): spline system, apex, Hermite arc, analytic lanes with truth."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

import fusion
from fusion import FusionParams, LaneDetection, Pose2D, Source
from fusion.analytic import AnalyticRoad, Segment, detect, distance_to_polyline
from fusion.spline import estimate_apex, hermite_gap, natural_spline_moments

R_REF = 20.0
LANE = (0.0, -4.0)  # right-hand lane of a right curve: borders at radius 20 and 16


@pytest.fixture(scope="module")
def right_curve() -> AnalyticRoad:
    """The paper's 90° right curve of reference radius 20 m between two straights."""
    return AnalyticRoad([Segment(60.0), Segment(math.pi / 2 * R_REF, -1.0 / R_REF), Segment(60.0)])


def gap_errors(road: AnalyticRoad, s_end: float, s_coop: float, interpolation: str, noise: float = 0.0,
               seed: int = 0, offsets: tuple[float, float] = LANE, **params: object) -> tuple[float, float]:
    """Max distance of the interpolated points of each border from the true border."""
    rng = np.random.default_rng(seed)
    ego = detect(road, s_end - 30.0, 30.0, *offsets, noise_m=noise, rng=rng)
    coop = detect(road, s_coop, 30.0, *offsets, noise_m=noise, rng=rng)
    result = fusion.fuse(ego, coop, mode="spline", interpolation=interpolation, params=FusionParams(**params))
    assert result.kind == "spline", result.reason
    errors = []
    for border, source, offset in ((result.left, result.left_source, offsets[0]),
                                   (result.right, result.right_source, offsets[1])):
        inside = source == Source.INTERPOLATED
        gap = border[inside]
        with_ends = inside | np.roll(inside, 1) | np.roll(inside, -1) if noise == 0.0 else inside
        assert np.hypot(*np.diff(border[with_ends], axis=0).T).max() <= 0.10 + 1e-3
        errors.append(float(distance_to_polyline(gap, road.border(offset)).max()))
    return errors[0], errors[1]


def test_natural_spline_moments_match_scipy() -> None:
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.2, 3.0, 6))
    y = rng.normal(size=(6, 2))
    reference = CubicSpline(t, y, bc_type="natural")(t, 2)
    for axis in (0, 1):
        moments = natural_spline_moments(np.diff(t).tolist(), y[:, axis].tolist())
        np.testing.assert_allclose(moments, reference[:, axis], atol=1e-10)


def test_apex_closed_form_for_a_right_angle() -> None:
    apex = estimate_apex((0.0, 0.0), (1.0, 0.0), (16.0, -16.0), (0.0, -1.0), 0.4)
    # P_i = (16, 0), P_j = chord midpoint (8, -8): P_c = P_i + 0.4·(P_j − P_i)
    np.testing.assert_allclose(apex, [12.8, -3.2], atol=1e-12)
    assert estimate_apex((0.0, 0.0), (1.0, 0.0), (10.0, 1.0), (1.0, 0.0), 0.4) is None
    # tangents meeting behind the ego end: no curve between them
    assert estimate_apex((0.0, 0.0), (1.0, 0.0), (10.0, -5.0), (0.6, 0.8), 0.4) is None


@pytest.mark.parametrize("turn_deg", [15.0, 60.0, 90.0, 120.0])
def test_hermite_reproduces_a_circular_arc(turn_deg: float) -> None:
    radius, theta = 16.0, math.radians(turn_deg)
    p3 = np.array([radius * math.sin(theta), -radius * (1 - math.cos(theta))])
    d1 = np.array([math.cos(theta), -math.sin(theta)])
    pts = hermite_gap(np.zeros(2), np.array([1.0, 0.0]), p3, d1, 0.1)
    np.testing.assert_allclose(np.hypot(pts[:, 0], pts[:, 1] + radius), radius, atol=1e-9)
    steps = np.hypot(*np.diff(np.vstack(([0.0, 0.0], pts, p3)), axis=0).T)
    assert steps.max() <= 0.1 + 1e-9
    assert len(pts) == math.ceil(radius * theta / 0.1) - 1


def test_hermite_reproduces_straight_then_arc() -> None:
    # 5 m straight, then a 90° arc of radius 10: the longer tangent leg carries the straight
    pts = hermite_gap(np.zeros(2), np.array([1.0, 0.0]), np.array([15.0, -10.0]), np.array([0.0, -1.0]), 0.1)
    on_line = pts[pts[:, 0] <= 5.0]
    np.testing.assert_allclose(on_line[:, 1], 0.0, atol=1e-12)
    on_arc = pts[pts[:, 0] > 5.0]
    np.testing.assert_allclose(np.hypot(on_arc[:, 0] - 5.0, on_arc[:, 1] + 10.0), 10.0, atol=1e-9)


def test_paper_90_degree_curve_reproduces_the_papers_error(right_curve: AnalyticRoad) -> None:
    apex = 60.0 + math.pi / 4 * R_REF
    left, right = gap_errors(right_curve, apex - 10.0, apex + 10.0, "paper")
    # paper, Table II: 0.693 / 0.707 m; this set-up gives 0.74 / 0.60 m (see docs/fusion/spline.md)
    assert 0.5 <= right <= 0.8
    assert 0.6 <= left <= 0.9
    # the paper's Fig. 4a (about 2.4 m without apex) needs a knot-index parameter: then the
    # spline is far too flat, and the apex brings it back to the same 0.74 / 0.60 m
    flat = gap_errors(right_curve, apex - 10.0, apex + 10.0, "paper", apex_min_turn_rad=math.pi,
                      spline_parameter="uniform")
    assert 1.8 <= min(flat) and max(flat) <= 2.7
    uniform = gap_errors(right_curve, apex - 10.0, apex + 10.0, "paper", spline_parameter="uniform")
    assert uniform == pytest.approx((left, right), abs=0.02)
    # with chord length the spline alone is already close (the apex then costs accuracy)
    chord_only = gap_errors(right_curve, apex - 10.0, apex + 10.0, "paper", apex_min_turn_rad=math.pi)
    assert max(chord_only) <= 0.2


def test_hermite_meets_its_goals_on_the_90_degree_curve(right_curve: AnalyticRoad) -> None:
    apex = 60.0 + math.pi / 4 * R_REF
    assert max(gap_errors(right_curve, apex - 10.0, apex + 10.0, "hermite")) <= 0.15
    noisy = [max(gap_errors(right_curve, apex - 10.0, apex + 10.0, "hermite", noise=0.05, seed=s)) for s in range(5)]
    assert max(noisy) <= 0.3


@pytest.mark.parametrize(
    ("segments", "s_end", "bound_paper", "bound_hermite"),
    [
        ([Segment(200.0)], 60.0, 1e-6, 1e-6),
        ([Segment(40.0), Segment(120.0, 1 / 60.0), Segment(40.0)], 80.0, 0.2, 0.01),
        ([Segment(40.0), Segment(30.0, 0.0, -1 / 40.0), Segment(30.0, -1 / 40.0), Segment(40.0)], 60.0, 0.3, 0.15),
        ([Segment(40.0), Segment(30.0, 0.0, 1 / 50.0), Segment(30.0, 1 / 50.0, -1 / 50.0),
          Segment(30.0, -1 / 50.0, 0.0), Segment(40.0)], 75.0, 0.3, 0.15),
    ],
    ids=["straight", "arc", "clothoid", "s-bend"],
)
def test_analytic_lanes_against_truth(segments: list[Segment], s_end: float, bound_paper: float,
                                      bound_hermite: float) -> None:
    road = AnalyticRoad(segments)
    for gap in (10.0, 20.0):
        assert max(gap_errors(road, s_end, s_end + gap, "paper")) <= bound_paper
        assert max(gap_errors(road, s_end, s_end + gap, "hermite")) <= bound_hermite


@pytest.mark.parametrize("interpolation", ["paper", "hermite"])
def test_parallel_tangents_with_offset_and_unequal_borders(interpolation: str) -> None:
    x = np.arange(0.0, 30.0, 0.1)
    ego = LaneDetection(Pose2D(0.0, 0.0, 0.0), np.column_stack((x, np.full_like(x, 2.0))),
                        np.column_stack((x[:200], np.full(200, -2.0))))
    coop = LaneDetection(Pose2D(45.0, 0.3, 0.0), np.column_stack((x, np.full_like(x, 2.0))),
                         np.column_stack((x, np.full_like(x, -2.0))))
    result = fusion.fuse(ego, coop, interpolation=interpolation)
    assert result.kind == "spline"
    for border, source in ((result.left, result.left_source), (result.right, result.right_source)):
        assert np.isfinite(border).all()
        assert np.diff(border[:, 0]).min() > 0.0
        gap = border[source == Source.INTERPOLATED]
        assert gap[:, 1].min() >= border[0, 1] - 1e-9 and gap[:, 1].max() <= border[-1, 1] + 1e-9


def test_zero_gap_is_not_a_spline_fusion() -> None:
    x = np.arange(0.0, 30.0001, 0.1)
    borders = (np.column_stack((x, np.full_like(x, 2.0))), np.column_stack((x, np.full_like(x, -2.0))))
    ego = LaneDetection(Pose2D(0.0, 0.0, 0.0), *borders)
    coop = LaneDetection(Pose2D(30.0, 0.0, 0.0), *borders)
    result = fusion.fuse(ego, coop, mode="spline")
    assert result.kind == "none"
    assert "d_s must be > 0" in result.reason


def test_hermite_gap_with_opposite_end_tangents_is_finite() -> None:
    """Exactly opposite end directions (a turn of π: the tangent lines never meet, sin(turn) = 0)
    take the Bézier fallback: finite points from end to end, no division by zero."""
    gap = hermite_gap(np.array((0.0, 0.0)), np.array((1.0, 0.0)), np.array((5.0, 3.0)), np.array((-1.0, 0.0)), 0.1)
    assert gap.shape[0] > 40 and np.isfinite(gap).all()
    assert np.hypot(*np.diff(gap, axis=0).T).max() <= 0.1 + 1e-9

