"""Statistical lane gate of a spline pair whose detections state per-point σ.

Everything in the ego vehicle frame (ISO 8855), m, rad. Under the hypothesis that the coop's
lane is the ego's, each coop border start lies inside the cone of the two end headings drawn
from the matching ego border end (:func:`fusion.association.border_excess`; an S-bend in the
gap may move it out by :func:`fusion.fusibility.s_bend_shift`); its measured lateral excess
outside the cone is then noise only. The gate normalises each border's excess by the
combined lateral σ of the two points it compares and of the cone's edges
(:func:`border_sigma`) and rejects the pair when the larger normalised excess squared
exceeds the χ²₁ quantile at a stated false rejection rate α, split over the two borders (Bonferroni: the rate holds whatever the
correlation of the two borders' errors, e.g. a shared pose error; the excess is one-sided,
so the bound is conservative). The adjacent lane lies a lane width w outside the cone: a
pair is *ambiguous* when a residual r passes the gate for the own lane and w − r would pass
it for the adjacent one (the σ is too large to tell lanes apart).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from statistics import NormalDist
from typing import Final

import numpy as np

from fusion.fusibility import CHORD_WINDOW_M
from fusion.types import NDArrayFloat
from fusion.uncertainty import BorderVariance

MIN_SIGMA_M: Final[float] = 0.01
"""Floor of the combined lateral σ [m]: a detection stating σ = 0 is still sampled on a
polyline, whose chord errors are of this order."""


def gate_threshold(false_rejection: float) -> float:
    """The gate on the larger normalised excess squared of the two borders: the χ²₁ quantile
    at 1 − α/2 (two borders, Bonferroni), i.e. Φ⁻¹(1 − α/4)² (one dof, two-sided)."""
    if not 0.0 < false_rejection < 1.0:
        raise ValueError(f"false_rejection must be in (0, 1), got {false_rejection!r}")
    z = NormalDist().inv_cdf(1.0 - false_rejection / 4.0)
    return z * z


def chord_heading_sigma(points: NDArrayFloat, sigma: NDArrayFloat, at_end: bool) -> float:
    """σ [rad] of a border end's chord heading (:func:`fusion.geometry.end_direction` over
    :data:`fusion.fusibility.CHORD_WINDOW_M`, as the cone uses it): the lateral σ of the
    chord's two points over its length; infinite for a chord of zero length."""
    chain = points[::-1] if at_end else points
    noise = sigma[::-1] if at_end else sigma
    s = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(chain, axis=0).T))))
    k = max(1, min(int(np.searchsorted(s, CHORD_WINDOW_M)), s.shape[0] - 1))
    if s[k] <= 0.0:
        return math.inf
    return math.hypot(float(noise[0]), float(noise[k])) / float(s[k])


@dataclass(frozen=True)
class GateBorder:
    """One border of the pair for the gate.

    Fields: ``ego_points`` the ego border ``(N, 2)`` and ``ego`` its variances; ``coop_points``
    the coop border ``(M, 2)`` and ``coop`` its variances (both ego frame, m, m²,
    :mod:`fusion.uncertainty`); ``excess`` the coop start's lateral excess outside the cone
    minus the S-bend shift, ≥ 0 [m].
    """

    ego_points: NDArrayFloat
    ego: BorderVariance
    coop_points: NDArrayFloat
    coop: BorderVariance
    excess: float


def turn_sigma(borders: tuple[GateBorder, GateBorder]) -> float:
    """σ [rad] of the cone's edges: the ego end and coop start headings are each the mean of
    their two borders' chord headings (:func:`chord_heading_sigma`), independent."""
    variance = 0.0
    for border in borders:
        for points, sigma, at_end in ((border.ego_points, border.ego.sensor, True),
                                      (border.coop_points, border.coop.sensor, False)):
            variance += 0.25 * chord_heading_sigma(points, np.sqrt(sigma), at_end) ** 2
    return math.sqrt(variance)


def border_sigma(border: GateBorder, gap_m: float, turn_sigma_rad: float) -> float:
    """Combined lateral σ [m] of a border's excess: the ego end's stated variance, the coop
    start's (stated, its sender's pose and the ego's pose in the ego frame) and the cone
    edges' heading σ (:func:`turn_sigma`) times the gap; at least :data:`MIN_SIGMA_M`."""
    ego_var = float(border.ego.sensor[-1])
    coop_var = float(border.coop.sensor[0] + border.coop.pose[0] + border.coop.relative[0])
    return max(math.sqrt(ego_var + coop_var + (turn_sigma_rad * gap_m) ** 2), MIN_SIGMA_M)


def gate_reason(borders: tuple[GateBorder, GateBorder], gap_m: float, width_m: float, false_rejection: float) -> str:
    """Why the gate rejects the pair ("" when it passes): the larger normalised excess squared
    of the two borders above :func:`gate_threshold` (another lane), or the adjacent lane a
    ``width_m`` outside the cone passing as well (ambiguous)."""
    threshold, turn = gate_threshold(false_rejection), turn_sigma(borders)
    statistic, excess, sigma = max(((b.excess / s) ** 2, b.excess, s)
                                   for b, s in ((b, border_sigma(b, gap_m, turn)) for b in borders))
    if statistic > threshold:
        return (f"a coop lane border starts {excess:.2f} m outside the cone of the end headings, "
                f"{math.sqrt(statistic):.1f} σ (σ = {sigma:.3f} m; gate {math.sqrt(threshold):.2f} σ at "
                f"{false_rejection:.1%} false rejection): another lane")
    if ((width_m - excess) / sigma) ** 2 <= threshold:
        return (f"ambiguous: the coop lane border {excess:.2f} m outside the cone passes the gate "
                f"({math.sqrt(threshold):.2f} σ, σ = {sigma:.3f} m) for the own lane and for the lane "
                f"{width_m:.2f} m beside it")
    return ""
