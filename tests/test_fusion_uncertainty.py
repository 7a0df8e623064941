"""Uncertainty through the fusion (issue 25): inverse-variance convoy weights, σ of fused,
bridged, history and chained points against closed forms; the defaults unchanged."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import fusion
from fusion import FusionParams, InvalidParameterError, LaneDetection, Source
from fusion.analytic import AnalyticRoad, Segment, detect, with_history
from fusion.geometry import distance_to_polyline, transform
from fusion.uncertainty import BRIDGE_SIGMA_FLOOR_PER_M, BRIDGE_SIGMA_PER_M, bridge_bend

WIDTH_M = 3.5
DETERMINISTIC = settings(max_examples=40, deadline=None, derandomize=True, database=None,
                         suppress_health_check=[HealthCheck.too_slow])


def straight(yaw_rad: float = 0.0) -> AnalyticRoad:
    return AnalyticRoad([Segment(300.0)], x0=5.0, y0=-3.0, yaw0=yaw_rad)


def sensed(road: AnalyticRoad, s_from: float, sigma: float | np.ndarray, *, shift_m: float = 0.0,
           pose_cov: np.ndarray | None = None, length_m: float = 30.0) -> LaneDetection:
    """Lane detection on ``road`` from ``s_from`` with both borders shifted left by ``shift_m``
    (a rigid lateral error) and stating ``sigma`` per point (a constant or a function of x)."""
    det = detect(road, s_from, length_m, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    left, right = (border + (0.0, shift_m) for border in (det.left, det.right))
    sigmas = [np.full(b.shape[0], sigma) if np.isscalar(sigma) else sigma(b[:, 0]) for b in (left, right)]
    return LaneDetection(det.pose, left, right, left_sigma=sigmas[0], right_sigma=sigmas[1], pose_cov=pose_cov)


def lateral(points: np.ndarray, road: AnalyticRoad, offset_m: float) -> np.ndarray:
    """Signed lateral offset of world ``points`` from the straight road's border at ``offset_m``."""
    yaw = float(road.heading[0])
    local = transform(points, 0.0, 0.0, -yaw) - transform(np.array([[road.xy[0, 0], road.xy[0, 1]]]), 0.0, 0.0, -yaw)
    return local[:, 1] - offset_m


def along_m(points: np.ndarray, road: AnalyticRoad) -> np.ndarray:
    yaw = float(road.heading[0])
    return (points - road.xy[0]) @ np.array([math.cos(yaw), math.sin(yaw)])


IV = FusionParams(convoy_weights="inverse-variance", convoy_blend_offset_m=10.0)


def overlap_middle(result: fusion.FusionResult, road: AnalyticRoad, s_from: float, s_to: float) -> np.ndarray:
    """Mask of the fused left border's points between road stations ``s_from`` and ``s_to``."""
    s = along_m(result.left, road)
    return (result.left_source == Source.FUSED) & (s > s_from) & (s < s_to)


@pytest.mark.parametrize("sigma_e, sigma_c", [(0.2, 0.1), (0.05, 0.05), (0.03, 0.12)])
def test_inverse_variance_weights_match_the_closed_form_of_two_gaussian_sources(sigma_e: float,
                                                                                 sigma_c: float) -> None:
    road = straight(0.4)
    a, b = 0.10, -0.05  # rigid lateral errors of the ego and the coop detection [m]
    ego = sensed(road, 10.0, sigma_e, shift_m=a)
    coop = sensed(road, 20.0, sigma_c, shift_m=b)  # 10 m ahead: a 20 m overlap
    result = fusion.fuse(ego, coop, params=IV)
    assert result.kind == "convoy"
    middle = overlap_middle(result, road, 25.5, 34.5)
    assert middle.sum() > 80
    w = sigma_e**2 / (sigma_e**2 + sigma_c**2)
    np.testing.assert_allclose(lateral(result.left[middle], road, 0.5 * WIDTH_M), w * b + (1 - w) * a, atol=1e-9)
    np.testing.assert_allclose(result.left_sigma[middle], math.sqrt(1.0 / (1.0 / sigma_e**2 + 1.0 / sigma_c**2)),
                               rtol=1e-12)


def test_inverse_variance_sigma_is_the_spread_of_fused_gaussian_errors() -> None:
    """Monte Carlo over seeded Gaussian rigid errors of both sources: the fused points' spread
    is the stated σ (300 draws: the sample σ lies within 10 % of the true one)."""
    road = straight()
    sigma_e, sigma_c = 0.08, 0.04
    rng = np.random.default_rng(7)
    errors, stated = [], None
    for a, b in zip(rng.normal(0.0, sigma_e, 300), rng.normal(0.0, sigma_c, 300)):
        result = fusion.fuse(sensed(road, 10.0, sigma_e, shift_m=a), sensed(road, 20.0, sigma_c, shift_m=b), params=IV)
        middle = overlap_middle(result, road, 29.9, 30.1)
        errors.append(lateral(result.left[middle], road, 0.5 * WIDTH_M)[0])
        stated = result.left_sigma[middle][0]
    expected = math.sqrt(1.0 / (1.0 / sigma_e**2 + 1.0 / sigma_c**2))
    assert stated == pytest.approx(expected, rel=1e-12)
    assert float(np.std(errors)) == pytest.approx(expected, rel=0.10)


@pytest.mark.parametrize("ego_cov", [None, np.diag([0.02**2, 0.05**2, 0.003**2])])
def test_pose_covariance_enters_weights_and_sigma_as_the_propagated_closed_form(ego_cov: np.ndarray | None) -> None:
    """Straight road heading 0.7 rad, anisotropic world covariances, exact poses. Road frame,
    state (lateral, yaw) of the coop's relative pose error: the coop's prior diag(a_c, b_c),
    a = sin²ψ·σx² + cos²ψ·σy², b = σψ², and the ego's carried to the coop 10 m ahead,
    E = [[a_e + 100·b_e, 10·b_e], [10·b_e, b_e]]; the overlap's ends measure it with rows
    (1, 0) and (1, 20) and the sensors' variances R. After the update (gain K) a coop point x
    ahead of the coop has ego-frame variance σ_c² + J·P⁺·Jᵀ and world variance σ_c² + J·M·Jᵀ,
    J = (1, x), P⁺ = (I − KH)(Σ_c + E)(I − KH)ᵀ + KRKᵀ, M = (I − KH)Σ_c(I − KH)ᵀ + KHEHᵀKᵀ +
    KRKᵀ. The correction carries the ego's errors at the left border's overlap ends in, so a
    fused point's variance adds 2w(1 − w)·σ_e·J·K·(σ_e,start, σ_e,end) (the ego's border errors
    taken as fully correlated)."""
    yaw = 0.7
    road = straight(yaw)
    sigma_e = lambda x: np.hypot(0.03, 0.004 * x)  # noqa: E731 - a σ growing with distance
    sigma_c = 0.04
    coop_cov = np.diag([0.08**2, 0.03**2, 0.002**2])
    ego = sensed(road, 10.0, sigma_e, pose_cov=ego_cov)
    coop = sensed(road, 20.0, sigma_c, pose_cov=coop_cov)
    result = fusion.fuse(ego, coop, params=IV)
    middle = overlap_middle(result, road, 25.5, 34.5)
    x_ego = along_m(result.left[middle], road) - 10.0
    x_coop = x_ego - 10.0

    def lateral_var(cov: np.ndarray | None) -> float:
        return 0.0 if cov is None else math.sin(yaw) ** 2 * cov[0, 0] + math.cos(yaw) ** 2 * cov[1, 1]

    def pose_var(cov: np.ndarray | None, x: np.ndarray) -> np.ndarray:
        return lateral_var(cov) + (0.0 if cov is None else cov[2, 2]) * x * x

    own = np.diag([lateral_var(coop_cov), coop_cov[2, 2]])
    b_e = 0.0 if ego_cov is None else ego_cov[2, 2]
    carried = np.array([[lateral_var(ego_cov) + 100.0 * b_e, 10.0 * b_e], [10.0 * b_e, b_e]])
    rows = np.array([[1.0, 0.0], [1.0, 20.0]] * 2)
    noise = np.diag(np.array([sigma_e(10.0), sigma_e(30.0)] * 2) ** 2 + sigma_c**2)
    prior = own + carried
    gain = prior @ rows.T @ np.linalg.inv(rows @ prior @ rows.T + noise)
    keep = np.eye(2) - gain @ rows
    relative = keep @ prior @ keep.T + gain @ noise @ gain.T
    world = keep @ own @ keep.T + gain @ rows @ carried @ rows.T @ gain.T + gain @ noise @ gain.T

    def left(cov: np.ndarray, x: np.ndarray) -> np.ndarray:
        return cov[0, 0] + 2.0 * cov[0, 1] * x + cov[1, 1] * x * x

    def shared(x: np.ndarray) -> np.ndarray:  # the correction's covariance with a unit-σ ego point of the border
        return np.column_stack((np.ones_like(x), x)) @ gain[:, :2] @ np.array([sigma_e(10.0), sigma_e(30.0)])

    ve, pe = sigma_e(x_ego) ** 2, pose_var(ego_cov, x_ego)
    vc = sigma_c**2
    w = ve / (ve + vc + left(relative, x_coop))  # ego frame: the coop carries what is left of both pose errors
    np.testing.assert_allclose(result.left_sigma[middle],
                               np.sqrt(w * w * (vc + left(world, x_coop)) + (1 - w) ** 2 * (ve + pe)
                                       + 2 * w * (1 - w) * sigma_e(x_ego) * shared(x_coop)), rtol=1e-6)
    ego_only = result.left_source == Source.EGO
    x0 = along_m(result.left[ego_only], road) - 10.0
    before = x0 < 10.0 - IV.convoy_end_blend_m  # short of the seam blend the ego's own σ
    assert before.sum() > 20
    np.testing.assert_allclose(result.left_sigma[ego_only][before],
                               np.sqrt(sigma_e(x0[before]) ** 2 + pose_var(ego_cov, x0[before])), rtol=1e-6)
    coop_only = result.left_source == Source.COOP
    x1 = along_m(result.left[coop_only], road) - 20.0
    beyond = x1 > 20.0 + IV.convoy_end_blend_m  # past the seam blend the coop's own σ, after the update
    np.testing.assert_allclose(result.left_sigma[coop_only][beyond], np.sqrt(vc + left(world, x1[beyond])), rtol=1e-6)
    # in the seam blend the coop point keeps 1 − λ·(1 − w_end) of its weight, the ego's last point the rest
    x_end = float(along_m(result.left[result.left_source == Source.FUSED], road)[-1]) - 10.0
    ve_end, pe_end = sigma_e(np.array(x_end)) ** 2, pose_var(ego_cov, np.array(x_end))
    w_end = ve_end / (ve_end + vc + left(relative, np.array(x_end - 10.0)))
    t = np.clip(1.0 - (x1[~beyond] - (x_end - 10.0)) / IV.convoy_end_blend_m, 0.0, 1.0)
    w_seam = 1.0 - (1.0 - w_end) * t * t * (3.0 - 2.0 * t)
    np.testing.assert_allclose(result.left_sigma[coop_only][~beyond],
                               np.sqrt(w_seam**2 * (vc + left(world, x1[~beyond]))
                                       + (1 - w_seam) ** 2 * (ve_end + pe_end)
                                       + 2 * w_seam * (1 - w_seam) * math.sqrt(ve_end) * shared(x1[~beyond])),
                               rtol=1e-6)


def test_inverse_variance_blends_in_and_out_without_a_step() -> None:
    road = straight()
    ego, coop = sensed(road, 10.0, 0.1, shift_m=0.08), sensed(road, 20.0, 0.05, shift_m=-0.08)
    steps = {}
    for weights in ("paper", "inverse-variance"):
        result = fusion.fuse(ego, coop, params=FusionParams(convoy_weights=weights))
        steps[weights] = float(np.abs(np.diff(lateral(result.left, road, 0.5 * WIDTH_M))).max())
    assert steps["paper"] == pytest.approx(0.75 * 0.16, abs=1e-6)  # the paper's weights jump at the overlap start
    assert steps["inverse-variance"] < 0.01  # smoothstep over 5 m: at most 1.5·0.16/5·0.1 m per point


def test_inverse_variance_weights_hold_to_the_overlap_ends_and_the_seams_fade_outside() -> None:
    """Rigid errors +a (ego), b (coop): the whole overlap sits at w·b + (1 − w)·a, the ego
    points λ·w·(b − a) and the coop points λ·(1 − w)·(a − b) from their own, λ the smoothstep
    of the distance d from the overlap, 1 − 3(d/L)² + 2(d/L)³ (L = 5 m)."""
    road = straight(-0.2)
    a, b, sigma_e, sigma_c = 0.08, -0.06, 0.1, 0.05
    result = fusion.fuse(sensed(road, 10.0, sigma_e, shift_m=a), sensed(road, 20.0, sigma_c, shift_m=b), params=IV)
    w = sigma_e**2 / (sigma_e**2 + sigma_c**2)
    s, offset = along_m(result.left, road), lateral(result.left, road, 0.5 * WIDTH_M)
    fused = result.left_source == Source.FUSED
    np.testing.assert_allclose(offset[fused], w * b + (1 - w) * a, atol=1e-9)
    start, end = s[fused].min(), s[fused].max()
    blend = lambda d: np.where(d < 5.0, 1 - 3 * (d / 5.0) ** 2 + 2 * (d / 5.0) ** 3, 0.0)  # noqa: E731
    ego = result.left_source == Source.EGO
    np.testing.assert_allclose(offset[ego], a + blend(start - s[ego]) * w * (b - a), atol=1e-6)
    coop = result.left_source == Source.COOP
    np.testing.assert_allclose(offset[coop], b + blend(s[coop] - end) * (1 - w) * (a - b), atol=1e-6)
    assert (s[ego] < start - 5.0).sum() > 20 and (s[coop] > end + 5.0).sum() > 20


def test_bridge_sigma_on_a_straight_road_is_the_propagated_closed_form() -> None:
    """Hermite propagation of the end errors, with the coop's pose error: at arc fraction τ of
    a bridge of length L (ego exact), σ² = (k₀·d)² + (k₁·F·d_t)² + h00²σ_E² + h01²σ_C² + h01²σ_xy² +
    (h11·L)²σ_ψ², d = L·min(τ, 1 − τ); a straight gap does not bend or turn, F = 0: only
    k₀·d is left."""
    road = straight(-0.3)
    sigma_e, sigma_c, sxy, syaw = 0.12, 0.05, 0.06, 0.004
    ego = sensed(road, 10.0, sigma_e)
    coop = sensed(road, 70.0, sigma_c, pose_cov=np.diag([sxy**2, sxy**2, syaw**2]))  # a 30 m gap
    for interpolation in ("paper", "hermite"):
        result = fusion.fuse(ego, coop, interpolation=interpolation)
        assert result.kind == "spline"
        gap = result.left_source == Source.INTERPOLATED
        tau = (along_m(result.left[gap], road) - 40.0) / 30.0
        h00, h01, h11 = 2 * tau**3 - 3 * tau**2 + 1, 3 * tau**2 - 2 * tau**3, tau**3 - tau**2
        d = 30.0 * np.minimum(tau, 1.0 - tau)
        expected = np.sqrt((BRIDGE_SIGMA_FLOOR_PER_M[interpolation] * d) ** 2 + (h00 * sigma_e) ** 2
                           + (h01 * sigma_c) ** 2 + (h01 * sxy) ** 2 + (h11 * 30.0 * syaw) ** 2)
        np.testing.assert_allclose(result.left_sigma[gap], expected, rtol=2e-3)


@pytest.mark.parametrize("interpolation", ["paper", "hermite"])
def test_bridge_interpolation_sigma_grows_with_the_turn_across_the_gap(interpolation: str) -> None:
    """A right-angle corner of radius 20 m inside the gap between two straights: the bend is
    F = π/2 for both (``hermite``: both ends straight, no arc follows the turn; ``paper``: the
    ends' turn); the interpolation term sqrt(k₀² + (k₁·F)²)·d at distance d from the nearer
    end (the ends equally far from the corner: hermite turns over the whole gap), on top of
    the ends' σ carried by h00, h01 (exact poses)."""
    sigma = 0.02
    arc = Segment(20.0 * math.pi / 2.0, 1.0 / 20.0)
    road = AnalyticRoad([Segment(80.0), arc, Segment(80.0)], yaw0=0.3)
    ego = sensed(road, 45.0, sigma)  # ends 5 m before the corner
    coop = sensed(road, 80.0 + arc.length_m + 5.0, sigma)  # starts 5 m after it
    result = fusion.fuse(ego, coop, interpolation=interpolation)
    assert result.kind == "spline"
    gap = result.left_source == Source.INTERPOLATED
    inside = np.flatnonzero(gap)
    chain = result.left[inside[0] - 1: inside[-1] + 2]
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    tau = s[1:-1] / s[-1]
    h00, h01 = 2 * tau**3 - 3 * tau**2 + 1, 3 * tau**2 - 2 * tau**3
    d = s[-1] * np.minimum(tau, 1.0 - tau)
    k0, k1 = BRIDGE_SIGMA_FLOOR_PER_M[interpolation], BRIDGE_SIGMA_PER_M[interpolation]
    expected = np.sqrt((k0 * d) ** 2 + (k1 * math.pi / 2.0 * d) ** 2 + (h00 * sigma) ** 2 + (h01 * sigma) ** 2)
    np.testing.assert_allclose(result.left_sigma[gap], expected, rtol=1e-3)
    assert result.left_sigma[gap].max() > 0.5  # k·F·d at mid-bridge, d ≥ 15 m


def test_hermite_bridge_sigma_bends_only_where_hermite_turns() -> None:
    """The corner of radius 20 m with the ego's end 15 m before it and the coop's start 5 m
    after it: the end tangents meet a = 35 m after the ego's end and b = 25 m before the coop's
    start, so hermite runs straight along the ego's tangent for a − b = 10 m (the road does
    too) and turns in the rest. The bend term grows with d_t, the distance from the nearer end
    of that turn, zero on the straight: σ² = (k₀·d)² + (k₁·F·d_t)² + h00²σ² + h01²σ², F = π/2,
    d_t = max(0, min(u − 10 m, L − u)) at arc length u."""
    sigma = 0.02
    arc = Segment(20.0 * math.pi / 2.0, 1.0 / 20.0)
    road = AnalyticRoad([Segment(80.0), arc, Segment(80.0)], yaw0=0.3)
    ego = sensed(road, 35.0, sigma)  # ends 15 m before the corner
    coop = sensed(road, 80.0 + arc.length_m + 5.0, sigma)  # starts 5 m after it
    result = fusion.fuse(ego, coop, interpolation="hermite")
    assert result.kind == "spline"
    inside = np.flatnonzero(result.left_source == Source.INTERPOLATED)
    chain = result.left[inside[0] - 1: inside[-1] + 2]
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    u, length = s[1:-1], s[-1]
    tau = u / length
    h00, h01 = 2 * tau**3 - 3 * tau**2 + 1, 3 * tau**2 - 2 * tau**3
    d, d_turn = np.minimum(u, length - u), np.maximum(np.minimum(u - 10.0, length - u), 0.0)
    k0, k1 = BRIDGE_SIGMA_FLOOR_PER_M["hermite"], BRIDGE_SIGMA_PER_M["hermite"]
    expected = np.sqrt((k0 * d) ** 2 + (k1 * math.pi / 2.0 * d_turn) ** 2 + (h00 * sigma) ** 2 + (h01 * sigma) ** 2)
    np.testing.assert_allclose(result.left_sigma[inside], expected, rtol=1e-3)
    straight_part = inside[u < 10.0]
    assert straight_part.size > 50
    assert distance_to_polyline(result.left[straight_part], road.border(0.5 * WIDTH_M)).max() < 1e-6


def test_bridge_inside_an_arc_has_no_interpolation_term_for_hermite() -> None:
    """A gap inside an arc of radius 150 m: the ends' turn is the arc's own (:func:`bridge_bend`
    F = 0), so hermite's bridge σ is the ends' σ carried by h00, h01 and its k₀·d, while the
    paper's keeps sqrt(k₀² + (k₁·F)²)·d with F = |Δψ| = 30 m / 150 m, the arc's turn between
    the ends."""
    sigma = 0.03
    road = AnalyticRoad([Segment(20.0), Segment(200.0, 1.0 / 150.0)], yaw0=-0.5)
    ego, coop = sensed(road, 40.0, sigma), sensed(road, 100.0, sigma)  # a 30 m gap
    for interpolation, bend in (("hermite", 0.0), ("paper", 30.0 / 150.0)):
        result = fusion.fuse(ego, coop, interpolation=interpolation)
        assert result.kind == "spline"
        inside = np.flatnonzero(result.left_source == Source.INTERPOLATED)
        chain = result.left[inside[0] - 1: inside[-1] + 2]
        s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
        tau = s[1:-1] / s[-1]
        h00, h01 = 2 * tau**3 - 3 * tau**2 + 1, 3 * tau**2 - 2 * tau**3
        d = s[-1] * np.minimum(tau, 1.0 - tau)
        per_m = math.hypot(BRIDGE_SIGMA_FLOOR_PER_M[interpolation], BRIDGE_SIGMA_PER_M[interpolation] * bend)
        expected = np.sqrt((per_m * d) ** 2 + (h00 * sigma) ** 2 + (h01 * sigma) ** 2)
        np.testing.assert_allclose(result.left_sigma[inside], expected, rtol=1e-2)


def test_bridge_bend_is_the_bend_no_line_and_arc_of_the_ends_curvatures_follows() -> None:
    """F = dist(Δψ, L·[min κ, max κ]) + L·min(|κ_E|, |κ_C|, |κ_C − κ_E|) in closed form: zero on
    a straight, an arc and a straight meeting an arc inside the gap; the whole turn of a corner
    between straights; the turn beyond what the ends' curvatures make; L·k across an S-bend
    of curvatures ±k; the smaller curvature of a compound curve."""
    length = 30.0
    assert bridge_bend(0.0, 0.0, 0.0, length) == 0.0
    assert bridge_bend(length / 150.0, 1.0 / 150.0, 1.0 / 150.0, length) == pytest.approx(0.0, abs=1e-15)
    assert bridge_bend(-0.1, 0.0, -1.0 / 100.0, length) == 0.0  # straight into a right arc turning 0.1 of 0.3 rad
    assert bridge_bend(0.25, 1.0 / 50.0, 0.0, length) == 0.0  # arc into a straight
    assert bridge_bend(math.pi / 2.0, 0.0, 0.0, length) == math.pi / 2.0
    assert bridge_bend(0.5, 0.0, 1.0 / 100.0, length) == pytest.approx(0.5 - 0.3)
    assert bridge_bend(-0.5, 0.0, 1.0 / 100.0, length) == pytest.approx(0.5)
    assert bridge_bend(0.0, 1.0 / 60.0, -1.0 / 60.0, length) == pytest.approx(length / 60.0)
    assert bridge_bend(0.45, 1.0 / 100.0, 1.0 / 50.0, length) == pytest.approx(length / 100.0)  # turn inside [0.3, 0.6]
    assert bridge_bend(0.35, 1.0 / 100.0, 1.0 / 80.0, length) == pytest.approx(length * (1.0 / 80.0 - 1.0 / 100.0))


def test_hermite_bridge_from_a_straight_into_an_arc_has_only_its_floor_term() -> None:
    """A straight meeting an arc of radius 100 m inside a 30 m gap: hermite (a straight, then the
    largest arc tangent to both ends' tangents) follows the road, and the bridge's bend is zero
    (the turn is one an arc of the coop's curvature makes after the ego's straight), so its σ
    is the ends' σ carried by h00, h01 and k₀·d."""
    sigma = 0.03
    road = AnalyticRoad([Segment(60.0), Segment(300.0, 1.0 / 100.0)], yaw0=0.7)
    ego, coop = sensed(road, 20.0, sigma), sensed(road, 80.0, sigma)  # the arc starts 10 m into the gap
    result = fusion.fuse(ego, coop, interpolation="hermite")
    assert result.kind == "spline"
    inside = np.flatnonzero(result.left_source == Source.INTERPOLATED)
    assert distance_to_polyline(result.left[inside], road.border(0.5 * WIDTH_M)).max() < 0.01
    chain = result.left[inside[0] - 1: inside[-1] + 2]
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    tau = s[1:-1] / s[-1]
    h00, h01 = 2 * tau**3 - 3 * tau**2 + 1, 3 * tau**2 - 2 * tau**3
    d = s[-1] * np.minimum(tau, 1.0 - tau)
    expected = np.sqrt((BRIDGE_SIGMA_FLOOR_PER_M["hermite"] * d) ** 2 + (h00 * sigma) ** 2 + (h01 * sigma) ** 2)
    np.testing.assert_allclose(result.left_sigma[inside], expected, rtol=1e-2)


def test_defaults_keep_todays_geometry_and_state_no_sigma() -> None:
    road = straight(0.2)
    stations = (10.0, 35.0, 70.0)
    plain = [detect(road, s, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M) for s in stations]
    assert FusionParams().convoy_weights == "paper" and FusionParams().coop_weight == 0.75
    for coop, station in zip(plain[1:], stations[1:]):
        bare = fusion.fuse(plain[0], coop)
        assert bare.kind != "none" and bare.left_sigma is None and bare.right_sigma is None
        stated = fusion.fuse(sensed(road, 10.0, 0.1), sensed(road, station, 0.05))
        np.testing.assert_array_equal(bare.left, stated.left)  # σ changes no point under the paper's weights
        np.testing.assert_array_equal(bare.right_source, stated.right_source)
    mean = fusion.fuse(plain[0], plain[1], params=FusionParams(convoy_weights="mean"))
    np.testing.assert_array_equal(mean.left, fusion.fuse(plain[0], plain[1],
                                                         params=FusionParams(convoy_strategy="mean")).left)
    assert fusion.fuse_chain(plain[0], plain[1:]).left_sigma is None


def test_inverse_variance_without_sigma_takes_the_mean_weights_and_bad_settings_are_refused() -> None:
    road = straight()
    ego, coop = (detect(road, s, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M) for s in (10.0, 35.0))
    np.testing.assert_array_equal(fusion.fuse(ego, coop, params=FusionParams(convoy_weights="inverse-variance")).left,
                                  fusion.fuse(ego, coop, params=FusionParams(convoy_weights="mean")).left)
    with pytest.raises(InvalidParameterError, match="convoy_weights"):
        FusionParams(convoy_weights="median")  # type: ignore[arg-type]
    with pytest.raises(InvalidParameterError, match="convoy_strategy 'weighted'"):
        FusionParams(convoy_weights="mean", convoy_strategy="nearest")


def test_history_points_fade_from_the_ego_seam_sigma_to_the_coop_seam_sigma() -> None:
    road = straight(0.1)
    ego = sensed(road, 10.0, 0.2)
    coop = with_history(road, sensed(road, 70.0, 0.05), 70.0, 40.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    result = fusion.fuse_history(ego, coop)
    assert result.kind == "history"
    gap = result.left_source == Source.COOP_HISTORY
    w = (along_m(result.left[gap], road) - 40.0) / 30.0
    np.testing.assert_allclose(result.left_sigma[gap], 0.2 + w * (0.05 - 0.2), atol=2e-3)


def test_a_chain_keeps_the_sigma_of_points_a_link_leaves_unchanged() -> None:
    road = straight()
    ego, first, second = sensed(road, 10.0, 0.1), sensed(road, 70.0, 0.05), sensed(road, 130.0, 0.07)
    chain = fusion.fuse_chain(ego, [first, second])
    pair = fusion.fuse(ego, first)
    assert chain.vehicles == 3 and chain.left_sigma.shape == chain.left.shape[:1]
    n = pair.left.shape[0] - first.left.shape[0]  # the pair's points before the first coop's detection
    np.testing.assert_array_equal(chain.left_sigma[:n], pair.left_sigma[:n])
    second_link = fusion.fuse(first, second)
    np.testing.assert_allclose(chain.left_sigma[-second_link.left.shape[0]:], second_link.left_sigma)


road_yaws = st.floats(-math.pi, math.pi)


@DETERMINISTIC
@given(yaw=road_yaws, curvature=st.floats(-1 / 40.0, 1 / 40.0), lead=st.floats(5.0, 75.0),
       sigma0=st.floats(0.0, 0.3), sigma1=st.floats(0.0, 0.01), pose_xy=st.floats(0.0, 0.2),
       pose_yaw=st.floats(0.0, 0.01), weights=st.sampled_from(["paper", "mean", "inverse-variance"]),
       interpolation=st.sampled_from(["paper", "hermite"]), history=st.booleans())
def test_sigma_is_finite_non_negative_and_one_per_fused_point(yaw: float, curvature: float, lead: float,
                                                              sigma0: float, sigma1: float, pose_xy: float,
                                                              pose_yaw: float, weights: str, interpolation: str,
                                                              history: bool) -> None:
    road = AnalyticRoad([Segment(40.0), Segment(60.0, curvature), Segment(120.0)], yaw0=yaw)
    cov = np.diag([pose_xy**2, pose_xy**2, pose_yaw**2])
    sigma = lambda x: np.hypot(sigma0, sigma1 * x)  # noqa: E731
    ego = sensed(road, 10.0, sigma)
    coop = sensed(road, 10.0 + lead, sigma, pose_cov=cov)
    if history:
        coop = with_history(road, coop, 10.0 + lead, 40.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    params = FusionParams(convoy_weights=weights)  # type: ignore[arg-type]
    results = [fusion.fuse_history(ego, coop, interpolation=interpolation, params=params),
               fusion.fuse_chain(ego, [coop, sensed(road, 20.0 + 2 * lead, sigma, pose_cov=cov)],
                                 interpolation=interpolation, params=params)]
    for result in results:
        for border, sigma_out in ((result.left, result.left_sigma), (result.right, result.right_sigma)):
            assert sigma_out is not None
            assert sigma_out.shape == (border.shape[0],)
            assert np.isfinite(sigma_out).all() and (sigma_out >= 0.0).all()


def test_fusion_result_refuses_sigma_of_another_length() -> None:
    road = straight()
    result = fusion.fuse(*(detect(road, s, 30.0, 1.75, -1.75) for s in (10.0, 35.0)))
    with pytest.raises(InvalidParameterError, match="left_sigma"):
        replace(result, left_sigma=np.zeros(result.left.shape[0] - 1))


def test_end_fits_weight_points_by_inverse_variance() -> None:
    """The last 1.5 m of the ego borders hook 0.3 m aside with a stated σ of 10 m (2 cm
    elsewhere): weighted by 1/σ² the end fit extrapolates the good points (the true end and
    heading); unweighted it follows the hook."""
    road = AnalyticRoad([Segment(200.0)])
    ego, coop = detect(road, 10.0, 30.0, 1.75, -1.75), detect(road, 70.0, 30.0, 1.75, -1.75)

    def hooked(border: np.ndarray) -> np.ndarray:
        out = border.copy()
        tail = out[:, 0] > 28.5
        out[tail, 1] += 0.3 * (out[tail, 0] - 28.5) / 1.5
        return out

    el, er = hooked(ego.left), hooked(ego.right)
    sigmas = [np.where(b[:, 0] > 28.5, 10.0, 0.02) for b in (el, er)] + [np.full(len(b), 0.02)
                                                                          for b in (coop.left, coop.right)]
    from fusion.spline import lane_end_fits

    plain, weighted = (lane_end_fits((el, er), (coop.left, coop.right), None, s)[0] for s in (None, sigmas))
    assert abs(weighted.point[1] - 1.75) < 1e-3 and abs(weighted.direction[1]) < 1e-3
    assert abs(plain.point[1] - 1.75) > 0.1 and abs(plain.direction[1]) > 0.1
    deviation = {}
    for stated in (None, sigmas):
        pair = [LaneDetection(d.pose, left, right, left_sigma=None if stated is None else stated[i],
                              right_sigma=None if stated is None else stated[i + 1])
                for i, (d, left, right) in zip((0, 2), ((ego, el, er), (coop, coop.left, coop.right)))]
        bridged = fusion.fuse(*pair, interpolation="hermite")
        gap = bridged.left[bridged.left_source == Source.INTERPOLATED]
        deviation[stated is None] = float(np.abs(gap[:, 1] - 1.75).max())
    assert deviation[False] < 1e-3 < 1.0 < deviation[True]  # the bridge follows the fits: the hook or the line
