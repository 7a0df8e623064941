"""Lane association on gentle curves under detection noise: the curvature of the whole
detection (:meth:`fusion.spline.EndFits.arcs`) lets the arc rule reject the adjacent lane
where the 2–6 m end fits cannot see the curve (analytic arcs, lane width 3.5 m, σ 5 cm)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusion
from fusion.analytic import AnalyticRoad, Segment, bend_segments, detect
from fusion.api import ego_frame_borders
from fusion.spline import EndFits

WIDTH = 3.5
NOISE_M = 0.05
SEEDS = range(8)


def lane(road: AnalyticRoad, s_from: float, index: int, rng: np.random.Generator,
         noise_m: float = NOISE_M) -> fusion.LaneDetection:
    """30 m detection of lane ``index`` (0 = ego lane, ±1 its neighbours) with noise."""
    offset = index * WIDTH
    return detect(road, s_from, 30.0, WIDTH / 2 + offset, -WIDTH / 2 + offset, noise_m=noise_m, rng=rng)


def arc(radius: float) -> AnalyticRoad:
    return AnalyticRoad([Segment(300.0, 1.0 / radius)])


def end_fits(ego: fusion.LaneDetection, coop: fusion.LaneDetection) -> EndFits:
    borders, _ = ego_frame_borders(ego, coop)
    return EndFits(borders, fusion.FusionParams())


@pytest.mark.parametrize("radius", [60.0, 130.0, -130.0, 300.0])
@pytest.mark.parametrize("gap", [20.0, 30.0])
def test_noisy_long_arc_rejects_the_neighbour_lane_and_accepts_the_same(radius: float, gap: float) -> None:
    """On one arc the ego end's arc predicts the coop start; the neighbour lane lies a lane
    width (3.5 m) off that prediction, the same lane within the noise, for every seed."""
    road = arc(radius)
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        ego = lane(road, 10.0, 0, rng)
        same = fusion.is_fusible(ego, lane(road, 40.0 + gap, 0, rng))
        assert same == (True, ""), (seed, same)
        for index in (1, -1):
            ok, reason = fusion.is_fusible(ego, lane(road, 40.0 + gap, index, rng))
            assert not ok and "another lane" in reason, (seed, index, reason)


def test_whole_detection_curvature_of_a_noisy_arc() -> None:
    """R 130 m under σ 5 cm: the 6 m end fits cannot resolve κ = 1/130 m⁻¹ (their σ_κ is
    more than a tenth of it); the fit over the whole 30 m detection has a σ_κ at least 10×
    smaller and lands within 4σ of each border's true curvature (1/(R ∓ w/2))."""
    road = arc(130.0)
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        fits = end_fits(lane(road, 10.0, 0, rng), lane(road, 70.0, 0, rng))
        for end, whole, offset in zip(fits(), fits.arcs(), (WIDTH / 2, -WIDTH / 2) * 2):
            assert end.curvature_sigma > 0.1 / 130.0
            assert whole.curvature_sigma < 0.1 * end.curvature_sigma
            assert abs(whole.curvature - 1.0 / (130.0 - offset)) < 4.0 * whole.curvature_sigma
            assert whole.point is end.point


def test_noise_free_arcs_and_tight_corners_keep_their_end_fits() -> None:
    """Noise-free ends on an arc resolve their curvature (σ_κ from the 2 mm noise floor), and
    ends inside a tight corner (R 15 m, 90°: arc from s = 50 to 73.6 m) turn each border by
    more than the whole-detection fit's model allows: both keep their end fits unchanged
    (the same objects)."""
    for road, s_ego, s_coop in ((arc(130.0), 10.0, 70.0),
                                (AnalyticRoad([Segment(50.0), *bend_segments(1.0 / 15.0, math.pi / 2), Segment(50.0)]),
                                 40.0, 72.0)):
        rng = np.random.default_rng(0)
        fits = end_fits(lane(road, s_ego, 0, rng, 0.0), lane(road, s_coop, 0, rng, 0.0))
        assert fits.arcs() is fits()


@pytest.mark.parametrize("s_ego", [85.0, 95.0])
def test_detection_over_a_curvature_change_is_no_whole_arc(s_ego: float) -> None:
    """A noisy ego detection over a straight and the clothoid that starts at s = 100 m (into a
    R 130 m arc) is no single arc: the whole fit's cubic test fails (σ_κ infinite), so its
    end fits stay; a detection on the straight alone is one arc of κ ≈ 0 (within 4σ)."""
    road = AnalyticRoad([Segment(100.0), *bend_segments(1.0 / 130.0, 0.5, 20.0), Segment(100.0)])
    for seed in SEEDS:
        rng = np.random.default_rng(seed)
        fits = end_fits(lane(road, s_ego, 0, rng), lane(road, 200.0, 0, rng))
        assert all(arc_fit is end for arc_fit, end in zip(fits.arcs()[:2], fits()[:2]))
        straight = end_fits(lane(road, 60.0, 0, rng), lane(road, 200.0, 0, rng)).arcs()
        for fit in straight[:2]:
            assert abs(fit.curvature) < 4.0 * fit.curvature_sigma < 4e-4
