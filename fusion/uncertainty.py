"""Lateral uncertainty (1σ) through the fusion: the model, in one place.

Every σ here is the *lateral* 1σ [m] of a border point: across the border, in the world
frame (a scalar, the same in any frame). Sources and how they combine:

- **Sensor**: the per-point σ a detection states (``LaneDetection.left_sigma`` /
  ``right_sigma``); a detection without them makes the fused σ unknown (None).
- **Pose**: a sender's pose error δ = (δx, δy, δψ) (covariance ``pose_cov``, world frame)
  moves its point p laterally by J·δ, J = (n_x, n_y, t·(p − s)): the position error projected
  on the border normal n, plus the yaw error times the lever arm of p from the sender s
  along the border tangent t (the distance ahead of the sender on a straight road). Its
  variance J Σ Jᵀ (cross terms included) is added to the sensor variance. A detection
  without ``pose_cov`` has an exact pose (the paper's assumption).
- **Relative pose**: the fusion works in the ego frame. There the ego's own points carry
  only their sensor variance, while the coop's points carry the coop's pose variance *and*
  the ego's (the relative pose ego⁻¹·coop holds both errors; to first order their
  covariances add, each with its own lever arm). Inverse-variance convoy weights are
  computed in the ego frame: w_coop = σ_e² / (σ_e² + σ_c² + J_cΣ_cJ_cᵀ + J_eΣ_eJ_eᵀ), or with
  the pose variance left after the coop's pose error is estimated from the overlap
  (:mod:`fusion.registration`) in place of the two pose terms.
- **Fused point** (world frame, the result's frame): with weight w of the coop point,
  σ² = w²·(σ_c² + J_cΣ_cJ_cᵀ) + (1 − w)²·(σ_e² + J_eΣ_eJ_eᵀ): the two senders' world errors
  are independent (after a pose update, :mod:`fusion.registration`, the corrected coop's
  error shares the ego's errors at the overlap's ends: + 2w(1 − w)·σ_e·shared). For
  inverse-variance weights, an exact ego pose and no update this is 1 / (1/σ_e² + 1/σ_c²). Beside the overlap, where inverse-variance weights fade their
  steps out (:func:`fusion.convoy.convoy_border`), a point takes the same formula with the
  faded weight of the other sender's end point, its error fully correlated with its own
  end's (neighbouring points of one lane model).
- **Gap bridge** (spline fusion): see :func:`bridge_variance`: the errors at the two ends
  propagated through the cubic Hermite basis (offsets by h00/h01, the senders' yaw errors
  turning the end tangents by h10/h11 times the gap length) plus an interpolation term of
  variance (k₀·d)² + (k₁·F·d_t)², growing with the distance d from the nearer end, and with
  the bend F (:func:`interpolation_bend`: for ``hermite`` the road's bend across the gap
  that no line and arc of the ends' curvatures follows, :func:`bridge_bend`; for ``paper``
  the ends' turn) times the distance d_t from the nearer end of the part of the bridge that
  turns (``hermite``'s straights along the end tangents excluded,
  :func:`fusion.spline.hermite_turns`; the whole bridge for ``paper``), k₀ and k₁ per
  interpolation from :data:`BRIDGE_SIGMA_FLOOR_PER_M` and :data:`BRIDGE_SIGMA_PER_M`.
- **History** (:func:`fusion.fuse_history`): a history point's σ fades linearly from the
  ego seam's σ to the coop seam's, like the seam offsets (:func:`seam_sigma`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Final, Sequence

import numpy as np

from fusion.geometry import EndFit
from fusion.types import LaneDetection, NDArrayFloat

BRIDGE_SIGMA_PER_M: Final[dict[str, float]] = {"paper": 0.075, "hermite": 0.075}
"""Interpolation error k₁ of a gap bridge per interpolation (1σ, m/(m·rad)): the bridge's
interpolation term has the variance (k₀·d)² + (k₁·F·d_t)² at distance d [m] from its nearer
end and d_t [m] from the nearer end of the part that turns (:func:`bridge_distances`;
:data:`BRIDGE_SIGMA_FLOOR_PER_M` k₀), F [rad] the bend :func:`interpolation_bend`. ``hermite``
(line and arc): F the road's bend across the gap that no line-and-arc curve of the ends'
curvatures follows (:func:`bridge_bend`), d_t inside its turn (its straights along the end
tangents follow the road's); ``paper``: F the turn between the two ends' fitted tangents
|Δψ| (its natural spline through an estimated apex errs on any turn, arcs included), d_t = d.
k₀ and k₁ of each chosen together on camera drives with pose errors
(``tools/calibrate_bridge_sigma.py --drives``)."""

BRIDGE_SIGMA_FLOOR_PER_M: Final[dict[str, float]] = {"paper": 0.0475, "hermite": 0.0025}
"""Interpolation error k₀ of a gap bridge that does not scale with the bend (1σ, m/m; see
:data:`BRIDGE_SIGMA_PER_M`): ``paper``'s end tangents, from two points 0.2 m apart, turn with
the detection's point noise on any road; ``hermite``'s fitted ends miss what changes inside
the gap without bending it (lane width, gentle curvature)."""

UNSTATED_SIGMA_M: Final[float] = 0.005
"""Lateral 1σ [m] that the coop's pose update (:mod:`fusion.registration`) takes for every
point of a detection that states no σ while a sender states a pose covariance (the ideal
sensor under pose errors): its points are exact in its own frame up to how its borders are
sampled; the update then has the overlap's geometry as nearly exact evidence of the pose
error. The fused lane still states no σ."""


def interpolation_bend(interpolation: str, bend: tuple[float, float, float], length_m: float) -> float:
    """The bend F [rad] that scales the interpolation term of a gap bridge of length L [m]
    (:data:`BRIDGE_SIGMA_PER_M`) from the ends' (Δψ, κ_E, κ_C) (:func:`gap_bend`): ``hermite``
    :func:`bridge_bend`, ``paper`` |Δψ|."""
    return bridge_bend(*bend, length_m) if interpolation == "hermite" else abs(bend[0])


@dataclass(frozen=True)
class BorderVariance:
    """Lateral variances [m²] of the points of one border of one detection.

    Fields: ``sensor`` the detection's stated σ² per point; ``pose`` the variance its sender's
    pose error adds per point (J Σ Jᵀ, see the module docstring), zeros without
    ``pose_cov``; ``relative`` the variance the *other* sender's pose error adds to these
    points in that sender's frame (zeros for the ego's own points; for a coop corrected by a
    pose update the ego-frame variance less the world one,
    :func:`fusion.registration.corrected_variance`). All ``(N,)``.
    """

    sensor: NDArrayFloat
    pose: NDArrayFloat
    relative: NDArrayFloat

    @property
    def world(self) -> NDArrayFloat:
        """Variance of the points in the world frame: sensor plus own pose [m²]."""
        return self.sensor + self.pose


def tangents(points: NDArrayFloat) -> NDArrayFloat:
    """Unit tangents ``(N, 2)`` of a polyline (central differences, one-sided at the ends)."""
    step = np.gradient(points, axis=0)
    norm = np.hypot(step[:, 0], step[:, 1])
    norm[norm == 0.0] = 1.0
    return step / norm[:, None]


def frame_covariance(pose_cov: NDArrayFloat | None, frame_yaw_rad: float) -> NDArrayFloat:
    """A world-frame (x, y, yaw) pose covariance expressed in a frame rotated by
    ``frame_yaw_rad`` (zeros for None)."""
    if pose_cov is None:
        return np.zeros((3, 3))
    c, s = math.cos(frame_yaw_rad), math.sin(frame_yaw_rad)
    rotation = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    return rotation @ pose_cov @ rotation.T


def pose_variance(points: NDArrayFloat, sender_xy: tuple[float, float], covariance: NDArrayFloat) -> NDArrayFloat:
    """Lateral variance [m²] of ``points`` (``(N, 2)``, a border) from a pose error of their
    sender at ``sender_xy`` with ``covariance`` (x, y, yaw), all in one frame: J Σ Jᵀ with
    J = (n_x, n_y, t·(p − s))."""
    if not covariance.any():
        return np.zeros(points.shape[0])
    jacobian = lateral_jacobian(points, sender_xy)
    return np.maximum(np.einsum("ij,jk,ik->i", jacobian, covariance, jacobian), 0.0)


def lateral_jacobian(points: NDArrayFloat, sender_xy: tuple[float, float]) -> NDArrayFloat:
    """``(N, 3)`` J = (n_x, n_y, t·(p − s)) of a border's ``points``: how a pose error (x, y,
    yaw) of their sender at ``sender_xy`` moves each laterally, one frame."""
    t = tangents(points)
    return np.column_stack((-t[:, 1], t[:, 0], np.einsum("ij,ij->i", t, points - np.asarray(sender_xy))))


def has_sigma(detection: LaneDetection) -> bool:
    """Whether a detection states the σ of both its borders."""
    return detection.left_sigma is not None and detection.right_sigma is not None


def _sigmas(detection: LaneDetection, unstated_m: float | None) -> tuple[NDArrayFloat, NDArrayFloat] | None:
    """The stated σ [m] of a detection's (left, right) border points; ``unstated_m`` for every
    point of a detection that states none (None then: no σ)."""
    if has_sigma(detection):
        assert detection.left_sigma is not None and detection.right_sigma is not None
        return detection.left_sigma, detection.right_sigma
    if unstated_m is None:
        return None
    return np.full(detection.left.shape[0], unstated_m), np.full(detection.right.shape[0], unstated_m)


def own_variances(detection: LaneDetection,
                  unstated_m: float | None = None) -> tuple[BorderVariance, BorderVariance] | None:
    """:class:`BorderVariance` of a detection's (left, right) borders with no other sender;
    None when it states no σ (and no ``unstated_m``, see :func:`_sigmas`)."""
    sigmas = _sigmas(detection, unstated_m)
    if sigmas is None:
        return None
    covariance = frame_covariance(detection.pose_cov, detection.pose.yaw)
    out = []
    for points, sigma in zip((detection.left, detection.right), sigmas):
        zeros = np.zeros(points.shape[0])
        out.append(BorderVariance(sigma * sigma, pose_variance(points, (0.0, 0.0), covariance), zeros))
    return out[0], out[1]


def lane_model_basis(sigma: NDArrayFloat | None, x_m: NDArrayFloat, variance: NDArrayFloat) -> NDArrayFloat:
    """``(N, 4)`` rows B of points of one border at forward distances ``x_m`` (``(N,)``,
    vehicle frame) with stated variances ``variance`` [m²]: B_i·B_j is the covariance [m²] of
    the lane model's shared error at points i and j (``sigma`` the coefficients' 1σ,
    :attr:`fusion.LaneDetection.lane_model_sigma`), B = Φ diag(σ) with the rows
    Φ(x) = (1, x, x²/2, x³/6); a point whose lane-model variance |B_i|² exceeds its stated
    one has its row scaled down to it. Zeros without ``sigma`` (independent points)."""
    x = np.asarray(x_m, dtype=np.float64)
    if sigma is None:
        return np.zeros((x.shape[0], 4))
    basis = np.column_stack((np.ones_like(x), x, x * x / 2.0, x**3 / 6.0)) * sigma
    shared = np.einsum("ij,ij->i", basis, basis)
    return basis * np.sqrt(np.minimum(1.0, variance / np.where(shared > 0.0, shared, 1.0)))[:, None]


def lane_model_covariance(sigma: NDArrayFloat | None, x_m: NDArrayFloat, variance: NDArrayFloat) -> NDArrayFloat:
    """``(N, N)`` covariance [m²] of the lateral errors of points of one border at forward
    distances ``x_m`` with stated variances ``variance``: :func:`shared_covariance` of its
    :func:`lane_model_basis`; without ``sigma`` diag(``variance``), independent points."""
    return shared_covariance((lane_model_basis(sigma, x_m, variance),), variance)


def shared_covariance(bases: Sequence[NDArrayFloat], variance: NDArrayFloat) -> NDArrayFloat:
    """``(N, N)`` covariance [m²] of N errors whose lane models' shared parts have the
    :func:`lane_model_basis` rows ``bases`` (one per detection, summed: Σ B Bᵀ) and whose
    stated variances are ``variance`` (the rest of each one its own), so the diagonal is the
    stated variance and the matrix positive semi-definite."""
    shared = sum(basis @ basis.T for basis in bases)
    return shared + np.diag(variance - np.diag(shared))


@dataclass(frozen=True)
class PairUncertainty:
    """What the fusion of a pair needs to know of its uncertainty, in the ego frame.

    Fields: ``borders`` :class:`BorderVariance` of (ego left, ego right, coop left, coop
    right); ``ego_cov``, ``coop_cov`` the senders' (x, y, yaw) pose covariances rotated into
    the ego frame (zeros when exact); ``coop_xy`` the coop's position there [m];
    ``lane_models`` the (ego's, coop's) :attr:`fusion.LaneDetection.lane_model_sigma` (None
    when not stated) and ``forward`` the four borders' points' forward coordinates [m] in
    their own sender's vehicle frame, where the lane model is evaluated.
    """

    borders: tuple[BorderVariance, BorderVariance, BorderVariance, BorderVariance]
    ego_cov: NDArrayFloat
    coop_cov: NDArrayFloat
    coop_xy: tuple[float, float]
    lane_models: tuple[NDArrayFloat | None, NDArrayFloat | None]
    forward: tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]


def pair_uncertainty(ego: LaneDetection, coop: LaneDetection, borders: tuple[NDArrayFloat, ...],
                     coop_xy: tuple[float, float], unstated_m: float | None = None) -> PairUncertainty | None:
    """:class:`PairUncertainty` of a pair whose ``borders`` (ego left, ego right, coop left,
    coop right) are in the ego frame with the coop at ``coop_xy``; None unless both
    detections state σ (a detection that states none takes ``unstated_m`` [m] for every
    point when given)."""
    own = own_variances(ego, unstated_m)
    coop_sigmas = _sigmas(coop, unstated_m)
    if own is None or coop_sigmas is None:
        return None
    yaw = ego.pose.yaw
    ego_cov, coop_cov = frame_covariance(ego.pose_cov, yaw), frame_covariance(coop.pose_cov, yaw)
    coop_parts = []
    for points, sigma in zip(borders[2:], coop_sigmas):
        coop_parts.append(BorderVariance(sigma * sigma, pose_variance(points, coop_xy, coop_cov),
                                         pose_variance(points, (0.0, 0.0), ego_cov)))
    return PairUncertainty((own[0], own[1], coop_parts[0], coop_parts[1]), ego_cov, coop_cov, coop_xy,
                           (ego.lane_model_sigma, coop.lane_model_sigma),
                           (ego.left[:, 0], ego.right[:, 0], coop.left[:, 0], coop.right[:, 0]))


def fused_variance(w: NDArrayFloat | float, ego_world: NDArrayFloat, coop_world: NDArrayFloat,
                   cross: NDArrayFloat | float | None = None) -> NDArrayFloat:
    """World variance [m²] of (1 − w)·P_ego + w·P_coop: w²·σ_c² + (1 − w)²·σ_e², plus
    2w(1 − w)·``cross`` when the two errors share a covariance [m²]."""
    variance = w * w * coop_world + (1.0 - w) * (1.0 - w) * ego_world
    return variance if cross is None else variance + 2.0 * w * (1.0 - w) * cross


def inverse_variance_weight(ego_frame_ego: NDArrayFloat, ego_frame_coop: NDArrayFloat) -> NDArrayFloat:
    """w_coop = σ_e² / (σ_e² + σ_c²) from the ego-frame variances of paired points; 0.5 where
    both are exact (0 / 0)."""
    total = ego_frame_ego + ego_frame_coop
    out = np.full(total.shape, 0.5)
    np.divide(ego_frame_ego, total, out=out, where=total > 0.0)
    return out


def smoothstep(x: NDArrayFloat) -> NDArrayFloat:
    """3x² − 2x³ on x clipped to [0, 1]: 0 → 1 with zero slope at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


@dataclass(frozen=True)
class BridgeEnd:
    """One end of a gap bridge: ``sensor`` the stated lateral variance of the end point
    [m²]; ``jacobian`` (3,) how its sender's pose error (x, y, yaw, the bridge's frame) moves
    the end laterally; ``covariance`` (3, 3) that pose error's covariance (zeros when exact)."""

    sensor: float
    jacobian: NDArrayFloat
    covariance: NDArrayFloat


def bridge_end(points: NDArrayFloat, variance: BorderVariance, at_end: bool, sender_xy: tuple[float, float],
               covariance: NDArrayFloat) -> BridgeEnd:
    """The :class:`BridgeEnd` of a border's last (``at_end``) or first point; ``points``,
    ``sender_xy`` and ``covariance`` in one frame."""
    k = -1 if at_end else 0
    step = points[-1] - points[-2] if at_end else points[1] - points[0]  # tangents() of the two end points
    t = step / (np.hypot(step[0], step[1]) or 1.0)
    lever = float(t @ (points[k] - np.asarray(sender_xy)))
    jacobian = np.array([-t[1], t[0], lever])
    return BridgeEnd(float(variance.sensor[k]), jacobian, covariance)


def bridge_bend(turn_rad: float, ego_curvature_per_m: float, coop_curvature_per_m: float, length_m: float) -> float:
    """The bend F [rad] of a gap bridge of length L [m] that scales ``hermite``'s interpolation
    error, from the ends' heading change Δψ and curvatures κ_E (ego end), κ_C (coop start):
    F = dist(Δψ, L·[min(κ_E, κ_C), max(κ_E, κ_C)]) + L·min(|κ_E|, |κ_C|, |κ_C − κ_E|).

    The first term is the turn that no curve switching once from κ_E to κ_C inside the gap
    makes (such a curve turns by between L·κ_E and L·κ_C); the second the curvature step that
    a line and an arc cannot make (two different curvatures, neither zero). Zero on a straight
    road, on an arc and where a straight meets an arc inside the gap, all of which ``hermite``
    (line and arc) follows exactly; π/2 for a right-angle corner between two straights."""
    low, high = sorted((length_m * ego_curvature_per_m, length_m * coop_curvature_per_m))
    step = min(abs(ego_curvature_per_m), abs(coop_curvature_per_m), abs(coop_curvature_per_m - ego_curvature_per_m))
    return max(low - turn_rad, turn_rad - high, 0.0) + length_m * step


def gap_bend(arcs: Sequence[EndFit]) -> tuple[float, float, float]:
    """(Δψ [rad], κ_E [1/m], κ_C [1/m]) across a gap from the end fits of (ego left, ego right,
    coop left, coop right), one frame: the turn from the ego end's tangent to the coop start's,
    and the curvature of the ego's end and of the coop's start, each end's two borders
    averaged."""
    ego_dir, coop_dir = (np.add(arcs[i].direction, arcs[i + 1].direction) for i in (0, 2))
    turn = math.atan2(ego_dir[0] * coop_dir[1] - ego_dir[1] * coop_dir[0], float(ego_dir @ coop_dir))
    return turn, 0.5 * (arcs[0].curvature + arcs[1].curvature), 0.5 * (arcs[2].curvature + arcs[3].curvature)


def bridge_variance(gap: NDArrayFloat, start: NDArrayFloat, stop: NDArrayFloat, ego_end: BridgeEnd,
                    coop_start: BridgeEnd, interpolation: str, bend: tuple[float, float, float],
                    turn: tuple[float, float] = (0.0, 1.0)) -> NDArrayFloat:
    """Lateral world variance [m²] of the gap points ``gap`` (``(K, 2)``) of a bridge from
    ``start`` to ``stop`` (the ego border's last and the coop border's first point).

    With τ the arc-length fraction along the bridge, L its length and d = L·min(τ, 1 − τ)
    the distance from the nearer end, the cubic Hermite basis carries the end errors in:
    the sensor parts of the ends' variances as (h00·σ_E)² + (h01·σ_C)², each sender's pose
    error δ as ((h00·J_E + h10·L·e_ψ)·δ)² for the ego end and ((h01·J_C + h11·L·e_ψ)·δ)² for
    the coop end (a yaw error turns that end's tangent, e_ψ = (0, 0, 1)); the interpolation
    error adds (k₀·d)² + (k₁·F·d_t)² (``interpolation``'s :data:`BRIDGE_SIGMA_FLOOR_PER_M` k₀
    and :data:`BRIDGE_SIGMA_PER_M` k₁), F = :func:`interpolation_bend` of ``bend`` (the ends'
    heading change [rad] and curvatures [1/m], :func:`gap_bend`) and d_t the distance from
    the nearer end of the part of the bridge that turns, ``turn`` = its (start, stop)
    fractions (:func:`fusion.spline.hermite_turns`; zero outside it; the whole bridge by
    default, d_t = d).
    """
    if gap.shape[0] == 0:
        return np.empty(0)
    tau, length = bridge_fraction(gap, start, stop)
    d, d_turn = bridge_distances(tau, length, turn)
    k0, k1 = BRIDGE_SIGMA_FLOOR_PER_M[interpolation], BRIDGE_SIGMA_PER_M[interpolation]
    return ((k0 * d) ** 2 + (k1 * interpolation_bend(interpolation, bend, length) * d_turn) ** 2
            + bridge_ends_variance(tau, length, ego_end, coop_start))


def bridge_distances(tau: NDArrayFloat, length_m: float,
                     turn: tuple[float, float] = (0.0, 1.0)) -> tuple[NDArrayFloat, NDArrayFloat]:
    """(d, d_t) [m] of the points at arc fractions ``tau`` of a bridge of length ``length_m``:
    the distance from the bridge's nearer end, and from the nearer end of its part between
    the fractions ``turn`` (zero outside it)."""
    return (length_m * np.minimum(tau, 1.0 - tau),
            length_m * np.maximum(np.minimum(tau - turn[0], turn[1] - tau), 0.0))


def bridge_fraction(gap: NDArrayFloat, start: NDArrayFloat, stop: NDArrayFloat) -> tuple[NDArrayFloat, float]:
    """(τ, L): the arc-length fraction of each gap point (``(K, 2)``) along the bridge from
    ``start`` to ``stop`` and its length L [m] (1 when zero)."""
    chain = np.concatenate((start[None, :], gap, stop[None, :]))
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    length = float(s[-1]) or 1.0
    return s[1:-1] / length, length


def bridge_ends_variance(tau: NDArrayFloat, length_m: float, ego_end: BridgeEnd, coop_start: BridgeEnd) -> NDArrayFloat:
    """The part of :func:`bridge_variance` [m²] the two ends carry in at arc fractions ``tau``
    of a bridge of length ``length_m`` [m] (no interpolation term)."""
    t2, t3 = tau * tau, tau * tau * tau
    h00, h01 = 2.0 * t3 - 3.0 * t2 + 1.0, 3.0 * t2 - 2.0 * t3
    h10, h11 = t3 - 2.0 * t2 + tau, t3 - t2
    out = np.zeros(tau.shape)
    for end, h_offset, h_turn in ((ego_end, h00, h10), (coop_start, h01, h11)):
        out += h_offset * h_offset * end.sensor
        if end.covariance.any():
            a = h_offset[:, None] * end.jacobian + (h_turn * length_m)[:, None] * np.array([0.0, 0.0, 1.0])
            out += np.maximum(np.einsum("ij,jk,ik->i", a, end.covariance, a), 0.0)
    return out


def seam_sigma(ego_end_sigma: float, coop_start_sigma: float, w: NDArrayFloat) -> NDArrayFloat:
    """σ [m] of history points blended between two seams (``w`` 0 at the ego seam, 1 at the
    coop seam): (1 − w)·σ_E + w·σ_C, the seams' errors faded like the offsets, taken as fully
    correlated with the history's own (an upper bound of the independent case)."""
    return (1.0 - w) * ego_end_sigma + w * coop_start_sigma
