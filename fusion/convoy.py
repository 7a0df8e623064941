"""Convoy fusion (paper sec. III-A) of one border pair in a common frame."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Final

import numpy as np

from fusion.geometry import project_point
from fusion.types import NDArrayFloat, Source
from fusion.uncertainty import BorderVariance, fused_variance, inverse_variance_weight, smoothstep

_HEADING_HALF_WINDOW: Final[int] = 5


@dataclass(frozen=True)
class OverlapStart:
    """Where a coop border starts on an ego border.

    Fields: ``s_ego`` arc length of every ego vertex [m]; ``s0`` arc length of the foot of
    the coop start on the ego border [m]; ``offset_m`` its distance from the border [m];
    ``heading_diff_rad`` angle between the two borders there [rad].
    """

    s_ego: NDArrayFloat
    s0: float
    offset_m: float
    heading_diff_rad: float


def overlap_start(ego: NDArrayFloat, coop: NDArrayFloat, s_ego: NDArrayFloat) -> OverlapStart:
    """Project the coop border start onto the ego border, whose vertices lie at arc lengths
    ``s_ego`` (see :class:`OverlapStart`)."""
    s0, offset, k = project_point(coop[0], ego, s_ego)
    a, b = max(0, k - _HEADING_HALF_WINDOW), min(ego.shape[0] - 1, k + 1 + _HEADING_HALF_WINDOW)
    c = min(coop.shape[0] - 1, 2 * _HEADING_HALF_WINDOW)
    (ax, ay), (bx, by), (c0x, c0y), (ccx, ccy) = ego[a].tolist(), ego[b].tolist(), coop[0].tolist(), coop[c].tolist()
    ex, ey, cx, cy = bx - ax, by - ay, ccx - c0x, ccy - c0y
    diff = math.atan2(ex * cy - ey * cx, ex * cx + ey * cy)
    return OverlapStart(s_ego, s0, offset, abs(diff))


def overlap_length(start: OverlapStart, s_coop: NDArrayFloat) -> tuple[float, bool]:
    """(length [m], whether the coop continues past the ego's end) of the overlap of a coop
    border (vertex arc lengths ``s_coop``) that starts on an ego border at ``start``: what
    is left of the ego border past s0, or the whole coop border when that ends first."""
    ego_left = start.s_ego.item(-1) - start.s0
    coop_continues = ego_left <= s_coop.item(-1)
    return (ego_left if coop_continues else s_coop.item(-1)), coop_continues


def convoy_border(ego: NDArrayFloat, coop: NDArrayFloat, s_coop: NDArrayFloat, start: OverlapStart,
                  coop_weight: float, blend_offset_m: float,
                  variances: tuple[BorderVariance, BorderVariance] | None = None,
                  inverse_variance: bool = False,
                  end_blend_m: float = 0.0,
                  shared: NDArrayFloat | None = None) -> list[tuple[NDArrayFloat, Source, NDArrayFloat | None]]:
    """Fuse one ego border with the coop border that starts inside it.

    The coop start projects onto the ego border at arc length s0 (``start``); ``s_coop`` are
    the arc lengths of the coop vertices. Ego points
    before s0 are kept; each ego point in the overlap, at arc length s, is paired with the
    coop point at arc length s − s0 along the coop border (arc-length pairing, not array
    index) and replaced by (1 − w)·P_ego + w·P_coop with w = ``coop_weight``; the rest of the
    coop border is appended. When the borders are more than ``blend_offset_m`` apart at s0,
    w instead rises linearly from 0 at the overlap start to 1 at its end, so the result has
    no jump. Returns the parts in order with their :class:`Source` labels and, with
    ``variances`` (ego's, coop's: :class:`fusion.uncertainty.BorderVariance`), their world
    variances [m²] (else None). ``inverse_variance`` (needs ``variances``) weights each pair
    by :func:`fusion.uncertainty.inverse_variance_weight` of their ego-frame variances over
    the whole overlap and closes the steps at its two ends outside it
    (:func:`_seam_blend`, over ``end_blend_m``). ``shared`` (per coop point, [m]) is the
    covariance of a coop point's error with that of an ego point of unit σ (a coop corrected
    from the overlap, :func:`fusion.registration.ego_shared`): a fused point's variance then
    adds 2w(1 − w)·σ_e·``shared``.
    """
    s_ego, s0, offset = start.s_ego, start.s0, start.offset_m
    first = int(s_ego.searchsorted(s0))
    overlap_end, coop_continues = overlap_length(start, s_coop)
    stop = ego.shape[0] if coop_continues else int(s_ego.searchsorted(s0 + overlap_end, side="right"))
    u = s_ego[first:stop] - s0
    paired = np.interp(u, s_coop, np.ascontiguousarray(coop).view(np.complex128)[:, 0])
    overlap = np.ascontiguousarray(ego[first:stop]).view(np.complex128)[:, 0]
    ramp = offset > blend_offset_m and overlap_end > 0.0
    seams = inverse_variance and variances is not None and not ramp and u.size > 0 and end_blend_m > 0.0
    if ramp:
        w: NDArrayFloat | float = u / overlap_end
    elif inverse_variance and variances is not None:
        e, c = variances
        w = inverse_variance_weight(e.sensor[first:stop], np.interp(u, s_coop, c.sensor + c.pose + c.relative))
    else:
        w = coop_weight
    difference = paired - overlap  # coop minus ego at each overlap point
    paired = overlap + w * difference
    ego_var = coop_var = paired_var = None
    cross = _cross(variances, shared, s_coop)
    if variances is not None:
        ego_var, coop_var = variances[0].world, variances[1].world
        paired_var = np.interp(u, s_coop, coop_var)
        fused_var: NDArrayFloat | None = fused_variance(w, ego_var[first:stop], paired_var,
                                                        cross(slice(first, stop), u))
    else:
        fused_var = None
    before, before_var = ego[:first], None if ego_var is None else ego_var[:first]
    if seams:
        assert isinstance(w, np.ndarray) and ego_var is not None and paired_var is not None
        before, before_var = _seam_blend(before, s0 - s_ego[:first], w[0] * difference[0], end_blend_m,
                                         lambda lam: fused_variance(w[0] * lam, ego_var[:first], paired_var[0],
                                                                    cross(slice(0, first), 0.0)))
    parts = [(before, Source.EGO, before_var), (paired.view(np.float64).reshape(-1, 2), Source.FUSED, fused_var)]
    if not coop_continues:
        after, after_var = ego[stop:], None if ego_var is None else ego_var[stop:]
        if seams:
            assert isinstance(w, np.ndarray) and ego_var is not None and paired_var is not None
            after, after_var = _seam_blend(after, s_ego[stop:] - s0 - u[-1], w[-1] * difference[-1], end_blend_m,
                                           lambda lam: fused_variance(w[-1] * lam, ego_var[stop:], paired_var[-1],
                                                                      cross(slice(stop, None), u[-1])))
        parts.append((after, Source.EGO, after_var))
    else:
        tail = int(s_coop.searchsorted(overlap_end, side="right"))
        after, after_var = coop[tail:], None if coop_var is None else coop_var[tail:]
        if seams:
            assert isinstance(w, np.ndarray) and ego_var is not None and coop_var is not None
            after, after_var = _seam_blend(after, s_coop[tail:] - u[-1], (w[-1] - 1.0) * difference[-1],
                                           end_blend_m, lambda lam: fused_variance(1.0 - (1.0 - w[-1]) * lam,
                                                                                   ego_var[stop - 1], coop_var[tail:],
                                                                                   cross(stop - 1, s_coop[tail:])))
        parts.append((after, Source.COOP, after_var))
    return parts


def _seam_blend(points: NDArrayFloat, distance: NDArrayFloat, step: complex, length_m: float,
                variance: Callable[[NDArrayFloat], NDArrayFloat]) -> tuple[NDArrayFloat, NDArrayFloat]:
    """Points of one sender beside an end of the overlap moved by λ·``step`` (the fused
    point minus this sender's at that end, x + iy [m]), λ = smoothstep(1 − d / ``length_m``)
    of their arc distance d [m] from that end (1 there, 0 from ``length_m`` on): the seam's
    fusion fades out instead of jumping, and ``variance(λ)`` gives their world variances [m²]."""
    lam = smoothstep(1.0 - distance / length_m)
    moved = points + lam[:, None] * np.array([step.real, step.imag])
    return moved, variance(lam)


def _cross(variances: tuple[BorderVariance, BorderVariance] | None, shared: NDArrayFloat | None,
           s_coop: NDArrayFloat) -> Callable[[slice | int, NDArrayFloat | float], NDArrayFloat | None]:
    """cross(ego points, u): the covariance [m²] of those ego points' errors with the coop's
    at arc lengths u, σ_e·``shared``(u) (None without ``shared``)."""
    def cross(ego: slice | int, u: NDArrayFloat | float) -> NDArrayFloat | None:
        if variances is None or shared is None:
            return None
        return np.sqrt(variances[0].sensor[ego]) * np.interp(u, s_coop, shared)
    return cross
