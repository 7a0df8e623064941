"""The coop's pose error estimated from a convoy overlap (inverse-variance weights): the
Gaussian MAP update against the information form of generalised least squares, the
corrected lane and its σ against closed forms on a straight road, curved and short overlaps."""

from __future__ import annotations

import math

import numpy as np
import pytest

import fusion
from fusion import FusionParams, LaneDetection, Pose2D, Source
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.convoy import OverlapStart, overlap_length
from fusion.geometry import distance_to_polyline, points_at, segment_at, transform
from fusion import registration
from fusion.registration import INCONSISTENT_RATE, consistency_limit, corrected, pose_update
from fusion.uncertainty import UNSTATED_SIGMA_M, lane_model_covariance

WIDTH_M = 3.5
IV = FusionParams(convoy_weights="inverse-variance")
ROAD_YAW = 0.3


def straight() -> AnalyticRoad:
    return AnalyticRoad([Segment(300.0)], x0=5.0, y0=-3.0, yaw0=ROAD_YAW)


def stated(det: LaneDetection, sigma: float, pose_cov: np.ndarray | None, pose: Pose2D | None = None) -> LaneDetection:
    """``det`` stating a constant ``sigma`` per point and ``pose_cov``, reporting ``pose``."""
    return LaneDetection(pose or det.pose, det.left, det.right, left_sigma=np.full(det.left.shape[0], sigma),
                         right_sigma=np.full(det.right.shape[0], sigma), pose_cov=pose_cov)


def road_frame(points: np.ndarray, road: AnalyticRoad) -> np.ndarray:
    """World ``points`` in the straight road's frame (x along it from its start, y left)."""
    return transform(points - road.xy[0], 0.0, 0.0, -ROAD_YAW)


def test_the_update_is_the_generalised_least_squares_solution_and_zero_covariance_the_identity() -> None:
    rng = np.random.default_rng(3)
    rows = rng.normal(size=(4, 3))
    differences = rng.normal(0.0, 0.1, 4)
    noise = rng.uniform(0.001, 0.01, 4)
    a = rng.normal(size=(3, 3))
    coop_cov = a @ a.T * 1e-3 + np.diag([1e-3, 1e-3, 1e-5])
    update = pose_update(rows, differences, noise, coop_cov, np.zeros((3, 3)), (10.0, 1.0))
    information = np.linalg.inv(coop_cov) + rows.T @ np.diag(1.0 / noise) @ rows
    posterior = np.linalg.inv(information)
    np.testing.assert_allclose(update.estimate, posterior @ rows.T @ (differences / noise), rtol=1e-9)
    np.testing.assert_allclose(update.relative, posterior, rtol=1e-9, atol=1e-15)
    np.testing.assert_array_equal(update.relative, update.world)  # an exact ego: the world keeps what is left
    none = pose_update(rows, differences, noise, np.zeros((3, 3)), np.zeros((3, 3)), (10.0, 1.0))
    assert not none.estimate.any() and not none.relative.any()


def test_the_egos_pose_error_enters_the_prior_carried_to_the_coop() -> None:
    """An ego yaw error δψ turns the coop at (s_x, s_y) about the ego: the relative pose error
    is (−s_y·δψ, s_x·δψ, δψ) about the coop; with only that prior the update is its GLS."""
    rows = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 20.0], [1.0, 0.0, -1.5]])
    noise = np.full(3, 1e-4)
    ego_cov = np.diag([0.0, 0.0, 0.003**2])
    carry = np.array([[1.0, 0.0, -2.0], [0.0, 1.0, 25.0], [0.0, 0.0, 1.0]])
    update = pose_update(rows, np.array([0.05, 0.1, 0.0]), noise, np.zeros((3, 3)), ego_cov, (25.0, 2.0))
    prior = carry @ ego_cov @ carry.T
    gain = prior @ rows.T @ np.linalg.inv(rows @ prior @ rows.T + np.diag(noise))
    np.testing.assert_allclose(update.estimate, gain @ np.array([0.05, 0.1, 0.0]), rtol=1e-9)
    assert np.linalg.eigvalsh(update.world).min() >= -1e-15


@pytest.mark.parametrize("offset_m, yaw_rad", [(0.08, 0.004), (-0.12, -0.006), (0.0, 0.003)])
def test_a_known_offset_and_yaw_are_estimated_as_gls_and_the_whole_coop_lane_corrected(offset_m: float,
                                                                                      yaw_rad: float) -> None:
    """Straight road, exact borders stating σ: the coop (20 m on the road, 10 m ahead of the
    ego) reports its pose ``offset_m`` to the left and turned by ``yaw_rad``. The overlap's ends
    (levers 0 and L = 20 m from the coop, both borders) measure d = (ℓ, ℓ + L·sin δψ); in the
    road frame H = (1, L·cos δψ) rows for (lateral, yaw), so the estimate is the GLS
    (P⁻¹ + HᵀR⁻¹H)⁻¹HᵀR⁻¹d and every coop point past the overlap is the reported one turned
    back by the estimated yaw and shifted back by the estimated offset."""
    road = straight()
    sigma_e, sigma_c, sxy, syaw = 0.05, 0.03, 0.1, 0.005
    cov = np.diag([sxy**2, sxy**2, syaw**2])
    ego = stated(detect(road, 10.0, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M), sigma_e, None)
    true = detect(road, 20.0, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    normal = (-math.sin(ROAD_YAW), math.cos(ROAD_YAW))
    reported = Pose2D(true.pose.x + offset_m * normal[0], true.pose.y + offset_m * normal[1], true.pose.yaw + yaw_rad)
    coop = stated(true, sigma_c, cov, reported)
    result = fusion.fuse(ego, coop, params=IV)
    assert result.kind == "convoy"
    lever = 20.0
    rows = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, lever * math.cos(yaw_rad)]] * 2)
    d = np.array([offset_m, offset_m + lever * math.sin(yaw_rad)] * 2)
    noise = 1.0 / (sigma_e**2 + sigma_c**2)
    posterior = np.linalg.inv(np.linalg.inv(cov) + noise * rows.T @ rows)  # cov is the same in the road frame
    estimate = posterior @ rows.T @ (noise * d)
    assert estimate[0] == pytest.approx(0.0, abs=1e-15)  # along the road: not observed
    # the reported border (road frame) shifted back by the estimate and turned back about the reported coop
    turn = lambda a: np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])  # noqa: E731
    coop_xy = np.array([20.0, offset_m])
    expected = coop_xy + (true.left @ turn(yaw_rad).T - estimate[:2]) @ turn(-estimate[2]).T
    coop_part = result.left_source == Source.COOP
    local = road_frame(result.left[coop_part], road)
    beyond = local[:, 0] > 40.0 + IV.convoy_end_blend_m
    assert beyond.sum() > 40
    np.testing.assert_allclose(local[beyond], expected[-beyond.sum():], atol=1e-9)
    uncorrected = (coop_xy + true.left @ turn(yaw_rad).T)[-beyond.sum():]
    assert np.abs(local[beyond, 1] - 0.5 * WIDTH_M).max() < np.abs(uncorrected[:, 1] - 0.5 * WIDTH_M).max()
    # its σ: the sensor's and what is left of the pose error, J·P⁺·Jᵀ with J = (n, t·(p − s_c))
    angle = yaw_rad - estimate[2]
    t, n = np.array([math.cos(angle), math.sin(angle)]), np.array([-math.sin(angle), math.cos(angle)])
    jacobian = np.column_stack((np.tile(n, (beyond.sum(), 1)), (local[beyond] - coop_xy) @ t))
    expected_var = sigma_c**2 + np.einsum("ij,jk,ik->i", jacobian, posterior, jacobian)
    np.testing.assert_allclose(result.left_sigma[coop_part][beyond], np.sqrt(expected_var), rtol=1e-6)


def test_zero_pose_covariance_leaves_inverse_variance_as_without_it() -> None:
    road = straight()
    ego = stated(detect(road, 10.0, 30.0, 1.75, -1.75), 0.05, None)
    det = detect(road, 20.0, 30.0, 1.75, -1.75)
    moved = Pose2D(det.pose.x, det.pose.y + 0.1, det.pose.yaw + 0.004)
    exact, zero = (fusion.fuse(ego, stated(det, 0.03, cov, moved), params=IV) for cov in (None, np.zeros((3, 3))))
    np.testing.assert_array_equal(exact.left, zero.left)
    np.testing.assert_array_equal(exact.right_sigma, zero.right_sigma)
    paper = [fusion.fuse(ego, stated(det, 0.03, cov, moved)) for cov in (None, np.diag([0.01, 0.01, 1e-5]))]
    np.testing.assert_array_equal(paper[0].left, paper[1].left)  # the paper's weights never move the coop


@pytest.mark.parametrize("curvature", [1 / 100.0, -1 / 80.0])
def test_a_curved_overlap_corrects_the_coops_pose_error(curvature: float) -> None:
    """On an arc the overlap's ends still measure the lateral offset and the yaw: with a small
    sensor σ the coop's far points come back to the road (their error a fifth of the
    uncorrected one or less)."""
    road = AnalyticRoad([Segment(5.0), Segment(200.0, curvature)], yaw0=-1.1)
    ego = stated(detect(road, 10.0, 30.0, 1.75, -1.75), 0.005, None)
    det = detect(road, 22.0, 30.0, 1.75, -1.75)
    moved = Pose2D(det.pose.x + 0.06, det.pose.y - 0.08, det.pose.yaw + 0.006)
    truth = road.border(1.75, 0.0, 120.0)
    errors = {}
    for weights in ("paper", "inverse-variance"):
        coop = stated(det, 0.005, np.diag([0.1**2, 0.1**2, 0.005**2]), moved)
        result = fusion.fuse(ego, coop, params=FusionParams(convoy_weights=weights))
        assert result.kind == "convoy" and np.isfinite(result.left_sigma).all()
        errors[weights] = distance_to_polyline(result.left[result.left_source == Source.COOP], truth).max()
    assert errors["paper"] > 0.1
    assert errors["inverse-variance"] < 0.2 * errors["paper"]


def test_a_short_overlap_leaves_the_yaw_to_the_prior_without_nan() -> None:
    """0.3 m of overlap: both ends sit at one lever, the yaw is not observed (its posterior
    variance stays the prior's) while the lateral offset is; nothing is NaN."""
    road = straight()
    ego = stated(detect(road, 10.0, 30.0, 1.75, -1.75), 0.05, None)
    det = detect(road, 39.7, 30.0, 1.75, -1.75)
    cov = np.diag([0.1**2, 0.1**2, 0.005**2])
    coop = stated(det, 0.03, cov, Pose2D(det.pose.x, det.pose.y, det.pose.yaw + 0.004))
    result = fusion.fuse(ego, coop, params=IV)
    assert result.kind == "convoy"
    for array in (result.left, result.right, result.left_sigma, result.right_sigma):
        assert np.isfinite(array).all()
    rows = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.3]] * 2)
    rows[:, :2] = rows[:, :2] @ np.array([[math.cos(ROAD_YAW), math.sin(ROAD_YAW)],
                                          [-math.sin(ROAD_YAW), math.cos(ROAD_YAW)]]) @ np.diag([1.0, 1.0])
    update = pose_update(rows, np.zeros(4), np.full(4, 0.05**2 + 0.03**2), cov, np.zeros((3, 3)), (0.0, 0.0))
    assert update.relative[2, 2] > 0.95 * cov[2, 2]
    assert update.relative[1, 1] < 0.5 * cov[1, 1] or update.relative[0, 0] < 0.5 * cov[0, 0]


@pytest.mark.parametrize("offset_m, yaw_rad", [(0.08, 0.004), (-0.12, -0.006)])
def test_without_stated_sigma_a_known_pose_error_is_estimated_with_the_unstated_sigma(offset_m: float,
                                                                                     yaw_rad: float) -> None:
    """The ideal sensor: exact borders stating no σ, the coop's pose covariance stated. The
    update takes σ_u = UNSTATED_SIGMA_M for every point (R = 2σ_u² per end), so the estimate is
    the GLS of the known-offset test with that R, the coop's far points come back to the road
    within 3σ of what the update leaves (J P⁺ Jᵀ), and the fused lane states no σ; the
    paper's weights keep the reported pose's error."""
    road = straight()
    sxy, syaw = 0.1, 0.005
    cov = np.diag([sxy**2, sxy**2, syaw**2])
    ego = detect(road, 10.0, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    true = detect(road, 20.0, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    normal = (-math.sin(ROAD_YAW), math.cos(ROAD_YAW))
    reported = Pose2D(true.pose.x + offset_m * normal[0], true.pose.y + offset_m * normal[1], true.pose.yaw + yaw_rad)
    coop = LaneDetection(reported, true.left, true.right, pose_cov=cov)
    result = fusion.fuse(ego, coop, params=IV)
    assert result.kind == "convoy" and result.left_sigma is None and result.right_sigma is None
    lever = 20.0
    rows = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, lever * math.cos(yaw_rad)]] * 2)
    d = np.array([offset_m, offset_m + lever * math.sin(yaw_rad)] * 2)
    noise = 1.0 / (2.0 * UNSTATED_SIGMA_M**2)
    posterior = np.linalg.inv(np.linalg.inv(cov) + noise * rows.T @ rows)
    estimate = posterior @ rows.T @ (noise * d)
    turn = lambda a: np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])  # noqa: E731
    coop_xy = np.array([20.0, offset_m])
    expected = coop_xy + (true.left @ turn(yaw_rad).T - estimate[:2]) @ turn(-estimate[2]).T
    local = road_frame(result.left[result.left_source == Source.COOP], road)
    beyond = local[:, 0] > 40.0 + IV.convoy_end_blend_m
    assert beyond.sum() > 40
    np.testing.assert_allclose(local[beyond], expected[-beyond.sum():], atol=1e-9)
    jacobian = np.column_stack((np.zeros(beyond.sum()), np.ones(beyond.sum()), local[beyond, 0] - coop_xy[0]))
    left_sigma = np.sqrt(np.einsum("ij,jk,ik->i", jacobian, posterior, jacobian))
    assert (np.abs(local[beyond, 1] - 0.5 * WIDTH_M) < 3.0 * left_sigma).all()
    paper = road_frame(fusion.fuse(ego, coop).left, road)
    assert np.abs(paper[:, 1] - 0.5 * WIDTH_M).max() > abs(offset_m) + 0.5 * lever * abs(yaw_rad)
    assert np.abs(local[:, 1] - 0.5 * WIDTH_M).max() < 0.1 * (abs(offset_m) + lever * abs(yaw_rad))


def test_an_overlap_that_contradicts_the_stated_sigma_makes_no_update() -> None:
    """The ego's borders 1 m to the left of the coop's in the overlap (a border turned into
    another lane): far beyond σ 0.05 m and a 0.1 m / 5 mrad pose covariance, so the
    innovation exceeds the χ²₄ limit at the stated rate, the coop is not moved and the
    overlap takes the fixed weights (0.5), as without σ."""
    road = straight()
    ego_det = detect(road, 10.0, 30.0, 0.5 * WIDTH_M + 1.0, -0.5 * WIDTH_M + 1.0)
    det = detect(road, 20.0, 30.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
    moved = Pose2D(det.pose.x, det.pose.y, det.pose.yaw + 0.004)
    cov = np.diag([0.1**2, 0.1**2, 0.005**2])
    sigma = 0.05
    result = fusion.fuse(stated(ego_det, sigma, None), stated(det, sigma, cov, moved), params=IV)
    bare = fusion.fuse(LaneDetection(ego_det.pose, ego_det.left, ego_det.right),
                       LaneDetection(moved, det.left, det.right), params=IV)
    np.testing.assert_allclose(result.left, bare.left, atol=1e-12)
    np.testing.assert_allclose(result.right, bare.right, atol=1e-12)
    # χ²₄'s survival function is e^(−x/2)(1 + x/2): the limit is where it equals the rate (47.9)
    assert math.exp(-consistency_limit(4) / 2) * (1 + consistency_limit(4) / 2) == pytest.approx(INCONSISTENT_RATE)


def test_corrected_inverts_a_rigid_pose_error_about_the_coop() -> None:
    """Points moved by a pose error δ (turned by δψ about the coop, then shifted by (δx, δy))
    come back exactly when corrected by δ."""
    rng = np.random.default_rng(5)
    points = rng.uniform(-30.0, 60.0, (50, 2))
    coop_xy, estimate = (25.0, -1.5), np.array([0.07, -0.12, 0.006])
    c, s = math.cos(estimate[2]), math.sin(estimate[2])
    moved = (points - coop_xy) @ np.array([[c, -s], [s, c]]).T + coop_xy + estimate[:2]
    np.testing.assert_allclose(corrected(moved, coop_xy, estimate), points, atol=1e-12)


def test_segment_at_and_overlap_length() -> None:
    """The segment of an arc length is that of the last vertex at or before it, the first or
    last one outside the line; the overlap is what is left of the ego border past s0 unless
    the coop border ends first."""
    s = np.array([0.0, 1.0, 3.0, 6.0])
    np.testing.assert_array_equal(segment_at(s, np.array([-1.0, 0.0, 0.5, 1.0, 2.9, 3.0, 6.0, 9.0])),
                                  [0, 0, 0, 1, 1, 2, 2, 2])
    line = np.column_stack((s, np.zeros(4)))
    np.testing.assert_allclose(points_at(line, s, np.array([0.5, 4.5])), [[0.5, 0.0], [4.5, 0.0]])
    start = OverlapStart(s, 2.0, 0.0, 0.0)
    assert overlap_length(start, np.array([0.0, 10.0])) == (4.0, True)
    assert overlap_length(start, np.array([0.0, 2.5])) == (2.5, False)


def test_lane_model_covariance_is_the_cubic_models_closed_form_with_the_stated_diagonal() -> None:
    """Two points of one border at x 3 and 25 m: cov = σ0² + σ1²x₁x₂ + σ2²x₁²x₂²/4 +
    σ3²x₁³x₂³/36, the diagonal the stated variance (lane model plus white noise); a stated
    variance below the model's scales that point's share down, the matrix stays positive
    semi-definite; without a model the points are independent."""
    sigma = np.array([0.05, 0.002, 4e-5, 1e-6])
    x = np.array([3.0, 25.0])
    model = [sigma[0] ** 2 + sigma[1] ** 2 * a * b + sigma[2] ** 2 * (a * b) ** 2 / 4
             + sigma[3] ** 2 * (a * b) ** 3 / 36 for a, b in ((3.0, 3.0), (3.0, 25.0), (25.0, 25.0))]
    stated = np.array([model[0], model[2]]) + 0.01**2
    covariance = lane_model_covariance(sigma, x, stated)
    np.testing.assert_allclose(covariance, [[stated[0], model[1]], [model[1], stated[1]]], rtol=1e-12)
    assert model[1] / math.sqrt(stated[0] * stated[1]) > 0.6  # the ends of one border are far from independent
    low = np.array([model[0], 0.5 * model[2]])
    tight = lane_model_covariance(sigma, x, low)
    np.testing.assert_allclose(np.diag(tight), low, rtol=1e-12)
    np.testing.assert_allclose(tight[0, 1], model[1] * math.sqrt(0.5), rtol=1e-12)
    assert np.linalg.eigvalsh(tight).min() >= -1e-18
    np.testing.assert_array_equal(lane_model_covariance(None, x, stated), np.diag(stated))


def convoy_innovations(monkeypatch: pytest.MonkeyPatch, state_model: bool,
                       pairs: int) -> tuple[np.ndarray, np.ndarray]:
    """Normalised innovations of the pose updates of ``pairs`` straight-road convoy pairs whose
    borders carry a cubic lane-model error drawn per border (σ of the camera profile) and
    whose coop reports a pose drawn from its stated covariance; the detections state their
    σ(x) and, with ``state_model``, their lane model. Also the error of each fused border's
    last point (the coop's, 25 m past the overlap) over its stated σ."""
    innovations: list[float] = []
    update = registration.pose_update

    def recorded(*args):  # type: ignore[no-untyped-def]
        result = update(*args)
        innovations.append(result.innovation)
        return result

    monkeypatch.setattr(registration, "pose_update", recorded)
    sigma = np.array([0.05, 0.002, 4e-5, 0.0])
    white = 0.01
    cov = np.diag([0.05**2, 0.05**2, 0.002**2])
    rng = np.random.default_rng(11)
    road = straight()

    def drawn(s_from: float, pose_error: np.ndarray | None) -> LaneDetection:
        det = detect(road, s_from, 50.0, 0.5 * WIDTH_M, -0.5 * WIDTH_M)
        borders, sigmas = [], []
        for border in (det.left, det.right):
            x = border[:, 0]
            basis = np.column_stack((np.ones_like(x), x, x * x / 2, x**3 / 6))
            error = basis @ rng.normal(0.0, sigma) + rng.normal(0.0, white, x.shape)
            borders.append(border + np.column_stack((np.zeros_like(x), error)))
            sigmas.append(np.sqrt(basis**2 @ sigma**2 + white**2))
        pose = det.pose if pose_error is None else Pose2D(det.pose.x + pose_error[0], det.pose.y + pose_error[1],
                                                          det.pose.yaw + pose_error[2])
        return LaneDetection(pose, borders[0], borders[1], left_sigma=sigmas[0], right_sigma=sigmas[1],
                             pose_cov=None if pose_error is None else cov,
                             lane_model_sigma=sigma if state_model else None)

    normalised = []
    for _ in range(pairs):
        ego = drawn(10.0, None)
        result = fusion.fuse(ego, drawn(35.0, rng.multivariate_normal(np.zeros(3), cov)), params=IV)
        assert result.kind == "convoy"
        for points, sigmas, offset in ((result.left, result.left_sigma, 0.5), (result.right, result.right_sigma, -0.5)):
            normalised.append(abs(road_frame(points[-1:], road)[0, 1] - offset * WIDTH_M) / sigmas[-1])
    monkeypatch.undo()
    return np.array(innovations), np.array(normalised)


def test_stated_lane_models_make_the_innovation_chi_square_as_the_update_assumes(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """Errors drawn from the model the detections state: with their lane models the
    normalised innovation of the 4 overlap-end differences follows χ²₄ (Kolmogorov–Smirnov,
    and 5 % of 300 above its 95 % quantile, 1σ 1.3 %); with the ends taken as independent it
    does not: R overstates how far the two ends of one border can part (one lane model moves
    both) and understates their common offset, so the tail is twice as heavy."""
    from scipy.stats import chi2, kstest

    correlated, _ = convoy_innovations(monkeypatch, True, 300)
    independent, _ = convoy_innovations(monkeypatch, False, 300)
    assert correlated.shape == independent.shape == (300,)
    tail = chi2.isf(0.05, 4)
    assert kstest(correlated, chi2(4).cdf).pvalue > 0.2 and 0.03 < np.mean(correlated > tail) < 0.07
    assert kstest(independent, chi2(4).cdf).pvalue < 0.05 and np.mean(independent > tail) > 0.08


def test_the_coops_far_points_state_an_honest_sigma_after_the_update(monkeypatch: pytest.MonkeyPatch) -> None:
    """The corrected coop's last points (25 m past the overlap, where its pose error has its
    longest lever): with stated lane models their σ counts that the update removed part of
    the coop's own lane-model error with the pose (the correction shares it,
    ``fusion.registration.own_shared``), and 68.3 % / 95.4 % of them lie within 1σ / 2σ (600
    points, 1σ 1.9 % / 0.9 %); without lane models the σ leaves that out and is too wide."""
    _, correlated = convoy_innovations(monkeypatch, True, 300)
    _, independent = convoy_innovations(monkeypatch, False, 300)
    assert 0.635 < np.mean(correlated <= 1.0) < 0.73 and 0.93 < np.mean(correlated <= 2.0) < 0.98
    assert np.mean(independent <= 1.0) > np.mean(correlated <= 1.0) + 0.03
