"""Public entry points: :func:`fuse` and :func:`is_fusible`."""

from __future__ import annotations

import math

import numpy as np

from fusion.convoy import OverlapStart, convoy_border, overlap_start
from fusion.errors import InvalidDetectionError, InvalidParameterError
from fusion.fusibility import LaneEnds, geometric_check, lane_ends, paper_check, relative_pose
from fusion.geometry import EndFit, to_world
from fusion.spline import hermite_lane, lane_end_fits, paper_gap
from fusion.types import FusionKind, FusionParams, FusionResult, LaneDetection, NDArrayFloat, Source

DEFAULT_PARAMS = FusionParams()
_MODES = ("auto", "convoy", "spline")
_INTERPOLATIONS = ("paper", "hermite")

Borders = tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]


def _world_borders(ego: LaneDetection, coop: LaneDetection) -> Borders:
    for name, det in (("ego", ego), ("coop", coop)):
        if not isinstance(det, LaneDetection):
            raise InvalidDetectionError(f"{name} must be a LaneDetection, got {type(det).__name__}")
    return (to_world(ego.left, ego.pose), to_world(ego.right, ego.pose),
            to_world(coop.left, coop.pose), to_world(coop.right, coop.pose))


def _convoy_reason(ego: LaneDetection, coop: LaneDetection, starts: tuple[OverlapStart, OverlapStart],
                   params: FusionParams) -> str:
    x_rel = relative_pose(ego.pose, coop.pose)[0]
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


class _EndFits:
    """Least-squares end fits of the four borders, computed once on first use."""

    def __init__(self, borders: Borders, params: FusionParams):
        self._borders, self._params, self._fits = borders, params, None

    def __call__(self) -> tuple[EndFit, EndFit, EndFit, EndFit]:
        if self._fits is None:
            el, er, cl, cr = self._borders
            self._fits = lane_end_fits((el, er), (cl, cr), self._params.heading_window_m, self._params.spacing_m)
        return self._fits


def _spline_reason(ego: LaneDetection, coop: LaneDetection, fits: _EndFits, ends: LaneEnds,
                   params: FusionParams) -> str:
    if params.fusibility == "paper":
        return paper_check(ego.pose, coop.pose, ends, params)
    return geometric_check(ego.pose, coop.pose, ends, params, fits)


def _decide(ego: LaneDetection, coop: LaneDetection, mode: str, params: FusionParams, borders: Borders,
            fits: _EndFits) -> tuple[FusionKind, str, LaneEnds, tuple[OverlapStart, OverlapStart] | None]:
    if mode not in _MODES:
        raise InvalidParameterError(f"mode must be one of {_MODES}, got {mode!r}")
    if not isinstance(params, FusionParams):
        raise InvalidParameterError(f"params must be a FusionParams, got {type(params).__name__}")
    ends = lane_ends(*borders)
    kind: FusionKind = ("convoy" if ends.gap_m <= 0.0 else "spline") if mode == "auto" else mode
    if kind == "spline":
        return kind, _spline_reason(ego, coop, fits, ends, params), ends, None
    el, er, cl, cr = borders
    if ends.gap_m > 0.0:
        return kind, f"no overlap: the coop detection starts {ends.gap_m:.2f} m after the ego detection ends", ends, None
    starts = (overlap_start(el, cl), overlap_start(er, cr))
    return kind, _convoy_reason(ego, coop, starts, params), ends, starts


def is_fusible(ego: LaneDetection, coop: LaneDetection, params: FusionParams = DEFAULT_PARAMS,
               *, mode: str = "auto") -> tuple[bool, str]:
    """Whether ``coop`` can be fused into ``ego``; ``(True, "")`` or ``(False, reason)``.

    In ``mode="auto"`` an overlap of the two detections is checked for convoy fusion, a gap
    for spline fusion with ``params.fusibility`` (``"geometric"`` by default, see
    :func:`fusion.fusibility.geometric_check`; ``"paper"`` for the paper's pose cases).
    """
    borders = _world_borders(ego, coop)
    _, reason, _, _ = _decide(ego, coop, mode, params, borders, _EndFits(borders, params))
    return not reason, reason


def _labelled(*parts: tuple[NDArrayFloat, Source]) -> tuple[NDArrayFloat, np.ndarray]:
    points = np.concatenate([p for p, _ in parts])
    labels = np.concatenate([np.full(p.shape[0], src, dtype=np.int8) for p, src in parts])
    return points, labels


def fuse(ego: LaneDetection, coop: LaneDetection, *, mode: str = "auto", interpolation: str = "paper",
         params: FusionParams = DEFAULT_PARAMS) -> FusionResult:
    """Collectively perceived lane of ``ego`` extended by ``coop`` (paper sec. III).

    ``mode``: ``"auto"`` (convoy fusion when the detections overlap, spline fusion across a
    gap), ``"convoy"`` or ``"spline"``. ``interpolation`` for the gap: ``"paper"`` (natural
    cubic spline through ego[-3], ego[-1], apex, coop[0], coop[2]) or ``"hermite"`` (G1
    cubic with least-squares end headings, exact on circular arcs). A pair that is not
    fusible returns the ego lane with ``kind="none"`` and the reason; malformed input raises
    :class:`fusion.FusionError`. Output borders are in the world frame.
    """
    if interpolation not in _INTERPOLATIONS:
        raise InvalidParameterError(f"interpolation must be one of {_INTERPOLATIONS}, got {interpolation!r}")
    borders = _world_borders(ego, coop)
    fits = _EndFits(borders, params)
    kind, reason, ends, starts = _decide(ego, coop, mode, params, borders, fits)
    el, er, cl, cr = borders
    if reason:
        return FusionResult(el, er, np.zeros(el.shape[0], np.int8), np.zeros(er.shape[0], np.int8),
                            "none", ends.gap_m, reason)
    if kind == "convoy":
        left, left_src = convoy_border(el, cl, starts[0], params.coop_weight, params.convoy_blend_offset_m)
        right, right_src = convoy_border(er, cr, starts[1], params.coop_weight, params.convoy_blend_offset_m)
        return FusionResult(left, right, left_src, right_src, "convoy", ends.gap_m)
    if interpolation == "paper":
        uniform = params.spline_parameter == "uniform"
        gaps = tuple(paper_gap(e, c, params.apex_min_turn_rad, params.apex_ratio, params.spacing_m, uniform)
                     for e, c in ((el, cl), (er, cr)))
    else:
        gaps = hermite_lane(fits(), params.spacing_m)
    (left, left_src), (right, right_src) = (
        _labelled((e, Source.EGO), (gap, Source.INTERPOLATED), (c, Source.COOP))
        for e, gap, c in ((el, gaps[0], cl), (er, gaps[1], cr)))
    return FusionResult(left, right, left_src, right_src, "spline", ends.gap_m)
