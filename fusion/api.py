"""Public entry points: :func:`fuse` and :func:`is_fusible`.

Internally everything runs in the ego vehicle frame (the coop detection is moved there in
one transform, the result to the world frame in another); all checks are frame-invariant.
"""

from __future__ import annotations

import math
from typing import Final, Sequence

import numpy as np

from fusion.convoy import OverlapStart, convoy_border, overlap_start
from fusion.errors import InvalidDetectionError, InvalidParameterError
from fusion.fusibility import LaneEnds, geometric_check, lane_ends, paper_check, relative_pose
from fusion.geometry import EndFit, to_world, transform
from fusion.spline import hermite_lane, lane_end_fits, paper_pieces, sample_pieces
from fusion.types import FusionKind, FusionParams, FusionResult, LaneDetection, NDArrayFloat, NDArrayInt8, Source

DEFAULT_PARAMS = FusionParams()
_MODES = ("auto", "convoy", "spline")
_INTERPOLATIONS = ("paper", "hermite")

_EGO_SOURCES: Final[NDArrayInt8] = np.array([Source.EGO] * 2, dtype=np.int8)
_SPLINE_SOURCES: Final[NDArrayInt8] = np.array([Source.EGO, Source.INTERPOLATED, Source.COOP] * 2, dtype=np.int8)

Borders = tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat, NDArrayFloat]


def _ego_frame_borders(ego: LaneDetection, coop: LaneDetection) -> tuple[Borders, float]:
    """(ego left, ego right, coop left, coop right) in the ego vehicle frame, and x_rel [m]."""
    for name, det in (("ego", ego), ("coop", coop)):
        if not isinstance(det, LaneDetection):
            raise InvalidDetectionError(f"{name} must be a LaneDetection, got {type(det).__name__}")
    x_rel, y_rel, psi_rel = relative_pose(ego.pose, coop.pose)
    coop_points = transform(coop.points, x_rel, y_rel, psi_rel)
    n_left = coop.left.shape[0]
    return (ego.left, ego.right, coop_points[:n_left], coop_points[n_left:]), x_rel


class _EndFits:
    """Least-squares end fits of the four borders, computed once on first use."""

    def __init__(self, borders: Borders, params: FusionParams):
        self._borders, self._params = borders, params
        self._fits: tuple[EndFit, EndFit, EndFit, EndFit] | None = None

    def __call__(self) -> tuple[EndFit, EndFit, EndFit, EndFit]:
        if self._fits is None:
            el, er, cl, cr = self._borders
            self._fits = lane_end_fits((el, er), (cl, cr), self._params.heading_window_m)
        return self._fits


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
            x_rel: float, fits: _EndFits) -> tuple[FusionKind, str, LaneEnds, tuple[OverlapStart, OverlapStart] | None]:
    if mode not in _MODES:
        raise InvalidParameterError(f"mode must be one of {_MODES}, got {mode!r}")
    if not isinstance(params, FusionParams):
        raise InvalidParameterError(f"params must be a FusionParams, got {type(params).__name__}")
    ends = lane_ends(*borders)
    kind: FusionKind = ("convoy" if ends.gap_m <= 0.0 else "spline") if mode == "auto" else mode
    if kind == "spline":
        if params.fusibility == "paper":
            return kind, paper_check(ego.pose, coop.pose, ends, params), ends, None
        return kind, geometric_check(ego.pose, coop.pose, ends, params, fits), ends, None
    if ends.gap_m > 0.0:
        return kind, f"no overlap: the coop detection starts {ends.gap_m:.2f} m after the ego detection ends", ends, None
    el, er, cl, cr = borders
    n_left = el.shape[0]
    starts = (overlap_start(el, cl, ego.arclength[:n_left]), overlap_start(er, cr, ego.arclength[n_left:]))
    return kind, _convoy_reason(x_rel, starts, params), ends, starts


def is_fusible(ego: LaneDetection, coop: LaneDetection, params: FusionParams = DEFAULT_PARAMS,
               *, mode: str = "auto") -> tuple[bool, str]:
    """Whether ``coop`` can be fused into ``ego``; ``(True, "")`` or ``(False, reason)``.

    In ``mode="auto"`` an overlap of the two detections is checked for convoy fusion, a gap
    for spline fusion with ``params.fusibility`` (``"geometric"`` by default, see
    :func:`fusion.fusibility.geometric_check`; ``"paper"`` for the paper's pose cases).
    """
    borders, x_rel = _ego_frame_borders(ego, coop)
    _, reason, _, _ = _decide(ego, coop, mode, params, borders, x_rel, _EndFits(borders, params))
    return not reason, reason


def ego_frame_result(ego: LaneDetection, parts: Sequence[NDArrayFloat], sources: NDArrayInt8, kind: FusionKind, gap_m: float,
            reason: str = "") -> FusionResult:
    """Result from ego-frame ``parts``, the left border's then as many of the right border's, with
    one :class:`Source` per part: one concatenation and one transform to the world frame."""
    counts = [points.shape[0] for points in parts]
    world = to_world(np.concatenate(parts), ego.pose)
    labels = sources.repeat(counts)
    n_left = sum(counts[: len(parts) // 2])
    return FusionResult(world[:n_left], world[n_left:], labels[:n_left], labels[n_left:], kind, gap_m, reason)


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
    borders, x_rel = _ego_frame_borders(ego, coop)
    fits = _EndFits(borders, params)
    kind, reason, ends, starts = _decide(ego, coop, mode, params, borders, x_rel, fits)
    el, er, cl, cr = borders
    if reason:
        return ego_frame_result(ego, (el, er), _EGO_SOURCES, "none", ends.gap_m, reason)
    if kind == "convoy":
        assert starts is not None
        w, blend = params.coop_weight, params.convoy_blend_offset_m
        n_left = cl.shape[0]
        parts, sources = zip(*convoy_border(el, cl, coop.arclength[:n_left], starts[0], w, blend),
                             *convoy_border(er, cr, coop.arclength[n_left:], starts[1], w, blend))
        return ego_frame_result(ego, parts, np.array(sources, dtype=np.int8), "convoy", ends.gap_m)
    if interpolation == "paper":
        uniform = params.spline_parameter == "uniform"
        gap_left, gap_right = sample_pieces(
            [paper_pieces(e, c, params.apex_min_turn_rad, params.apex_ratio, uniform) for e, c in ((el, cl), (er, cr))],
            params.spacing_m)
    else:
        gap_left, gap_right = hermite_lane(fits(), params.spacing_m)
    return ego_frame_result(ego, (el, gap_left, cl, er, gap_right, cr), _SPLINE_SOURCES, "spline", ends.gap_m)
