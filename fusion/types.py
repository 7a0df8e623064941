"""Data model of the fusion library: poses, lane detections, parameters and results.

Frames: the *world* frame is the OpenDRIVE inertial frame (x east, y north, yaw
counter-clockwise from x); the *vehicle* frame is ISO 8855 (x forward, y left). Units: m, rad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from fusion.errors import InvalidDetectionError, InvalidParameterError

NDArrayFloat = npt.NDArray[np.float64]
NDArrayInt8 = npt.NDArray[np.int8]

FusionKind = Literal["convoy", "spline", "history", "none"]
FusionMode = Literal["auto", "convoy", "spline"]
Interpolation = Literal["paper", "hermite"]
Fusibility = Literal["geometric", "paper"]
MIN_CONFIDENCE: Final[float] = 0.4
"""Default lowest association confidence fused (``FusionParams.min_confidence``)."""
AssociationRule = Literal["confidence", "strict", "separation", "fork", "legacy"]
ASSOCIATION_RULES: Final[tuple[str, ...]] = ("confidence", "strict", "separation", "fork", "legacy")
SEPARATION_RULES: Final[tuple[str, ...]] = ("separation", "fork")
"""The association rules that apply the separation test and read d_s ≤ d_i to
:data:`fusion.fusibility.GAP_TOLERANCE_M`."""
ConvoyStrategy = Literal["weighted", "mean", "nearest"]
ConvoyWeights = Literal["paper", "mean", "inverse-variance"]
CONVOY_WEIGHTS: Final[tuple[str, ...]] = ("paper", "mean", "inverse-variance")
SplineParameter = Literal["chord", "uniform"]
END_REACHED: Final[tuple[str, ...]] = ("range", "map_end")
"""``LaneDetection.end_reason`` values of a detection that ran as far as the sensor looks:
its range (``"range"``) or the end of the lane it follows (``"map_end"``)."""
END_EARLY: Final[tuple[str, ...]] = ("field_of_view", "crest", "occlusion", "unmarked")
"""``LaneDetection.end_reason`` values of a detection that stopped short of its range: the
lane left the field of view, went behind a crest or another vehicle, or its markings stopped
(``"unmarked"``: where a junction begins)."""
END_REASONS: Final[tuple[str, ...]] = END_REACHED + END_EARLY
"""Every ``LaneDetection.end_reason`` (None: not stated)."""

MIN_BORDER_POINTS: Final[int] = 2
MIN_POINT_STEP_M: Final[float] = 1e-9


class Source(IntEnum):
    """Origin of one point of a fused border."""

    EGO = 0
    FUSED = 1
    INTERPOLATED = 2
    COOP = 3
    COOP_HISTORY = 4


def _source_counts(source: NDArrayInt8) -> str:
    """"EGO 300, COOP 300": the number of points per :class:`Source` label present, in label order."""
    labels, counts = np.unique(source, return_counts=True)
    return ", ".join(f"{Source(int(label)).name} {int(count)}" for label, count in zip(labels, counts))


def _given(value: object) -> str:
    return "no" if value is None else "yes"


def _frozen(array: NDArrayFloat) -> NDArrayFloat:
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class Pose2D:
    """Planar pose of a vehicle in the world frame.

    Fields: ``x``, ``y`` position [m]; ``yaw`` heading [rad], counter-clockwise from x.
    """

    x: float
    y: float
    yaw: float

    def __post_init__(self) -> None:
        for name in ("x", "y", "yaw"):
            value = getattr(self, name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or not math.isfinite(value):
                raise InvalidDetectionError(f"Pose2D.{name} must be a finite number, got {value!r}")


def validated_border(name: str, points: object) -> NDArrayFloat:
    """Read-only float64 copy of a border ``(N, 2)`` with consecutive duplicates removed.

    Raises ``InvalidDetectionError`` naming ``name`` for a wrong shape, NaN/inf or fewer
    than two distinct points.
    """
    return _validated_border(name, points)[0]


def clean_borders(points: NDArrayFloat, offsets: npt.NDArray[np.intp]) -> npt.NDArray[np.bool_]:
    """Per border of the stack ``points`` (float64 ``(N, 2)``, border k is
    ``points[offsets[k]:offsets[k + 1]]``), whether :func:`validated_border` keeps it as it
    is: finite, at least two points, none within ``MIN_POINT_STEP_M`` of its predecessor
    (one check for the whole stack)."""
    counts = np.diff(offsets)
    out = counts >= MIN_BORDER_POINTS
    if len(points) == 0:
        return out
    step = np.diff(points, axis=0)
    bad = np.zeros(len(points), dtype=bool)
    bad[1:] = ~(np.hypot(step[:, 0], step[:, 1]) > MIN_POINT_STEP_M)
    starts = offsets[:-1][counts > 0]
    bad[starts] = False
    finite = np.isfinite(points)
    if not finite.all():
        bad |= ~(finite[:, 0] & finite[:, 1])
    if bad.any():
        out[counts > 0] &= ~np.logical_or.reduceat(bad, starts)
    return out


def stacked_arclengths(points: NDArrayFloat, offsets: npt.NDArray[np.intp]) -> NDArrayFloat:
    """:func:`stacked_arclength` of every polyline of the stack ``points`` (polyline k is
    ``points[offsets[k]:offsets[k + 1]]``, at least one point each), each from 0 at its first
    point: the segment lengths in one pass, accumulated polyline by polyline (the same values)."""
    seg = np.abs((points[1:] - points[:-1]).view(np.complex128)[:, 0])
    out = np.zeros(len(points))
    for start, stop in zip(offsets[:-1].tolist(), offsets[1:].tolist()):
        np.cumsum(seg[start: stop - 1], out=out[start + 1: stop])
    return out


def _float_array(name: str, values: object) -> NDArrayFloat:
    """``values`` as a float64 array; ``InvalidDetectionError`` naming ``name`` when not numeric."""
    try:
        return np.array(values, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InvalidDetectionError(f"{name} is not numeric: {exc}") from None


def _validated_border(name: str, points: object) -> tuple[NDArrayFloat, npt.NDArray[np.bool_] | None]:
    """``validated_border`` and the mask of the input points it kept (None: all)."""
    array = _float_array(name, points)
    if array.ndim != 2 or array.shape[1] != 2:
        raise InvalidDetectionError(f"{name} must have shape (N, 2), got {array.shape}")
    if not np.isfinite(array).all():
        raise InvalidDetectionError(f"{name} contains NaN or inf")
    kept = None
    if array.shape[0] >= 2:
        step = np.diff(array, axis=0)
        keep = np.empty(array.shape[0], dtype=bool)
        keep[0] = True
        keep[1:] = np.hypot(step[:, 0], step[:, 1]) > MIN_POINT_STEP_M
        if not keep.all():
            array, kept = array[keep], keep
    if array.shape[0] < MIN_BORDER_POINTS:
        raise InvalidDetectionError(
            f"{name} needs at least {MIN_BORDER_POINTS} distinct points, got {array.shape[0]}"
        )
    return _frozen(array), kept


def _validated_sigma(name: str, sigma: object, n_points: int, kept: npt.NDArray[np.bool_] | None) -> NDArrayFloat:
    """Read-only per-point 1σ ``(n_points,)`` [m], finite and >= 0, reduced to ``kept``."""
    array = _float_array(name, sigma)
    if array.shape != (n_points,):
        raise InvalidDetectionError(f"{name} must have shape ({n_points},), one per border point, got {array.shape}")
    if not (np.isfinite(array).all() and (array >= 0.0).all()):
        raise InvalidDetectionError(f"{name} must be finite and >= 0 m")
    return _frozen(array if kept is None else array[kept])


def _validated_lane_model(name: str, sigma: object) -> NDArrayFloat:
    """Read-only ``(4,)`` 1σ of a lane model's coefficient errors, finite and >= 0."""
    array = _float_array(name, sigma)
    if array.shape != (4,) or not (np.isfinite(array).all() and (array >= 0.0).all()):
        raise InvalidDetectionError(f"{name} must be 4 finite values >= 0 (c0 m, c1 rad, c2 1/m, c3 1/m²), "
                                    f"got shape {array.shape}")
    return _frozen(array)


def _validated_covariance(name: str, covariance: object) -> NDArrayFloat:
    """Read-only symmetric positive semi-definite ``(3, 3)`` covariance."""
    array = _float_array(name, covariance)
    if array.shape != (3, 3) or not np.isfinite(array).all():
        raise InvalidDetectionError(f"{name} must be a finite (3, 3) covariance of (x, y, yaw), got shape {array.shape}")
    if not np.allclose(array, array.T, rtol=0.0, atol=1e-12) or np.linalg.eigvalsh(array).min() < -1e-12:
        raise InvalidDetectionError(f"{name} must be symmetric positive semi-definite")
    return _frozen(array)


def stacked_arclength(points: NDArrayFloat, n_first: int) -> NDArrayFloat:
    """Arc length [m] along ``points[:n_first]`` and along ``points[n_first:]``, each from 0,
    in one pass over the stacked ``(N, 2)`` polylines."""
    step = points[1:] - points[:-1]
    seg = np.abs(step.view(np.complex128)[:, 0])
    out = np.zeros(points.shape[0])
    np.cumsum(seg[: n_first - 1], out=out[1:n_first])
    np.cumsum(seg[n_first:], out=out[n_first + 1:])
    return out


@dataclass(frozen=True)
class NeighbourLane:
    """A lane beside the sender's lane, driven the same way, detected with it.

    Fields:
        index: where it lies: ``+k`` is the k-th lane to the left, ``-k`` the k-th to the
            right of the sender's lane (k >= 1, driving direction).
        left, right: its borders, ``(N, 2)`` float64 in the sender's *vehicle* frame [m],
            driving order, only where the lane exists in the detection window (validated like
            :class:`LaneDetection`'s).
        at_start, at_end: whether the lane exists at the detection's first / last
            cross-section (at the sender, and one sensor range ahead).
    """

    index: int
    left: NDArrayFloat
    right: NDArrayFloat
    at_start: bool = True
    at_end: bool = True

    def __post_init__(self) -> None:
        if isinstance(self.index, bool) or not isinstance(self.index, (int, np.integer)) or self.index == 0:
            raise InvalidDetectionError(f"NeighbourLane.index must be a non-zero integer, got {self.index!r}")
        object.__setattr__(self, "left", validated_border(f"NeighbourLane {self.index} left", self.left))
        object.__setattr__(self, "right", validated_border(f"NeighbourLane {self.index} right", self.right))


@dataclass(frozen=True)
class _BorderPair:
    """Two lane borders validated like :class:`LaneDetection`'s (errors name the class)."""

    left: NDArrayFloat
    right: NDArrayFloat

    def __post_init__(self) -> None:
        name = type(self).__name__
        object.__setattr__(self, "left", validated_border(f"{name}.left", self.left))
        object.__setattr__(self, "right", validated_border(f"{name}.right", self.right))


@dataclass(frozen=True)
class LaneBranch(_BorderPair):
    """A lane that leaves the sender's lane at a fork inside the detection window.

    Fields: ``left``, ``right`` its borders from the fork on, ``(N, 2)`` float64 in the
    sender's *vehicle* frame [m], driving order (validated like :class:`LaneDetection`'s).
    """


@dataclass(frozen=True)
class LaneHistory(_BorderPair):
    """The lane a vehicle perceived over its last metres of travel, registered with its own
    odometry.

    Fields:
        left, right: lane borders, ``(N, 2)`` float64 in the sender's *vehicle* frame at the
            detection's time [m] (x forward, y left), ordered in driving direction, ending
            where the current detection starts (at the vehicle); validated like the
            detection's borders.
    """


@dataclass(frozen=True)
class RoadEdges:
    """Where the road edge lies: the lane whose outer border has no further driving lane of
    the same direction beyond it, at the detection's first (``start_*``) and last (``end_*``)
    cross-section, on the ``left`` and ``right`` (driving direction).

    Fields: ``start_left``, ``start_right``, ``end_left``, ``end_right``: that lane's index
    (0 = the sender's lane, ``±k`` = :attr:`NeighbourLane.index`; >= 0 on the left, <= 0 on
    the right), or None when the edge was not seen (further lanes than the sensor detects).
    """

    start_left: int | None = None
    start_right: int | None = None
    end_left: int | None = None
    end_right: int | None = None

    def __post_init__(self) -> None:
        for name, sign in (("start_left", 1), ("start_right", -1), ("end_left", 1), ("end_right", -1)):
            value = getattr(self, name)
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                                      or value * sign < 0):
                raise InvalidDetectionError(f"RoadEdges.{name} must be None or an integer "
                                            f"{'>= 0' if sign > 0 else '<= 0'}, got {value!r}")


@dataclass(frozen=True)
class LaneDetection:
    """One vehicle's detection of one lane.

    Fields:
        pose: the sender's pose in the world frame at detection time.
        left, right: lane borders, ``(N, 2)`` float64 in the sender's *vehicle* frame [m],
            ordered in driving direction, about 0.10 m apart. The two borders may have
            different lengths. Points within 1 nm of their predecessor (duplicates) are
            dropped on construction;
            fewer than two distinct points, NaN or inf raise ``InvalidDetectionError``.
        stamp: detection time [s] (informative; the fusion is static, no time alignment).
        sender: identifier of the sending vehicle (informative).
        history: the lane the sender perceived behind it (:class:`LaneHistory`, same frame),
            or None (default); :func:`fusion.fuse_history` bridges a gap with it.
        neighbours: lanes beside the sender's lane driven the same way (:class:`NeighbourLane`,
            distinct indices; empty = the sender's lane only, as a single-lane sensor).
        road_edges: where the road edges lie (:class:`RoadEdges`), or None when unknown.
        branches: lanes leaving the sender's lane at a fork inside the window
            (:class:`LaneBranch`; a multi-lane sensor reports them with the neighbours).
        points: both borders stacked, left then right, ``(N_left + N_right, 2)`` [m, vehicle
            frame]; ``left`` and ``right`` are read-only views of it (set on construction).
        arclength: ``(N_left + N_right,)`` arc length of every point of ``points`` along its
            own border, from 0 at each border's first point [m] (set on construction; arc
            length does not depend on the frame, so fusion reuses it in any frame).
        left_sigma, right_sigma: lateral 1σ [m] of every point of ``left`` / ``right`` as
            given (one per input point; reduced with the duplicates dropped), or None when
            the sender states no uncertainty (default).
        pose_cov: ``(3, 3)`` covariance of the sender's pose error in (x [m], y [m],
            yaw [rad]), world frame, or None when unknown (default).
        lane_model_sigma: ``(4,)`` 1σ of the errors of a cubic lane model's coefficients
            (δc0 [m], δc1 [rad], δc2 [1/m], δc3 [1/m²]): the part of the stated σ that one
            error of each border shares over its points, e(x) = δc0 + δc1·x + δc2·x²/2 +
            δc3·x³/6 at the point's forward coordinate x [m] (vehicle frame), the two
            borders' independent; the rest of a point's stated variance is its own. None
            (default): the stated σ says nothing of how points' errors correlate (used by
            the convoy's pose update, :mod:`fusion.registration`).
        end_reason: why the detection ended, one of :data:`END_REASONS`, or None when not
            stated (default); ``association="fork"`` reads it (:mod:`fusion.association`).
    """

    pose: Pose2D
    left: NDArrayFloat
    right: NDArrayFloat
    stamp: float = 0.0
    sender: str = ""
    history: LaneHistory | None = field(default=None, repr=False, compare=False)
    neighbours: tuple[NeighbourLane, ...] = ()
    road_edges: RoadEdges | None = None
    branches: tuple[LaneBranch, ...] = ()
    left_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    right_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    pose_cov: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    end_reason: str | None = field(default=None, compare=False)
    lane_model_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    points: NDArrayFloat = field(init=False, repr=False, compare=False)
    arclength: NDArrayFloat = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.pose, Pose2D):
            raise InvalidDetectionError(f"LaneDetection.pose must be a Pose2D, got {type(self.pose).__name__}")
        raw_left, raw_right = self.left, self.right
        left, left_kept = _validated_border("LaneDetection.left", raw_left)
        right, right_kept = _validated_border("LaneDetection.right", raw_right)
        for name, sigma, raw, kept in (("left_sigma", self.left_sigma, raw_left, left_kept),
                                       ("right_sigma", self.right_sigma, raw_right, right_kept)):
            if sigma is not None:
                object.__setattr__(self, name, _validated_sigma(f"LaneDetection.{name}", sigma, len(raw), kept))
        if self.pose_cov is not None:
            object.__setattr__(self, "pose_cov", _validated_covariance("LaneDetection.pose_cov", self.pose_cov))
        if self.lane_model_sigma is not None:
            object.__setattr__(self, "lane_model_sigma",
                               _validated_lane_model("LaneDetection.lane_model_sigma", self.lane_model_sigma))
        points = _frozen(np.concatenate((left, right)))
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "left", points[: left.shape[0]])
        object.__setattr__(self, "right", points[left.shape[0]:])
        object.__setattr__(self, "arclength", _frozen(stacked_arclength(points, left.shape[0])))
        if not math.isfinite(float(self.stamp)):
            raise InvalidDetectionError(f"LaneDetection.stamp must be finite, got {self.stamp!r}")
        if self.history is not None and not isinstance(self.history, LaneHistory):
            raise InvalidDetectionError(
                f"LaneDetection.history must be a LaneHistory or None, got {type(self.history).__name__}")
        neighbours = tuple(self.neighbours)
        for lane in neighbours:
            if not isinstance(lane, NeighbourLane):
                raise InvalidDetectionError(f"LaneDetection.neighbours must hold NeighbourLane, got {type(lane).__name__}")
        if len({lane.index for lane in neighbours}) != len(neighbours):
            raise InvalidDetectionError("LaneDetection.neighbours: two lanes share an index")
        object.__setattr__(self, "neighbours", neighbours)
        branches = tuple(self.branches)
        for branch in branches:
            if not isinstance(branch, LaneBranch):
                raise InvalidDetectionError(f"LaneDetection.branches must hold LaneBranch, got {type(branch).__name__}")
        object.__setattr__(self, "branches", branches)
        if self.road_edges is not None and not isinstance(self.road_edges, RoadEdges):
            raise InvalidDetectionError(f"LaneDetection.road_edges must be RoadEdges or None, "
                                        f"got {type(self.road_edges).__name__}")
        if self.end_reason is not None and self.end_reason not in END_REASONS:
            raise InvalidDetectionError(f"LaneDetection.end_reason must be None or one of {', '.join(END_REASONS)}, "
                                        f"got {self.end_reason!r}")

    @classmethod
    def trusted(cls, pose: Pose2D, points: NDArrayFloat, n_left: int, *, stamp: float = 0.0, sender: str = "",
                neighbours: tuple[NeighbourLane, ...] = (), road_edges: RoadEdges | None = None,
                branches: tuple[LaneBranch, ...] = (), left_sigma: NDArrayFloat | None = None,
                right_sigma: NDArrayFloat | None = None, pose_cov: NDArrayFloat | None = None,
                arclength: NDArrayFloat | None = None, end_reason: str | None = None,
                lane_model_sigma: NDArrayFloat | None = None) -> LaneDetection:
        """The detection of borders already checked as a block (:func:`clean_borders` true for
        both, ``points`` the stacked left and right, float64, read-only), sigmas, covariance
        and (if given) ``arclength`` (:func:`stacked_arclengths`) already valid and read-only,
        ``end_reason`` one of :data:`END_REASONS` or None, ``lane_model_sigma`` valid:
        equal to the constructor's, without its per-detection checks and copies."""
        detection = object.__new__(cls)
        put = object.__setattr__
        for name, value in (("pose", pose), ("stamp", stamp), ("sender", sender), ("history", None),
                            ("neighbours", neighbours), ("road_edges", road_edges), ("branches", branches),
                            ("left_sigma", left_sigma), ("right_sigma", right_sigma), ("pose_cov", pose_cov),
                            ("end_reason", end_reason), ("lane_model_sigma", lane_model_sigma), ("points", points),
                            ("left", points[:n_left]), ("right", points[n_left:]),
                            ("arclength", _frozen(stacked_arclength(points, n_left)) if arclength is None else arclength)):
            put(detection, name, value)
        return detection

    def __repr__(self) -> str:
        """One line: sender, stamp, pose, points per border and what else the detection carries."""
        return (f"LaneDetection(sender={self.sender!r}, stamp={self.stamp:g} s, pose=({self.pose.x:.3f} m, "
                f"{self.pose.y:.3f} m, {self.pose.yaw:.4f} rad), left: {len(self.left)} points, right: "
                f"{len(self.right)} points, neighbours: {len(self.neighbours)}, branches: {len(self.branches)}, "
                f"road_edges: {_given(self.road_edges)}, history: {_given(self.history)}, "
                f"sigma: {_given(self.left_sigma if self.left_sigma is not None else self.right_sigma)}, "
                f"pose_cov: {_given(self.pose_cov)})")


@dataclass(frozen=True)
class FusionParams:
    """Parameters of :func:`fusion.fuse`; defaults are the paper's values where it gives one.

    Fields:
        t_pos_m: lateral position tolerance |y_rel| of the paper's fusibility check [m]
            (paper: 0.40; the geometric check uses fractions of the measured lane width).
        t_psi_rad: orientation tolerance of the fusibility checks [rad] (paper: 10°).
        d_i_m: maximum gap d_s bridged by spline fusion [m] (default 50).
        apex_min_turn_rad: relative orientation above which the apex is estimated [rad]
            (paper: 10°).
        apex_ratio: P_c = P_i + apex_ratio·(P_j − P_i) (paper: 0.4).
        spline_parameter: knot parameter of the paper's spline: ``"chord"`` (cumulative chord
            length, default) or ``"uniform"`` (knot index; reproduces the paper's too-flat
            curve without apex, Fig. 4a, for the ablation).
        spacing_m: sampling step of interpolated points [m] (paper: 0.10).
        w_coop: weight of the cooperative detection in the weighted convoy fusion (paper: 0.75).
        convoy_strategy: ``"weighted"`` (paper, ``w_coop``), ``"mean"`` (0.5) or ``"nearest"``
            (the coop detection, nearest to its sensor, replaces the ego one in the overlap).
        convoy_weights: the weights of the convoy overlap: ``"paper"`` (default: the fixed
            weights of ``convoy_strategy``, the paper's 0.75 coop / 0.25 ego), ``"mean"`` (0.5
            each) or ``"inverse-variance"`` (point by point from both detections' σ and pose
            covariances, :mod:`fusion.uncertainty`, over the whole overlap; with a pose
            covariance the coop's relative pose error is first estimated from the overlap's
            ends and its whole detection corrected, :mod:`fusion.registration`, unless the
            overlap contradicts the stated σ; the steps at its two ends fade out over
            ``convoy_end_blend_m`` outside it; a detection that states no σ under a pose
            covariance takes :data:`fusion.uncertainty.UNSTATED_SIGMA_M` per point for the
            update and the weights, its fused lane stating none; the weights of ``"mean"``
            when a detection states no σ and no sender a pose covariance, or the overlap
            contradicts the stated σ).
            ``"mean"`` and ``"inverse-variance"`` need ``convoy_strategy="weighted"``.
        convoy_end_blend_m: length over which the steps of inverse-variance weights at the
            overlap's ends fade out (smoothstep) into the ego lane before it and into the
            detection that continues after it [m] (default 5; 0 keeps the steps).
        convoy_blend_offset_m: offset of the two borders at the overlap start above which the
            overlap blends linearly from ego to coop instead of the weights [m].
        convoy_max_offset_m: largest lateral distance of the coop border start from the ego
            border for a convoy overlap [m]; a lane width away is the adjacent lane.
        convoy_max_heading_rad: largest heading difference of the two borders at the
            overlap start [rad].
        fusibility: ``"geometric"`` (default, works across curves, see
            :func:`fusion.fusibility.geometric_check`) or ``"paper"`` (the paper's three pose
            cases, :func:`fusion.fusibility.paper_check`).
        association: the decision on a pair that passed the geometric rules: ``"legacy"``
            (default: the geometric and lane rules alone; reproduces the paper study's
            figures), ``"confidence"`` (also rejects a pair whose association confidence is
            below ``min_confidence`` as "ambiguous" and, with ``gate_false_rejection`` set and
            both detections stating σ, a spline pair that fails the statistical gate of
            :mod:`fusion.gate`, as "another lane" or "ambiguous") or ``"strict"`` (as
            ``"confidence"``, and without neighbour lanes a gap pair is ambiguous when the lane
            a lane width beside the coop's would pass the geometric check too: precision
            before recall) or ``"separation"`` (as ``"confidence"``, and without neighbour
            lanes a gap pair is ambiguous when the lane a lane width beside the coop's passes
            the geometric check using less than :data:`fusion.association.SEPARATION_MARGIN`
            more of its lateral limits than the coop's own lane; and the gap d_s ≤ d_i is read
            to :data:`fusion.fusibility.GAP_TOLERANCE_M`) or ``"fork"`` (as ``"separation"``, and a
            lane branching off where the ego's detection ends — the detection runs less than
            :data:`fusion.association.FORK_SEEN_M` along it — is a fork whose way the ego's
            lane takes is not seen: a coop that continues that branch as well as or better
            than the ego's lane is rejected; so is, by the ego's ``end_reason``, one that
            continues a branch the ego's detection lies on where it stopped short of its
            range, and a single-lane gap pair whose ego detection ended ``"unmarked"``). Opt-in: measured on the map families in
            docs/fusion/association.md and docs/results/association.md.
        min_confidence: lowest association confidence fused with ``association="confidence"``,
            ``"strict"`` or ``"separation"``
            (in [0, 1]; chosen on the tune seeds of ``tools/study_families.py``, see
            docs/fusion/association.md).
        gate_false_rejection: false rejection rate α of the statistical gate of
            ``association="confidence"``/``"strict"``/``"separation"``, in (0, 1), e.g. 0.01;
            ``None`` (default: with the camera sensor it costs recall at d_s 50 m and adds no
            precision to ``"separation"``) turns the gate off.
        heading_window_m: length of the border ends fitted by least squares for
            ``interpolation="hermite"`` [m]; ``None`` (default) picks it per end among
            2–6 m from the detection noise (see :func:`fusion.geometry.fit_ends`).
    """

    t_pos_m: float = 0.40
    t_psi_rad: float = math.radians(10.0)
    d_i_m: float = 50.0
    apex_min_turn_rad: float = math.radians(10.0)
    apex_ratio: float = 0.4
    spline_parameter: SplineParameter = "chord"
    spacing_m: float = 0.10
    w_coop: float = 0.75
    convoy_strategy: ConvoyStrategy = "weighted"
    convoy_weights: ConvoyWeights = "paper"
    convoy_end_blend_m: float = 5.0
    convoy_blend_offset_m: float = 0.20
    convoy_max_offset_m: float = 1.0
    convoy_max_heading_rad: float = math.radians(30.0)
    fusibility: Fusibility = "geometric"
    association: AssociationRule = "legacy"
    min_confidence: float = MIN_CONFIDENCE
    gate_false_rejection: float | None = None
    heading_window_m: float | None = None

    def __post_init__(self) -> None:
        positive = ("t_pos_m", "t_psi_rad", "d_i_m", "spacing_m", "convoy_max_offset_m",
                    "convoy_max_heading_rad")
        if self.heading_window_m is not None:
            positive += ("heading_window_m",)
        for name in positive:
            value = getattr(self, name)
            if not math.isfinite(value) or value <= 0.0:
                raise InvalidParameterError(f"FusionParams.{name} must be finite and > 0, got {value!r}")
        for name in ("apex_min_turn_rad", "convoy_blend_offset_m", "convoy_end_blend_m"):
            value = getattr(self, name)
            if not math.isfinite(value) or value < 0.0:
                raise InvalidParameterError(f"FusionParams.{name} must be finite and >= 0, got {value!r}")
        for name in ("apex_ratio", "w_coop"):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise InvalidParameterError(f"FusionParams.{name} must be in [0, 1], got {value!r}")
        if self.convoy_strategy not in ("weighted", "mean", "nearest"):
            raise InvalidParameterError(f"FusionParams.convoy_strategy unknown: {self.convoy_strategy!r}")
        if self.convoy_weights not in CONVOY_WEIGHTS:
            raise InvalidParameterError(f"FusionParams.convoy_weights must be one of {CONVOY_WEIGHTS}, "
                                        f"got {self.convoy_weights!r}")
        if self.convoy_weights != "paper" and self.convoy_strategy != "weighted":
            raise InvalidParameterError(f"FusionParams.convoy_weights {self.convoy_weights!r} sets the weights: "
                                        f"it needs convoy_strategy 'weighted', got {self.convoy_strategy!r}")
        if self.spline_parameter not in ("chord", "uniform"):
            raise InvalidParameterError(f"FusionParams.spline_parameter unknown: {self.spline_parameter!r}")
        if self.fusibility not in ("geometric", "paper"):
            raise InvalidParameterError(f"FusionParams.fusibility unknown: {self.fusibility!r}")
        if self.association not in ASSOCIATION_RULES:
            raise InvalidParameterError(f"FusionParams.association must be one of {ASSOCIATION_RULES}, "
                                        f"got {self.association!r}")
        if not 0.0 <= self.min_confidence <= 1.0:
            raise InvalidParameterError(f"FusionParams.min_confidence must be in [0, 1], got {self.min_confidence!r}")
        if self.gate_false_rejection is not None and not 0.0 < self.gate_false_rejection < 1.0:
            raise InvalidParameterError(f"FusionParams.gate_false_rejection must be in (0, 1), "
                                        f"got {self.gate_false_rejection!r}")

    @property
    def coop_weight(self) -> float:
        """Fixed weight of the coop point in the convoy overlap: ``convoy_strategy``'s with
        ``convoy_weights="paper"``, else 0.5 (``"mean"``, and ``"inverse-variance"`` without σ
        or where the overlap contradicts it)."""
        if self.convoy_weights != "paper":
            return 0.5
        return {"weighted": self.w_coop, "mean": 0.5, "nearest": 1.0}[self.convoy_strategy]


@dataclass(frozen=True)
class FusionResult:
    """Collectively perceived lane.

    Fields:
        left, right: fused borders, ``(N, 2)`` float64 in the *world* frame [m], ordered in
            driving direction (the ego detection alone when ``kind == "none"``).
        left_source, right_source: ``(N,)`` int8 per-point :class:`Source` labels.
        kind: ``"convoy"``, ``"spline"``, ``"history"`` (the gap bridged by the coop's
            history alone, :func:`fusion.fuse_history`) or ``"none"`` (nothing fused).
        gap_m: signed gap d_s between the ego end and the coop start on the centre line [m]
            (its length, negative along the ego end heading for an overlap).
        reason: why nothing was fused (empty when something was).
        confidence: how sure the lane association is, in [0, 1] (see
            :func:`fusion.association.associate`; 0 when nothing was fused).
        lanes: the neighbour lanes fused as well (both detections carry them and they
            match), ``(index, left, right)`` world frame [m], index as
            :attr:`NeighbourLane.index`; empty without neighbours.
        left_sigma, right_sigma: lateral 1σ [m] of every point of ``left`` / ``right`` in the
            world frame (:mod:`fusion.uncertainty`), ``(N,)`` finite and >= 0; None when a
            detection fused states no σ (the default).
    """

    left: NDArrayFloat
    right: NDArrayFloat
    left_source: NDArrayInt8
    right_source: NDArrayInt8
    kind: FusionKind
    gap_m: float
    reason: str = ""
    confidence: float = 0.0
    lanes: tuple[tuple[int, NDArrayFloat, NDArrayFloat], ...] = ()
    left_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)
    right_sigma: NDArrayFloat | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        for name, border in (("left_sigma", self.left), ("right_sigma", self.right)):
            sigma = getattr(self, name)
            if sigma is not None and sigma.shape != (border.shape[0],):
                raise InvalidParameterError(f"FusionResult.{name} must have shape ({border.shape[0]},), one per "
                                            f"border point, got {sigma.shape}")
        for array in (self.left, self.right, self.left_source, self.right_source, self.left_sigma, self.right_sigma):
            if array is not None:
                array.setflags(write=False)

    def __repr__(self) -> str:
        """One line: kind, reason, gap, points per border with their :class:`Source` counts,
        confidence, neighbour lanes and whether σ is given."""
        reason = f", reason={self.reason!r}" if self.reason else ""
        sigma = "yes" if self.left_sigma is not None and self.right_sigma is not None else "no"
        return (f"FusionResult(kind={self.kind!r}{reason}, gap_m={self.gap_m:.3f}, "
                f"left: {len(self.left)} points ({_source_counts(self.left_source)}), "
                f"right: {len(self.right)} points ({_source_counts(self.right_source)}), "
                f"confidence={self.confidence:.3f}, lanes: {len(self.lanes)}, sigma: {sigma})")
