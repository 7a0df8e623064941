"""Verification of fusibility (paper sec. III-B.1) and the curve-aware default rule.

Frames: the paper states its pose cases in a left-handed frame (CARLA), where "ahead-right"
is y_rel > 0. This module uses ISO 8855 / OpenDRIVE (right-handed, y left, yaw CCW), so
"ahead-right turning right" is y_rel < 0 with Ψ_rel ≈ −90° and "ahead-left turning left"
is y_rel > 0 with Ψ_rel ≈ +90°.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fusion.geometry import end_direction, wrap_angle
from fusion.types import FusionParams, NDArrayFloat, Pose2D

_CHORD_WINDOW_M = 4.0
_CURVATURE_WINDOW_M = 5.0
_MIN_ARC_CURVATURE = 1.0 / 300.0


@dataclass(frozen=True)
class LaneEnds:
    """Where the ego detection ends and the coop detection starts (world frame).

    Fields: ``p_end``/``p_start`` centre points [m]; ``t_end``/``t_start`` unit tangents
    (driving direction); ``width_m`` ego lane width at its end [m]; ``gap_m`` signed
    centre-line gap (Euclidean length, negative when the coop start is not ahead of the ego
    end along ``t_end``).
    """

    p_end: NDArrayFloat
    p_start: NDArrayFloat
    t_end: tuple[float, float]
    t_start: tuple[float, float]
    width_m: float
    gap_m: float


def _mean_direction(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    x, y = a[0] + b[0], a[1] + b[1]
    n = math.hypot(x, y) or 1.0
    return x / n, y / n


def lane_ends(ego_left: NDArrayFloat, ego_right: NDArrayFloat, coop_left: NDArrayFloat,
              coop_right: NDArrayFloat) -> LaneEnds:
    """Centre-line end of the ego lane and start of the coop lane, in the world frame."""
    p_end = 0.5 * (ego_left[-1] + ego_right[-1])
    p_start = 0.5 * (coop_left[0] + coop_right[0])
    t_end = _mean_direction(end_direction(ego_left, True, _CHORD_WINDOW_M),
                            end_direction(ego_right, True, _CHORD_WINDOW_M))
    t_start = _mean_direction(end_direction(coop_left, False, _CHORD_WINDOW_M),
                              end_direction(coop_right, False, _CHORD_WINDOW_M))
    d = p_start - p_end
    length = math.hypot(d[0], d[1])
    along = d[0] * t_end[0] + d[1] * t_end[1]
    width = math.hypot(*(ego_left[-1] - ego_right[-1]))
    return LaneEnds(p_end, p_start, t_end, t_start, width, length if along > 0.0 else -length)


def relative_pose(ego: Pose2D, coop: Pose2D) -> tuple[float, float, float]:
    """``(x_rel, y_rel, psi_rel)`` of the coop vehicle in the ego vehicle frame [m, m, rad]."""
    dx, dy = coop.x - ego.x, coop.y - ego.y
    c, s = math.cos(ego.yaw), math.sin(ego.yaw)
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(coop.yaw - ego.yaw)


def _gap_reason(ends: LaneEnds, params: FusionParams) -> str:
    if ends.gap_m <= 0.0:
        return f"no gap: the coop detection starts {-ends.gap_m:.2f} m before the ego detection ends (d_s must be > 0)"
    if ends.gap_m > params.d_i_m:
        return f"gap d_s = {ends.gap_m:.2f} m exceeds d_i = {params.d_i_m:.2f} m"
    return ""


def paper_check(ego: Pose2D, coop: Pose2D, ends: LaneEnds, params: FusionParams) -> str:
    """The paper's three pose cases; returns the rejection reason or ``""``.

    Accepts x_rel > 0 and one of: |y_rel| ≤ t_pos with |Ψ_rel| ≤ t_Ψ (ahead, same
    direction); y_rel < 0 with |Ψ_rel + 90°| ≤ t_Ψ (ahead-right turning right; the paper's
    y_rel > 0 in its left-handed frame); y_rel > 0 with |Ψ_rel − 90°| ≤ t_Ψ (ahead-left
    turning left). Then 0 < d_s ≤ d_i.
    """
    x_rel, y_rel, psi = relative_pose(ego, coop)
    if x_rel <= 0.0:
        return f"coop vehicle is not ahead of the ego (x_rel = {x_rel:.2f} m)"
    tol = params.t_psi_rad
    straight = abs(y_rel) <= params.t_pos_m and abs(psi) <= tol
    right = y_rel < 0.0 and abs(psi + math.pi / 2) <= tol
    left = y_rel > 0.0 and abs(psi - math.pi / 2) <= tol
    if not (straight or right or left):
        return (f"relative pose (y_rel = {y_rel:.2f} m, psi_rel = {math.degrees(psi):.1f} deg) matches none of "
                "the paper's cases (ahead, ahead-right turning right, ahead-left turning left)")
    return _gap_reason(ends, params)


def geometric_check(ego: Pose2D, coop: Pose2D, ends: LaneEnds, params: FusionParams,
                    curvatures: tuple[float, float] | None = None) -> str:
    """Curve-aware fusibility of a gap; returns the rejection reason or ``""``.

    The rule compares the *detections*, not the vehicle poses, so a coop vehicle on the same
    lane in the middle of a curve passes. With the ego end P0 (heading ψ0), the coop start
    P1 (heading ψ1), Δψ = ψ1 − ψ0 and the chord direction φ of P0→P1 relative to ψ0:

    1. the coop vehicle is ahead of the ego vehicle (x_rel > 0), and 0 < d_s ≤ d_i;
    2. |Δψ| ≤ 90° + t_Ψ: the same direction up to a right-angle turn (rejects the opposite
       direction);
    3. cone: a lane that turns one way between P0 and P1 has its chord between the two end
       headings, so φ must lie between 0 and Δψ; the lateral excess of P1 outside that cone
       may be at most half the ego lane width (measured at the ego end). On a straight this
       is a lateral offset test that rejects the adjacent lane (a full lane width off) while
       tolerating heading noise over a 50 m gap and the shift of an S-bend;
    4. arc consistency: when both ends are curved the same way (the detections' curvatures
       agree within 50 %), the gap is taken as one arc, whose chord direction is Δψ/2;
       P1 may then deviate from that line by at most half the ego lane width (the adjacent
       lane of a curve lies a full lane width off it). ``curvatures`` are the centre-line
       curvatures (ego end, coop start) [1/m], see :func:`lane_curvatures`; the check is
       skipped without them or when |Δψ| ≤ t_Ψ.
    """
    x_rel, _, _ = relative_pose(ego, coop)
    if x_rel <= 0.0:
        return f"coop vehicle is not ahead of the ego (x_rel = {x_rel:.2f} m)"
    reason = _gap_reason(ends, params)
    if reason:
        return reason
    t0, t1 = ends.t_end, ends.t_start
    turn = math.atan2(t0[0] * t1[1] - t0[1] * t1[0], t0[0] * t1[0] + t0[1] * t1[1])
    if abs(turn) > math.pi / 2 + params.t_psi_rad:
        return f"coop lane heading differs by {math.degrees(turn):.1f} deg (more than 90 deg + t_psi): not the same direction"
    d = ends.p_start - ends.p_end
    phi = math.atan2(t0[0] * d[1] - t0[1] * d[0], t0[0] * d[0] + t0[1] * d[1])
    lo, hi = min(0.0, turn), max(0.0, turn)
    outside = max(lo - phi, phi - hi, 0.0)
    excess = ends.gap_m * math.sin(min(outside, math.pi / 2))
    if excess > 0.5 * ends.width_m:
        return (f"coop lane start lies {excess:.2f} m laterally outside the turn between the two end headings "
                f"(more than half the lane width {ends.width_m:.2f} m): another lane")
    if curvatures is not None and abs(turn) > params.t_psi_rad:
        k0, k1 = curvatures
        one_arc = (k0 * k1 > 0.0 and min(abs(k0), abs(k1)) >= _MIN_ARC_CURVATURE
                   and abs(k0 - k1) <= 0.5 * max(abs(k0), abs(k1)))
        mismatch = arc_mismatch(ends)
        if one_arc and mismatch > 0.5 * ends.width_m:
            return (f"both detections lie on one arc but the coop start is {mismatch:.2f} m off it "
                    f"(more than half the lane width {ends.width_m:.2f} m): another lane")
    return ""


def lane_curvatures(ego_left: NDArrayFloat, ego_right: NDArrayFloat, coop_left: NDArrayFloat,
                    coop_right: NDArrayFloat) -> tuple[float, float]:
    """Centre-line curvature at the ego end and at the coop start [1/m] (mean of the borders)."""
    w = _CURVATURE_WINDOW_M
    k_end = 0.5 * (end_curvature(ego_left, True, w) + end_curvature(ego_right, True, w))
    k_start = 0.5 * (end_curvature(coop_left, False, w) + end_curvature(coop_right, False, w))
    return k_end, k_start


def arc_mismatch(ends: LaneEnds) -> float:
    """Lateral distance of the coop start from the line P0 + r·(heading ψ0 + Δψ/2) [m]."""
    t0, t1 = ends.t_end, ends.t_start
    turn = math.atan2(t0[0] * t1[1] - t0[1] * t1[0], t0[0] * t1[0] + t0[1] * t1[1])
    c, s = math.cos(turn / 2), math.sin(turn / 2)
    mx, my = t0[0] * c - t0[1] * s, t0[0] * s + t0[1] * c
    d = ends.p_start - ends.p_end
    return abs(mx * d[1] - my * d[0])


def end_curvature(border: NDArrayFloat, at_end: bool, window_m: float) -> float:
    """Mean curvature of the last/first ``2·window_m`` of a border [1/m] (positive left)."""
    a = end_direction(border, at_end, window_m)
    n = border.shape[0]
    approx = float(np.hypot(*(border[-1] - border[0]))) / (n - 1) or 1.0
    k = min(n - 1, max(1, int(round(window_m / approx))))
    if 2 * k >= n:
        return 0.0
    part = border[: n - k] if at_end else border[k:]
    b = end_direction(part, at_end, window_m)
    first, second = (b, a) if at_end else (a, b)
    return math.atan2(first[0] * second[1] - first[1] * second[0], first[0] * second[0] + first[1] * second[1]) / (k * approx)
