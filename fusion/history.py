"""Spline fusion across a gap the cooperative vehicle drove through: its lane history.

A coop detection may carry :class:`fusion.types.LaneHistory`: the lane the coop perceived
over its last metres of travel, registered with its own odometry, in its vehicle frame
and ending where its current detection starts. Where that history covers the gap between
the ego's detection end and the coop's detection start, the gap is *observed* geometry
instead of an interpolation; only what no history covers is interpolated (``paper`` or
``hermite``, :func:`fusion.fuse`).

Seams (both borders, each on its own):

- *ego seam*: the ego border's last point ``e`` projects onto the history at arc length
  s_e (foot ``h(s_e)``); the history before s_e (behind the ego's end) is dropped.
- *coop seam*: the history ends (at arc length s_c) where the coop border starts (``c``),
  the same place seen at two instants; its offset there is ``c − h(s_c)`` across the
  lane's direction there (the along-track part is only the two samplings' spacing).
- Between them each history point at arc length s is moved by
  ``(1 − w)·Δ_e + w·Δ_c`` with ``w = (s − s_e) / (s_c − s_e)``, Δ_e = ``e − h(s_e)`` and Δ_c
  the coop seam offset: the two offsets (the coop's pose error, odometry drift, detection
  noise) fade linearly along the gap. The result runs exactly through ``e`` and across
  ``c`` (no jump, C0), keeps the history's shape (a constant offset is removed exactly, a
  drift that grows linearly along the gap too), and its direction changes at a seam by
  |Δ_e − Δ_c| / (s_c − s_e) at most.

Checks: first the pair's own (:func:`fusion.api.assess`: the fusibility check across the gap
and the lane association), with its reasons, so a history never admits a coop the pair
fusion rejects. Then the history must pass within ``convoy_max_offset_m`` of the ego border
end, with a heading within ``convoy_max_heading_rad`` there (the coop's history *overlaps*
the ego's detection, so the convoy tolerances apply: a neighbour lane lies a lane width
away), and along the overlap the ego border's offset from the history may change from its
value at the end by at most half the lane width (:func:`_overlap`): the end offset
is the coop's position error, which the seam removes; heading error, odometry drift and
noise change it by decimetres (up to 1.44 m measured with 0.5° yaw error, σ 5 cm and typical
drift, d_s 20–50 m), while a history more than half a lane off lies nearer the neighbouring
lane's border than this lane's. A history that does not reach back to the ego's end is
joined to the coop detection (same seam offset faded along the history) and the remaining
gap goes to :func:`fusion.fuse`, whose fusibility check then sees the history's start.

Forks: when the ego's detection ends inside a fork on its own lane while the coop took the
other branch, the ego's last points leave the history within a few metres (a border turning
at radius r parts from the straight one by x²/(2r) after x metres). If the checks above
accept the pair, an ego border whose end lies more than ``_FORK_DEPARTURE_M`` (0.25 m) off
the straight line fitted to its offsets from the history further back (a pose or heading
error only tilts that line), averaged over five points against noise, loses its points
after the last one back within ``_FORK_RETURN_M`` (0.08 m), and the ego seam moves there:
the lane then follows the branch the coop drove (Town01's worst branch fusion 0.36 → 0.11 m)
(:func:`_fork_cut`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Final, NamedTuple

import numpy as np
import numpy.typing as npt

from fusion.api import DEFAULT_PARAMS, assess, ego_frame_borders, ego_frame_result, ego_result, fuse, matched_lane
from fusion.fusibility import lane_ends, relative_pose
from fusion.geometry import cumulative_length, end_direction, foot_near_vertex, transform
from fusion.types import FusionParams, FusionResult, LaneDetection, NDArrayFloat, NDArrayInt8, Source
from fusion.uncertainty import PairUncertainty, pair_uncertainty, seam_sigma

NDArrayComplex = npt.NDArray[np.complex128]

_HEADING_WINDOW_M: Final[float] = 2.0
_HEADING_HALF_POINTS: Final[int] = 10  # vertices each side of a history vertex for its heading
_MIN_COVER_M: Final[float] = 1e-6
_PROBE_STEP_M: Final[float] = 1.0  # ego border probes along the overlap with the history
_PROBE_MARGIN_M: Final[float] = 5.0  # history searched this much beyond the ego's length
_FORK_WINDOW_M: Final[float] = 6.0  # an ego border's last metres searched for a fork
_FORK_SMOOTH_POINTS: Final[int] = 5  # offsets averaged over this many points against noise
_FORK_DEPARTURE_M: Final[float] = 0.25  # averaged offset from the overlap's line at the end that means a fork
_FORK_RETURN_M: Final[float] = 0.08  # … and back within this where the border is cut
_VERTEX_STEP_M: Final[float] = 0.5  # history vertices about this far apart for the probes (sagitta < 1 cm at R 4 m)
_HISTORY_SOURCES: Final[NDArrayInt8] = np.array([Source.EGO, Source.COOP_HISTORY, Source.COOP] * 2, dtype=np.int8)


def _heading(points: NDArrayFloat, at: int) -> tuple[float, float]:
    """Unit tangent (driving direction) of a polyline around vertex ``at`` by a chord of up to
    ``_HEADING_WINDOW_M`` ending at most ``_HEADING_HALF_POINTS`` vertices after it."""
    lo, hi = max(0, at - _HEADING_HALF_POINTS), min(points.shape[0] - 1, at + _HEADING_HALF_POINTS)
    return end_direction(points[lo: hi + 1], True, _HEADING_WINDOW_M)


def _seam_weights(s_history: NDArrayFloat, s_from: float, keep_first: bool) -> tuple[int, NDArrayFloat]:
    """Index of the first history point :func:`seam_blend` moves, and the fade w of each
    point it moves (0 at arc length ``s_from``, 1 at the history's end)."""
    first = int(s_history.searchsorted(s_from if keep_first else s_from + _MIN_COVER_M,
                                       side="left" if keep_first else "right"))
    return first, (s_history[first:-1] - s_from) / (s_history[-1] - s_from)


def seam_blend(history: NDArrayFloat, s_history: NDArrayFloat, s_from: float, ego_offset: complex,
               coop_offset: complex, *, keep_first: bool = False) -> NDArrayFloat:
    """History points after arc length ``s_from`` (from it with ``keep_first``) and before the
    last one, each moved by the seam offsets faded linearly in arc length (see the module
    docstring): ``ego_offset`` (m, x + iy) at ``s_from``, ``coop_offset`` at the history's end."""
    first, w = _seam_weights(s_history, s_from, keep_first)
    z = history[first:-1].view(np.complex128)[:, 0] + ego_offset + w * (coop_offset - ego_offset)
    return z.view(np.float64).reshape(-1, 2)


def _coop_offset(history: NDArrayFloat, coop: NDArrayFloat) -> complex:
    """Offset [m] (x + iy) of the coop border's first point from the history's end, across the
    lane's direction there (the along-track part is the spacing of the two, not an error); the
    direction is the mean of the two chords that end and start there, exact on an arc."""
    (hx, hy), (cx, cy) = end_direction(history, True, _HEADING_WINDOW_M), end_direction(coop, False, _HEADING_WINDOW_M)
    norm = math.hypot(hx + cx, hy + cy) or 1.0
    tx, ty = (hx + cx) / norm, (hy + cy) / norm
    (x0, y0), (x1, y1) = coop[0].tolist(), history[-1].tolist()
    dx, dy = x0 - x1, y0 - y1
    across = -ty * dx + tx * dy
    return complex(-ty * across, tx * across)


class _Overlap(NamedTuple):
    """How the ego border lies on the history where they overlap (:func:`_overlap`).

    Fields: ``departure_m`` the largest change [m] of the ego border's signed offset from
    the history, from its value at the ego's end; ``slope`` and ``intercept_m`` the straight
    line (offset [m] against distance back from the ego's end [m]) fitted to the offsets
    more than :data:`_FORK_WINDOW_M` back (a pose or heading error tilts it, a fork bends
    away from it); ``end_deviation_m`` the end's offset from that line [m] (0, and no line,
    when the departure is within :data:`_FORK_DEPARTURE_M` or too few probes lie that far
    back).
    """

    departure_m: float
    slope: float
    intercept_m: float
    end_deviation_m: float


class _Cover(NamedTuple):
    """Where an ego border end meets the history (frame of the history).

    Fields: ``rest`` the history from the vertex before the one nearest the end on;
    ``s_rest`` its arc lengths [m]; ``s_e`` the foot's arc length on ``rest`` [m];
    ``ego_offset`` the end minus its foot point [m, x + iy]; ``offset_m`` the end's distance
    from the foot [m]; ``heading_rad`` the angle between the history and the ego border there
    [rad]; ``overlap`` how the ego border lies on the history where they overlap
    (:func:`_overlap`); ``k`` the history vertex nearest the end; ``spacing_m`` the history's
    mean vertex spacing from there on [m].
    """

    rest: NDArrayFloat
    s_rest: NDArrayFloat
    s_e: float
    ego_offset: complex
    offset_m: float
    heading_rad: float
    overlap: _Overlap
    k: int
    spacing_m: float


def _probes(ego: NDArrayFloat, s_ego: NDArrayFloat,
            to_history: tuple[float, float, float]) -> tuple[NDArrayComplex, NDArrayFloat]:
    """The ego border's points about every :data:`_PROBE_STEP_M` back from its end (the end
    first), moved by ``to_history`` into the history's frame, as x + iy; and their distances
    back from the end [m]."""
    step = max(1, int(_PROBE_STEP_M * (ego.shape[0] - 1) / s_ego[-1]))
    return transform(ego[::-step], *to_history).view(np.complex128)[:, 0], s_ego[-1] - s_ego[::-step]


def _signed_offsets(points: NDArrayComplex, window: NDArrayComplex) -> tuple[NDArrayFloat, npt.NDArray[np.bool_]]:
    """Signed lateral offset [m] of each point (x + iy) across the segment of ``window`` (history
    vertices in reverse driving order, x + iy) at its nearest vertex, and whether that vertex
    is not the window's last (the oldest) one."""
    squares = (points[:, None] - window).view(np.float64)
    squares *= squares
    nearest = (squares[:, ::2] + squares[:, 1::2]).argmin(axis=1)
    j = np.minimum(nearest, window.shape[0] - 2)
    here = window[j]
    backwards = window[j + 1] - here
    return ((points - here) * backwards.conjugate()).imag / np.abs(backwards), nearest < window.shape[0] - 1


def _history_window(history: NDArrayComplex, k: int, length_m: float, spacing_m: float) -> tuple[NDArrayComplex, bool]:
    """The last history vertices up to its vertex ``k`` (``spacing_m`` apart on average) over
    ``length_m`` plus :data:`_PROBE_MARGIN_M`, in reverse order, thinned to about
    :data:`_VERTEX_STEP_M` apart; and whether the window reaches the history's start."""
    n_window = min(k + 1, math.ceil((length_m + _PROBE_MARGIN_M) / spacing_m) + 1)
    stride = max(1, min(int(_VERTEX_STEP_M / spacing_m), n_window - 1))
    return history[k::-stride][: (n_window - 1) // stride + 1], n_window == k + 1


def _overlap(probes: NDArrayComplex, back_m: NDArrayFloat, history: NDArrayComplex, k: int, length_m: float,
             spacing_m: float) -> _Overlap:
    """The ego border's offsets from the history along their overlap: each of the ego's
    ``probes`` (:func:`_probes`, ``length_m`` long border; ``back_m`` their distances back
    from its end) is offset across the history segment at its nearest vertex in the
    :func:`_history_window` before the history's vertex ``k`` nearest the ego's end; probes
    behind the history's start are left out. ``history`` as x + iy."""
    window, whole = _history_window(history, k, length_m, spacing_m)
    offset, inside = _signed_offsets(probes, window)
    if whole:
        offset, back_m = offset[inside], back_m[inside]
    departure = float(np.abs(offset - offset[0]).max())
    far = back_m > _FORK_WINDOW_M
    if departure <= _FORK_DEPARTURE_M or int(far.sum()) < 3:  # no end deviation can reach the fork threshold
        return _Overlap(departure, 0.0, float(offset[0]), 0.0)
    u, o = back_m[far], offset[far]
    u_mean, o_mean = float(u.mean()), float(o.mean())
    slope = float((u - u_mean) @ (o - o_mean) / ((u - u_mean) @ (u - u_mean)))
    intercept = o_mean - slope * u_mean
    return _Overlap(departure, slope, intercept, float(offset[0]) - intercept)


def _fork_cut(trailing: NDArrayComplex, back_m: NDArrayFloat, history: NDArrayComplex, k: int, spacing_m: float,
              overlap: _Overlap) -> int:
    """How many of an ego border's last points to drop because they leave the history (a
    fork: the ego's detection ends inside it, on its own lane, while the coop took the other
    branch); 0 to keep them all.

    ``trailing``: the border's last :data:`_FORK_WINDOW_M` of points (x + iy in the history's
    frame, driving order), ``back_m`` their distances back from its end [m]. Their offsets
    from the history minus ``overlap``'s line, averaged over :data:`_FORK_SMOOTH_POINTS`
    points (noise), must exceed :data:`_FORK_DEPARTURE_M` at the end; the border is then cut
    after the last point whose average is back within :data:`_FORK_RETURN_M` (none in the
    window: kept, that is no fork but another lane, for the other checks).
    """
    window, _ = _history_window(history, k, _FORK_WINDOW_M, spacing_m)
    offset, _ = _signed_offsets(trailing, window)
    deviation = offset - (overlap.intercept_m + overlap.slope * back_m)
    if deviation.shape[0] < _FORK_SMOOTH_POINTS:
        return 0
    smooth = np.abs(np.convolve(deviation, np.full(_FORK_SMOOTH_POINTS, 1.0 / _FORK_SMOOTH_POINTS), mode="valid"))
    if smooth[-1] <= _FORK_DEPARTURE_M:
        return 0
    back = np.flatnonzero(smooth <= _FORK_RETURN_M)
    if back.shape[0] == 0:
        return 0
    return int(smooth.shape[0] - 1 - back[-1])


def _cover(probes: NDArrayComplex, back_m: NDArrayFloat, length_m: float, direction: complex,
           history: NDArrayFloat) -> _Cover | None:
    """Where the end of an ego border (``length_m`` long; its :func:`_probes` and their
    distances back from its end ``back_m``, unit end direction ``direction`` as x + iy, all
    in the history's frame) meets the history; None when the history does not reach back
    past the end."""
    points = history.view(np.complex128)[:, 0]
    k = int(np.abs(points - probes[0]).argmin())
    if k == 0 or k == history.shape[0] - 1:
        return None
    rest = history[k - 1:]
    s_rest = cumulative_length(rest)
    end = complex(probes[0])
    offset, i, t, fx, fy = foot_near_vertex(end.real, end.imag, rest, 1)
    s_e = float(s_rest[i] + t * (s_rest[i + 1] - s_rest[i]))
    if s_e <= _MIN_COVER_M and k == 1:
        return None
    heading = complex(*_heading(rest, 1)) / direction
    spacing = s_rest[-1] / (rest.shape[0] - 1)
    overlap = _overlap(probes, back_m, points, k, length_m, spacing)
    return _Cover(rest, s_rest, s_e, end - complex(fx, fy), offset, abs(math.atan2(heading.imag, heading.real)),
                  overlap, k, spacing)


def _border_cover(own: NDArrayFloat, s: NDArrayFloat, history: NDArrayFloat, to_coop: tuple[float, float, float],
                  rotation: complex) -> _Cover | None:
    """:func:`_cover` of the ego border ``own`` (ego frame, arc lengths ``s``) on a history
    border (coop frame; ``to_coop`` moves ego-frame points there, ``rotation`` its turn)."""
    probes, back = _probes(own, s, to_coop)
    return _cover(probes, back, float(s[-1]), complex(*end_direction(own, True, _HEADING_WINDOW_M)) * rotation,
                  history)


def _fork_trimmed(own: NDArrayFloat, s: NDArrayFloat, history: NDArrayFloat, cover: _Cover,
                  to_coop: tuple[float, float, float], rotation: complex) -> tuple[NDArrayFloat, _Cover]:
    """The ego border ``own`` (arc lengths ``s``) and its ``cover`` on a history border,
    without the last points that leave the history in a fork (:func:`_fork_cut`); unchanged
    when the overlap shows no fork (the end within :data:`_FORK_DEPARTURE_M` of the
    overlap's line)."""
    overlap = cover.overlap
    if abs(overlap.end_deviation_m) <= _FORK_DEPARTURE_M:
        return own, cover
    first = int(s.searchsorted(s[-1] - _FORK_WINDOW_M))
    trailing = transform(own[first:], *to_coop).view(np.complex128)[:, 0]
    cut = _fork_cut(trailing, s[-1] - s[first:], history.view(np.complex128)[:, 0], cover.k, cover.spacing_m, overlap)
    trimmed = _border_cover(own[:-cut], s[:-cut], history, to_coop, rotation) if cut else None
    return (own, cover) if trimmed is None else (own[:-cut], trimmed)


def _reason(side: str, cover: _Cover, width_m: float, params: FusionParams) -> str:
    """Why a history does not join the ego border ``side`` (``width_m``: the ego lane's width
    at its end, m), or ""."""
    if cover.offset_m > params.convoy_max_offset_m:
        return (f"coop history passes {cover.offset_m:.2f} m from the ego {side} border end "
                f"(> {params.convoy_max_offset_m:.2f} m): another lane")
    if cover.heading_rad > params.convoy_max_heading_rad:
        return (f"coop history heads {math.degrees(cover.heading_rad):.1f} deg away from the ego {side} border at "
                f"its end (> {math.degrees(params.convoy_max_heading_rad):.1f} deg)")
    if cover.overlap.departure_m > 0.5 * width_m:
        return (f"coop history leaves the ego {side} border by {cover.overlap.departure_m:.2f} m where they overlap "
                f"(> half the lane width, {0.5 * width_m:.2f} m): another lane")
    return ""


def _ahead_of(points: NDArrayFloat, end: NDArrayFloat, direction: tuple[float, float]) -> NDArrayFloat:
    """Mask of the points beyond the line through ``end`` normal to ``direction``."""
    return (points - end) @ np.array(direction) > _MIN_COVER_M


def fuse_history(ego: LaneDetection, coop: LaneDetection, *, mode: str = "auto", interpolation: str = "paper",
                 params: FusionParams = DEFAULT_PARAMS) -> FusionResult:
    """Collectively perceived lane of ``ego`` extended by ``coop`` and its history.

    Without ``coop.history``, with ``mode="convoy"`` or when the detections overlap, this is
    :func:`fusion.fuse`. When the history covers the gap on both borders the result is the ego
    lane, the blended history (:class:`Source` ``COOP_HISTORY``) and the coop lane,
    ``kind="history"`` (seams in the module docstring); otherwise the history extends the coop
    detection backwards and :func:`fusion.fuse` interpolates the rest (history points still
    labelled ``COOP_HISTORY``). Output in the world frame.
    """
    history = coop.history
    if history is None or mode == "convoy":
        return fuse(ego, coop, mode=mode, interpolation=interpolation, params=params)
    framed = ego_frame_borders(ego, coop)
    (el, er, cl, cr), (x_rel, y_rel, psi_rel) = framed
    ends = lane_ends(el, er, cl, cr)
    if x_rel <= 0.0 or ends.gap_m <= 0.0:
        return fuse(ego, coop, mode=mode, interpolation=interpolation, params=params)
    association = assess(ego, coop, params, mode=mode, framed=framed, ends=ends)
    if association.reason:
        return ego_result(ego, (el, er), ends.gap_m, association.reason)
    # the history stays in the coop frame; the ego's border probes go there
    to_coop = relative_pose(coop.pose, ego.pose)
    rotation = complex(math.cos(to_coop[2]), math.sin(to_coop[2]))
    n_left = el.shape[0]
    borders = ((el, ego.arclength[:n_left], history.left), (er, ego.arclength[n_left:], history.right))
    covers = []
    for own, s, side in borders:
        cover = _border_cover(own, s, side, to_coop, rotation)
        if cover is None:
            t_end = complex(*ends.t_end) * rotation
            p_end = transform(np.array([ends.p_end]), *to_coop)[0]
            return _partial(ego, coop, p_end, (t_end.real, t_end.imag), mode, interpolation, params)
        covers.append(cover)
    for side, cover in zip(("left", "right"), covers):
        reason = _reason(side, cover, ends.width_m, params)
        if reason:
            return ego_result(ego, (el, er), ends.gap_m, reason)
    # only a history the checks accept at the ego's real end may replace the ego's last points
    (el, covers[0]), (er, covers[1]) = (_fork_trimmed(own, s, side, cover, to_coop, rotation)
                                        for (own, s, side), cover in zip(borders, covers))
    gaps = [seam_blend(cover.rest, cover.s_rest, cover.s_e, cover.ego_offset, _coop_offset(cover.rest, c))
            for cover, c in zip(covers, (coop.left, coop.right))]
    n_gap = gaps[0].shape[0]
    gap = transform(np.concatenate(gaps), x_rel, y_rel, psi_rel)
    lanes = tuple(matched_lane(ego, coop, index, "spline", interpolation, params) for index in association.matched)
    uncertainty = pair_uncertainty(ego, coop, framed[0], (x_rel, y_rel))
    variances = None if uncertainty is None else _history_variances(uncertainty, covers, (el, er))
    return replace(ego_frame_result(ego, (el, gap[:n_gap], cl, er, gap[n_gap:], cr), _HISTORY_SOURCES, "history",
                                    ends.gap_m, variances=variances), confidence=association.confidence, lanes=lanes)


def _history_variances(uncertainty: PairUncertainty, covers: list[_Cover],
                       ego_borders: tuple[NDArrayFloat, NDArrayFloat]) -> list[NDArrayFloat]:
    """World variances of the parts (ego, history, coop per border) of a history fusion: the
    detections' own (the ego borders maybe cut at a fork), and across the gap
    :func:`fusion.uncertainty.seam_sigma` between the ego end's σ and the coop start's."""
    out = []
    for side, (cover, own) in enumerate(zip(covers, ego_borders)):
        ego_var = uncertainty.borders[side].world[: own.shape[0]]
        coop_var = uncertainty.borders[2 + side].world
        _, w = _seam_weights(cover.s_rest, cover.s_e, False)
        sigma = seam_sigma(math.sqrt(ego_var[-1]), math.sqrt(coop_var[0]), w)
        out += [ego_var, sigma * sigma, coop_var]
    return out


def _partial(ego: LaneDetection, coop: LaneDetection, p_end: NDArrayFloat, t_end: tuple[float, float], mode: str,
             interpolation: str, params: FusionParams) -> FusionResult:
    """A history short of the ego's end: its part beyond the ego's end (the line through the
    ego lane's end ``p_end`` normal to its direction ``t_end``, both in the coop frame) joined
    to the coop detection, the seam offset faded in along it, the rest interpolated by
    :func:`fusion.fuse`."""
    assert coop.history is not None
    extended = []
    for history, first in zip((coop.history.left, coop.history.right), (coop.left, coop.right)):
        ahead = history[_ahead_of(history, p_end, t_end)]
        if ahead.shape[0] < 2:
            return fuse(ego, coop, mode=mode, interpolation=interpolation, params=params)
        joined = seam_blend(ahead, cumulative_length(ahead), 0.0, 0j, _coop_offset(ahead, first), keep_first=True)
        extended.append(np.concatenate((joined, first)))
    sigmas = [None if sigma is None else np.concatenate((np.full(joined.shape[0] - own.shape[0], sigma[0]), sigma))
              for joined, own, sigma in zip(extended, (coop.left, coop.right), (coop.left_sigma, coop.right_sigma))]
    longer = replace(coop, left=extended[0], right=extended[1], history=None, left_sigma=sigmas[0],
                     right_sigma=sigmas[1])
    result = fuse(ego, longer, mode=mode, interpolation=interpolation, params=params)
    if result.kind == "none":
        return result
    labels = []
    for source, border, own in ((result.left_source, longer.left, coop.left),
                                (result.right_source, longer.right, coop.right)):
        relabelled = source.copy()
        n_coop = int(np.count_nonzero(source == Source.COOP))
        first_coop = source.shape[0] - n_coop
        relabelled[first_coop: first_coop + min(n_coop, border.shape[0] - own.shape[0])] = Source.COOP_HISTORY
        labels.append(relabelled)
    return replace(result, left_source=labels[0], right_source=labels[1])
