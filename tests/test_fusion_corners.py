"""Hermite across turns between straight ends (clothoid pair) on held-out analytic road families."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.analytic import AnalyticRoad, Segment, family_case, gap_errors
from fusion.errors import InvalidParameterError
from fusion.spline import hermite_gap, transition_tangent

NDArrayComplex = np.ndarray


def dense_pair(turn: float, n: int = 200_000) -> NDArrayComplex:
    """Midpoint-rule points of the clothoid pair of half length 1 (start 0, heading 0)."""
    s = (np.arange(n) + 0.5) * (2.0 / n)
    heading = np.where(s < 1.0, 0.5 * turn * s * s, turn - 0.5 * turn * (2.0 - s) ** 2)
    return np.cumsum(np.exp(1j * heading)) * (2.0 / n)


@pytest.mark.parametrize("turn_deg", [-100.0, -45.0, 10.0, 90.0])
def test_transition_tangent_matches_integration(turn_deg: float) -> None:
    turn = math.radians(turn_deg)
    end = dense_pair(turn)[-1]  # a pair of half length 1 has radius 1 / |turn|
    pair = transition_tangent(turn, 1.0) / abs(turn)
    assert pair == pytest.approx(end.real - end.imag / math.tan(turn), abs=1e-8)
    assert transition_tangent(turn, 1e-9) == pytest.approx(math.tan(abs(turn) / 2.0), rel=1e-8)  # the arc
    # spiral–curve–spiral of road design: clothoids of length L shift the arc (R = 1) inwards by
    # p ≈ L²/24 and its tangent points back by k ≈ L/2, so the tangent is (1 + p)·tan(θ/2) + k
    length = 0.05 * abs(turn)
    expected = (1.0 + length ** 2 / 24.0) * math.tan(abs(turn) / 2.0) + length / 2.0
    assert transition_tangent(turn, 0.05) == pytest.approx(expected, abs=1e-5)


def test_turn_between_straights_is_a_g2_clothoid_pair() -> None:
    # 90° right turn, tangent lengths 12 m (ego) and 20 m (coop): 8 m straight on the coop side
    p3, d1 = np.array([12.0, -20.0]), np.array([0.0, -1.0])
    pts = hermite_gap(np.zeros(2), np.array([1.0, 0.0]), p3, d1, 0.1, share=1.0)
    full = np.vstack(([0.0, 0.0], pts, p3))
    step = np.hypot(*np.diff(full, axis=0).T)
    assert step.max() <= 0.1 + 1e-9 and step.min() > 0.099
    heading = np.unwrap(np.arctan2(*np.diff(full, axis=0).T[::-1]))
    curvature = np.diff(heading) / step[:-1]
    half = 12.0 / transition_tangent(-math.pi / 2, 1.0) * (math.pi / 2)
    rate = (math.pi / 2) / half ** 2  # |κ'| of each clothoid
    np.testing.assert_allclose(curvature[:10], -rate * 0.1 * np.arange(1, 11), atol=2e-4)  # from κ = 0
    assert abs(curvature[-79:]).max() < 1e-6  # the straight on the coop side
    assert curvature.min() == pytest.approx(-(math.pi / 2) / half, abs=rate * 0.1)  # peak θ / half, ± one step
    assert abs(np.diff(curvature)).max() < 1.5 * rate * 0.1  # linear: no jump
    # the pair's middle point lies on the bisector of the corner (12, 0) at the integrated distance
    mid = dense_pair(-math.pi / 2)[100_000 - 1] * half
    apex = pts[np.argmin(np.abs(pts[:, 0] + pts[:, 1] - 12.0))]
    assert np.hypot(*(apex - (mid.real, mid.imag))) < 0.06
    np.testing.assert_allclose(full[-81:, 0], 12.0, atol=1e-6)


def test_unknown_family_is_named() -> None:
    with pytest.raises(InvalidParameterError, match="unknown road family 'spiral'"):
        family_case("spiral", np.random.default_rng(0))


@pytest.fixture(scope="module")
def corner_errors() -> dict[str, np.ndarray]:
    """Errors of arc / hermite / paper on 16 random corners (held out: seed not used elsewhere)."""
    rng = np.random.default_rng(2024)
    cases = [gap_errors(*family_case(family, rng)) for family in ("corner", "clothoid corner") for _ in range(12)]
    fused = [c for c in cases if c is not None]
    assert len(fused) >= 8
    return {k: np.array([c[k] for c in fused]) for k in ("arc", "hermite", "paper")}


def test_turns_inside_the_gap_beat_the_largest_arc(corner_errors: dict[str, np.ndarray]) -> None:
    arc, hermite, paper = corner_errors["arc"], corner_errors["hermite"], corner_errors["paper"]
    assert hermite.mean() < 0.8 * arc.mean() and hermite.max() <= arc.max()
    assert hermite.mean() < paper.mean()


def test_tight_corner_cuts_less_than_the_arc() -> None:
    # radius 10 m, 90°, 10 m straight before and after the turn inside a 35.7 m gap
    road = AnalyticRoad([Segment(80.0), Segment(5 * math.pi, -0.1), Segment(80.0)])
    errors = gap_errors(road, 70.0, 80.0 + 5 * math.pi + 10.0)
    assert errors is not None
    # largest arc: radius 20 instead of 10, so it misses the apex by 10·(√2 − 1) = 4.14 m
    assert errors["arc"] == pytest.approx(10.0 * (math.sqrt(2.0) - 1.0), abs=0.05)
    assert errors["hermite"] < 0.75 * errors["arc"]


@pytest.mark.parametrize("noise", [0.0, 0.05])
def test_arcs_and_s_bends_keep_their_accuracy(noise: float) -> None:
    rng = np.random.default_rng(7)
    for family in ("arc", "s-bend"):
        cases = [gap_errors(*family_case(family, rng), noise_m=noise, rng=rng) for _ in range(4)]
        fused = [c for c in cases if c is not None]
        assert len(fused) >= 3
        for errors in fused:
            if noise == 0.0:  # ends on arcs are not straight: the arc stays
                assert errors["hermite"] == pytest.approx(errors["arc"], abs=1e-9)
            if family == "arc":  # with noise a gentle end may pass as straight; the bound still holds
                assert errors["hermite"] <= (0.15 if noise == 0.0 else 0.3)
