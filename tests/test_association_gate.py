"""The statistical lane gate (fusion.gate) and the confidence rule of the association."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fusion.api import assess
from fusion import FusionParams, InvalidParameterError, LaneDetection
from fusion.gate import GateBorder, chord_heading_sigma, gate_reason, gate_threshold
from fusion.types import Pose2D
from fusion.uncertainty import BorderVariance

LANE_WIDTH_M = 3.5
SIGMA_M = 0.05
LENGTH_M = 30.0
GATED = FusionParams(association="confidence", gate_false_rejection=0.01)
STEP_M = 0.5


def straight_detection(x0: float, offset_m: float, rng: np.random.Generator, sigma_m: float) -> LaneDetection:
    """A lane of a straight road along +x from ``x0`` over LENGTH_M, centred ``offset_m`` to
    the left of y = 0, seen by a vehicle 5 m behind its start (borders in its frame) with
    lateral noise ``sigma_m`` and stating it."""
    x = np.arange(5.0, 5.0 + LENGTH_M + 1e-9, STEP_M)
    borders = []
    for side in (0.5, -0.5):
        y = side * LANE_WIDTH_M + rng.normal(0.0, sigma_m, x.shape[0])
        borders.append(np.column_stack((x, y)))
    sigma = np.full(x.shape[0], sigma_m)
    return LaneDetection(Pose2D(x0 - 5.0, offset_m, 0.0), borders[0], borders[1], left_sigma=sigma, right_sigma=sigma)


def pair(seed: int, gap_m: float, coop_offset_m: float) -> tuple[LaneDetection, LaneDetection]:
    rng = np.random.default_rng(seed)
    ego = straight_detection(0.0, 0.0, rng, SIGMA_M)
    return ego, straight_detection(LENGTH_M + gap_m, coop_offset_m, rng, SIGMA_M)


@given(seed=st.integers(0, 2**32 - 1), gap_m=st.sampled_from([20.0, 30.0]))
def test_gate_accepts_own_lane_rejects_adjacent_under_5cm_noise(seed: int, gap_m: float) -> None:
    """σ = 5 cm per point, both detections stating it, the gate at α = 1 %: the own lane is
    fused, the lane 3.5 m to either side is not, for every example (issue 25 Done-when), at
    d_s 20 and 30 m. At 50 m the cone's 4 m chord headings put z·σ ≈ 2.4 m above half a lane
    width and the gate calls some own-lane pairs ambiguous (docs/fusion/association.md)."""
    ego, own = pair(seed, gap_m, 0.0)
    assert assess(ego, own, GATED).reason == ""
    for offset in (LANE_WIDTH_M, -LANE_WIDTH_M):
        _, adjacent = pair(seed, gap_m, offset)
        assert assess(ego, adjacent, GATED).reason != ""


@given(seed=st.integers(0, 2**32 - 1), gap_m=st.sampled_from([20.0, 30.0]))
def test_gate_alone_separates_lanes(seed: int, gap_m: float) -> None:
    """The gate by itself (fusion.gate.gate_reason on the noisy borders' excesses outside the
    cone of the true headings): the own lane's start lies at most noise outside, the adjacent
    lane's a lane width: passes / rejected as another lane (not as ambiguous)."""
    rng = np.random.default_rng(seed)
    ego = straight_detection(0.0, 0.0, rng, SIGMA_M)
    for offset, passes in ((0.0, True), (LANE_WIDTH_M, False)):
        coop = straight_detection(LENGTH_M + gap_m, offset, rng, SIGMA_M)
        borders = tuple(GateBorder(e, _variance(e), c, _variance(c), abs(offset + float(c[0, 1] - e[-1, 1])))
                        for e, c in ((ego.left, coop.left), (ego.right, coop.right)))
        reason = gate_reason(borders, gap_m, LANE_WIDTH_M, 0.01)
        assert (reason == "") == passes
        assert passes or "another lane" in reason


def _variance(points: np.ndarray, sigma_m: float = SIGMA_M) -> BorderVariance:
    zeros = np.zeros(points.shape[0])
    return BorderVariance(np.full(points.shape[0], sigma_m**2), zeros, zeros)


def test_gate_threshold_closed_form() -> None:
    """Φ⁻¹(1 − α/4)²: α = 1 % → 2.807² = 7.879; α = 5 % → 2.241² = 5.024; χ²₁ at 1 − α/2."""
    assert gate_threshold(0.01) == pytest.approx(2.807034**2, rel=1e-6)
    assert gate_threshold(0.05) == pytest.approx(2.241403**2, rel=1e-6)
    with pytest.raises(ValueError, match="false_rejection"):
        gate_threshold(0.0)


def test_gate_boundary_closed_form() -> None:
    """A border excess just inside / outside z·σ, σ² = σ_e² + σ_c² + (d·σ_ψ)² with the chord
    headings' σ_ψ² = ¼·Σ (√2·σ / 4 m)² over four chords = σ²/8 (rad²): passes / rejected."""
    x = np.arange(0.0, 10.0 + 1e-9, 1.0)
    line = np.column_stack((x, np.zeros_like(x)))
    assert chord_heading_sigma(line, np.full(x.shape[0], SIGMA_M), True) == pytest.approx(math.sqrt(2) * SIGMA_M / 4)
    gap = 20.0
    sigma = math.sqrt(2 * SIGMA_M**2 + gap**2 * SIGMA_M**2 / 8)
    z = math.sqrt(gate_threshold(0.01))
    for excess, passes in ((0.99 * z * sigma, True), (1.01 * z * sigma, False)):
        borders = (GateBorder(line, _variance(line), line, _variance(line), excess),
                   GateBorder(line, _variance(line), line, _variance(line), 0.0))
        assert (gate_reason(borders, gap, LANE_WIDTH_M, 0.01) == "") == passes


def test_gate_ambiguous_when_sigma_cannot_tell_lanes_apart() -> None:
    """With σ so large that the lane a width beside passes too, the pair is rejected as
    ambiguous (a stable reason phrase)."""
    x = np.arange(0.0, 10.0 + 1e-9, 1.0)
    line = np.column_stack((x, np.zeros_like(x)))
    big = _variance(line, 0.8)
    borders = (GateBorder(line, big, line, big, 0.1), GateBorder(line, big, line, big, 0.1))
    assert gate_reason(borders, 20.0, LANE_WIDTH_M, 0.01).startswith("ambiguous")


def test_confidence_rule_rejects_below_threshold_as_ambiguous_legacy_keeps() -> None:
    """A noise-free pair without σ: legacy fuses it at its confidence c; min_confidence just
    above c rejects it with the reason "ambiguous: ...", just below fuses it."""
    ego, coop = (replace(d, left_sigma=None, right_sigma=None) for d in pair(0, 30.0, 0.0))
    legacy = assess(ego, coop, FusionParams(association="legacy"))
    assert legacy.reason == "" and 0.0 < legacy.confidence < 1.0
    assert assess(ego, coop) == legacy  # legacy is the default
    above = assess(ego, coop, FusionParams(association="confidence",
                                           min_confidence=min(legacy.confidence + 0.01, 1.0)))
    assert above.reason.startswith("ambiguous: association confidence")
    below = assess(ego, coop, FusionParams(association="confidence", min_confidence=legacy.confidence - 0.01))
    assert below.reason == "" and below.confidence == legacy.confidence


def test_confidence_rejects_a_reverse_curve_legacy_fuses() -> None:
    """Ego end in a left arc (R 60 m), coop start in the right arc (R 100 m) after a clothoid,
    d_s 40 m: legacy fuses the same lane (S-bend shift); the confidence rule rejects it as
    ambiguous (S-bend evidence, confidence ≤ 0.3 < 0.4): the recall it gives up."""
    from fusion.analytic import AnalyticRoad, Segment, detect

    road = AnalyticRoad([Segment(100.0), Segment(40.0, 1 / 60.0), Segment(20.0, 1 / 60.0, -1 / 100.0),
                         Segment(80.0, -1 / 100.0), Segment(100.0)])
    ego, coop = detect(road, 108.0, 30.0, 1.75, -1.75), detect(road, 178.0, 30.0, 1.75, -1.75)
    assert assess(ego, coop).reason == ""
    reason = assess(ego, coop, FusionParams(association="confidence")).reason
    assert reason.startswith("ambiguous: association confidence")


def test_strict_rejects_a_lane_whose_neighbour_passes_the_geometry_too() -> None:
    """A whole 90° bend (R 20 m) inside a 34 m gap between two straights: the cone is wide
    (open radius), legacy fuses the own lane; "strict" finds the lane a width beside it
    passing as well and rejects the pair as ambiguous; on a straight it still fuses."""
    from fusion.analytic import AnalyticRoad, Segment, detect

    bend = AnalyticRoad([Segment(100.0), Segment(20.0 * math.pi / 2, 1 / 20.0), Segment(100.0)])
    ego, coop = detect(bend, 68.0, 30.0, 1.75, -1.75), detect(bend, 132.0, 30.0, 1.75, -1.75)
    legacy = assess(ego, coop, FusionParams(association="legacy"))
    strict = assess(ego, coop, FusionParams(association="strict"))
    assert legacy.reason == "" and legacy.confidence == pytest.approx(0.4)  # open radius
    assert strict.reason.startswith("ambiguous: the lane a lane width")
    straight = [replace(d, left_sigma=None, right_sigma=None) for d in pair(1, 30.0, 0.0)]
    assert assess(*straight, FusionParams(association="strict")).reason == ""


@pytest.mark.parametrize("field, value", [("association", "strict!"), ("min_confidence", 1.5),
                                          ("gate_false_rejection", 0.0)])
def test_association_params_validated(field: str, value: object) -> None:
    with pytest.raises(InvalidParameterError, match=field):
        FusionParams(**{field: value})
