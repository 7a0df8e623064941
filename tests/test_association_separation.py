"""The "separation" association rule: a single-lane gap pair is ambiguous when the lane a
lane width aside passes the geometry using less than SEPARATION_MARGIN more of a lateral
limit than the pair itself; d_s <= d_i read to GAP_TOLERANCE_M."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion import FusionParams, LaneDetection
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.api import assess
from fusion.association import SEPARATION_MARGIN
from fusion.fusibility import GAP_TOLERANCE_M
from fusion.types import Pose2D

WIDTH_M = 4.0
LENGTH_M = 30.0
LEGACY = FusionParams(association="legacy")
SEPARATION = FusionParams(association="separation")


def straight(x0_m: float, offset_m: float) -> LaneDetection:
    """Noise-free straight lane WIDTH_M wide along +x, centred ``offset_m`` left of y = 0,
    seen from x0_m to x0_m + LENGTH_M by a vehicle at x0_m (borders every 0.1 m)."""
    x = np.arange(0.0, LENGTH_M + 1e-9, 0.1)
    return LaneDetection(Pose2D(x0_m, offset_m, 0.0), np.column_stack((x, np.full_like(x, 0.5 * WIDTH_M))),
                         np.column_stack((x, np.full_like(x, -0.5 * WIDTH_M))))


def test_margin_is_a_share_of_a_limit() -> None:
    assert 0.0 < SEPARATION_MARGIN < 1.0


@pytest.mark.parametrize("offset_m, ambiguous", [(0.0, False), (1.9, False), (2.0, True), (-2.0, True)])
def test_straight_gap_neighbour_passes_only_on_the_limit(offset_m: float, ambiguous: bool) -> None:
    """On a straight the cone decides: the coop start offset y uses |y| / (w/2) of the limit,
    the lane a width w toward the ego's line |y ∓ w| / (w/2). Both pass only at |y| = w/2
    (both use 1.0: separation 0 < margin, ambiguous); at 1.9 m the neighbour is 2.1 m off
    and fails, so separation fuses whatever legacy fuses short of the limit."""
    ego, coop = straight(0.0, 0.0), straight(LENGTH_M + 30.0, offset_m)
    legacy, separation = assess(ego, coop, LEGACY), assess(ego, coop, SEPARATION)
    assert legacy.reason == ""
    assert legacy.confidence == pytest.approx(0.8 * (1.0 - 0.5 * abs(offset_m) / (0.5 * WIDTH_M)))
    if ambiguous:
        assert separation.reason.startswith("ambiguous: the lane a lane width to the")
        assert "using 1.00 of a lateral limit, the coop's lane 1.00" in separation.reason
    else:
        assert separation == legacy


def test_open_bend_rejected_as_ambiguous() -> None:
    """A whole 90° bend (R 20 m) inside a 34 m gap between two straights: both the own lane
    and the lanes a width aside lie inside the cone of the end headings (each uses 0.00 of
    a limit; open radius, confidence 0.4 exactly, which "confidence" keeps): ambiguous."""
    bend = AnalyticRoad([Segment(100.0), Segment(20.0 * math.pi / 2, 1 / 20.0), Segment(100.0)])
    ego, coop = detect(bend, 68.0, 30.0, 1.75, -1.75), detect(bend, 132.0, 30.0, 1.75, -1.75)
    assert assess(ego, coop, FusionParams(association="confidence")).confidence == pytest.approx(0.4)
    reason = assess(ego, coop, SEPARATION).reason
    assert reason.startswith("ambiguous: the lane a lane width to the")
    assert "using 0.00 of a lateral limit, the coop's lane 0.00" in reason


@pytest.mark.parametrize("gap_m", [20.0, 30.0, 50.0])
def test_one_arc_across_the_gap_fused_neighbours_not(gap_m: float) -> None:
    """Both ends on one arc (R 150 m, lane 3.5 m): the arc predicts the gap, the own lane
    passes on it (confidence 0.7, the arc level, within the clothoid-free prediction) and
    the lanes a width inside and outside miss it by a lane width: separation fuses the own
    lane where strict would too, and no rule fuses a neighbour."""
    arc = AnalyticRoad([Segment(400.0, 1 / 150.0)])
    ego = detect(arc, 20.0, LENGTH_M, 1.75, -1.75)
    s_coop = 20.0 + LENGTH_M + gap_m
    own = assess(ego, detect(arc, s_coop, LENGTH_M, 1.75, -1.75), SEPARATION)
    assert own.reason == "" and own.confidence == pytest.approx(0.7, abs=0.01)
    for left, right in ((5.25, 1.75), (-1.75, -5.25)):
        for params in (LEGACY, SEPARATION):
            assert assess(ego, detect(arc, s_coop, LENGTH_M, left, right), params).reason != ""


@pytest.mark.parametrize("excess_m, legacy_fuses, separation_fuses",
                         [(-1e-3, True, True), (0.5 * GAP_TOLERANCE_M, False, True),
                          (2.0 * GAP_TOLERANCE_M, False, False)])
def test_gap_at_d_i_read_to_the_tolerance(excess_m: float, legacy_fuses: bool, separation_fuses: bool) -> None:
    """A straight coop whose detection starts d_i + e after the ego's ends: legacy rejects
    any e > 0, separation up to GAP_TOLERANCE_M (pairs a lane length d_i apart differ from
    d_i only by rounding)."""
    ego, coop = straight(0.0, 0.0), straight(LENGTH_M + 50.0 + excess_m, 0.0)
    assert (assess(ego, coop, LEGACY).reason == "") is legacy_fuses
    assert (assess(ego, coop, SEPARATION).reason == "") is separation_fuses
