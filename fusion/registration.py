"""The coop's pose error estimated from a convoy overlap (``convoy_weights="inverse-variance"``).

A sender's pose error moves its whole detection rigidly, so the coop's points are not
independent of each other: where the two detections overlap, their lateral differences
measure the relative pose error δ = (δx, δy, δψ) of the coop in the ego frame (yaw about
the coop's position). The Gaussian MAP (Kalman) update with the pose covariances as the
prior gives its estimate and the covariance left after it, in closed form:

    P = Σ_c + T Σ_e Tᵀ,   K = P Hᵀ (H P Hᵀ + R)⁻¹,   δ̂ = K d,   P⁺ = (I − K H) P (I − K H)ᵀ + K R Kᵀ

with d the measured lateral differences (coop minus ego, along the ego border's left normal
n), H their rows (n_x, n_y, n·R₉₀(p − s_c)) (p the coop point, s_c the coop, R₉₀ the
quarter turn), R the covariance of the two detections' sensor errors there, and
T = [[1, 0, −s_y], [0, 1, s_x], [0, 0, 1]] carrying the ego's pose error (about the ego) to the coop. The
measurements are the overlap's two ends on each border: a lane detection's error is
correlated along the border (a lane model's offset and heading), so its many points carry
about as much information as a line through its ends, not one independent draw each; with
a short overlap the two ends nearly coincide, the yaw is not observed and the prior keeps
it. R's diagonal is the stated variances; a detection that states its lane model
(:attr:`fusion.LaneDetection.lane_model_sigma`) adds the covariance of its error at the two
ends of one border (:func:`fusion.uncertainty.lane_model_covariance`; the borders
independent), without it the ends are independent. The coop's whole detection is moved by
−δ̂ before the overlap is fused point by point.

The update holds only while the overlap agrees with the model: when the normalised innovation
squared dᵀ(H P Hᵀ + R)⁻¹d exceeds the χ² quantile of its M dof at the false rejection rate
:data:`INCONSISTENT_RATE`, the two detections differ by far more than their stated σ and pose
covariances allow (a border that turns into a junction lane, a lane model gone wrong), the
difference is not the coop's pose error, and :func:`registered` makes no update.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Final

import numpy as np

from fusion.convoy import OverlapStart, overlap_length, overlap_start
from fusion.geometry import norms, points_at, segment_at, transform
from fusion.types import NDArrayFloat
from fusion.uncertainty import (BorderVariance, PairUncertainty, lane_model_basis, lateral_jacobian, pose_variance,
                                shared_covariance)

INCONSISTENT_RATE: Final[float] = 1e-9
"""False rejection rate of the update's consistency test (module docstring): the overlap's
differences are taken as no measurement of the coop's pose when their normalised innovation
squared exceeds the χ² quantile at 1 − this rate."""


@dataclass(frozen=True)
class PoseUpdate:
    """The relative pose error of the coop estimated from a convoy overlap, ego frame.

    Fields: ``estimate`` δ̂ (x [m], y [m], yaw [rad]; yaw about the coop); ``relative`` its
    error's covariance P⁺ (what is left of the coop's pose error relative to the ego, (3, 3));
    ``world`` the covariance of the corrected coop's pose error in the world frame (its own
    pose error less the estimate; equal to ``relative`` when the ego's pose is exact);
    ``gain`` K (3, M), how the estimate follows each measurement; ``innovation`` the
    normalised innovation squared dᵀ(H P Hᵀ + R)⁻¹d (χ² of M dof when the model holds).
    """

    estimate: NDArrayFloat
    relative: NDArrayFloat
    world: NDArrayFloat
    gain: NDArrayFloat
    innovation: float


def overlap_rows(ego: NDArrayFloat, coop: NDArrayFloat, s_coop: NDArrayFloat, start: OverlapStart,
                 ego_sensor: NDArrayFloat, coop_sensor: NDArrayFloat, coop_xy: tuple[float, float],
                 lane_models: tuple[NDArrayFloat | None, NDArrayFloat | None],
                 forward: tuple[NDArrayFloat, NDArrayFloat]
                 ) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """(H (2, 3), d (2,), R (2, 2), the ego's variances in R (2,), the coop's
    :func:`fusion.uncertainty.lane_model_basis` there (2, 4)) of one border pair at the
    overlap's start and end (the coop start's foot on the ego border and the arc length
    ``convoy_border`` pairs last, :func:`fusion.convoy.overlap_length`), ego frame: the
    lateral difference coop minus ego along the ego border's left normal, how the coop's
    pose error moves it, and the sum of the two detections' sensor error covariances there
    [m²] (:func:`fusion.uncertainty.shared_covariance` of the (ego's, coop's)
    ``lane_models`` at the (ego's, coop's) ``forward`` coordinates of the border points,
    each in its sender's vehicle frame; independent ends without a lane model)."""
    u = np.array([0.0, overlap_length(start, s_coop)[0]])
    s = start.s0 + u
    p_ego, p_coop = points_at(ego, start.s_ego, s), points_at(coop, s_coop, u)
    k = segment_at(start.s_ego, s)
    t = ego[k + 1] - ego[k]
    length = norms(t)
    t = t / np.where(length > 0.0, length, 1.0)[:, None]
    normal = np.column_stack((-t[:, 1], t[:, 0]))
    lever = p_coop - np.asarray(coop_xy)
    rows = np.column_stack((normal, normal[:, 1] * lever[:, 0] - normal[:, 0] * lever[:, 1]))
    differences = np.einsum("ij,ij->i", normal, p_coop - p_ego)
    ego_noise, coop_noise = np.interp(s, start.s_ego, ego_sensor), np.interp(u, s_coop, coop_sensor)
    ego_basis = lane_model_basis(lane_models[0], np.interp(s, start.s_ego, forward[0]), ego_noise)
    coop_basis = lane_model_basis(lane_models[1], np.interp(u, s_coop, forward[1]), coop_noise)
    return rows, differences, shared_covariance((ego_basis, coop_basis), ego_noise + coop_noise), ego_noise, coop_basis


def pose_update(rows: NDArrayFloat, differences: NDArrayFloat, noise: NDArrayFloat, coop_cov: NDArrayFloat,
                ego_cov: NDArrayFloat, coop_xy: tuple[float, float]) -> PoseUpdate:
    """:class:`PoseUpdate` from measurements H (``rows``, (M, 3)), d (``differences``) and their
    error covariance R (``noise``, (M, M) [m²], or (M,) the variances of independent ones)
    with the senders' (x, y, yaw) covariances in the ego frame
    (see the module docstring). Zero covariances give δ̂ = 0 (the identity); a singular
    innovation covariance (no sensor noise and an unobserved direction) is pseudo-inverted."""
    sx, sy = coop_xy
    carry = np.array([[1.0, 0.0, -sy], [0.0, 1.0, sx], [0.0, 0.0, 1.0]])
    ego_part = carry @ ego_cov @ carry.T
    prior = coop_cov + ego_part
    noise_cov = np.diag(noise) if noise.ndim == 1 else noise
    innovation = rows @ prior @ rows.T + noise_cov
    inverse = np.linalg.pinv(innovation, hermitian=True)
    gain = prior @ rows.T @ inverse
    keep = np.eye(3) - gain @ rows
    measured = gain @ noise_cov @ gain.T
    relative = keep @ prior @ keep.T + measured
    world = keep @ coop_cov @ keep.T + gain @ rows @ ego_part @ rows.T @ gain.T + measured
    return PoseUpdate(gain @ differences, 0.5 * (relative + relative.T), 0.5 * (world + world.T), gain,
                      float(differences @ inverse @ differences))


@functools.cache
def consistency_limit(measurements: int) -> float:
    """The largest normalised innovation squared of ``measurements`` differences that
    :func:`registered` takes as a measurement of the pose: the χ² quantile at 1 −
    :data:`INCONSISTENT_RATE`."""
    from scipy.stats import chi2

    return float(chi2.isf(INCONSISTENT_RATE, measurements))


def corrected(points: NDArrayFloat, coop_xy: tuple[float, float], estimate: NDArrayFloat) -> NDArrayFloat:
    """Coop ``points`` (ego frame) moved by the inverse of the pose error ``estimate``: shifted
    by −(δx, δy) and turned by −δψ about the coop at ``coop_xy``."""
    x, y = coop_xy
    return transform(points - (np.array([x, y]) + estimate[:2]), x, y, -float(estimate[2]))


def corrected_variance(points: NDArrayFloat, sensor: NDArrayFloat, coop_xy: tuple[float, float],
                       update: PoseUpdate, own: NDArrayFloat) -> BorderVariance:
    """:class:`BorderVariance` of a corrected coop border (``points`` ego frame): its sensor
    variance, the world pose variance left after the update (J·``world``·Jᵀ) less 2·``own``
    as ``pose`` and the ego-frame one less the world one (J·(``relative`` − ``world``)·Jᵀ,
    negative where the correction took on more of the ego's pose error than it left of the
    coop's) as ``relative``, so that sensor + pose + relative is the ego-frame variance.
    ``own`` [m²] per point is the covariance of the correction J·K·v with the point's own
    sensor error (:func:`own_shared`): the update subtracts the share of the coop's lane model
    that it read at the overlap's ends as pose."""
    world = pose_variance(points, coop_xy, update.world)
    return BorderVariance(sensor, world - 2.0 * own, pose_variance(points, coop_xy, update.relative) - world)


def own_shared(points: NDArrayFloat, coop_xy: tuple[float, float], gain: NDArrayFloat, ends: NDArrayFloat,
               basis: NDArrayFloat) -> NDArrayFloat:
    """Per point of a corrected coop border (``points`` ego frame), the covariance [m²] of
    the correction's sensor part J·K·v with the point's own sensor error: v holds the coop's
    errors at that border's overlap ends (``gain`` their columns of K, (3, 2)), which share
    the coop's lane model with its points, B_ends·B_pᵀ (:func:`fusion.uncertainty.lane_model_basis`
    of the ends, ``ends`` (2, 4), and of the points, ``basis`` (N, 4)); zero without a lane model."""
    return np.einsum("ik,ki->i", lateral_jacobian(points, coop_xy) @ gain, ends @ basis.T)


def registered(borders: tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat],
               arclengths: tuple[NDArrayFloat, NDArrayFloat], starts: tuple[OverlapStart, OverlapStart],
               uncertainty: PairUncertainty
               ) -> tuple[NDArrayFloat, NDArrayFloat, tuple[OverlapStart, OverlapStart],
                          tuple[BorderVariance, BorderVariance, BorderVariance, BorderVariance],
                          tuple[NDArrayFloat, NDArrayFloat]] | None:
    """The coop's (left, right) borders of a convoy pair (``borders`` ego left, ego right, coop
    left, coop right, ego frame; ``arclengths`` of the coop's) corrected by the
    :func:`pose_update` of both borders' overlap ends, their overlap starts on the ego borders
    the four borders' :class:`BorderVariance` (the coop's with the covariance left after
    the update) and the coop borders' :func:`ego_shared`; None when the overlap contradicts
    the model (its innovation above :func:`consistency_limit`: no update)."""
    xy = uncertainty.coop_xy
    forward = uncertainty.forward
    measured = [overlap_rows(borders[side], borders[2 + side], arclengths[side], starts[side],
                             uncertainty.borders[side].sensor, uncertainty.borders[2 + side].sensor, xy,
                             uncertainty.lane_models, (forward[side], forward[2 + side]))
                for side in (0, 1)]
    rows, differences, ego_noise = (np.concatenate([m[i] for m in measured]) for i in (0, 1, 3))
    noise = np.zeros((4, 4))
    noise[:2, :2], noise[2:, 2:] = measured[0][2], measured[1][2]
    update = pose_update(rows, differences, noise, uncertainty.coop_cov, uncertainty.ego_cov, xy)
    if update.innovation > consistency_limit(differences.shape[0]):
        return None
    left, right = (corrected(borders[2 + side], xy, update.estimate) for side in (0, 1))
    moved_starts = (overlap_start(borders[0], left, starts[0].s_ego), overlap_start(borders[1], right, starts[1].s_ego))
    variances = (uncertainty.borders[0], uncertainty.borders[1],
                 *(corrected_variance(points, uncertainty.borders[2 + side].sensor, xy, update,
                                      own_shared(points, xy, update.gain[:, 2 * side: 2 * side + 2], measured[side][4],
                                                 lane_model_basis(uncertainty.lane_models[1], forward[2 + side],
                                                                  uncertainty.borders[2 + side].sensor)))
                   for side, points in enumerate((left, right))))
    shared = tuple(ego_shared(points, xy, update.gain[:, 2 * side: 2 * side + 2], ego_noise[2 * side: 2 * side + 2])
                   for side, points in enumerate((left, right)))
    return left, right, moved_starts, variances, shared


def ego_shared(points: NDArrayFloat, coop_xy: tuple[float, float], gain: NDArrayFloat,
               ego_variance: NDArrayFloat) -> NDArrayFloat:
    """Per point of a corrected coop border, the covariance [m] of its error with an ego point
    of unit σ on the same border: the correction carries the ego's errors at that border's
    overlap ends (variances ``ego_variance`` [m²], their columns ``gain`` of K) in as
    J·K·e_ends, and an ego point's error is taken as fully correlated with its border's ends
    (one lane model), Σ_k (J·K)_k·σ_e,k."""
    return lateral_jacobian(points, coop_xy) @ (gain @ np.sqrt(ego_variance))
