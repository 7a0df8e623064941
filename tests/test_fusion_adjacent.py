"""Default (geometric) fusibility: the adjacent lane is rejected where a curve starts or ends
inside the gap, the same lane is accepted (analytic roads, lane width 3.5 m)."""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np
import pytest

import fusion
from fusion.analytic import AnalyticRoad, Segment, bend_segments, detect
from fusion.geometry import fit_ends, to_world
from fusion.spline import lane_end_fits

WIDTH = 3.5
PARAMS = fusion.FusionParams(d_i_m=51.0)
CURVE_START = 100.0


def lane(road: AnalyticRoad, s_from: float, index: int, noise_m: float = 0.0, seed: int = 0) -> fusion.LaneDetection:
    """30 m detection of lane ``index`` (0 = ego lane, +1 its left neighbour, −1 its right one)."""
    offset = index * WIDTH
    return detect(road, s_from, 30.0, WIDTH / 2 + offset, -WIDTH / 2 + offset, noise_m=noise_m,
                  rng=np.random.default_rng(seed))


@lru_cache(maxsize=None)
def bend(radius: float, turn_deg: float, sign: int, entry_m: float = 0.0) -> AnalyticRoad:
    """Straight of 100 m, a bend of ``turn_deg`` (clothoids of ``entry_m`` each side), straight."""
    return AnalyticRoad([Segment(CURVE_START), *bend_segments(sign / radius, math.radians(turn_deg), entry_m),
                         Segment(100.0)])


def verdicts(road: AnalyticRoad, s_end: float, gap: float) -> tuple[tuple[bool, str], ...]:
    """is_fusible of the coop in the ego lane, its left and its right neighbour, d_s = gap."""
    ego = lane(road, s_end - 30.0, 0)
    return tuple(fusion.is_fusible(ego, lane(road, s_end + gap, index), PARAMS) for index in (0, 1, -1))


def assert_same_lane_only(results: tuple[tuple[bool, str], ...]) -> None:
    assert results[0] == (True, ""), results[0]
    for ok, reason in results[1:]:
        assert not ok and "another lane" in reason, reason


@pytest.mark.parametrize("radius", [50.0, 100.0, 200.0, 500.0])
@pytest.mark.parametrize("sign", [1, -1])
@pytest.mark.parametrize("gap", [20.0, 40.0])
@pytest.mark.parametrize("into_gap", [0.1, 0.5, 0.9])
def test_curve_starting_inside_the_gap(radius: float, sign: int, gap: float, into_gap: float) -> None:
    """Ego end on the straight, the curve starts ``into_gap``·d_s after it, the coop starts in the arc."""
    road = bend(radius, 60.0 if radius <= 100.0 else 20.0, sign)
    assert_same_lane_only(verdicts(road, CURVE_START - into_gap * gap, gap))


@pytest.mark.parametrize("radius", [30.0, 100.0, 300.0])
@pytest.mark.parametrize("sign", [1, -1])
@pytest.mark.parametrize("into_gap", [0.2, 0.5, 0.8])
def test_curve_ending_inside_the_gap(radius: float, sign: int, into_gap: float) -> None:
    """Ego end in the arc, the arc ends ``into_gap``·d_s after it, the coop starts on the straight."""
    turn = 45.0 if radius <= 100.0 else 15.0
    road = bend(radius, turn, sign)
    gap = 20.0
    arc_end = CURVE_START + math.radians(turn) * radius
    assert_same_lane_only(verdicts(road, arc_end - into_gap * gap, gap))


@pytest.mark.parametrize(("radius", "gap"), [(140.0, 30.0), (140.0, 50.0), (300.0, 50.0)])
def test_both_ends_in_a_gentle_curve(radius: float, gap: float) -> None:
    """Town04's case: both ends in a gentle arc, the inner neighbour lies inside the cone of the
    end headings (the rule before this one accepted it)."""
    road = bend(radius, 40.0, -1)
    assert_same_lane_only(verdicts(road, CURVE_START + 35.0, gap))


@pytest.mark.parametrize("radius", [15.0, 30.0, 60.0])
@pytest.mark.parametrize("entry_m", [0.0, 10.0])
@pytest.mark.parametrize("gap", [10.0, 20.0, 40.0])
def test_right_angle_curves(radius: float, entry_m: float, gap: float) -> None:
    """90° bends (plain arcs, clothoid entries): the same lane is accepted everywhere along the
    curve; a neighbour is rejected wherever one detection end lies 6 m or more inside the arc
    (where it can measure the curvature; two straight ends leave the radius open)."""
    road = bend(radius, 90.0, 1, entry_m)
    arc_from = CURVE_START + entry_m
    arc_to = CURVE_START + math.pi / 2 * radius - entry_m
    for s_end in np.arange(CURVE_START - 20.0, arc_to + 20.0, 6.0):
        results = verdicts(road, float(s_end), gap)
        assert results[0] == (True, ""), (s_end, results[0])
        s_coop = s_end + gap
        if arc_from + 6.0 <= s_end <= arc_to or arc_from + 6.0 <= s_coop <= arc_to - 6.0:
            for ok, reason in results[1:]:
                assert not ok and "another lane" in reason, (s_end, reason)


@pytest.mark.parametrize("gap", [20.0, 40.0, 50.0])
def test_same_lane_through_a_reverse_curve(gap: float) -> None:
    """Ego end in a left arc, coop start in the right arc after a clothoid (the rural map's
    S-bend): the lane shifts by up to κ·L²/4 between the end headings and is accepted; a lane
    width to the side of a straight is still rejected (test_fusion_fusibility)."""
    road = AnalyticRoad([Segment(CURVE_START), Segment(40.0, 1 / 60.0), Segment(20.0, 1 / 60.0, -1 / 100.0),
                         Segment(80.0, -1 / 100.0), Segment(100.0)])
    ego_end = CURVE_START + 38.0
    assert verdicts(road, ego_end, gap)[0] == (True, "")


@pytest.mark.parametrize("seed", range(4))
def test_noisy_same_lane_across_a_curve_start_is_accepted(seed: int) -> None:
    road = bend(100.0, 60.0, 1)
    for s_end in (CURVE_START - 15.0, CURVE_START - 5.0, CURVE_START + 5.0):
        ego = lane(road, s_end - 30.0, 0, noise_m=0.05, seed=seed)
        coop = lane(road, s_end + 20.0, 0, noise_m=0.05, seed=seed + 100)
        assert fusion.is_fusible(ego, coop, PARAMS) == (True, "")


def end_fit(points: np.ndarray) -> fusion.geometry.EndFit:
    return fit_ends([points], [True], (2.0, 3.0, 4.5, 6.0), 5.0)[0]


@pytest.mark.parametrize("radius", [15.0, 40.0, 140.0, 500.0])
def test_end_curvature_of_an_arc_is_exact_and_certain(radius: float) -> None:
    road = AnalyticRoad([Segment(50.0), Segment(200.0, -1.0 / radius)])
    fit = end_fit(lane(road, 80.0, 0).right)
    border_radius = radius - WIDTH / 2  # right border of a right curve lies inside
    assert fit.curvature_sigma < 3e-4  # the 2 mm noise floor over a 6 m window
    assert abs(fit.curvature + 1.0 / border_radius) < 0.03 / border_radius + 3.0 * fit.curvature_sigma


@pytest.mark.parametrize("into_m", [5.0, 8.0, 14.0])
def test_end_inside_a_clothoid_has_no_single_arc(into_m: float) -> None:
    """The end lies ``into_m`` into a clothoid of 15 m to 1/30 m⁻¹ (curvature rate 2.2e-3 m⁻²)."""
    road = AnalyticRoad([Segment(50.0), Segment(15.0, 0.0, 1.0 / 30.0), Segment(50.0, 1.0 / 30.0)])
    assert end_fit(lane(road, 20.0 + into_m, 0).left).curvature_sigma == math.inf


def test_end_on_a_straight_is_not_curved() -> None:
    fit = end_fit(lane(AnalyticRoad([Segment(100.0)]), 10.0, 0).left)
    assert abs(fit.curvature) < 1e-6 < fit.curvature_sigma < 1e-3


def test_arc_mismatch_is_a_lane_width_for_the_neighbour() -> None:
    """Closed form: on one arc the neighbour's start lies exactly one lane width off the arc."""
    from fusion.fusibility import arc_mismatch, lane_ends

    road = bend(140.0, 40.0, -1)
    ego = lane(road, CURVE_START + 5.0, 0)
    for index, expected in ((0, 0.0), (1, WIDTH), (-1, WIDTH)):
        coop = lane(road, CURVE_START + 65.0, index)
        left, right = to_world(coop.left, coop.pose), to_world(coop.right, coop.pose)
        ego_left, ego_right = to_world(ego.left, ego.pose), to_world(ego.right, ego.pose)
        mismatch = arc_mismatch(lane_ends(ego_left, ego_right, left, right),
                                lane_end_fits((ego_left, ego_right), (left, right), None))
        assert mismatch == pytest.approx(expected, abs=0.35)
