"""Lane association: whether the coop's lane is the ego's, with a confidence and a reason.

Everything in the ego vehicle frame (ISO 8855), m, rad. Every pair first meets two
tightened geometric rules (:func:`geometry_check`: each coop border, not only the centre,
within the cone's half-lane-width limit across a gap; the ego's end inside the coop's lane
in a convoy). Without neighbour lanes the geometric check then decides alone
(:func:`fusion.fusibility.geometric_assessment` for a gap, the overlap offsets for a convoy)
and the confidence level says how much its rule can tell lanes apart; every confidence is
graded by the lateral margin the pair leaves (:data:`CONFIDENCE_AT_LIMIT`). With a
multi-lane sensor (:class:`fusion.NeighbourLane`, :class:`fusion.RoadEdges`,
:class:`fusion.LaneBranch`) the lanes are matched as a whole: under a lateral *shift* δ the
coop's lane i continues the ego's lane i + δ. The coop is the ego's lane when δ = 0 passes
and no other shift explains the detections as well:

- geometry: a shift is plausible when the lane pairs it puts together that both detections
  hold at the gap — (coop 0, ego δ) and (coop −δ, ego 0) — all pass the geometric check;
- lane index from the road edge: on each side where both see the edge, the number of lanes
  between the lane and the edge must agree (a side where one sees the edge and the other
  more lanes than that beyond its lane contradicts too); a side that contradicts scores −1,
  one that agrees +1, an unknown one 0. A contradiction is only taken for a lane that opens
  or ends in the gap when the other side agrees; otherwise the coop is in another lane;
- forks: when a lane leaves the ego's lane inside its detection and the coop start is
  explained by that branch as well or better (less turn, less lateral excess), the coop is on
  the other branch (or ambiguous);
- best continuation: when the road edges contradict on one side (a lane opens or ends in the
  gap, so they alone are ambiguous), the ego's lane must continue into the coop's lane 0
  better than into any other lane the coop holds, and the coop's lane 0 continue the ego's
  lane 0 better than any other ego lane.

What decides (``FusionParams.association``): ``"legacy"`` (default) the rules above alone;
``"confidence"`` also rejects a pair below ``FusionParams.min_confidence`` (and, with
``gate_false_rejection``, one that fails the σ gate of :mod:`fusion.gate`); ``"strict"`` also
a single-lane gap pair whose lane a width aside passes the geometry too; ``"separation"``
instead only one whose lane a width aside passes using less than :data:`SEPARATION_MARGIN`
more of the lateral limits than the own lane (the geometry does not separate the two);
``"fork"`` as ``"separation"``, and a branch the ego's detection ends at (runs less than
:data:`FORK_SEEN_M` along) is not a lane the detection lies on: a camera's detection ends where
the markings stop at a junction, so which way the ego's lane goes is not seen, and a coop that
continues such a branch as well as or better than the ego's lane is rejected; where the ego's
detection states why it ended (``LaneDetection.end_reason``), one that stopped short of its range
(:data:`fusion.types.END_EARLY`) shows no branch as a lane it lies on, and a single-lane gap pair
whose ego detection ended ``"unmarked"`` (where a junction begins) is ambiguous.
Rejections for ambiguity start with "ambiguous".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Final, Mapping, Sequence

import numpy as np

from fusion.convoy import overlap_start
from fusion.fusibility import (
    ARC_TOLERANCE_LANES,
    Evidence,
    LaneEnds,
    arc_mismatch,
    cone_excess,
    cone_point_excess,
    end_turn,
    geometric_assessment,
    lane_ends,
    relative_pose,
    s_bend_shift,
)
from fusion.gate import GateBorder, gate_reason
from fusion.geometry import EndFit, end_direction, foot_point, transform
from fusion.spline import EndFits
from fusion.types import END_EARLY, SEPARATION_RULES, FusionParams, LaneDetection, NDArrayFloat, stacked_arclength
from fusion.uncertainty import pair_uncertainty

Lane = tuple[NDArrayFloat, NDArrayFloat]

GEOMETRY_CONFIDENCE: Final[Mapping[Evidence, float]] = {"cone": 0.8, "arc": 0.7, "open": 0.4, "s_bend": 0.3}
"""Confidence level of a geometric decision by the rule that made it: the cone alone (a
straight or one arc across the gap: the neighbour lane lies a lane width outside it) and an
arc prediction tell lanes apart; an open radius (whole curve inside the gap) and an S-bend
shift do not."""
CONFIDENCE_AT_LIMIT: Final[float] = 0.5
"""Share of its confidence level a fused pair keeps when it uses a lateral limit of the
geometric rules fully (:func:`geometry_check`); the confidence falls linearly from the level
(no lateral deviation) to this share of it (on the limit)."""
CONFIDENCE_EDGES_BOTH: Final[float] = 1.0
"""Lane index from the road edge agrees on both sides, no other shift plausible."""
CONFIDENCE_EDGES_ONE: Final[float] = 0.95
"""Agrees on one side, the other unknown."""
CONFIDENCE_NEIGHBOURS: Final[float] = 0.9
"""No edge seen on either side, but the neighbour lanes rule every other shift out."""
CONFIDENCE_WEAKER_ALTERNATIVE: Final[float] = 0.6
"""Another shift is plausible by geometry but has less road-edge support."""
CONFIDENCE_LANE_COUNT_CHANGE: Final[float] = 0.5
"""The lane index agrees on one side and not on the other (a lane opens or ends in the gap)."""


SEPARATION_MARGIN: Final[float] = 0.1
"""Under ``association="separation"`` a single-lane gap pair is ambiguous when the coop's
lane moved a lane width aside passes the geometric check using less than this share of a
lateral limit (``used`` of :func:`geometry_check`) more than the pair itself. Chosen on the
tune seeds of ``tools/study_families.py`` (docs/fusion/association.md): the tune false
fusions left by ``min_confidence`` 0.4 all have a neighbour that uses at most as much of a
limit (≤ 0); 0.1 keeps a tenth of a limit's buffer, larger margins only lose true pairs."""


FORK_TIE: Final[float] = 0.02
"""Costs (:func:`_fit_cost`: m for a convoy, rad + lane widths across a gap) closer than
this make a branch and the ego's own lane equally good continuations: the coop's lane is
ambiguous (lanes that still overlap just past a fork)."""


FORK_SEEN_M: Final[float] = 0.3
"""Under ``association="fork"`` a branch the ego's detection end lies inside counts as a lane
the detection lies on only when the detection runs at least this far [m] past the branch's
start (along the ego's end heading, :func:`branch_seen_m`). A camera's detection ends where
the markings stop at a junction: its branches start at its end (within the 0.1 m sampling)
or beyond it, so the fork is not seen past; a sensor that sees through the junction runs
along the branch. Chosen on the tune seeds (docs/fusion/association.md): the camera's
branches the ego end lies in start at most 0.09 m before it, the ideal sensor's at least
0.6 m."""


@dataclass(frozen=True)
class Association:
    """The lane association of one pair.

    Fields: ``reason`` why the coop's lane is not the ego's ("" when it is); ``confidence``
    in [0, 1] (0 when rejected); ``matched`` the neighbour indices both detections hold at
    the gap and that are fused too (empty without neighbours).
    """

    reason: str
    confidence: float
    matched: tuple[int, ...] = ()


def _lanes(detection: LaneDetection, own: Lane, at_end: bool, move: Callable[[NDArrayFloat], NDArrayFloat]) -> dict[int, Lane]:
    """Lane index → borders (ego frame) of the lanes a detection holds at its end (ego) or
    start (coop); ``own`` is its lane 0 already in the ego frame."""
    lanes = {0: own}
    for lane in detection.neighbours:
        if lane.at_end if at_end else lane.at_start:
            lanes[lane.index] = (move(lane.left), move(lane.right))
    return lanes


def _seen(lanes: Mapping[int, Lane], sign: int) -> int:
    """Consecutive lanes beside lane 0 on side ``sign`` (+1 left, −1 right)."""
    count = 0
    while sign * (count + 1) in lanes:
        count += 1
    return count


def _side(ego_edge: int | None, coop_edge: int | None, ego_seen: int, coop_seen: int, shift: int, sign: int) -> int:
    """+1 / −1 / 0: whether the lanes beyond the coop's lane 0 and beyond the ego's lane
    ``shift`` up to the road edge on side ``sign`` agree / contradict / cannot be compared."""
    beyond_ego = None if ego_edge is None else sign * (ego_edge - shift)
    beyond_coop = None if coop_edge is None else sign * coop_edge
    if beyond_ego is not None and beyond_coop is not None:
        return 1 if beyond_ego == beyond_coop else -1
    if beyond_ego is not None:
        return -1 if beyond_ego <= coop_seen else 0
    if beyond_coop is not None:
        return -1 if beyond_coop <= ego_seen - sign * shift else 0
    return 0


class _Pairs:
    """Geometric pass/fail of (ego lane, coop lane) pairs, computed on demand."""

    def __init__(self, ego: LaneDetection, coop: LaneDetection, ego_lanes: Mapping[int, Lane],
                 coop_lanes: Mapping[int, Lane], convoy: bool, params: FusionParams) -> None:
        self.ego, self.coop, self.ego_lanes, self.coop_lanes = ego, coop, ego_lanes, coop_lanes
        self.convoy, self.params = convoy, params

    def passes(self, ego_index: int, coop_index: int) -> bool:
        ego_lane, coop_lane = self.ego_lanes[ego_index], self.coop_lanes[coop_index]
        if self.convoy:
            return _fit_cost(ego_lane, coop_lane, True) <= self.params.convoy_max_offset_m
        (el, er), (cl, cr) = ego_lane, coop_lane
        ends = lane_ends(el, er, cl, cr)
        fits = EndFits((el, er, cl, cr), self.params)
        return not geometric_assessment(self.ego.pose, self.coop.pose, ends, self.params, fits.arcs)[0]

    def plausible(self, shift: int) -> bool | None:
        """Whether shift δ passes on every pair it forms with lane 0; None without a pair."""
        pairs = [(shift, 0)] if shift in self.ego_lanes else []
        pairs += [(0, -shift)] if -shift in self.coop_lanes else []
        return all(self.passes(e, c) for e, c in pairs) if pairs else None


def _fit_cost(ego_lane: Lane, coop_lane: Lane, convoy: bool) -> float:
    """How badly the coop lane continues an ego lane (ego frame): for a convoy overlap the
    larger distance [m] of the coop border starts from the ego borders; across a gap the turn
    between the two ends [rad] plus the coop start's lateral excess outside their cone in
    lane widths (:func:`fusion.fusibility.cone_excess`)."""
    (el, er), (cl, cr) = ego_lane, coop_lane
    if convoy:
        return max(overlap_start(e, c, stacked_arclength(e, e.shape[0])).offset_m for e, c in ((el, cl), (er, cr)))
    ends = lane_ends(el, er, cl, cr)
    turn, excess = cone_excess(ends)
    return abs(turn) + excess / max(ends.width_m, 1e-9)


def overlap_end_offset(own: tuple[Lane, Lane]) -> tuple[float, float]:
    """(distance [m] of the ego lane's end centre from the other lane's centre at that
    cross-section, half the other lane's width there [m]) of an ego lane and a lane that
    overlaps its end (the coop's in a convoy, a branch; ego frame): the feet of the end centre
    on the two other borders span the cross-section."""
    (el, er), (cl, cr) = own
    end = 0.5 * (el[-1] + er[-1])
    (lx, ly), (rx, ry) = foot_point(end, cl), foot_point(end, cr)
    ex, ey = end.tolist()
    return math.hypot(ex - 0.5 * (lx + rx), ey - 0.5 * (ly + ry)), 0.5 * math.hypot(lx - rx, ly - ry)


def _end_inside(ego_lane: Lane, other: Lane) -> bool:
    """Whether the ego lane's end centre lies inside ``other`` (:func:`overlap_end_offset`)."""
    offset, half_width = overlap_end_offset((ego_lane, other))
    return offset <= half_width


def branch_seen_m(ego_lane: Lane, branch: Lane) -> float:
    """How far [m] the ego's detection runs past the start of a branch (ego frame): the
    ego's end centre minus the branch's start centre along the ego's end heading (the chord
    over its last 2 m of each border); negative when the branch starts beyond the end."""
    (el, er), (bl, br) = ego_lane, branch
    (lx, ly), (rx, ry) = end_direction(el, True, 2.0), end_direction(er, True, 2.0)
    tx, ty = lx + rx, ly + ry
    norm = math.hypot(tx, ty) or 1.0
    dx, dy = (0.5 * (el[-1] + er[-1]) - 0.5 * (bl[0] + br[0])).tolist()
    return (dx * tx + dy * ty) / norm


def _branch_reason(ego: LaneDetection, own: tuple[Lane, Lane], convoy: bool, fork_at_end: bool = False) -> str:
    """Why the coop lane continues a lane leaving the ego's inside its detection as well as
    or better than the ego's own lane (:func:`_fit_cost`, within :data:`FORK_TIE`), or "". A
    branch that has not yet drifted away from the ego's detection end (the end lies inside
    it, :func:`overlap_end_offset`) is a lane the detection lies on as well: the coop may
    continue it or the ego's own lane, whichever is better; with ``fork_at_end``
    (``association="fork"``) only when the detection also runs :data:`FORK_SEEN_M` past the
    branch's start (:func:`branch_seen_m`) and did not stop short of its range (``ego.end_reason``
    not in :data:`fusion.types.END_EARLY`): a fork at the detection's end is not seen past, and
    beyond a detection that stopped early the lanes part unseen."""
    lanes = [(branch.left, branch.right) for branch in ego.branches]
    end_inside = [lane for lane in lanes if _end_inside(own[0], lane)]
    early = fork_at_end and ego.end_reason in END_EARLY
    inside = [lane for lane in end_inside
              if not (fork_at_end and (early or branch_seen_m(own[0], lane) < FORK_SEEN_M))]
    main = min(_fit_cost(lane, own[1], convoy) for lane in (own[0], *inside))
    for lane in lanes:
        if any(lane is other for other in inside):
            continue
        cost = _fit_cost(lane, own[1], convoy)
        if cost <= main + FORK_TIE:
            if any(lane is other for other in end_inside):
                return (f"ambiguous: a lane leaves the ego's lane at a fork at the end of the ego detection and the "
                        f"coop lane continues it as well or better ({cost:.2f} vs {main:.2f}): branch unknown")
            what = "as well: ambiguous at a fork" if cost > main - FORK_TIE else "better: other branch"
            return (f"coop lane continues the lane that leaves the ego's lane at a fork inside the ego detection "
                    f"{what} ({cost:.2f} vs {main:.2f}), another lane")
    return ""


def _better_neighbour(ego_lanes: Mapping[int, Lane], coop_lanes: Mapping[int, Lane], convoy: bool) -> str:
    """Why the ego's lane continues into another of the coop's lanes, or the coop's lane
    continues another of the ego's lanes, better than the two lanes 0 (:func:`_fit_cost`, by
    more than :data:`FORK_TIE`), or "" (a lane that opens or ends in the gap leaves the road
    edges ambiguous; the best continuation decides)."""
    main = _fit_cost(ego_lanes[0], coop_lanes[0], convoy)
    for index, lane in coop_lanes.items():
        if index and _fit_cost(ego_lanes[0], lane, convoy) < main - FORK_TIE:
            return f"the ego's lane continues into the coop's lane {index:+d} better: another lane"
    for index, lane in ego_lanes.items():
        if index and _fit_cost(lane, coop_lanes[0], convoy) < main - FORK_TIE:
            return f"the coop's lane continues the ego's lane {index:+d} better: another lane"
    return ""


def border_excesses(own: tuple[Lane, Lane], ends: LaneEnds) -> tuple[float, float]:
    """The lateral excess [m] of the (left, right) coop border start outside the cone of the
    two end headings drawn from the matching ego border end (:func:`fusion.fusibility.cone_excess`
    on each border instead of the centre line)."""
    (el, er), (cl, cr) = own
    turn = end_turn(ends)
    out = []
    for ego_border, coop_border in ((el, cl), (er, cr)):
        p_end, p_start = ego_border[-1].tolist(), coop_border[0].tolist()
        chord = math.hypot(p_start[0] - p_end[0], p_start[1] - p_end[1])
        out.append(cone_point_excess(ends.t_end, turn, p_end, p_start, chord))
    return out[0], out[1]


def border_excess(own: tuple[Lane, Lane], ends: LaneEnds) -> float:
    """The larger of :func:`border_excesses`."""
    return max(border_excesses(own, ends))


def geometry_check(own: tuple[Lane, Lane], convoy: bool, evidence: Evidence, params: FusionParams,
                   fits: Callable[[], Sequence[EndFit]] | None = None, start_offset_m: float | None = None,
                   ends: LaneEnds | None = None) -> tuple[str, float]:
    """``(reason, used)``: why the coop's lane is not the ego's by the two tightened geometric
    rules ("" when it may be), and the largest share in [0, 1] of a lateral limit the pair
    uses (its margin: convoy start offset / ``params.convoy_max_offset_m``, end offset / half
    the coop lane width; across a gap the larger border excess / its limit and, with
    ``evidence`` ``"arc"``, the arc prediction's mismatch / its limit; 1 when rejected;
    ``start_offset_m``, ``ends``: the convoy start offset [m] and the lane ends of ``own``
    when known). The rules:

    - convoy: the ego's detection end must lie inside the coop's lane (no farther from its
      centre than half its width), the counterpart at the overlap's end of the offset limit
      at its start: two lanes that part at a fork inside the overlap (the coop already on
      the other branch) have drifted apart there. The same half width draws the line between
      a fork the ego's detection has passed and one it still lies on in the true relation
      (:func:`cold_maps.simulation.drive.lane_relation`);
    - gap: not only the centre but each border of the coop's lane must start within half the
      ego lane width (+ the S-bend shift when the ends curve opposite ways,
      :func:`fusion.fusibility.s_bend_shift` of ``fits``) of the cone of the two end headings
      drawn from the matching ego border. A lane border is a marking that does not jump
      sideways; a lane that opens beside the ego's lane (its outer border a lane width off)
      fails while its centre may still pass, the same lane changing its width by up to a
      lane width does not.
    """
    (el, er), (cl, cr) = own
    if convoy:
        offset, half_width = overlap_end_offset(own)
        if offset > half_width:
            return (f"the ego's detection ends {offset:.2f} m from the centre of the coop's lane (outside its half "
                    f"width {half_width:.2f} m): the lanes part inside the overlap, another lane"), 1.0
        start = _fit_cost(own[0], own[1], True) if start_offset_m is None else start_offset_m
        return "", min(1.0, max(start / params.convoy_max_offset_m, offset / max(half_width, 1e-9)))
    ends = lane_ends(el, er, cl, cr) if ends is None else ends
    excess, limit = border_excess(own, ends), 0.5 * ends.width_m
    if (excess > limit or evidence == "s_bend") and fits is not None:
        limit += s_bend_shift(ends.gap_m, fits())
    if excess > limit:
        return (f"a coop lane border starts {excess:.2f} m laterally outside the turn between the two end headings "
                f"(more than {limit:.2f} m: half the lane width {ends.width_m:.2f} m and the S-bend shift): "
                "another lane"), 1.0
    used = excess / max(limit, 1e-9)
    if evidence == "arc" and fits is not None:
        used = max(used, arc_mismatch(ends, fits()) / (ARC_TOLERANCE_LANES * max(ends.width_m, 1e-9)))
    return "", min(used, 1.0)


def associate(ego: LaneDetection, coop: LaneDetection, own: tuple[Lane, Lane], convoy: bool, evidence: Evidence,
              params: FusionParams, fits: Callable[[], Sequence[EndFit]] | None = None,
              start_offset_m: float | None = None,
              ends: LaneEnds | None = None) -> Association:
    """The association of a pair whose lanes 0 passed the geometric check (``evidence``: the
    rule that passed them; a convoy overlap counts as ``"cone"``). ``own``: (ego lane, coop
    lane) borders in the ego frame; ``fits`` their end fits (:meth:`fusion.spline.EndFits.arcs`),
    ``start_offset_m`` a convoy's start offset and ``ends`` their lane ends when known (for :func:`geometry_check`). The confidence of a fused pair is its level (the rule
    or the road-edge evidence that decided) times 1 − (1 − :data:`CONFIDENCE_AT_LIMIT`)·used,
    ``used`` the share of a lateral limit the pair uses: monotone in the margin. See the
    module docstring."""
    reason, used = geometry_check(own, convoy, evidence, params, fits, start_offset_m, ends)
    if reason:
        return Association(reason, 0.0)
    graded = 1.0 - (1.0 - CONFIDENCE_AT_LIMIT) * used
    single = not _multi_lane(ego, coop)
    if single:
        association = Association("", GEOMETRY_CONFIDENCE[evidence] * graded)
    else:
        association = _associate_lanes(ego, coop, own, convoy, evidence, params)
        if association.reason:
            return association
        association = Association("", association.confidence * graded, association.matched)
    if params.association == "legacy":
        return association
    if params.association in SEPARATION_RULES and single and not convoy:
        reason = _unmarked_end_reason(ego, params) or _separation_reason(ego, coop, own, params, fits, used)
        if reason:
            return Association(reason, 0.0)
    return _confident(ego, coop, own, convoy, association, params, fits, ends)


def _confident(ego: LaneDetection, coop: LaneDetection, own: tuple[Lane, Lane], convoy: bool,
               association: Association, params: FusionParams, fits: Callable[[], Sequence[EndFit]] | None,
               ends: LaneEnds | None) -> Association:
    """``association`` (accepted) under ``params.association`` ``"confidence"``, ``"strict"`` or
    ``"separation"``:
    rejected as ambiguous below ``params.min_confidence``; with ``"strict"`` also a single-lane
    gap pair whose lane moved a lane width aside would pass too (:func:`_neighbour_uses`);
    with ``params.gate_false_rejection`` a spline pair whose detections state σ when it fails
    the gate of :mod:`fusion.gate`."""
    if association.confidence < params.min_confidence:
        return Association(f"ambiguous: association confidence {association.confidence:.2f} below "
                           f"{params.min_confidence:.2f}", 0.0)
    if params.association == "strict" and not convoy and not _multi_lane(ego, coop):
        passing = _neighbour_uses(ego, coop, own, params, fits)
        if passing:
            return Association(f"ambiguous: the lane a lane width to the {passing[0][0]} of the coop's would pass "
                               "the geometric check as well", 0.0)
    if convoy or params.gate_false_rejection is None:
        return association
    (el, er), (cl, cr) = own
    x_rel, y_rel, _ = relative_pose(ego.pose, coop.pose)
    uncertainty = pair_uncertainty(ego, coop, (el, er, cl, cr), (x_rel, y_rel))
    if uncertainty is None:
        return association
    ends = lane_ends(el, er, cl, cr) if ends is None else ends
    shift = s_bend_shift(ends.gap_m, fits()) if fits is not None else 0.0
    excess = border_excesses(own, ends)
    variances = uncertainty.borders
    borders = (GateBorder(el, variances[0], cl, variances[2], max(excess[0] - shift, 0.0)),
               GateBorder(er, variances[1], cr, variances[3], max(excess[1] - shift, 0.0)))
    reason = gate_reason(borders, ends.gap_m, ends.width_m, params.gate_false_rejection)
    return Association(reason, 0.0) if reason else association


def _neighbour_uses(ego: LaneDetection, coop: LaneDetection, own: tuple[Lane, Lane], params: FusionParams,
                    fits: Callable[[], Sequence[EndFit]] | None) -> list[tuple[str, float]]:
    """("left" / "right", used) for each side where the coop's lane moved a lane width that
    way (across its start heading) passes the geometric check of a gap too
    (:func:`fusion.fusibility.geometric_assessment`, the same end fits: a shift moves no
    heading or curvature); ``used`` is the share of a lateral limit the moved lane uses
    (:func:`geometry_check`; infinite when the tightened borders rule rejects it). Without
    neighbour lanes the geometry cannot tell the coop's lane from a passing one."""
    (el, er), (cl, cr) = own
    ends = lane_ends(el, er, cl, cr)
    normal = np.array([-ends.t_start[1], ends.t_start[0]]) * ends.width_m
    found = []
    for sign, side in ((1.0, "left"), (-1.0, "right")):
        moved_lane = (cl + sign * normal, cr + sign * normal)
        moved = lane_ends(el, er, *moved_lane)
        reason, evidence = geometric_assessment(ego.pose, coop.pose, moved, params, fits)
        if reason:
            continue
        reason, used = geometry_check(((el, er), moved_lane), False, evidence, params, fits, None, moved)
        found.append((side, math.inf if reason else used))
    return found


def _separation_reason(ego: LaneDetection, coop: LaneDetection, own: tuple[Lane, Lane], params: FusionParams,
                       fits: Callable[[], Sequence[EndFit]] | None, used: float) -> str:
    """Why a single-lane gap pair is ambiguous under ``association="separation"`` (""
    when it is not): the lane a lane width aside passes the geometry using less than
    :data:`SEPARATION_MARGIN` more of a lateral limit than the pair's own ``used``."""
    for side, moved_used in _neighbour_uses(ego, coop, own, params, fits):
        if moved_used < used + SEPARATION_MARGIN:
            return (f"ambiguous: the lane a lane width to the {side} of the coop's passes the geometric check "
                    f"using {moved_used:.2f} of a lateral limit, the coop's lane {used:.2f} (separation below "
                    f"{SEPARATION_MARGIN:.2f})")
    return ""


def _unmarked_end_reason(ego: LaneDetection, params: FusionParams) -> str:
    """Why a single-lane gap pair is ambiguous under ``association="fork"`` ("" when it is
    not): the ego's detection ended where its lane's markings stop (``end_reason``
    ``"unmarked"``), where a junction begins; which of the lanes that may leave there the
    ego's lane takes is not seen, and a single-lane sensor reports none of them."""
    if params.association != "fork" or ego.end_reason != "unmarked":
        return ""
    return ("ambiguous: the ego detection ends where its lane markings stop (a junction may begin there) and "
            "reports no lane beside it: which way the ego's lane goes beyond is not seen")


def _multi_lane(ego: LaneDetection, coop: LaneDetection) -> bool:
    """Whether either detection carries lane evidence beyond its own lane (neighbours, road
    edges, the ego's branches)."""
    return bool(ego.neighbours or coop.neighbours or ego.branches or ego.road_edges or coop.road_edges)


def _associate_lanes(ego: LaneDetection, coop: LaneDetection, own: tuple[Lane, Lane], convoy: bool,
                     evidence: Evidence, params: FusionParams) -> Association:
    """The association by lane evidence alone (:func:`_multi_lane` holds), confidence at its
    level (see :func:`associate`)."""
    x_rel, y_rel, psi_rel = relative_pose(ego.pose, coop.pose)
    ego_lanes = _lanes(ego, own[0], True, lambda points: points)
    coop_lanes = _lanes(coop, own[1], False, lambda points: transform(points, x_rel, y_rel, psi_rel))
    reason = _branch_reason(ego, own, convoy, params.association == "fork")
    if reason:
        return Association(reason, 0.0)
    ego_edges, coop_edges = ego.road_edges, coop.road_edges
    edges = ((ego_edges.end_left if ego_edges else None, coop_edges.start_left if coop_edges else None, 1),
             (ego_edges.end_right if ego_edges else None, coop_edges.start_right if coop_edges else None, -1))

    def sides(shift: int) -> tuple[int, int]:
        left, right = (_side(e, c, _seen(ego_lanes, sign), _seen(coop_lanes, sign), shift, sign)
                       for e, c, sign in edges)
        return left, right

    pairs = _Pairs(ego, coop, ego_lanes, coop_lanes, convoy, params)
    left0, right0 = sides(0)
    if min(left0, right0) < 0 and max(left0, right0) < 1:
        sides_off = "both sides" if max(left0, right0) < 0 else ("the left" if left0 < 0 else "the right")
        return Association(f"the lane index from the road edge differs on {sides_off} and agrees on neither: "
                           "another lane", 0.0)
    reach = max(map(abs, (*ego_lanes, *coop_lanes))) + 1
    tested, alternatives = False, []
    for shift in (s for n in range(1, reach + 1) for s in (n, -n)):
        plausible = pairs.plausible(shift)
        tested |= plausible is not None
        support = sides(shift)
        if plausible and min(support) >= 0:
            alternatives.append((sum(support), shift))
    if min(left0, right0) < 0:
        reason = _better_neighbour(ego_lanes, coop_lanes, convoy)
        if reason:
            return Association(reason, 0.0)
    score0 = left0 + right0
    if alternatives:
        best, shift = max(alternatives)
        if best > score0:
            return Association(f"coop lane matches the ego's lane {shift:+d} better (road edges): another lane", 0.0)
        if best == score0:
            return Association(f"coop lane also matches the ego's lane {shift:+d}: ambiguous, another lane", 0.0)
    if min(left0, right0) < 0:
        confidence = CONFIDENCE_LANE_COUNT_CHANGE
    elif alternatives:
        confidence = CONFIDENCE_WEAKER_ALTERNATIVE
    elif score0 == 2:
        confidence = CONFIDENCE_EDGES_BOTH
    elif score0 == 1:
        confidence = CONFIDENCE_EDGES_ONE
    else:
        confidence = CONFIDENCE_NEIGHBOURS if tested else GEOMETRY_CONFIDENCE[evidence]
    matched = tuple(sorted(k for k in ego_lanes if k != 0 and k in coop_lanes))
    return Association("", confidence, matched)

