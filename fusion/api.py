"""Public entry points: :func:`fuse` and :func:`is_fusible`.

Internally everything runs in the ego vehicle frame (the coop detection is moved there in
one transform, the result to the world frame in another); all checks are frame-invariant.
"""

from __future__ import annotations

import math
import threading
from typing import Any, Callable, Final, Sequence, TypeVar

import numpy as np

from fusion.association import Association, associate
from fusion.convoy import OverlapStart, convoy_border, overlap_start
from fusion.errors import InvalidDetectionError, InvalidParameterError
from fusion.fusibility import (EgoEnd, LaneEnds, ego_lane_end, geometric_assessment, lane_ends, paper_check,
                               relative_pose)
from fusion.geometry import to_world, transform
from fusion.registration import registered
from fusion.spline import EndFits, hermite_lane, hermite_turns, paper_pieces, sample_pieces
from fusion.types import FusionKind, FusionParams, FusionResult, LaneDetection, NDArrayFloat, NDArrayInt8, Source
from fusion.uncertainty import (UNSTATED_SIGMA_M, PairUncertainty, bridge_end, bridge_variance, gap_bend, has_sigma,
                                own_variances, pair_uncertainty)

DEFAULT_PARAMS = FusionParams()
_MODES = ("auto", "convoy", "spline")
_INTERPOLATIONS = ("paper", "hermite")

EGO_SOURCES: Final[NDArrayInt8] = np.array([Source.EGO] * 2, dtype=np.int8)
_SPLINE_SOURCES: Final[NDArrayInt8] = np.array([Source.EGO, Source.INTERPOLATED, Source.COOP] * 2, dtype=np.int8)

Borders = tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]


def ego_frame_borders(ego: LaneDetection, coop: LaneDetection) -> tuple[Borders, tuple[float, float, float]]:
    """(ego left, ego right, coop left, coop right) in the ego vehicle frame, and the coop's
    pose relative to the ego (x_rel m, y_rel m, psi_rel rad)."""
    for name, det in (("ego", ego), ("coop", coop)):
        if not isinstance(det, LaneDetection):
            raise InvalidDetectionError(f"{name} must be a LaneDetection, got {type(det).__name__}")
    relative = relative_pose(ego.pose, coop.pose)
    coop_points = transform(coop.points, *relative)
    n_left = coop.left.shape[0]
    return (ego.left, ego.right, coop_points[:n_left], coop_points[n_left:]), relative


def end_fits(ego: LaneDetection, coop: LaneDetection, borders: Borders, params: FusionParams) -> EndFits:
    """The :class:`fusion.spline.EndFits` of a pair's ego-frame ``borders``, weighted by 1/σ²
    where both detections state σ."""
    if has_sigma(ego) and has_sigma(coop):
        return EndFits(borders, params, (ego.left_sigma, ego.right_sigma, coop.left_sigma, coop.right_sigma))
    return EndFits(borders, params)


def _overlap_starts(borders: Borders, ego_arclength: NDArrayFloat) -> tuple[OverlapStart, OverlapStart]:
    """Where the coop borders start against the ego borders (convoy overlap)."""
    el, er, cl, cr = borders
    n_left = el.shape[0]
    return overlap_start(el, cl, ego_arclength[:n_left]), overlap_start(er, cr, ego_arclength[n_left:])


def _convoy_reason(x_rel: float, starts: tuple[OverlapStart, OverlapStart], params: FusionParams) -> str:
    if x_rel <= 0.0:
        return f"coop vehicle is not ahead of the ego (x_rel = {x_rel:.2f} m)"
    for side, start in zip(("left", "right"), starts):
        if start.offset_m > params.convoy_max_offset_m:
            return (f"coop {side} border starts {start.offset_m:.2f} m from the ego {side} border "
                    f"(> {params.convoy_max_offset_m:.2f} m): no overlap on the same lane")
        if start.heading_diff_rad > params.convoy_max_heading_rad:
            return (f"coop {side} border heads {math.degrees(start.heading_diff_rad):.1f} deg away from the ego "
                    f"{side} border at the overlap (> {math.degrees(params.convoy_max_heading_rad):.1f} deg)")
    return ""


def _decide(ego: LaneDetection, coop: LaneDetection, mode: str, params: FusionParams, borders: Borders,
            x_rel: float, fits: EndFits, ends: LaneEnds | None = None
            ) -> tuple[FusionKind, Association, LaneEnds, tuple[OverlapStart, OverlapStart] | None]:
    if mode not in _MODES:
        raise InvalidParameterError(f"mode must be one of {_MODES}, got {mode!r}")
    if not isinstance(params, FusionParams):
        raise InvalidParameterError(f"params must be a FusionParams, got {type(params).__name__}")
    ends = lane_ends(*borders) if ends is None else ends
    kind: FusionKind = ("convoy" if ends.gap_m <= 0.0 else "spline") if mode == "auto" else mode
    el, er, cl, cr = borders
    starts = None
    if kind == "spline":
        if params.fusibility == "paper":
            reason, evidence = paper_check(ego.pose, coop.pose, ends, params), "open"
        else:
            reason, evidence = geometric_assessment(ego.pose, coop.pose, ends, params, fits.arcs)
    elif ends.gap_m > 0.0:
        reason, evidence = f"no overlap: the coop detection starts {ends.gap_m:.2f} m after the ego detection ends", "cone"
    else:
        starts = _overlap_starts(borders, ego.arclength)
        reason, evidence = _convoy_reason(x_rel, starts, params), "cone"
    if reason:
        return kind, Association(reason, 0.0), ends, starts
    start_offset_m = None if starts is None else max(start.offset_m for start in starts)
    association = associate(ego, coop, ((el, er), (cl, cr)), kind == "convoy", evidence, params, fits.arcs,
                            start_offset_m, ends)
    return kind, association, ends, starts


def is_fusible(ego: LaneDetection, coop: LaneDetection, params: FusionParams = DEFAULT_PARAMS,
               *, mode: str = "auto") -> tuple[bool, str]:
    """Whether ``coop`` can be fused into ``ego``; ``(True, "")`` or ``(False, reason)``.

    In ``mode="auto"`` an overlap of the two detections is checked for convoy fusion, a gap
    for spline fusion with ``params.fusibility`` (``"geometric"`` by default, see
    :func:`fusion.fusibility.geometric_check`; ``"paper"`` for the paper's pose cases); then
    the lane association (:func:`fusion.association.associate`, which uses neighbour lanes,
    road edges and forks when the detections carry them).
    """
    association = assess(ego, coop, params, mode=mode)
    return not association.reason, association.reason


def assess(ego: LaneDetection, coop: LaneDetection, params: FusionParams = DEFAULT_PARAMS,
           *, mode: str = "auto", framed: tuple[Borders, tuple[float, float, float]] | None = None,
           ends: LaneEnds | None = None) -> Association:
    """The fusibility decision of :func:`is_fusible` with its confidence in [0, 1] and the
    neighbour lanes matched (:class:`fusion.association.Association`); ``framed`` is
    :func:`ego_frame_borders` of the pair and ``ends`` its :func:`fusion.fusibility.lane_ends`
    when the caller has them already."""
    if framed is None and ends is None:
        return _pair_work(ego, coop, params).decision(mode)[1]
    borders, (x_rel, _, _) = framed or ego_frame_borders(ego, coop)
    return _decide(ego, coop, mode, params, borders, x_rel, end_fits(ego, coop, borders, params), ends)[1]


class _EgoWork:
    """What the pairs of one ego detection share: ``end`` (:func:`fusion.fusibility.ego_lane_end`
    of its borders) and the ego lane alone (:meth:`refused`). Kept for the last
    :data:`_MAX_EGOS` ego detections (:func:`_ego_work`): an evaluation fuses one ego detection
    with every other vehicle of the frame."""

    __slots__ = ("ego", "end", "_alone")

    def __init__(self, ego: LaneDetection) -> None:
        self.ego = ego  # held, so the id that keys the entry stays its
        self.end: EgoEnd = ego_lane_end(ego.left, ego.right)
        self._alone: FusionResult | None = None

    def refused(self, gap_m: float, reason: str) -> FusionResult:
        """:func:`ego_result` of the ego's whole borders with ``gap_m`` and ``reason``; every
        such result shares its (read-only) arrays."""
        alone = self._alone
        if alone is None:
            alone = self._alone = ego_result(self.ego, (self.ego.left, self.ego.right), gap_m, reason)
            return alone
        return FusionResult(alone.left, alone.right, alone.left_source, alone.right_source, "none", gap_m, reason,
                            left_sigma=alone.left_sigma, right_sigma=alone.right_sigma)


class _PairWork:
    """What :func:`fuse` and :func:`assess` work out of a pair before fusing it: ``framed``
    (:func:`ego_frame_borders`), ``fits`` (:func:`end_fits`, each fit made on first use),
    ``ends`` (:func:`fusion.fusibility.lane_ends`), the decision per mode (:meth:`decision`)
    and the result of a refused pair (:meth:`refused`).
    Kept for the last :data:`_MAX_PAIRS` pairs (:func:`_pair_work`): an evaluation fuses one
    pair with several interpolations and checks it again; a :class:`LaneDetection` is
    immutable (read-only arrays), so the work is the same."""

    __slots__ = ("pair", "framed", "fits", "ends", "ego_work", "_decided", "_refused")

    def __init__(self, ego: LaneDetection, coop: LaneDetection, params: FusionParams) -> None:
        self.pair = (ego, coop, params)  # held, so the ids that key the entry stay theirs
        self.framed = ego_frame_borders(ego, coop)
        for border in self.framed[0][2:]:
            border.flags.writeable = False  # shared by every call of the pair
        self.fits = end_fits(ego, coop, self.framed[0], params)
        self.ego_work = _ego_work(ego)
        self.ends = lane_ends(*self.framed[0], ego_end=self.ego_work.end)
        self._decided: dict[str, tuple[FusionKind, Association, LaneEnds, tuple[OverlapStart, OverlapStart] | None]] = {}
        self._refused: dict[str, FusionResult] = {}

    def decision(self, mode: str) -> tuple[FusionKind, Association, LaneEnds, tuple[OverlapStart, OverlapStart] | None]:
        """:func:`_decide` of the pair in ``mode``, made once."""
        found = self._decided.get(mode)
        if found is None:
            ego, coop, params = self.pair
            found = self._decided[mode] = _decide(ego, coop, mode, params, self.framed[0], self.framed[1][0], self.fits,
                                                  self.ends)
        return found

    def refused(self, mode: str) -> FusionResult:
        """:func:`ego_result` of the pair that its :meth:`decision` in ``mode`` refuses, made
        once (a :class:`FusionResult` is immutable: read-only arrays)."""
        found = self._refused.get(mode)
        if found is None:
            _, association, ends, _ = self.decision(mode)
            found = self._refused[mode] = self.ego_work.refused(ends.gap_m, association.reason)
        return found


_Kept = TypeVar("_Kept")
_PAIRS: dict[tuple[int, int, int], _PairWork] = {}
_MAX_PAIRS: Final[int] = 32
_EGOS: dict[int, _EgoWork] = {}
_MAX_EGOS: Final[int] = 8
_PAIRS_CHANGING = threading.Lock()
"""Held while :data:`_PAIRS` or :data:`_EGOS` drops and adds entries: fusing from several
threads at once finds the oldest entry while no other thread adds one."""


def _kept(table: dict[Any, _Kept], key: Any, make: Callable[[], _Kept], size: int) -> _Kept:
    """``table[key]``, made by ``make()`` on first use; the oldest of ``size`` entries dropped
    to add it (under :data:`_PAIRS_CHANGING`)."""
    found = table.get(key)
    if found is None:
        found = make()
        with _PAIRS_CHANGING:
            if len(table) >= size:
                table.pop(next(iter(table)))
            table[key] = found
    return found


def _ego_work(ego: LaneDetection) -> _EgoWork:
    """The :class:`_EgoWork` of ``ego``, kept for the last :data:`_MAX_EGOS` ego detections."""
    return _kept(_EGOS, id(ego), lambda: _EgoWork(ego), _MAX_EGOS)


def _pair_work(ego: LaneDetection, coop: LaneDetection, params: FusionParams) -> _PairWork:
    """The :class:`_PairWork` of (``ego``, ``coop``, ``params``), kept for the last :data:`_MAX_PAIRS` pairs."""
    return _kept(_PAIRS, (id(ego), id(coop), id(params)), lambda: _PairWork(ego, coop, params), _MAX_PAIRS)


def ego_frame_result(ego: LaneDetection, parts: Sequence[NDArrayFloat], sources: NDArrayInt8, kind: FusionKind,
                     gap_m: float, reason: str = "", confidence: float = 0.0,
                     lanes: tuple[tuple[int, NDArrayFloat, NDArrayFloat], ...] = (),
                     variances: Sequence[NDArrayFloat] | None = None) -> FusionResult:
    """Result from ego-frame ``parts``, the left border's then as many of the right border's, with
    one :class:`Source` per part: one concatenation and one transform to the world frame (the
    other fields as :class:`FusionResult`); ``variances``, one per part (lateral world
    variances [m²]), give the result's σ."""
    counts = [points.shape[0] for points in parts]
    world = to_world(np.concatenate(parts), ego.pose, in_place=True)
    labels = sources.repeat(counts)
    n_left = sum(counts[: len(parts) // 2])
    left_sigma = right_sigma = None
    if variances is not None:
        sigma = np.sqrt(np.concatenate(variances))
        left_sigma, right_sigma = sigma[:n_left], sigma[n_left:]
    return FusionResult(world[:n_left], world[n_left:], labels[:n_left], labels[n_left:], kind, gap_m, reason,
                        confidence, lanes, left_sigma, right_sigma)


def ego_result(ego: LaneDetection, borders: tuple[NDArrayFloat, NDArrayFloat], gap_m: float,
               reason: str) -> FusionResult:
    """The ego lane alone (``kind="none"``, ego-frame ``borders``: the ego's, maybe trimmed at
    their ends) with its ``reason`` and, when the ego states σ, its own σ."""
    own = own_variances(ego)
    variances = None if own is None else [v.world[: b.shape[0]] for v, b in zip(own, borders)]
    return ego_frame_result(ego, borders, EGO_SOURCES, "none", gap_m, reason, variances=variances)


def fuse(ego: LaneDetection, coop: LaneDetection, *, mode: str = "auto", interpolation: str = "paper",
         params: FusionParams = DEFAULT_PARAMS) -> FusionResult:
    """Collectively perceived lane of ``ego`` extended by ``coop`` (paper sec. III).

    ``mode``: ``"auto"`` (convoy fusion when the detections overlap, spline fusion across a
    gap), ``"convoy"`` or ``"spline"``. ``interpolation`` for the gap: ``"paper"`` (natural
    cubic spline through ego[-3], ego[-1], apex, coop[0], coop[2]) or ``"hermite"`` (G1
    line and circular arc with least-squares end headings, exact on circular arcs). A pair
    that is not fusible returns the ego lane with ``kind="none"`` and the reason; malformed
    input raises :class:`fusion.FusionError`. Output borders are in the world frame.
    """
    if interpolation not in _INTERPOLATIONS:
        raise InvalidParameterError(f"interpolation must be one of {_INTERPOLATIONS}, got {interpolation!r}")
    work = _pair_work(ego, coop, params)
    borders, (x_rel, y_rel, _) = work.framed
    fits = work.fits
    kind, association, ends, starts = work.decision(mode)
    el, er, _, _ = borders
    if association.reason:
        return work.refused(mode)
    uncertainty = pair_uncertainty(ego, coop, borders, (x_rel, y_rel))
    posed = uncertainty  # for the convoy's pose update and weights; without σ under a pose covariance: exact points
    if uncertainty is None and kind == "convoy" and params.convoy_weights == "inverse-variance" and (
            ego.pose_cov is not None or coop.pose_cov is not None):
        posed = pair_uncertainty(ego, coop, borders, (x_rel, y_rel), UNSTATED_SIGMA_M)
    parts, sources, variances = _fused(coop, borders, fits, kind, starts, interpolation, params, posed)
    if uncertainty is None:
        variances = None  # no detection stated σ: neither does the fused lane
    lanes = tuple(matched_lane(ego, coop, index, kind, interpolation, params) for index in association.matched)
    return ego_frame_result(ego, parts, sources, kind, ends.gap_m, "", association.confidence, lanes, variances)


def _fused(coop: LaneDetection, borders: Borders, fits: EndFits, kind: FusionKind,
           starts: tuple[OverlapStart, OverlapStart] | None, interpolation: str, params: FusionParams,
           uncertainty: PairUncertainty | None = None
           ) -> tuple[Sequence[NDArrayFloat], NDArrayInt8, Sequence[NDArrayFloat] | None]:
    """The ego-frame parts, their sources and, with ``uncertainty``, their world variances
    (:func:`ego_frame_result`) of the fused lane of a pair found fusible (``kind``, the convoy
    overlap ``starts``)."""
    el, er, cl, cr = borders
    if kind == "convoy":
        assert starts is not None
        w, blend = params.coop_weight, params.convoy_blend_offset_m
        inverse = params.convoy_weights == "inverse-variance"
        n_left = cl.shape[0]
        arclengths = (coop.arclength[:n_left], coop.arclength[n_left:])
        known = None if uncertainty is None else uncertainty.borders
        shared: tuple[NDArrayFloat | None, NDArrayFloat | None] = (None, None)
        if inverse and uncertainty is not None and (uncertainty.coop_cov.any() or uncertainty.ego_cov.any()):
            update = registered(borders, arclengths, starts, uncertainty)
            if update is None:
                inverse = False
            else:
                cl, cr, starts, known, shared = update
        pairs = (None, None) if known is None else ((known[0], known[2]), (known[1], known[3]))
        end = params.convoy_end_blend_m
        parts, sources, variances = zip(
            *convoy_border(el, cl, arclengths[0], starts[0], w, blend, pairs[0], inverse, end, shared[0]),
            *convoy_border(er, cr, arclengths[1], starts[1], w, blend, pairs[1], inverse, end, shared[1]))
        return parts, np.array(sources, dtype=np.int8), None if uncertainty is None else variances
    if interpolation == "paper":
        uniform = params.spline_parameter == "uniform"
        gap_left, gap_right = sample_pieces(
            [paper_pieces(e, c, params.apex_min_turn_rad, params.apex_ratio, uniform) for e, c in ((el, cl), (er, cr))],
            params.spacing_m)
    else:
        gap_left, gap_right = hermite_lane(fits(), params.spacing_m)
    parts = (el, gap_left, cl, er, gap_right, cr)
    if uncertainty is None:
        return parts, _SPLINE_SOURCES, None
    turns = ((0.0, 1.0), (0.0, 1.0)) if interpolation == "paper" else hermite_turns(fits())
    return parts, _SPLINE_SOURCES, _spline_variances(parts, uncertainty, interpolation, gap_bend(fits.arcs()), turns)


def _spline_variances(parts: Sequence[NDArrayFloat], uncertainty: PairUncertainty, interpolation: str,
                      bend: tuple[float, float, float],
                      turns: Sequence[tuple[float, float]]) -> list[NDArrayFloat]:
    """World variances of the parts (ego, gap, coop per border) of a spline fusion: the
    detections' own, and :func:`fusion.uncertainty.bridge_variance` of ``interpolation``
    across the gap (``bend`` from :func:`fusion.uncertainty.gap_bend`, ``turns`` the (left,
    right) gaps' turning parts, :func:`fusion.spline.hermite_turns`)."""
    out = []
    for side in (0, 1):
        ego, gap, coop = parts[3 * side: 3 * side + 3]
        ego_var, coop_var = uncertainty.borders[side], uncertainty.borders[2 + side]
        ends = (bridge_end(ego, ego_var, True, (0.0, 0.0), uncertainty.ego_cov),
                bridge_end(coop, coop_var, False, uncertainty.coop_xy, uncertainty.coop_cov))
        out += [ego_var.world, bridge_variance(gap, ego[-1], coop[0], *ends, interpolation, bend, turns[side]),
                coop_var.world]
    return out


def matched_lane(ego: LaneDetection, coop: LaneDetection, index: int, kind: FusionKind, interpolation: str,
                  params: FusionParams) -> tuple[int, NDArrayFloat, NDArrayFloat]:
    """Neighbour lane ``index`` of both detections fused like their own lanes (world frame)."""
    pair = [next(lane for lane in detection.neighbours if lane.index == index) for detection in (ego, coop)]
    lanes = [LaneDetection(detection.pose, lane.left, lane.right) for detection, lane in zip((ego, coop), pair)]
    borders, _ = ego_frame_borders(*lanes)
    starts = None
    if kind == "convoy":
        starts = _overlap_starts(borders, lanes[0].arclength)
    parts, sources, _ = _fused(lanes[1], borders, EndFits(borders, params), kind, starts, interpolation, params)
    fused = ego_frame_result(lanes[0], parts, sources, kind, 0.0)
    return index, fused.left, fused.right
