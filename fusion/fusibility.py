"""Verification of fusibility (paper sec. III-B.1) and the curve-aware default rule.

Frames: the paper states its pose cases in a left-handed frame (CARLA), where "ahead-right"
is y_rel > 0. This module uses ISO 8855 / OpenDRIVE (right-handed, y left, yaw CCW), so
"ahead-right turning right" is y_rel < 0 with Ψ_rel ≈ −90° and "ahead-left turning left"
is y_rel > 0 with Ψ_rel ≈ +90°.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Final, Literal, Sequence


from fusion.geometry import EndFit, end_direction, wrap_angle
from fusion.types import SEPARATION_RULES, FusionParams, NDArrayFloat, Pose2D

CHORD_WINDOW_M: Final[float] = 4.0
_MIN_GAP_M: Final[float] = 1e-6
_MIN_ARC_CURVATURE: Final[float] = 1.0 / 1000.0
_ARC_LENGTH_SLACK: Final[float] = 1.2
_CURVATURE_SLACK: Final[float] = 0.02
_CURVED_SIGMAS: Final[float] = 4.0
ARC_TOLERANCE_LANES: Final[float] = 0.5
"""Largest mismatch of an arc prediction (rule 4 of :func:`geometric_assessment`), in lane widths."""
_CONE_DECIDES_LANES: Final[float] = 0.4
GAP_TOLERANCE_M: Final[float] = 1e-3
"""Tolerance [m] on d_s ≤ d_i under ``association="separation"`` and ``"fork"``: a coop a lane length d_i
behind the ego's detection end lies at d_s = d_i up to the detections' rounding (1 µm) and
floating point; without it half of such pairs fail on d_s − d_i ≈ 1e-8 m."""
_TANGENT_SLACK_M: Final[float] = 2.0
"""How far [m] an end's arc may meet the other end's heading beyond that end (the arc
radius ± 2 % + 3σ, clothoid transitions) before the prediction counts as missed."""

Evidence = Literal["cone", "arc", "open", "s_bend"]


@dataclass(frozen=True)
class LaneEnds:
    """Where the ego detection ends and the coop detection starts (one common frame).

    Fields: ``p_end``/``p_start`` centre points [m]; ``t_end``/``t_start`` unit tangents
    (driving direction); ``width_m`` ego lane width at its end [m]; ``gap_m`` signed
    centre-line gap (Euclidean length, negative when the coop start is not more than 1 µm
    ahead of the ego end along ``t_end``).
    """

    p_end: tuple[float, float]
    p_start: tuple[float, float]
    t_end: tuple[float, float]
    t_start: tuple[float, float]
    width_m: float
    gap_m: float


def _mean_direction(a: tuple[float, float], b: tuple[float, float]) -> tuple[float, float]:
    x, y = a[0] + b[0], a[1] + b[1]
    n = math.hypot(x, y) or 1.0
    return x / n, y / n


def lane_end(left: NDArrayFloat, right: NDArrayFloat, at_end: bool) -> tuple[tuple[float, float], tuple[float, float]]:
    """``(point, tangent)`` of a lane's centre line at its last (``at_end``) or first cross-section,
    in the borders' frame: the middle of the two border points [m] and the mean of the two
    borders' chord tangents (:func:`fusion.geometry.end_direction`, driving direction)."""
    (lx, ly), (rx, ry) = (left[-1] if at_end else left[0]).tolist(), (right[-1] if at_end else right[0]).tolist()
    return ((0.5 * (lx + rx), 0.5 * (ly + ry)),
            _mean_direction(end_direction(left, at_end, CHORD_WINDOW_M), end_direction(right, at_end, CHORD_WINDOW_M)))


def signed_gap_m(p_end: tuple[float, float], t_end: tuple[float, float], p_start: tuple[float, float]) -> float:
    """The centre-line gap from an end ``p_end`` (unit tangent ``t_end``) to a start ``p_start``
    [m]: their distance, negative when the start is not more than 1 µm ahead along ``t_end``."""
    dx, dy = p_start[0] - p_end[0], p_start[1] - p_end[1]
    length = math.hypot(dx, dy)
    return length if dx * t_end[0] + dy * t_end[1] > _MIN_GAP_M else -length


EgoEnd = tuple[tuple[float, float], tuple[float, float], float]
"""``(point, tangent, width_m)`` of the ego lane at its end (:func:`ego_lane_end`)."""


def ego_lane_end(ego_left: NDArrayFloat, ego_right: NDArrayFloat) -> EgoEnd:
    """The ego lane's centre-line end point and tangent (:func:`lane_end`) and its width
    there [m], in the borders' frame."""
    p_end, t_end = lane_end(ego_left, ego_right, True)
    (lx, ly), (rx, ry) = ego_left[-1].tolist(), ego_right[-1].tolist()
    return p_end, t_end, math.hypot(lx - rx, ly - ry)


def lane_ends(ego_left: NDArrayFloat, ego_right: NDArrayFloat, coop_left: NDArrayFloat,
              coop_right: NDArrayFloat, ego_end: EgoEnd | None = None) -> LaneEnds:
    """Centre-line end of the ego lane and start of the coop lane, in the borders' frame;
    ``ego_end`` the :func:`ego_lane_end` of the ego borders when the caller has it."""
    p_end, t_end, width = ego_lane_end(ego_left, ego_right) if ego_end is None else ego_end
    p_start, t_start = lane_end(coop_left, coop_right, False)
    return LaneEnds(p_end, p_start, t_end, t_start, width, signed_gap_m(p_end, t_end, p_start))


def relative_pose(ego: Pose2D, coop: Pose2D) -> tuple[float, float, float]:
    """``(x_rel, y_rel, psi_rel)`` of the coop vehicle in the ego vehicle frame [m, m, rad]."""
    dx, dy = coop.x - ego.x, coop.y - ego.y
    c, s = math.cos(ego.yaw), math.sin(ego.yaw)
    return c * dx + s * dy, -s * dx + c * dy, wrap_angle(coop.yaw - ego.yaw)


def max_gap_m(params: FusionParams) -> float:
    """The longest gap d_s [m] the rule bridges: d_i, plus :data:`GAP_TOLERANCE_M` under the
    separation rules."""
    return params.d_i_m + (GAP_TOLERANCE_M if params.association in SEPARATION_RULES else 0.0)


def _gap_reason(ends: LaneEnds, params: FusionParams) -> str:
    if ends.gap_m <= 0.0:
        return f"no gap: the coop detection starts {-ends.gap_m:.2f} m before the ego detection ends (d_s must be > 0)"
    if ends.gap_m > max_gap_m(params):
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
                    end_fits: Callable[[], Sequence[EndFit]] | None = None) -> str:
    """Curve-aware fusibility of a gap; returns the rejection reason or ``""`` (the reason
    of :func:`geometric_assessment`)."""
    return geometric_assessment(ego, coop, ends, params, end_fits)[0]


def geometric_assessment(ego: Pose2D, coop: Pose2D, ends: LaneEnds, params: FusionParams,
                         end_fits: Callable[[], Sequence[EndFit]] | None = None) -> tuple[str, Evidence]:
    """Curve-aware fusibility of a gap: ``(reason, evidence)``, reason ``""`` when fusible.

    ``evidence`` says which rule decided (see :data:`Evidence`): ``"cone"`` when the cone of
    rule 3 is narrower than 0.4 lane widths (a straight or one arc across the gap: the
    neighbour lane lies a lane width outside it), ``"arc"`` when rule 4 applied, ``"open"``
    when neither (the radius inside the gap is open), ``"s_bend"`` when the coop start passed
    only with the S-bend shift.

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
       tolerating heading noise over a 50 m gap. When the two ends curve opposite ways (an
       S-bend in the gap) the excess may grow by the bend's shift (:func:`s_bend_shift`);
    4. arcs: where the cone is wider than 0.4 of the lane width (d_s·sin|Δψ| above that;
       narrower, rule 3 already rejects a neighbour), a detection end that lies on an arc
       (measured curvature, see :func:`fusion.geometry.fit_ends`) predicts the gap: the lane
       follows that arc to the other end's heading, then goes straight. The coop start (from
       a curved ego end) or the ego end (from a curved coop start, backwards) must lie within
       half the lane width of that prediction (:func:`arc_mismatch`). This rejects the
       neighbour lane when a curve starts or ends inside the gap, or both ends lie in one
       curve, however gentle; the same lane is off only by a clothoid shift (L²/24R).
       ``end_fits`` returns the least-squares fits of the (ego left, ego right) ends and (coop
       left, coop right) starts (:func:`fusion.spline.lane_end_fits`; :func:`fusion.fuse`
       passes :meth:`fusion.spline.EndFits.arcs`, which takes the curvature of a whole
       detection that is one arc where the end window cannot resolve it under noise); the
       rule is skipped without them. Two straight ends (a whole curve inside the gap), clothoid ends and ends
       curving opposite ways leave the radius in the gap open: only the cone applies then.
    """
    x_rel, _, _ = relative_pose(ego, coop)
    if x_rel <= 0.0:
        return f"coop vehicle is not ahead of the ego (x_rel = {x_rel:.2f} m)", "cone"
    reason = _gap_reason(ends, params)
    if reason:
        return reason, "cone"
    turn, excess = cone_excess(ends)
    if abs(turn) > math.pi / 2 + params.t_psi_rad:
        return (f"coop lane heading differs by {math.degrees(turn):.1f} deg (more than 90 deg + t_psi): "
                "not the same direction"), "cone"
    evidence: Evidence = "cone"
    if excess > 0.5 * ends.width_m:
        shift = s_bend_shift(ends.gap_m, end_fits()) if end_fits is not None else 0.0
        if excess > 0.5 * ends.width_m + shift:
            return (f"coop lane start lies {excess:.2f} m laterally outside the turn between the two end headings "
                    f"(more than half the lane width {ends.width_m:.2f} m + S-bend shift {shift:.2f} m): another lane",
                    "cone")
        evidence = "s_bend"
    cone_width = ends.gap_m * math.sin(min(abs(turn), math.pi / 2))
    if cone_width > _CONE_DECIDES_LANES * ends.width_m and evidence == "cone":
        evidence = "open"
        predictions = arc_predictions(ends, end_fits()) if end_fits is not None else []
        if predictions:
            evidence = "arc"
            mismatch = min(predictions)
            if mismatch > ARC_TOLERANCE_LANES * ends.width_m:
                return (f"a detection end lies on an arc that puts the coop start {mismatch:.2f} m off "
                        f"(more than {ARC_TOLERANCE_LANES:.2f} of the lane width {ends.width_m:.2f} m, or the "
                        "arc meets the other end's heading beyond that end): another lane", "arc")
    return "", evidence


def cone_excess(ends: LaneEnds) -> tuple[float, float]:
    """``(turn, excess)``: the heading change Δψ from the ego end to the coop start [rad] and
    how far [m] the coop start lies laterally outside the cone of the two end headings (rule 3
    of :func:`geometric_assessment`; 0 inside)."""
    turn = end_turn(ends)
    return turn, cone_point_excess(ends.t_end, turn, ends.p_end, ends.p_start, abs(ends.gap_m))


def end_turn(ends: LaneEnds) -> float:
    """The heading change Δψ from the ego end to the coop start [rad]."""
    t0, t1 = ends.t_end, ends.t_start
    return math.atan2(t0[0] * t1[1] - t0[1] * t1[0], t0[0] * t1[0] + t0[1] * t1[1])


def cone_point_excess(t_end: tuple[float, float], turn: float, p_end: tuple[float, float],
                      p_start: tuple[float, float], distance_m: float) -> float:
    """How far [m] ``p_start`` lies laterally outside the cone drawn from ``p_end`` between the
    heading ``t_end`` (unit vector) and that heading turned by ``turn`` [rad], for a point
    ``distance_m`` away (:func:`cone_excess` on floats; 0 inside)."""
    t0 = t_end
    d = (p_start[0] - p_end[0], p_start[1] - p_end[1])
    phi = math.atan2(t0[0] * d[1] - t0[1] * d[0], t0[0] * d[0] + t0[1] * d[1])
    outside = max(min(0.0, turn) - phi, phi - max(0.0, turn), 0.0)
    return distance_m * math.sin(min(outside, math.pi / 2))


def _mean_heading(a: EndFit, b: EndFit) -> float:
    return math.atan2(a.direction[1] + b.direction[1], a.direction[0] + b.direction[0])


def _curvature(a: EndFit, b: EndFit) -> tuple[float, float]:
    """Centre curvature [1/m] at an end from its two border fits, and its σ [1/m]."""
    return 0.5 * (a.curvature + b.curvature), 0.5 * math.hypot(a.curvature_sigma, b.curvature_sigma)


def clearly_curved(k: float, sd: float) -> bool:
    """Whether an end of curvature ``k`` (σ ``sd``) [1/m] is clearly curved: |κ| at least
    1/1000 m⁻¹ and 4σ."""
    return abs(k) >= max(_MIN_ARC_CURVATURE, _CURVED_SIGMAS * sd)


def _opposite_curves(k0: float, s0: float, k1: float, s1: float) -> bool:
    """Whether two ends with curvatures ``k0``, ``k1`` (σ ``s0``, ``s1``) [1/m] clearly curve
    opposite ways."""
    return clearly_curved(k0, s0) and clearly_curved(k1, s1) and k0 * k1 < 0.0


def s_bend_shift(gap_m: float, fits: Sequence[EndFit]) -> float:
    """Lateral shift [m] an S-bend can put between the two end headings over ``gap_m``.

    When the ego end and the coop start (least-squares ``fits`` of ego left, ego right, coop
    left, coop right) clearly curve opposite ways, the lane reverses its curve inside the
    gap; two arcs of curvature κ and −κ over L/2 each shift it by κ·L²/4 (κ the smaller of
    the two measured |κ|). 0 otherwise.
    """
    (k0, s0), (k1, s1) = _curvature(fits[0], fits[1]), _curvature(fits[2], fits[3])
    return min(abs(k0), abs(k1)) * gap_m * gap_m / 4.0 if _opposite_curves(k0, s0, k1, s1) else 0.0


def _arc_line_mismatch(p_from: tuple[float, float], psi_from: float, p_to: tuple[float, float], psi_to: float,
                       turn: float, radii: tuple[float, float]) -> float:
    """Smallest mismatch [m] of ``p_to`` with the straight (heading ``psi_to``) that follows an
    arc leaving ``p_from`` at ``psi_from`` and turning by ``turn``, over the radii in ``radii``
    [m]: its lateral offset from that straight, or, when ``p_to`` lies behind the arc's end
    along ``psi_to`` by more than :data:`_TANGENT_SLACK_M` (the lane would have to leave the
    arc before reaching ``p_to``'s heading: the curve of ``p_to``'s lane began before
    ``p_from``), that shortfall beyond the slack if larger. Both are affine in the radius, so
    the minimum is taken over the interval ends."""
    vx, vy = math.sin(psi_from + turn) - math.sin(psi_from), math.cos(psi_from) - math.cos(psi_from + turn)
    dx, dy = p_to[0] - p_from[0], p_to[1] - p_from[1]
    c, s = math.cos(psi_to), math.sin(psi_to)
    sign = math.copysign(1.0, turn)
    base, slope = c * dy - s * dx, (c * vy - s * vx) * sign
    lo, hi = base - slope * radii[0], base - slope * radii[1]
    lateral = 0.0 if lo * hi <= 0.0 else min(abs(lo), abs(hi))
    along_base, along_slope = c * dx + s * dy, (c * vx + s * vy) * sign
    along = max(along_base - along_slope * radii[0], along_base - along_slope * radii[1])
    return max(lateral, -along - _TANGENT_SLACK_M)


def _end_arc_radii(k: float, sd: float, turn: float, gap_m: float) -> tuple[float, float] | None:
    """Radius interval [m] of an end's arc that turns the lane by ``turn`` inside the gap, or
    ``None`` when the end is not clearly curved that way (|κ| < 1/1000 m⁻¹ or < 4σ, or the
    other way) or its arc is too gentle to make the turn within 1.2·``gap_m`` (then the
    curvature must change in the gap, and the end's arc says nothing about where the lane
    goes)."""
    k_feasible = abs(turn) / (_ARC_LENGTH_SLACK * gap_m)
    if abs(k) < max(_MIN_ARC_CURVATURE, _CURVED_SIGMAS * sd, k_feasible) or k * turn <= 0.0:
        return None
    k_hi = abs(k) * (1.0 + _CURVATURE_SLACK) + 3.0 * sd
    k_lo = max(abs(k) * (1.0 - _CURVATURE_SLACK) - 3.0 * sd, k_feasible)
    return (1.0 / k_hi, 1.0 / k_lo) if k_lo < k_hi else None


def arc_mismatch(ends: LaneEnds, fits: Sequence[EndFit]) -> float:
    """Lateral mismatch [m] of the two detection ends with the arc a curved end lies on: the
    smallest of :func:`arc_predictions`, 0 when there is none."""
    return min(arc_predictions(ends, fits), default=0.0)


def arc_predictions(ends: LaneEnds, fits: Sequence[EndFit]) -> list[float]:
    """Mismatches [m] of the two detection ends with the arcs the curved ends lie on.

    A detection end that is clearly curved the way the lane turns (see
    :func:`_end_arc_radii`; curvature from the least-squares ``fits`` of (ego left, ego right,
    coop left, coop right), ± 2 % + 3σ) predicts the gap: the lane goes on along that arc
    until it reaches the other end's heading, then straight. From a curved ego end the coop
    start must lie on that straight; from a curved coop start (followed backwards) the ego
    end must (:func:`_arc_line_mismatch`, which also misses an end lying behind where the arc
    reaches its heading). This covers a curve that starts or ends inside the gap (one end
    straight) and both ends in one curve; the adjacent lane lies a lane width off either way,
    the same lane within a clothoid shift (L²/24R). Two curved ends whose radius intervals
    overlap lie on one arc (its radii: the intersection; one prediction); otherwise (a
    compound curve) one per curved end. Empty when no end applies, when the ends curve
    opposite ways (an S-bend in the gap) or when there is no gap.
    """
    if ends.gap_m <= 0.0:
        return []
    psi0, psi1 = _mean_heading(fits[0], fits[1]), _mean_heading(fits[2], fits[3])
    turn = wrap_angle(psi1 - psi0)
    (k0, s0), (k1, s1) = _curvature(fits[0], fits[1]), _curvature(fits[2], fits[3])
    if _opposite_curves(k0, s0, k1, s1):
        return []
    ego_radii, coop_radii = _end_arc_radii(k0, s0, turn, ends.gap_m), _end_arc_radii(k1, s1, turn, ends.gap_m)
    if ego_radii is not None and coop_radii is not None:
        common = (max(ego_radii[0], coop_radii[0]), min(ego_radii[1], coop_radii[1]))
        if common[0] <= common[1]:
            ego_radii, coop_radii = common, None
    mismatches = []
    if ego_radii is not None:
        mismatches.append(_arc_line_mismatch(ends.p_end, psi0, ends.p_start, psi1, turn, ego_radii))
    if coop_radii is not None:
        mismatches.append(_arc_line_mismatch(ends.p_start, psi1 + math.pi, ends.p_end, psi0 + math.pi, -turn,
                                             coop_radii))
    return mismatches
