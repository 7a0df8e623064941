"""The output of an evaluation run: ``metrics.json``, ``summary.md`` and ``frames.csv``.

``metrics.json`` schema (version 1)::

    {
      "schema_version": 1,
      "partial": false,              # true when the run was interrupted
      "provenance": {                # how it was made (added in version 1; a reader takes a file without it)
        "program": "cold-eval", "command": "cold-eval --map maps/junction.xodr --out r",
        "version": "0.1.0",          # cold-maps version
        "seed": "0", "sensor": "sensor ideal (ideal): ...",   # SensorProfile.describe()
        "inputs": [{"role": "map", "name": "junction.xodr", "path": "maps/junction.xodr", "sha256": "..."}],
        "params": {"frames": "None", "...": "..."}   # every option as text
      },
      "scenarios": [                 # one per map x fusion x interpolation x d_s x boundary
        {
          "map": "Town04",           # map name (file stem)
          "fusion": "spline",        # "local" (ego only, the paper's l_ego) | "convoy" | "spline"
          "interpolation": "paper",  # interpolation variant of the spline ("" when not used)
          "d_s": 20.0,               # interpolation distance (m); 0 for local and convoy
          "boundary": "left",        # "left" | "right" lane border, seen in driving direction
          "points": 12345,           # error samples pooled over all fused frames
          "mean_error_m": 0.02,      # mean closest-point distance to GT (the paper's "MSE", eq. 1)
          "rmse_m": 0.05,            # root mean square of the same distances
          "max_error_m": 0.6,        # largest distance over the run
          "p95_error_m": 0.1,        # 95th percentile (linear interpolation) of the distances
          "mean_frame_max_error_m": 0.11,  # per-frame maximum, averaged over fused frames
          "perception_range_m": 80.0,      # mean length of the evaluated lane over fused frames,
                                           # a frame without an ego lane counted once as 0
          "frames": 300,             # evaluations: frames x vehicle pairs
          "fused_frames": 280,       # evaluations that produced a lane
          "rejected": {"no_overlap": 20},  # reason -> count of evaluations without a lane
          "gt_unmatched": {"past_gt_end": 3},  # only when any: why the GT did not cover a lane, or "map_broken"
          "runtime_ms": {"mean": 3.6, "std": 0.7, "max": 6.6},  # fusion runtime per evaluation
          "fusibility": {"precision": 0.98, "recall": 1.0,     # fusibility check vs GT
                         "recall_detected": 1.0,  # recall over the true pairs whose detections as made
                                                  # admit the paper's rule (docs/metrics.md); null: unknown
                         "fused": {"own": 250, "branch": 12},   # true fusions: ego's route / a branch
                         "false": {"adjacent": 2},              # false fusions by kind of pair
                         "by_confidence": [{"threshold": 0.5, "precision": 0.99, "recall": 0.97}]},
          "by_route": {"own_route": {"fused": 250, "mean_error_m": 0.01, "max_error_m": 0.2, "p95_error_m": 0.05},
                       "branch": {"fused": 12, "mean_error_m": 0.3, "max_error_m": 1.9, "p95_error_m": 1.2}},
                                     # only when its fusions carry the kind of pair: the errors of the
                                     # true fusions on the ego's own route and on another branch
          # only in runs with --coops > 1, --history or --exchange (absent otherwise):
          "vehicles": 3,             # vehicles fused: 1 local, 2 a pair, more a chain
          "history_m": 100.0,        # lane history the coops send (m)
          "exchange": "bezier",      # "sampled" | "bezier" | "" (detections fused directly)
          "bytes_per_message": 136.0,  # mean bytes on air per message of the scenario's coops
          "bytes_per_second": 340.0,   # their bytes on air per vehicle-second
          "correct_only": {"mean_error_m": 0.02, "max_error_m": 0.3, "p95_error_m": 0.1},
                                     # the same over fusions whose partner truly continues the ego's lane
          # always (added in the same schema version; a reader takes a file without them):
          "perception_range_distribution_m": {"mean": 80.0, "p5": 70.1, "p50": 80.0, "p95": 83.1},
                                     # the range over fused evaluations and frames without an ego
                                     # lane (0): mean and percentiles (linear)
          "by_distance": {"split_m": 40.0,   # errors of the points near (<= 40 m along the border from
                          "near": {"points": 400, "mean_error_m": 0.01, "max_error_m": 0.1, "p95_error_m": 0.02},
                          "far": {"points": 0, "mean_error_m": null, "max_error_m": null, "p95_error_m": null}},
                                     # the ego) and far (beyond), as OpenLane splits them; null: no point
          "stopping": {"distance_m": 43.7,   # d = 1.1 (v t_r + v^2 / (2 a)); null when not measured
                       "speed_mps": 10.0, "reaction_time_s": 2.5, "deceleration_mps2": 3.4,
                       "accuracy_m": 0.75,   # the paper's sufficient accuracy
                       "frames": 300,        # distinct frames evaluated
                       "known_frames": 290,  # frames with an evaluation's lane known within accuracy_m out to d
                       "share": 0.967},      # known_frames / frames (null without frames)
          "end_reasons": {"range": 300},     # why the ego's own detections ended (local scenarios; {} elsewhere)
          # only when the lanes evaluated state their σ (fusion.FusionResult.left_sigma):
          "calibration": {"points": 12000, "within_1sigma": 0.69, "within_2sigma": 0.95,
                          "mean_sigma_m": 0.08, "mean_error_m": 0.06},
                                     # share of points whose error is within 1σ / 2σ of their stated σ
                                     # (68 % / 95 % when calibrated), mean stated σ beside the mean error
          "calibration_correct": {"points": 11500, "within_1sigma": 0.70, "within_2sigma": 0.96,
                                  "mean_sigma_m": 0.08, "mean_error_m": 0.05}
                                     # the same over the correct fusions alone (truly fusible pairs);
                                     # beside "calibration" in fusion scenarios; points 0 and nulls
                                     # when no correct fusion states σ
        }
      ]
    }

The kinds of pairs are ``cold_maps.simulation.drive.RELATION_KINDS``; ``by_confidence`` counts
a decision as fusible only when its association confidence reaches the threshold
(:data:`CONFIDENCE_THRESHOLDS`); ``by_route`` pools the errors of the true fusions by where the
coop drives (:data:`ROUTE_GROUPS`). Errors are pooled point distances (not averages of
per-frame averages). A value that does not exist (no fused frame, no runtime measured, no
fusibility decision) is ``null``. ``by_distance``, ``stopping`` and ``end_reasons`` are
defined in docs/metrics.md (``evaluation.safety``, ``gt_matching.metrics``).
Every file is written to a temporary name and renamed, so none is ever half-written.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import json
import math
import operator
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Final, Iterable, Iterator, Literal, Mapping, Sequence

import numpy as np

from cold_maps.common.memory import release_free_heap
from cold_maps.evaluation.safety import (
    LANE_ACCURACY_M,
    STOPPING_FORMULA,
    StoppingDistance,
    StoppingError,
    StoppingRule,
)
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.common.provenance import Provenance
from converters.atomic_io import atomic_output
from cold_maps.evaluation.columns import (from_lists, from_numpy, from_values, nulls, repeated_string, to_numpy,
                                         to_strings)
from cold_maps.evaluation.records import PointPool, RecordStore, Spool, list_values, pools
from gt_matching.metrics import NEAR_FAR_SPLIT_M, P95, Calibration, ErrorStats

if TYPE_CHECKING:
    import pyarrow as pa

Fusion = Literal["local", "convoy", "spline"]
Boundary = Literal["left", "right"]
RoadType = Literal["straight", "right_curve_90", "rural"]
FUSIONS: Final[tuple[str, ...]] = ("local", "convoy", "spline")
BOUNDARIES: Final[tuple[str, ...]] = ("left", "right")
METRICS_SCHEMA_VERSION: Final[int] = 1
P95_PERCENT: Final[float] = 95.0
CONFIDENCE_THRESHOLDS: Final[tuple[float, ...]] = (0.0, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95, 1.0)
"""Association confidences at which summary.md and metrics.json give a precision-recall point."""
ROUTE_GROUPS: Final[Mapping[str, str]] = {"own_route": "own", "branch": "branch"}
"""``by_route`` group → the relation kind of the true fusions it pools (the coop's lane on the
ego's own route, or on another branch of a fork inside the gap)."""

# The paper's results (cold-fusion-paper.tex, sec. IV "Results"). Table II: per road type and
# method, (mean error m, max error m) for the left and right border. The paper's "MSE" is
# its eq. 1, the mean of |P_s - P_GT|, i.e. our mean_error_m. Methods: "local" = l_ego,
# "convoy" / "spline" = l_coll. The spline column used d_s = 30 m on the straight lane and
# d_s = 20 m on the 90° curve and the rural road (sec. IV-B text).
PAPER_TABLE_II: Final[Mapping[tuple[str, str], Mapping[str, tuple[float, float]]]] = {
    ("straight", "local"): {"left": (0.005, 0.010), "right": (0.005, 0.011)},
    ("straight", "convoy"): {"left": (0.005, 0.010), "right": (0.005, 0.011)},
    ("straight", "spline"): {"left": (0.005, 0.027), "right": (0.005, 0.028)},
    ("right_curve_90", "local"): {"left": (0.005, 0.010), "right": (0.005, 0.011)},
    ("right_curve_90", "convoy"): {"left": (0.005, 0.010), "right": (0.005, 0.011)},
    ("right_curve_90", "spline"): {"left": (0.029, 0.693), "right": (0.030, 0.707)},
    ("rural", "local"): {"left": (0.005, 0.010), "right": (0.005, 0.010)},
    ("rural", "convoy"): {"left": (0.005, 0.010), "right": (0.005, 0.010)},
    ("rural", "spline"): {"left": (0.023, 0.560), "right": (0.020, 0.572)},
}
PAPER_SPLINE_D_S_M: Final[Mapping[str, float]] = {"straight": 30.0, "right_curve_90": 20.0, "rural": 20.0}
# Spline errors the text quotes for other gaps, (mean, max) per border, NaN = not given:
# "even for higher interpolation distances up to 50 m the maximum deviation ... was about 0.05 m".
PAPER_SPLINE_TEXT: Final[Mapping[tuple[str, float], tuple[float, float]]] = {("straight", 50.0): (math.nan, 0.05)}
# Perception range (m): Table II's last row for local and convoy; for the spline the text's
# figure per gap ("80 m" at d_s = 20, "90 m" at 30, "110 m" at 50), i.e. 2 r_lane + d_s.
PAPER_PERCEPTION_RANGE_M: Final[Mapping[str, float]] = {"local": 30.0, "convoy": 55.0}
PAPER_SPLINE_RANGE_M: Final[Mapping[float, float]] = {20.0: 80.0, 30.0: 90.0, 50.0: 110.0}
# Table I: fusion runtime (ms) on the rural road, 300 frames: (mean, σ, max).
PAPER_TABLE_I_MS: Final[Mapping[str, tuple[float, float, float]]] = {
    "convoy": (2.23, 0.42, 3.66), "spline": (3.62, 0.70, 6.62)}

FRAMES_CSV_COLUMNS: Final[tuple[str, ...]] = (
    "map", "fusion", "interpolation", "d_s", "boundary", "frame", "stamp_s", "ego", "coop", "fused",
    "rejected", "points", "mean_error_m", "max_error_m", "perception_range_m", "runtime_ms",
    "predicted_fusible", "truly_fusible", "relation", "confidence",
    "end_reason", "near_points", "near_max_error_m", "far_max_error_m", "known_to_m", "stopping_distance_m",
    "detected_fusible")
RANGE_PERCENTS: Final[tuple[float, ...]] = (5.0, 50.0, 95.0)
"""Percentiles (linear interpolation) of the perception range over fused evaluations and
the frames without an ego lane (:data:`NO_EGO_LANE`)."""
NO_EGO_LANE: Final[frozenset[str]] = frozenset({"ego_not_seen", "ego_dropped"})
"""Rejections of a frame in which the ego had no lane of its own (its sensor saw none, or an
error model dropped it): no scenario can report a lane then, so the frame counts once with
range 0 m in the scenario's perception range (``perception_range_m`` and its distribution)."""


class ReportError(ValueError):
    """A report that cannot be built, written or read; the message names the thing."""


def _finite_or_none(value: float) -> float | None:
    return None if value is None or not math.isfinite(value) else float(value)


def _none_to_nan(value: Any, where: str) -> float:
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ReportError(f"{where}: expected a number or null, got {value!r}")
    return float(value)


def scenario_label(fusion: str, interpolation: str, d_s: float, vehicles: int) -> str:
    """``local``, ``convoy`` or ``spline-<interpolation>-d<d_s>``, ``-v<vehicles>`` for a chain
    (the name of a scenario in plots, overlays and metrics channels)."""
    base = fusion if fusion != "spline" else f"spline-{interpolation}-d{d_s:g}"
    return base if vehicles <= 2 else f"{base}-v{vehicles}"


@dataclass(frozen=True, slots=True)
class ScenarioKey:
    """What a scenario evaluates.

    Fields:
        map: map name (usually the file stem).
        fusion: "local" (ego only), "convoy" or "spline".
        interpolation: spline interpolation variant ("" when not used).
        d_s: interpolation distance (m), 0 when not used.
        boundary: "left" or "right" border in driving direction.
        vehicles: vehicles fused (1 local, 2 a pair, more a chain); 0 when the run uses
            neither chains, history nor messages (the record then leaves out the fields of
            :data:`EXTENDED_KEYS`).
        history_m: lane history the coops send (m).
        exchange: "sampled" or "bezier" when lanes travel as messages, "" otherwise.
    """

    map: str
    fusion: str
    interpolation: str
    d_s: float
    boundary: str
    vehicles: int = 0
    history_m: float = 0.0
    exchange: str = ""

    @property
    def label(self) -> str:
        """The scenario's name (:func:`scenario_label`)."""
        return scenario_label(self.fusion, self.interpolation, self.d_s, self.vehicles)

    def __post_init__(self) -> None:
        if self.fusion not in FUSIONS:
            raise ReportError(f"fusion: expected one of {FUSIONS}, got {self.fusion!r}")
        if self.boundary not in BOUNDARIES:
            raise ReportError(f"boundary: expected one of {BOUNDARIES}, got {self.boundary!r}")
        if not isinstance(self.d_s, (int, float)) or not math.isfinite(self.d_s) or self.d_s < 0:
            raise ReportError(f"d_s: expected a finite distance >= 0 m, got {self.d_s!r}")


@dataclass(frozen=True, slots=True)
class FrameRecord:
    """One evaluation: one frame, one vehicle pair, one scenario.

    Fields:
        frame: frame index.
        stamp_s: frame time (s).
        ego, coop: vehicle ids ("" for coop when the fusion is local).
        errors_m: closest-point distances (m) of the evaluated lane's points to the GT;
            empty when no lane was produced.
        perception_range_m: length of the evaluated lane (m), NaN when none.
        runtime_ms: fusion runtime (ms), NaN when not measured.
        rejected: why no lane was produced ("" when one was).
        predicted_fusible: the fusibility check's decision, None when not applicable.
        truly_fusible: whether the pair is fusible by the ground truth, None when unknown.
        gt_unmatched: why the GT did not cover the lane when ``rejected`` is "gt_unmatched"
            ("off_lane", "past_gt_end"; see ``groundtruth.meter``), else "".
        relation: kind of pair (``cold_maps.simulation.drive.RELATION_KINDS``), "" when unknown.
        confidence: the association confidence in [0, 1] of a fused pair (0 rejected), NaN
            when not applicable.
        end_reason: why the ego's own detection ended (``range``, ``map_end``; a camera
            sensor adds ``field_of_view``, ``crest``, ``occlusion``, ``unmarked``:
            ``simulation.camera.END_REASONS``); "" when
            unknown or not a local evaluation.
        near_points: how many leading ``errors_m`` lie within ``NEAR_FAR_SPLIT_M`` of the
            ego along the border (the rest are far); None when the distances are unknown
            (the points then count in neither split).
        known_to_m: how far from the ego both borders of the lane are known within
            ``LANE_ACCURACY_M`` (m, ``gt_matching.metrics.known_distance_m``, the smaller
            of the two; the same on both borders' records); NaN when no lane was scored.
        stopping: the stopping distance the lane is needed to (``evaluation.safety``), None
            when not measured.
        sigma_m: the stated lateral 1σ (m) of the point of each of ``errors_m``, same shape;
            None when the lane states no σ.
        detected_fusible: whether the pair is truly fusible and the two detections as the
            sensors made them admit the paper's rule (they overlap for convoy, leave a gap
            0 < d_s <= d_i for the spline; ``evaluator.MapEvaluator._detected``), None when
            unknown (a detection missing, a lane history or exchange).
    """

    frame: int
    stamp_s: float
    ego: str
    coop: str
    errors_m: NDArrayFloat
    perception_range_m: float = math.nan
    runtime_ms: float = math.nan
    rejected: str = ""
    predicted_fusible: bool | None = None
    truly_fusible: bool | None = None
    gt_unmatched: str = ""
    relation: str = ""
    confidence: float = math.nan
    end_reason: str = ""
    near_points: int | None = None
    known_to_m: float = math.nan
    stopping: StoppingDistance | None = None
    sigma_m: NDArrayFloat | None = None
    detected_fusible: bool | None = None

    def __post_init__(self) -> None:
        if self.sigma_m is not None:
            sigma = np.asarray(self.sigma_m, dtype=np.float64)
            if sigma.shape != np.shape(self.errors_m) or sigma.size and not (sigma.min() >= 0.0
                                                                             and sigma.max() < math.inf):
                raise ReportError(f"frame {self.frame}: sigma_m must be finite σ >= 0, one per error sample")
            object.__setattr__(self, "sigma_m", sigma)
        errors = np.asarray(self.errors_m, dtype=np.float64)
        # min >= 0 and max < inf: every distance finite and >= 0 (a NaN fails the first)
        if errors.ndim != 1 or errors.size and not (errors.min() >= 0.0 and errors.max() < math.inf):
            raise ReportError(f"frame {self.frame}: errors_m must be a 1-D array of finite distances >= 0")
        if errors.size and self.rejected:
            raise ReportError(f"frame {self.frame}: an evaluation with a lane cannot be rejected ({self.rejected!r})")
        if self.near_points is not None and not 0 <= self.near_points <= errors.size:
            raise ReportError(f"frame {self.frame}: near_points {self.near_points} outside 0 ... {errors.size}")
        if not (math.isnan(self.known_to_m) or 0.0 <= self.known_to_m < math.inf):
            raise ReportError(f"frame {self.frame}: known_to_m must be a distance >= 0 m or NaN, got {self.known_to_m}")
        object.__setattr__(self, "errors_m", errors)

    @classmethod
    def trusted(cls, frame: int, stamp_s: float, ego: str, coop: str, errors_m: NDArrayFloat,
                **fields: Any) -> FrameRecord:
        """The record of values already valid (``errors_m`` and ``sigma_m`` float64 arrays,
        the distances finite and >= 0 and the σ of the same shape, ``near_points`` and
        ``known_to_m`` in range, no ``rejected`` with errors; optional fields by keyword):
        equal to the constructor's, without its checks and conversions."""
        values = _RECORD_DEFAULTS | fields
        if len(values) != len(_RECORD_DEFAULTS):
            raise TypeError(f"FrameRecord.trusted: unknown fields {sorted(set(fields) - set(_RECORD_DEFAULTS))}")
        record = object.__new__(cls)
        for put, value in zip(_RECORD_SETTERS, (frame, stamp_s, ego, coop, errors_m, *values.values())):
            put(record, value)
        return record

    @property
    def fused(self) -> bool:
        """Whether this evaluation produced a lane (it has error samples)."""
        return len(self.errors_m) > 0

    @property
    def known_to_stop(self) -> bool:
        """Whether the lane is known within ``LANE_ACCURACY_M`` out to the stopping distance."""
        return self.stopping is not None and self.known_to_m >= self.stopping.distance_m

    def split_errors(self) -> tuple[NDArrayFloat, NDArrayFloat]:
        """(near, far) errors (m); both empty when ``near_points`` is None."""
        if self.near_points is None:
            return np.empty(0), np.empty(0)
        return self.errors_m[:self.near_points], self.errors_m[self.near_points:]


_RECORD_DEFAULTS: Final[dict[str, Any]] = {field.name: field.default for field in dataclasses.fields(FrameRecord)
                                           if field.default is not dataclasses.MISSING}
"""The optional fields of a :class:`FrameRecord` and their defaults (:meth:`FrameRecord.trusted`)."""
_RECORD_SETTERS: Final[tuple[Callable[[FrameRecord, Any], None], ...]] = tuple(
    getattr(FrameRecord, field.name).__set__ for field in dataclasses.fields(FrameRecord))
"""The slot setter of each field of a :class:`FrameRecord`, in field order (the optional
fields in the order of ``_RECORD_DEFAULTS``)."""


@dataclass(frozen=True, slots=True)
class RuntimeStats:
    """Runtime over a scenario's evaluations (ms): mean, sample standard deviation, max."""

    mean: float
    std: float
    max: float


@dataclass(frozen=True, slots=True)
class RouteErrors:
    """Errors of the true fusions of one :data:`ROUTE_GROUPS` group.

    Fields: ``fused`` their count; ``mean_error_m``, ``max_error_m``, ``p95_error_m`` the
    pooled closest-point distances (m; NaN without a fusion).
    """

    fused: int
    mean_error_m: float
    max_error_m: float
    p95_error_m: float

    @classmethod
    def of_pool(cls, fused: int, errors: PointPool) -> RouteErrors:
        """The statistics over the pooled errors of ``fused`` fusions."""
        return cls(fused, errors.mean(), errors.max(), errors.percentile(P95_PERCENT))


@dataclass(frozen=True, slots=True)
class ScenarioResult:
    """Aggregated result of one scenario; the fields of one ``metrics.json`` record.

    Fields:
        key: the scenario (map, fusion, interpolation, d_s, boundary).
        points: error samples pooled over all fused evaluations.
        mean_error_m, rmse_m, max_error_m, p95_error_m: statistics of the pooled
            closest-point distances (m); NaN without samples.
        mean_frame_max_error_m: per-evaluation maximum error averaged over fused ones (m).
        perception_range_m: mean evaluated lane length over fused evaluations and, as 0,
            the frames without an ego lane (:data:`NO_EGO_LANE`) (m).
        frames: evaluations (frames x vehicle pairs).
        fused_frames: evaluations that produced a lane.
        rejected: (reason, count) of evaluations without a lane, sorted by reason.
        runtime_ms: fusion runtime statistics (ms).
        fusibility_precision, fusibility_recall: the fusibility check against the GT;
            NaN when undefined.
        fusibility_recall_detected: the recall over the pairs truly fusible whose detections
            as made admit the paper's rule (:attr:`FrameRecord.detected_fusible`); NaN when
            undefined.
        correct_mean_error_m, correct_max_error_m, correct_p95_error_m: the same statistics
            over the fusions whose partner truly continues the ego's lane (m; NaN without, and
            when ``key.vehicles`` is 0: the record leaves them out).
        bytes_per_message: mean bytes on air per lane message of the scenario's coops.
        bytes_per_second: their bytes on air per vehicle-second.
        gt_unmatched: (reason, count) of the evaluations rejected as "gt_unmatched".
        fused_by_relation: (kind, count) of the true fusions (``own``, ``branch``).
        false_by_relation: (kind, count) of the false fusions (``adjacent``, ``opposite``,
            ``other_branch``, ``behind``, ``other``).
        by_confidence: (threshold, precision, recall) per :data:`CONFIDENCE_THRESHOLDS`
            (NaN when undefined); empty when no decision carries a confidence.
        by_route: (group, :class:`RouteErrors`) per :data:`ROUTE_GROUPS` group; empty when
            no fusion of the scenario carries the kind of its pair.
        range_percentiles_m: the perception range's percentiles :data:`RANGE_PERCENTS`
            over fused evaluations (m; NaN without).
        near, far: the pooled errors of the points within / beyond ``NEAR_FAR_SPLIT_M`` of
            the ego along the border (``gt_matching.metrics.ErrorStats``, m).
        stopping: the stopping distance the records were scored against, None when none was.
        stopping_frames: distinct frames evaluated with a stopping distance.
        stopping_known_frames: those in which an evaluation's lane was known within
            ``LANE_ACCURACY_M`` out to the stopping distance (:attr:`FrameRecord.known_to_stop`).
        end_reasons: (reason, count) of why the ego's own detections ended, sorted by reason.
        calibration: the errors of the fused points that state a σ against it
            (:class:`gt_matching.metrics.Calibration`), None when none does.
        calibration_correct: the same over the correct fusions alone (records truly
            fusible), None without ``calibration`` or when no record knows its truth (local
            scenarios); no points (NaN shares) when no correct fusion states σ.
    """

    key: ScenarioKey
    points: int
    mean_error_m: float
    rmse_m: float
    max_error_m: float
    p95_error_m: float
    mean_frame_max_error_m: float
    perception_range_m: float
    frames: int
    fused_frames: int
    rejected: tuple[tuple[str, int], ...]
    runtime_ms: RuntimeStats
    fusibility_precision: float
    fusibility_recall: float
    correct_mean_error_m: float = math.nan
    correct_max_error_m: float = math.nan
    correct_p95_error_m: float = math.nan
    bytes_per_message: float = math.nan
    bytes_per_second: float = math.nan
    gt_unmatched: tuple[tuple[str, int], ...] = ()
    fused_by_relation: tuple[tuple[str, int], ...] = ()
    false_by_relation: tuple[tuple[str, int], ...] = ()
    by_confidence: tuple[tuple[float, float, float], ...] = ()
    by_route: tuple[tuple[str, RouteErrors], ...] = ()
    range_percentiles_m: tuple[float, ...] = (math.nan,) * len(RANGE_PERCENTS)
    near: ErrorStats = ErrorStats(0, math.nan, math.nan, math.nan)
    far: ErrorStats = ErrorStats(0, math.nan, math.nan, math.nan)
    stopping: StoppingDistance | None = None
    stopping_frames: int = 0
    stopping_known_frames: int = 0
    end_reasons: tuple[tuple[str, int], ...] = ()
    calibration: Calibration | None = None
    calibration_correct: Calibration | None = None
    fusibility_recall_detected: float = math.nan

    @property
    def stopping_share(self) -> float:
        """Share of :attr:`stopping_frames` with the lane known to the stopping distance
        (NaN without such frames)."""
        return _ratio(self.stopping_known_frames, self.stopping_frames)

    def to_dict(self) -> dict[str, Any]:
        """The ``metrics.json`` record (NaN as null); the :data:`EXTENDED_KEYS` only when
        ``key.vehicles`` is recorded (> 0)."""
        f = _finite_or_none
        extended = {} if self.key.vehicles <= 0 else {
            "vehicles": self.key.vehicles, "history_m": self.key.history_m, "exchange": self.key.exchange,
            "bytes_per_message": f(self.bytes_per_message), "bytes_per_second": f(self.bytes_per_second),
            "correct_only": {"mean_error_m": f(self.correct_mean_error_m), "max_error_m": f(self.correct_max_error_m),
                             "p95_error_m": f(self.correct_p95_error_m)}}
        return {
            "map": self.key.map, "fusion": self.key.fusion, "interpolation": self.key.interpolation,
            "d_s": self.key.d_s, "boundary": self.key.boundary, "points": self.points,
            "mean_error_m": f(self.mean_error_m), "rmse_m": f(self.rmse_m), "max_error_m": f(self.max_error_m),
            "p95_error_m": f(self.p95_error_m), "mean_frame_max_error_m": f(self.mean_frame_max_error_m),
            "perception_range_m": f(self.perception_range_m), "frames": self.frames,
            "fused_frames": self.fused_frames, "rejected": dict(self.rejected),
            "runtime_ms": {"mean": f(self.runtime_ms.mean), "std": f(self.runtime_ms.std),
                           "max": f(self.runtime_ms.max)},
            "fusibility": {"precision": f(self.fusibility_precision), "recall": f(self.fusibility_recall),
                           "recall_detected": f(self.fusibility_recall_detected),
                           "fused": dict(self.fused_by_relation), "false": dict(self.false_by_relation),
                           "by_confidence": [{"threshold": t, "precision": f(p), "recall": f(r)}
                                             for t, p, r in self.by_confidence]},
        } | extended | ({"gt_unmatched": dict(self.gt_unmatched)} if self.gt_unmatched else {}) | (
            {"by_route": {group: {"fused": e.fused, "mean_error_m": f(e.mean_error_m), "max_error_m": f(e.max_error_m),
                                  "p95_error_m": f(e.p95_error_m)} for group, e in self.by_route}}
            if self.by_route else {}) | self._added_dict() | {
                name: {"points": c.points, "within_1sigma": f(c.within_1sigma), "within_2sigma": f(c.within_2sigma),
                       "mean_sigma_m": f(c.mean_sigma_m), "mean_error_m": f(c.mean_error_m)}
                for name, c in (("calibration", self.calibration), ("calibration_correct", self.calibration_correct))
                if c is not None}

    def _added_dict(self) -> dict[str, Any]:
        """The keys of the range distribution, the near / far errors, the stopping distance
        and the detection ends (see the module docstring)."""
        f = _finite_or_none
        stats = {name: {"points": e.points, "mean_error_m": f(e.mean_error_m), "max_error_m": f(e.max_error_m),
                        "p95_error_m": f(e.p95_error_m)} for name, e in (("near", self.near), ("far", self.far))}
        stop = self.stopping
        return {
            "perception_range_distribution_m": {"mean": f(self.perception_range_m)} | {
                f"p{q:g}": f(v) for q, v in zip(RANGE_PERCENTS, self.range_percentiles_m)},
            "by_distance": {"split_m": NEAR_FAR_SPLIT_M} | stats,
            "stopping": None if stop is None else {
                "distance_m": stop.distance_m, "speed_mps": stop.speed_mps,
                "reaction_time_s": stop.rule.reaction_time_s, "deceleration_mps2": stop.rule.deceleration_mps2,
                "accuracy_m": LANE_ACCURACY_M, "frames": self.stopping_frames,
                "known_frames": self.stopping_known_frames, "share": f(self.stopping_share)},
            "end_reasons": dict(self.end_reasons),
        }

    @staticmethod
    def _added_fields(record: Mapping[str, Any], where: str) -> dict[str, Any]:
        """The fields :meth:`_added_dict` wrote (their defaults when a file predates them)."""
        distribution = record.get("perception_range_distribution_m", {})
        by_distance = record.get("by_distance", {})
        split = {name: ErrorStats(int(by_distance[name]["points"]), *(
            _none_to_nan(by_distance[name][stat], f"{where}.by_distance.{name}.{stat}")
            for stat in ("mean_error_m", "max_error_m", "p95_error_m")))
            for name in ("near", "far") if name in by_distance}
        stop = record.get("stopping")
        try:
            stopping = None if stop is None else StoppingRule(
                float(stop["reaction_time_s"]), float(stop["deceleration_mps2"])).at(float(stop["speed_mps"]))
        except StoppingError as exc:
            raise ReportError(f"{where}.stopping: {exc}") from exc
        return split | {
            "range_percentiles_m": tuple(_none_to_nan(distribution.get(f"p{q:g}"), f"{where}.perception_range_"
                                                      f"distribution_m.p{q:g}") for q in RANGE_PERCENTS),
            "stopping": stopping,
            "stopping_frames": 0 if stop is None else int(stop["frames"]),
            "stopping_known_frames": 0 if stop is None else int(stop["known_frames"]),
            "end_reasons": tuple(sorted((str(k), int(v)) for k, v in record.get("end_reasons", {}).items())),
        }

    @classmethod
    def from_dict(cls, record: Mapping[str, Any], where: str = "scenario") -> ScenarioResult:
        """The inverse of :meth:`to_dict`; ReportError naming ``where`` and the key otherwise."""
        try:
            d_s = _none_to_nan(record["d_s"], f"{where}.d_s")
            try:
                key = ScenarioKey(str(record["map"]), str(record["fusion"]), str(record["interpolation"]), d_s,
                                  str(record["boundary"]), int(record.get("vehicles", 0)),
                                  _none_to_nan(record.get("history_m", 0.0), f"{where}.history_m"),
                                  str(record.get("exchange", "")))
            except ReportError as exc:
                raise ReportError(f"{where}: {exc}") from exc
            num = {name: _none_to_nan(record[name], f"{where}.{name}") for name in (
                "mean_error_m", "rmse_m", "max_error_m", "p95_error_m", "mean_frame_max_error_m",
                "perception_range_m")}
            runtime = RuntimeStats(*(_none_to_nan(record["runtime_ms"][k], f"{where}.runtime_ms.{k}")
                                     for k in ("mean", "std", "max")))
            rejected = tuple(sorted((str(k), int(v)) for k, v in record["rejected"].items()))
            correct = record.get("correct_only", {})
            for name in ("mean_error_m", "max_error_m", "p95_error_m"):
                num[f"correct_{name}"] = _none_to_nan(correct.get(name), f"{where}.correct_only.{name}")
            for name in ("bytes_per_message", "bytes_per_second"):
                num[name] = _none_to_nan(record.get(name), f"{where}.{name}")
            gt_unmatched = tuple(sorted((str(k), int(v)) for k, v in record.get("gt_unmatched", {}).items()))
            fusibility = record["fusibility"]
            counts = {name: tuple(sorted((str(k), int(v)) for k, v in fusibility.get(name, {}).items()))
                      for name in ("fused", "false")}
            points = tuple((float(point["threshold"]),
                            _none_to_nan(point["precision"], f"{where}.fusibility.by_confidence"),
                            _none_to_nan(point["recall"], f"{where}.fusibility.by_confidence"))
                           for point in fusibility.get("by_confidence", []))
            by_route = tuple((str(group), RouteErrors(int(errors["fused"]), *(
                _none_to_nan(errors[name], f"{where}.by_route.{group}.{name}")
                for name in ("mean_error_m", "max_error_m", "p95_error_m"))))
                for group, errors in record.get("by_route", {}).items())
            calibration = {name: Calibration(int(record[name]["points"]), *(
                _none_to_nan(record[name][field], f"{where}.{name}.{field}")
                for field in ("within_1sigma", "within_2sigma", "mean_sigma_m", "mean_error_m")))
                for name in ("calibration", "calibration_correct") if name in record}
            return cls(key=key, points=int(record["points"]), frames=int(record["frames"]),
                       fused_frames=int(record["fused_frames"]), rejected=rejected, gt_unmatched=gt_unmatched,
                       runtime_ms=runtime,
                       fusibility_precision=_none_to_nan(record["fusibility"]["precision"], f"{where}.fusibility"),
                       fusibility_recall=_none_to_nan(record["fusibility"]["recall"], f"{where}.fusibility"),
                       fusibility_recall_detected=_none_to_nan(record["fusibility"].get("recall_detected"),
                                                               f"{where}.fusibility"),
                       fused_by_relation=counts["fused"], false_by_relation=counts["false"], by_confidence=points,
                       by_route=by_route, **calibration, **num, **cls._added_fields(record, where))
        except ReportError:
            raise
        except KeyError as exc:
            raise ReportError(f"{where}: missing key {exc.args[0]!r}") from exc
        except (TypeError, AttributeError, ValueError) as exc:
            raise ReportError(f"{where}: malformed record: {exc}") from exc


def record_schema() -> pa.Schema:
    """The columns of a segment: the fields of a ``FrameRecord`` (the stopping distance as its
    speed and rule, null without one) and the per-record figures of ``frames.csv``
    (``mean_error_m``, ``max_error_m``, ``near_max_error_m``, ``far_max_error_m``; NaN
    where the CSV leaves them empty)."""
    import pyarrow as pa

    f64, text, flag = pa.float64(), pa.string(), pa.bool_()
    return pa.schema([
        ("frame", pa.int64()), ("stamp_s", f64), ("ego", text), ("coop", text), ("errors_m", pa.list_(f64)),
        ("perception_range_m", f64), ("runtime_ms", f64), ("rejected", text), ("predicted_fusible", flag),
        ("truly_fusible", flag), ("gt_unmatched", text), ("relation", text), ("confidence", f64),
        ("end_reason", text), ("near_points", pa.int64()), ("known_to_m", f64), ("stopping_speed_mps", f64),
        ("stopping_reaction_time_s", f64), ("stopping_deceleration_mps2", f64), ("sigma_m", pa.list_(f64)),
        ("mean_error_m", f64), ("max_error_m", f64), ("near_max_error_m", f64), ("far_max_error_m", f64),
        ("detected_fusible", flag)])


def _record_figures(errors: list[NDArrayFloat], near_points: Sequence[int | None]) -> tuple[NDArrayFloat, ...]:
    """(mean, max, near max, far max) error (m) of each record of ``errors`` (its ``errors_m``,
    finite) split at its ``near_points``, NaN where ``frames.csv`` is empty: the mean as
    ``np.mean`` computes it (the sum's ufunc reduction over the count) record by record, the
    maxima of all records in one segmented reduction (a maximum does not depend on the order)."""
    count = len(errors)
    sizes = np.fromiter(map(len, errors), dtype=np.int64, count=count)
    mean, most, near_max, far_max = (np.full(count, math.nan) for _ in range(4))
    fused = np.flatnonzero(sizes)
    if not fused.size:
        return mean, most, near_max, far_max
    mean[fused] = [float(np.add.reduce(errors[i])) / errors[i].size for i in fused.tolist()]
    # one element after the errors, so that every segment start indexes into the pool
    pool = np.concatenate([*(errors[i] for i in fused.tolist()), np.zeros(1)])
    starts = np.zeros(fused.size + 1, dtype=np.int64)
    np.cumsum(sizes[fused], out=starts[1:])
    largest = np.maximum.reduceat
    most[fused] = largest(pool, starts)[:-1]
    split = [near_points[i] for i in fused.tolist()]
    known = np.array([n is not None for n in split], dtype=bool)  # the records whose errors are split
    near = np.array([n or 0 for n in split], dtype=np.int64)
    bounds = np.empty(2 * fused.size + 1, dtype=np.int64)
    bounds[0::2], bounds[1::2] = starts, starts[:-1] + near  # near, far, near, far, ..., the pad
    halves = largest(pool, bounds)[:-1]
    near_max[fused] = np.where(known & (near > 0), halves[0::2], math.nan)
    far_max[fused] = np.where(known & (near < sizes[fused]), halves[1::2], math.nan)
    return mean, most, near_max, far_max


#: The :func:`record_schema` columns read straight off a :class:`FrameRecord`'s fields.
_PLAIN_COLUMNS: Final[tuple[str, ...]] = (
    "frame", "stamp_s", "ego", "coop", "perception_range_m", "runtime_ms", "rejected", "predicted_fusible",
    "truly_fusible", "gt_unmatched", "relation", "confidence", "end_reason", "near_points", "known_to_m",
    "detected_fusible")


def records_to_batch(records: Sequence[FrameRecord]) -> pa.RecordBatch:
    """The records as one batch of :func:`record_schema`."""
    import pyarrow as pa

    plain = dict(zip(_PLAIN_COLUMNS, zip(*map(operator.attrgetter(*_PLAIN_COLUMNS), records))
                     if records else [()] * len(_PLAIN_COLUMNS)))
    stop = [r.stopping for r in records]
    errors = [r.errors_m for r in records]
    figures = _record_figures(errors, plain["near_points"])
    columns: dict[str, Any] = {
        **plain, "errors_m": from_lists(errors), "sigma_m": from_lists([r.sigma_m for r in records]),
        "stopping_speed_mps": [None if s is None else s.speed_mps for s in stop],
        "stopping_reaction_time_s": [None if s is None else s.rule.reaction_time_s for s in stop],
        "stopping_deceleration_mps2": [None if s is None else s.rule.deceleration_mps2 for s in stop],
        **{name: from_numpy(values, pa.float64()) for name, values in zip(
            ("mean_error_m", "max_error_m", "near_max_error_m", "far_max_error_m"), figures)},
    }
    schema = record_schema()
    return pa.RecordBatch.from_arrays([columns[name] if isinstance(columns[name], pa.Array)
                                       else from_values(columns[name], schema.field(name).type)
                                       for name in schema.names], schema=schema)


def batch_records(batch: pa.RecordBatch) -> Iterator[FrameRecord]:
    """The :class:`FrameRecord` s of a batch of :func:`record_schema` (exact inverse of
    :func:`records_to_batch`)."""
    data = {name: batch.column(name).to_pylist() for name in batch.schema.names
            if name not in ("errors_m", "sigma_m")}
    errors, error_offsets = list_values(batch.column("errors_m"))
    sigmas, sigma_offsets = list_values(batch.column("sigma_m"))
    sigma_null = nulls(batch.column("sigma_m"))
    for i in range(batch.num_rows):
        speed = data["stopping_speed_mps"][i]
        yield FrameRecord(
            frame=data["frame"][i], stamp_s=data["stamp_s"][i], ego=data["ego"][i], coop=data["coop"][i],
            errors_m=errors[error_offsets[i]:error_offsets[i + 1]].copy(),
            perception_range_m=data["perception_range_m"][i], runtime_ms=data["runtime_ms"][i],
            rejected=data["rejected"][i], predicted_fusible=data["predicted_fusible"][i],
            truly_fusible=data["truly_fusible"][i], gt_unmatched=data["gt_unmatched"][i],
            relation=data["relation"][i], confidence=data["confidence"][i], end_reason=data["end_reason"][i],
            near_points=data["near_points"][i], known_to_m=data["known_to_m"][i],
            stopping=None if speed is None else StoppingRule(
                data["stopping_reaction_time_s"][i], data["stopping_deceleration_mps2"][i]).at(speed),
            sigma_m=None if sigma_null[i] else sigmas[sigma_offsets[i]:sigma_offsets[i + 1]].copy(),
            detected_fusible=data["detected_fusible"][i])



def _ratio(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def flags(column: Any) -> tuple[np.ndarray, np.ndarray]:
    """(known, value) boolean arrays of a nullable bool column."""
    return ~nulls(column), to_numpy(column, fill=False)


SCALAR_COLUMNS: Final[tuple[str, ...]] = (
    "frame", "perception_range_m", "runtime_ms", "rejected", "gt_unmatched", "relation", "confidence", "end_reason",
    "known_to_m", "stopping_speed_mps", "stopping_reaction_time_s", "stopping_deceleration_mps2", "max_error_m")
"""The per-record columns :meth:`ScenarioAccumulator.result` loads whole (one scenario's)."""
POINT_POOLS: Final[tuple[str, ...]] = ("all", "correct", "near", "far", "sigma_errors", "sigmas",
                                       "correct_sigma_errors", "correct_sigmas",
                                       *(f"route_{group}" for group in ROUTE_GROUPS))
"""The pooled point errors :meth:`ScenarioAccumulator.result` builds in one pass."""


class ScenarioAccumulator:
    """Collects the :class:`FrameRecord` s of one scenario (streamed to a
    :class:`~cold_maps.evaluation.records.RecordStore`) and aggregates them from its columns.

    Fields:
        key: the scenario.
        records: the evaluations added so far, in order (iterable, ``len``).
        messages: lane messages its senders sent.
        message_bytes: their bytes.
        sender_ns: time its senders were counted, integer ns (a sum independent of the
            order the frames are added in, so parallel runs give the same rates).
    """

    def __init__(self, key: ScenarioKey, records: Iterable[FrameRecord] = (), *, spool: Spool | None = None) -> None:
        self.key = key
        self.records = RecordStore(spool if spool is not None else Spool(), records_to_batch, batch_records)
        self.messages = 0
        self.message_bytes = 0
        self.sender_ns = 0
        for record in records:
            self.add(record)

    def add(self, record: FrameRecord) -> None:
        """Adds one evaluation."""
        self.records.add(record)

    def add_traffic(self, sent_bytes: int, seconds: float) -> None:
        """Counts one sender-frame of ``seconds`` (s) in which ``sent_bytes`` were sent (0: none)."""
        self.messages += sent_bytes > 0
        self.message_bytes += sent_bytes
        self.sender_ns += round(seconds * 1e9)

    def merge(self, later: ScenarioAccumulator) -> None:
        """Appends the records and the traffic of ``later`` (its segments adopted)."""
        self.records.extend(later.records)
        self.messages += later.messages
        self.message_bytes += later.message_bytes
        self.sender_ns += later.sender_ns

    def _scalars(self) -> dict[str, Any]:
        """The :data:`SCALAR_COLUMNS` of every record (numpy arrays, text as lists), the
        ``points`` per record, the (known, value) flags ``predicted``, ``truly`` and
        ``detected``."""
        parts: dict[str, list[Any]] = {name: [] for name in (*SCALAR_COLUMNS, "points", "predicted", "truly",
                                                              "detected")}
        for batch in self.records.batches((*SCALAR_COLUMNS, "errors_m", "predicted_fusible", "truly_fusible",
                                           "detected_fusible")):
            for name in SCALAR_COLUMNS:  # copies: a view would keep the whole segment (its points) in memory
                column = batch.column(name)
                parts[name].append(to_strings(column) if str(column.type) == "string" else to_numpy(column).copy())
            parts["points"].append(np.diff(list_values(batch.column("errors_m"))[1]))
            parts["predicted"].append(flags(batch.column("predicted_fusible")))
            parts["truly"].append(flags(batch.column("truly_fusible")))
            parts["detected"].append(flags(batch.column("detected_fusible")))
        out: dict[str, Any] = {}
        for name, chunks in parts.items():
            if name in ("predicted", "truly", "detected"):
                out[name] = tuple(np.concatenate([c[i] for c in chunks]) if chunks else np.empty(0, dtype=bool)
                                  for i in range(2))
            elif chunks and isinstance(chunks[0], list):
                out[name] = [value for chunk in chunks for value in chunk]
            else:
                out[name] = np.concatenate(chunks) if chunks else np.empty(0)
        return out

    def _pools(self, spool: Spool) -> tuple[dict[str, PointPool], dict[str, list[int]]]:
        """The :data:`POINT_POOLS` in one pass over the points, and how many σ-stating points
        lie within 1σ and 2σ: of all fused records (``"sigma"``) and of the correct fusions
        (``"correct_sigma"``, truly fusible)."""
        pooled = pools(spool, POINT_POOLS)
        within = {"sigma": [0, 0], "correct_sigma": [0, 0]}
        for batch in self.records.batches(("errors_m", "sigma_m", "near_points", "predicted_fusible",
                                           "truly_fusible", "relation")):
            values, offsets = list_values(batch.column("errors_m"))
            lengths = np.diff(offsets)
            start = offsets[:-1]
            fused = lengths > 0
            pooled["all"].append(values[offsets[0]:offsets[-1]])
            predicted_known, predicted = flags(batch.column("predicted_fusible"))
            truly_known, truly = flags(batch.column("truly_fusible"))
            relation = np.array(batch.column("relation").to_pylist(), dtype=object)

            def points(mask: np.ndarray) -> NDArrayFloat:
                chosen = np.repeat(mask, lengths)
                return values[offsets[0]:offsets[-1]][chosen]

            if self.key.vehicles > 0:
                pooled["correct"].append(points(fused & truly))
            pairs = fused & predicted & predicted_known & truly_known & truly & (relation != "")
            for group, kind in ROUTE_GROUPS.items():
                pooled[f"route_{group}"].append(points(pairs & (relation == kind)))
            near_column = batch.column("near_points")
            split = fused & ~nulls(near_column)
            near_points = to_numpy(near_column, fill=0)
            position = np.arange(offsets[-1] - offsets[0]) - np.repeat(start - offsets[0], lengths)
            near = np.repeat(split, lengths) & (position < np.repeat(near_points, lengths))
            far = np.repeat(split, lengths) & ~near
            pooled["near"].append(values[offsets[0]:offsets[-1]][near])
            pooled["far"].append(values[offsets[0]:offsets[-1]][far])
            sigma_column = batch.column("sigma_m")
            stated = fused & ~nulls(sigma_column)
            if stated.any():
                sigma_values, sigma_offsets = list_values(sigma_column)
                sigma_lengths = np.diff(sigma_offsets)
                for name, chosen in (("sigma", stated), ("correct_sigma", stated & truly)):
                    errors = points(chosen)
                    sigmas = sigma_values[sigma_offsets[0]:sigma_offsets[-1]][np.repeat(chosen, sigma_lengths)]
                    within[name][0] += int(np.count_nonzero(errors <= sigmas))
                    within[name][1] += int(np.count_nonzero(errors <= 2.0 * sigmas))
                    pooled[f"{name}_errors"].append(errors)
                    pooled[f"{name}s"].append(sigmas)
        return pooled, within

    def result(self) -> ScenarioResult:
        """The aggregate over all records (pooled distances, see the module docstring),
        computed from the store's columns: the per-record columns loaded whole, the points
        pooled with at most ``records.POOL_MEMORY_POINTS`` each in memory (:func:`scenario_results`
        hands their pages back to the system after all scenarios)."""
        spool = Spool()
        try:
            pooled, within = self._pools(spool)
            return self._result(self._scalars(), pooled, within)
        finally:
            for pool in pooled.values() if "pooled" in locals() else ():
                pool.close()
            spool.close()

    def _result(self, c: Mapping[str, Any], pooled: Mapping[str, PointPool],
                within: Mapping[str, list[int]]) -> ScenarioResult:
        nan = math.nan
        points, frame = c["points"], c["frame"]
        fused = points > 0
        count = len(points)
        rejected, relation = c["rejected"], np.array(c["relation"], dtype=object)
        no_ego = {int(f) for f, why in zip(frame.tolist(), rejected) if why in NO_EGO_LANE}
        ranges_fused = c["perception_range_m"][fused]
        ranges = np.concatenate((ranges_fused[np.isfinite(ranges_fused)], np.zeros(len(no_ego))))
        runtimes = c["runtime_ms"][np.isfinite(c["runtime_ms"])]
        predicted_known, predicted = c["predicted"]
        truly_known, truly = c["truly"]
        decided = predicted_known & truly_known
        true_positive = int(np.count_nonzero(decided & predicted & truly))
        detected_known, detected = c["detected"]
        detected = decided & detected_known & detected
        fused_pairs = predicted_known & predicted & truly_known & (relation != "")
        confidence = c["confidence"]
        scored = decided & (~predicted | np.isfinite(confidence))
        score = np.where(predicted, confidence, -math.inf)[scored]
        truth = truly[scored]
        by_confidence = tuple(
            (t, _ratio(int(np.count_nonzero((score >= t) & truth)), int(np.count_nonzero(score >= t))),
             _ratio(int(np.count_nonzero((score >= t) & truth)), int(np.count_nonzero(truth))))
            for t in CONFIDENCE_THRESHOLDS) if np.isfinite(confidence).any() else ()
        errors, right = pooled["all"], pooled["correct"]
        maxima = c["max_error_m"][fused]
        return ScenarioResult(
            **self._added_result(c, fused, pooled, ranges),
            key=self.key,
            points=errors.size,
            mean_error_m=errors.mean(),
            rmse_m=float(np.sqrt(errors.mean(np.square))) if errors.size else nan,
            max_error_m=errors.max(),
            p95_error_m=errors.percentile(P95_PERCENT),
            mean_frame_max_error_m=float(np.mean(maxima)) if maxima.size else nan,
            perception_range_m=float(np.mean(ranges)) if ranges.size else nan,
            frames=count,
            fused_frames=int(np.count_nonzero(fused)),
            rejected=tuple(sorted(Counter(r for r in rejected if r).items())),
            runtime_ms=RuntimeStats(
                mean=float(runtimes.mean()) if runtimes.size else nan,
                std=float(runtimes.std(ddof=1)) if runtimes.size > 1 else nan,
                max=float(runtimes.max()) if runtimes.size else nan),
            fusibility_precision=_ratio(true_positive, int(np.count_nonzero(decided & predicted))),
            fusibility_recall=_ratio(true_positive, int(np.count_nonzero(decided & truly))),
            fusibility_recall_detected=_ratio(int(np.count_nonzero(detected & predicted)),
                                              int(np.count_nonzero(detected))),
            correct_mean_error_m=right.mean(),
            correct_max_error_m=right.max(),
            correct_p95_error_m=right.percentile(P95_PERCENT),
            bytes_per_message=self.message_bytes / self.messages if self.messages else nan,
            bytes_per_second=self.message_bytes * 1e9 / self.sender_ns if self.sender_ns > 0 else nan,
            gt_unmatched=tuple(sorted(Counter(r for r in c["gt_unmatched"] if r).items())),
            fused_by_relation=tuple(sorted(Counter(relation[fused_pairs & truly].tolist()).items())),
            false_by_relation=tuple(sorted(Counter(relation[fused_pairs & ~truly].tolist()).items())),
            by_confidence=by_confidence,
            by_route=tuple((group, RouteErrors.of_pool(int(np.count_nonzero(fused_pairs & fused & truly
                                                                             & (relation == kind))),
                                                       pooled[f"route_{group}"]))
                           for group, kind in ROUTE_GROUPS.items()) if fused_pairs.any() else (),
            calibration=None if not pooled["sigmas"].size else _calibration(pooled, within, "sigma"),
            calibration_correct=None if not pooled["sigmas"].size or not truly_known.any()
            else _calibration(pooled, within, "correct_sigma"),
        )

    def _added_result(self, c: Mapping[str, Any], fused: np.ndarray, pooled: Mapping[str, PointPool],
                      ranges: NDArrayFloat) -> dict[str, Any]:
        """The :class:`ScenarioResult` fields of the range distribution, the near / far
        errors, the stopping distance and the detection ends."""
        speed = c["stopping_speed_mps"]
        measured = ~np.isnan(speed)
        rules = {(float(v), float(t), float(a)) for v, t, a in zip(
            speed[measured], c["stopping_reaction_time_s"][measured], c["stopping_deceleration_mps2"][measured])}
        if len(rules) > 1:
            raise ReportError(f"{self.key.map} {self.key.label} {self.key.boundary}: records scored against "
                              f"{len(rules)} different stopping distances")
        stopping = None
        if rules:
            speed_mps, reaction_s, deceleration_mps2 = rules.pop()
            stopping = StoppingRule(reaction_s, deceleration_mps2).at(speed_mps)
        frames = c["frame"][measured]
        known = c["known_to_m"][measured] >= stopping.distance_m if stopping is not None else np.empty(0, dtype=bool)
        return {
            "range_percentiles_m": tuple(float(np.percentile(ranges, q)) for q in RANGE_PERCENTS) if ranges.size
            else (math.nan,) * len(RANGE_PERCENTS),
            "near": _error_stats(pooled["near"]),
            "far": _error_stats(pooled["far"]),
            "stopping": stopping,
            "stopping_frames": len(set(frames.tolist())),
            "stopping_known_frames": len(set(frames[known].tolist())),
            "end_reasons": tuple(sorted(Counter(r for r in c["end_reason"] if r).items())),
        }

    def frames_batches(self) -> Iterator[Any]:
        """The scenario's ``frames.parquet`` rows (:func:`frames_batch`), batch by batch."""
        for batch in self.records.batches(FRAMES_COLUMNS_STORED):
            yield frames_batch(self.key, batch)


def scenario_results(accumulators: Iterable[ScenarioAccumulator]) -> list[ScenarioResult]:
    """Each scenario's :meth:`ScenarioAccumulator.result`, in order; the heap's free pages
    handed back to the system once after them all (after each one, the pages a scenario
    frees would be faulted in again by the next one's pools)."""
    results = [accumulator.result() for accumulator in accumulators]
    release_free_heap()
    return results


def _calibration(pooled: Mapping[str, PointPool], within: Mapping[str, list[int]], name: str) -> Calibration:
    """The :class:`Calibration` of the pools ``{name}s`` (stated σ) and ``{name}_errors`` with
    ``within[name]`` points within 1σ and 2σ (NaN shares and means without points)."""
    sigmas, count = pooled[f"{name}s"], pooled[f"{name}s"].size
    return Calibration(points=count, within_1sigma=_ratio(within[name][0], count),
                       within_2sigma=_ratio(within[name][1], count), mean_sigma_m=sigmas.mean(),
                       mean_error_m=pooled[f"{name}_errors"].mean())


def _error_stats(pool: PointPool) -> ErrorStats:
    """``ErrorStats.of`` the pooled samples."""
    if not pool.size:
        return ErrorStats(0, math.nan, math.nan, math.nan)
    return ErrorStats(pool.size, pool.mean(), pool.max(), pool.partition_percentile(P95))


FRAMES_COLUMNS_STORED: Final[tuple[str, ...]] = (
    "frame", "stamp_s", "ego", "coop", "errors_m", "rejected", "mean_error_m", "max_error_m", "perception_range_m",
    "runtime_ms", "predicted_fusible", "truly_fusible", "relation", "confidence", "end_reason", "near_points",
    "near_max_error_m", "far_max_error_m", "known_to_m", "stopping_speed_mps", "stopping_reaction_time_s",
    "stopping_deceleration_mps2", "detected_fusible")
"""The stored columns ``frames.csv`` and ``frames.parquet`` are made from."""
ROW_GROUP_ROWS: Final[int] = 1 << 13
"""Rows ``frames.parquet`` gathers into one row group (a record segment holds far fewer: a
row group per segment would make the writer's footer grow with the run, ~20 kB each)."""


def frames_schema() -> Any:
    """The ``frames.parquet`` schema: the :data:`FRAMES_CSV_COLUMNS`, typed (null where
    ``frames.csv`` is empty)."""
    import pyarrow as pa

    text, f64, i64, flag = pa.string(), pa.float64(), pa.int64(), pa.bool_()
    types = {"map": text, "fusion": text, "interpolation": text, "d_s": f64, "boundary": text, "frame": i64,
             "stamp_s": f64, "ego": text, "coop": text, "fused": flag, "rejected": text, "points": i64,
             "mean_error_m": f64, "max_error_m": f64, "perception_range_m": f64, "runtime_ms": f64,
             "predicted_fusible": flag, "truly_fusible": flag, "relation": text, "confidence": f64,
             "end_reason": text, "near_points": i64, "near_max_error_m": f64, "far_max_error_m": f64,
             "known_to_m": f64, "stopping_distance_m": f64, "detected_fusible": flag}
    return pa.schema([(name, types[name]) for name in FRAMES_CSV_COLUMNS])


@functools.lru_cache(maxsize=64)
def _stopping_distance_m(speed_mps: float, reaction_time_s: float, deceleration_mps2: float) -> float:
    """``StoppingRule.distance_m`` (m), once per rule and speed (a run has few of them)."""
    return StoppingRule(reaction_time_s, deceleration_mps2).distance_m(speed_mps)


def frames_batch(key: ScenarioKey, batch: Any) -> Any:
    """The ``frames.parquet`` rows of a batch of stored records (:data:`FRAMES_COLUMNS_STORED`)
    of the scenario ``key``."""
    import pyarrow as pa

    rows = batch.num_rows

    def finite(values: Any) -> Any:
        array = to_numpy(values) if isinstance(values, pa.Array) else np.asarray(values, dtype=np.float64)
        return from_numpy(array, pa.float64(), valid=np.isfinite(array))

    lengths = np.diff(list_values(batch.column("errors_m"))[1])
    speed = batch.column("stopping_speed_mps").to_pylist()
    reaction = batch.column("stopping_reaction_time_s").to_pylist()
    deceleration = batch.column("stopping_deceleration_mps2").to_pylist()
    distance = [math.nan if v is None else _stopping_distance_m(v, t, a)
                for v, t, a in zip(speed, reaction, deceleration)]
    columns = {
        "map": repeated_string(key.map, rows), "fusion": repeated_string(key.fusion, rows),
        "interpolation": repeated_string(key.interpolation, rows),
        "d_s": from_numpy(np.full(rows, float(key.d_s)), pa.float64()),
        "boundary": repeated_string(key.boundary, rows), "frame": batch.column("frame"),
        "stamp_s": finite(batch.column("stamp_s")), "ego": batch.column("ego"), "coop": batch.column("coop"),
        "fused": from_numpy(lengths > 0, pa.bool_()), "rejected": batch.column("rejected"),
        "points": from_numpy(lengths, pa.int64()),
        "stopping_distance_m": finite(distance),
    }
    for name in ("mean_error_m", "max_error_m", "perception_range_m", "runtime_ms", "confidence",
                 "near_max_error_m", "far_max_error_m", "known_to_m"):
        columns[name] = finite(batch.column(name))
    for name in ("predicted_fusible", "truly_fusible", "relation", "end_reason", "near_points", "detected_fusible"):
        columns[name] = batch.column(name)
    schema = frames_schema()
    return pa.RecordBatch.from_arrays([columns[name] for name in schema.names], schema=schema)


def _csv_cells(column: Any) -> list[Any]:
    """The ``frames.csv`` cells of one column: floats as ``repr``, flags 0 / 1, empty where null."""
    values = column.to_pylist()
    kind = str(column.type)
    if kind == "double":
        return ["" if v is None else repr(v) for v in values] if column.null_count else list(map(repr, values))
    if kind == "bool":
        return ["" if v is None else int(v) for v in values]
    return ["" if v is None else v for v in values]


def frames_csv_rows(batch: Any) -> Iterator[tuple[Any, ...]]:
    """The ``frames.csv`` rows of a :func:`frames_batch` as tuples in its column order
    (:data:`FRAMES_CSV_COLUMNS`), converted a column at a time (:func:`_csv_cells`)."""
    return zip(*(_csv_cells(column) for column in batch.columns))


def atomic_write_bytes(path: str | os.PathLike[str], data: bytes) -> None:
    """Writes ``data`` to ``path`` atomically (:func:`converters.atomic_io.atomic_output`)."""
    path = Path(path)
    if not path.parent.is_dir():
        raise ReportError(f"{path}: cannot write: no folder {path.parent}")
    with atomic_output(path, "wb") as stream:
        stream.write(data)


def atomic_write_text(path: str | os.PathLike[str], text: str) -> None:
    """Writes UTF-8 ``text`` to ``path`` atomically (see :func:`atomic_write_bytes`)."""
    atomic_write_bytes(path, text.encode("utf-8"))


def metrics_document(results: Sequence[ScenarioResult], *, partial: bool = False,
                     provenance: Provenance | None = None) -> dict[str, Any]:
    """The ``metrics.json`` document (see the module docstring)."""
    return {"schema_version": METRICS_SCHEMA_VERSION, "partial": bool(partial)} | (
        {"provenance": provenance.to_dict()} if provenance is not None else {}) | {
        "scenarios": [r.to_dict() for r in results]}


def write_metrics_json(path: str | os.PathLike[str], results: Sequence[ScenarioResult], *, partial: bool = False,
                       provenance: Provenance | None = None) -> None:
    """Writes ``metrics.json`` atomically."""
    document = metrics_document(results, partial=partial, provenance=provenance)
    atomic_write_text(path, json.dumps(document, indent=2, allow_nan=False) + "\n")


def read_metrics_json(path: str | os.PathLike[str]) -> tuple[list[ScenarioResult], bool]:
    """The scenarios and the partial flag of a ``metrics.json``; ReportError naming the file."""
    path = Path(path)
    try:
        document = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ReportError(f"{path}: cannot read: {exc.strerror}") from exc
    except ValueError as exc:
        raise ReportError(f"{path}: not JSON: {exc}") from exc
    if not isinstance(document, dict) or not isinstance(document.get("scenarios"), list):
        raise ReportError(f"{path}: expected an object with a 'scenarios' list")
    if document.get("schema_version") != METRICS_SCHEMA_VERSION:
        raise ReportError(f"{path}: schema_version {document.get('schema_version')!r}, "
                          f"expected {METRICS_SCHEMA_VERSION}")
    results = [ScenarioResult.from_dict(r, f"{path}: scenarios[{i}]") for i, r in enumerate(document["scenarios"])]
    return results, bool(document.get("partial", False))


def write_frames(csv_path: str | os.PathLike[str], parquet_path: str | os.PathLike[str],
                 accumulators: Iterable[ScenarioAccumulator]) -> None:
    """Writes ``frames.csv`` (one row per frame, vehicle pair and scenario) and
    ``frames.parquet`` (the same rows, typed by :func:`frames_schema`, null where
    ``frames.csv`` is empty; row groups of about :data:`ROW_GROUP_ROWS` rows) atomically, both
    streamed from one pass over the records' columns: neither file is written when either fails."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    for path in (Path(csv_path), Path(parquet_path)):
        if not path.parent.is_dir():
            raise ReportError(f"{path}: cannot write: no folder {path.parent}")
    schema = frames_schema().with_metadata({"made_by": "cold-maps cold_maps.evaluation.report.write_frames",
                                            "rows": "as frames.csv: one per frame, vehicle pair and scenario; "
                                                    "null where frames.csv is empty"})
    with (atomic_output(csv_path, "wb") as csv_stream, atomic_output(parquet_path, "wb") as parquet_stream,
          pq.ParquetWriter(parquet_stream, schema) as parquet):
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(FRAMES_CSV_COLUMNS)
        group: list[Any] = []
        rows = 0
        for accumulator in accumulators:
            for batch in accumulator.frames_batches():
                writer.writerows(frames_csv_rows(batch))
                csv_stream.write(buffer.getvalue().encode("utf-8"))
                buffer.seek(0)
                buffer.truncate()
                # copies: the columns are views of the record segment, which holds the points too
                group.append(pa.RecordBatch.from_arrays([pa.concat_arrays([c]) for c in batch.columns], schema=schema))
                rows += batch.num_rows
                if rows >= ROW_GROUP_ROWS:
                    parquet.write_table(pa.Table.from_batches(group, schema))
                    group, rows = [], 0
                    release_free_heap()
        if group:
            parquet.write_table(pa.Table.from_batches(group, schema))
        csv_stream.write(buffer.getvalue().encode("utf-8"))


def _fmt(value: float, digits: int = 3) -> str:
    return "–" if not math.isfinite(value) else f"{value:.{digits}f}"


def _table(header: Sequence[str], rows: Iterable[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def _sort_key(result: ScenarioResult) -> tuple[Any, ...]:
    k = result.key
    return (k.map, FUSIONS.index(k.fusion), k.interpolation, k.d_s, k.vehicles, k.history_m, k.exchange,
            BOUNDARIES.index(k.boundary))


REJECTION_REASONS: Final[Mapping[str, str]] = {
    "coop_not_ahead": "the coop is not ahead of the ego",
    "other_lane": "the two detections lie on different lanes",
    "no_overlap": "convoy: the detections do not overlap",
    "no_gap": "spline: the detections overlap, there is no gap to bridge",
    "gap_too_long": "spline: the gap exceeds d_i",
    "opposite_direction": "the vehicles drive in opposite directions",
    "heading_mismatch": "the detections' headings differ too much",
    "pose_case": "the relative pose matches none of the paper's cases",
    "other": "another refusal of the fusion",
    "ego_not_seen": "the ego's sensor saw no lane", "coop_not_seen": "the coop's sensor saw no lane",
    "ego_dropped": "an error model dropped the ego's detection",
    "coop_dropped": "an error model dropped the coop's detection",
    "no_ground_truth": "no ground truth lane at the ego's pose",
    "gt_unmatched": "the ground truth does not cover the lane (why in brackets)",
}
"""Rejection reasons of the results table and what each means (the legend of ``summary.md``)."""
COLUMN_LEGEND: Final[str] = (
    "Columns: **mean / RMSE / max / p95** — closest-point distance of the evaluated lane's points to the "
    "ground truth border, pooled over all points of the scenario (mean is the paper's eq. 1 \"MSE\"); "
    "**range** — mean length of the evaluated lane over the fused evaluations; **fused / evaluated** — evaluations "
    "(frames × vehicle pairs, distractor pairs included) that produced a lane / all; **rejected** — why the others "
    "produced none (reason: count); **fus. precision / recall** — the fusibility check against the ground truth "
    "(of the pairs it fused, the share truly on one lane / of the pairs truly on one lane, the share it fused); "
    "**vehicles** — vehicles fused (1 local, 2 a pair, more a chain). Runtimes are in the Runtime section, "
    "one per scenario.\n")
DRIVE_LENGTH_NOTE: Final[str] = (
    "Drive length: every drive is as long as the farthest coop asked for needs (the longest gap), and the "
    "routes, frames and distractors follow from it; the results at one gap therefore change when other gaps are "
    "asked for. Compare gaps within one run, not across runs with different gap lists.\n")


def legend_markdown(results: Sequence[ScenarioResult]) -> str:
    """The columns of the results table and the rejection reasons that occur in ``results``."""
    reasons = sorted({reason for r in results for reason, _ in r.rejected})
    if not reasons:
        return COLUMN_LEGEND
    return COLUMN_LEGEND + "\nRejection reasons:\n\n" + "".join(
        f"- `{reason}`: {REJECTION_REASONS.get(reason, 'as named')}\n" for reason in reasons)


def runtime_markdown(results: Sequence[ScenarioResult], check_ms: Mapping[tuple[str, str], Sequence[float]]) -> str:
    """One fusion runtime per scenario (its left-border record: both borders share the
    evaluations; all pairs, as ``metrics.json`` ``runtime_ms``), the fusibility check timed
    alone (``check_ms``: (map, label) → ms, the scenario's own coop) and the paper's Table I;
    "" when no scenario timed a fusion."""
    def stats(values: Sequence[float]) -> str:
        if not len(values):
            return "–"
        array = np.asarray(values, dtype=float)
        std = float(array.std(ddof=1)) if array.size > 1 else math.nan
        return " / ".join(_fmt(v, 2) for v in (float(array.mean()), std, float(array.max())))

    rows = []
    for r in sorted(results, key=_sort_key):
        if r.key.boundary != "left" or not math.isfinite(r.runtime_ms.mean):
            continue
        paper = PAPER_TABLE_I_MS.get(r.key.fusion)
        rows.append([r.key.map, _setup(r.key),
                     " / ".join(_fmt(v, 2) for v in (r.runtime_ms.mean, r.runtime_ms.std, r.runtime_ms.max)),
                     stats(check_ms.get((r.key.map, r.key.label), ())),
                     " / ".join(f"{v:.2f}" for v in paper) if paper else "–"])
    if not rows:
        return ""
    return ("Fusion time per evaluation (`fusion.fuse`, includes its checks; every pair, distractors included), "
            "and the check alone on the scenario's own coop (`fusion.is_fusible`: the overlap check for convoy, "
            "the fusibility check for spline). The paper's Table I: rural road, 300 frames, AMD Ryzen 7 5700X.\n\n"
            + _table(["map", "scenario", "fusion mean / σ / max [ms]",
                      "check alone mean / σ / max [ms]", "paper Table I [ms]"], rows))


def summary_markdown(results: Sequence[ScenarioResult], *, partial: bool = False,
                     road_types: Mapping[str, str] | None = None, warnings: Sequence[str] = (),
                     program: str = "cold-eval", provenance: Provenance | None = None,
                     check_ms: Mapping[tuple[str, str], Sequence[float]] | None = None) -> str:
    """``summary.md`` of the command ``program``: how it was made (``provenance``), the
    partial mark and ``warnings`` on the ground truth, one row per scenario (like the paper's
    Table II, a vehicles column when chains run) with the legend of its columns, one runtime
    per scenario (:func:`runtime_markdown`, ``check_ms`` its checks timed alone), then, for
    maps named in ``road_types`` (map -> paper road type), the side-by-side with the paper."""
    parts = [f"# {program} summary\n"]
    if partial:
        parts.append("\n**PARTIAL RUN: interrupted; the figures cover only the frames evaluated.**\n")
    if provenance is not None:
        parts.append("\n" + provenance.markdown())
    if warnings:
        parts.append("\n**GROUND TRUTH NOT TRUSTWORTHY on this run:**\n\n" + "".join(f"- {w}\n" for w in warnings))
    chains = any(r.key.vehicles > 0 for r in results)
    header = ["map", "fusion", "interp.", "d_s [m]", *(["vehicles"] if chains else []), "boundary", "mean [m]",
              "RMSE [m]", "max [m]", "p95 [m]", "range [m]", "fused / evaluated", "rejected", "fus. precision",
              "fus. recall"]
    rows = []
    for r in sorted(results, key=_sort_key):
        k = r.key
        why = dict(r.gt_unmatched)
        rejected = ", ".join(f"{reason}: {count}" + (f" ({', '.join(f'{w}: {n}' for w, n in why.items())})"
                                                      if reason == "gt_unmatched" and why else "")
                             for reason, count in r.rejected) or "–"
        rows.append([k.map, k.fusion, k.interpolation or "–", _fmt(k.d_s, 1), *([str(k.vehicles)] if chains else []),
                     k.boundary, _fmt(r.mean_error_m), _fmt(r.rmse_m), _fmt(r.max_error_m), _fmt(r.p95_error_m),
                     _fmt(r.perception_range_m, 1), f"{r.fused_frames} / {r.frames}", rejected,
                     _fmt(r.fusibility_precision), _fmt(r.fusibility_recall)])
    parts += ["\n## Results per scenario\n\n", _table(header, rows), "\n", legend_markdown(results)]
    if any(r.key.fusion == "spline" for r in results):
        parts += ["\n", DRIVE_LENGTH_NOTE]
    parts += ["\n## What CoLD adds\n\n", cold_adds_markdown(results)]
    if chains:
        parts += ["\n## Chains, history and exchange\n\n", extended_markdown(results)]
    association = association_markdown(results)
    if association:
        parts += ["\n## Lane association\n\n", association]
    runtime = runtime_markdown(results, check_ms or {})
    if runtime:
        parts += ["\n## Runtime (Table I)\n\n", runtime]
    calibration = calibration_markdown(results)
    if calibration:
        parts += ["\n## Calibration of the stated σ\n\n", calibration]
    if road_types:
        parts += ["\n## Ours vs the paper\n\n", paper_comparison_markdown(results, road_types)]
    return "".join(parts)


def _setup(key: ScenarioKey) -> str:
    """A scenario's name with its history and exchange, when recorded."""
    extra = [f"history {key.history_m:g} m"] if key.history_m else []
    extra += [f"exchange {key.exchange}"] if key.exchange else []
    return key.label + (f" ({', '.join(extra)})" if extra else "")


def _split_cell(stats: ErrorStats) -> str:
    if not stats.points:
        return "no point"
    return f"{stats.points} / " + " / ".join(_fmt(v) for v in (stats.mean_error_m, stats.max_error_m,
                                                                 stats.p95_error_m))


def cold_adds_markdown(results: Sequence[ScenarioResult]) -> str:
    """The perception range's distribution and the errors near / far from the ego per
    scenario and border; per scenario the share of frames with the lane known to the
    stopping distance; per map why the ego's own detections ended."""
    ordered = sorted(results, key=_sort_key)
    split = f"{NEAR_FAR_SPLIT_M:g}"
    ranges = [[r.key.map, _setup(r.key), r.key.boundary,
               " / ".join(_fmt(v, 1) for v in (r.perception_range_m, *r.range_percentiles_m)),
               _split_cell(r.near), _split_cell(r.far)] for r in ordered]
    text = (f"Perception range over the fused evaluations, a frame without an ego lane counted as 0 m; errors of "
            f"the points within {split} m of the ego along the border (near) and beyond (far), as OpenLane splits "
            "them (points / mean / max / p95 [m]).\n\n"
            + _table(["map", "scenario", "boundary", "range mean / p5 / p50 / p95 [m]", f"near ≤ {split} m",
                      f"far > {split} m"], ranges))
    stops = [[r.key.map, _setup(r.key), _fmt(r.stopping.speed_mps, 1), _fmt(r.stopping.rule.reaction_time_s, 2),
              _fmt(r.stopping.rule.deceleration_mps2, 2), _fmt(r.stopping.distance_m, 1),
              f"{r.stopping_known_frames} / {r.stopping_frames}", _fmt(r.stopping_share)]
             for r in ordered if r.key.boundary == "left" and r.stopping is not None]
    if stops:
        text += (f"\nFrames in which the lane is known to the stopping distance {STOPPING_FORMULA}: an "
                 f"evaluation's lane has both borders within {LANE_ACCURACY_M:g} m of the ground truth at every point "
                 "from the ego out to d (docs/metrics.md).\n\n"
                 + _table(["map", "scenario", "v [m/s]", "t_r [s]", "a [m/s²]", "d [m]", "known / frames", "share"],
                          stops))
    ends = [[r.key.map, ", ".join(f"{reason}: {count}" for reason, count in r.end_reasons) or "unknown"]
            for r in ordered if r.key.fusion == "local" and r.key.boundary == "left"]
    if ends:
        text += "\nWhy the ego's own detections ended (local evaluations):\n\n" + _table(["map", "ended by"], ends)
    return text


def calibration_markdown(results: Sequence[ScenarioResult]) -> str:
    """The scenarios whose lanes state σ: share of points within 1σ / 2σ (68 % / 95 % when
    calibrated), mean stated σ beside the mean error, of all fused points and of the correct
    fusions' ("–" for local scenarios); "" when none states σ."""
    def cells(c: Calibration | None) -> list[str]:
        if c is None:
            return ["–"] * 5
        return [str(c.points), _fmt(100.0 * c.within_1sigma, 1), _fmt(100.0 * c.within_2sigma, 1),
                _fmt(c.mean_sigma_m), _fmt(c.mean_error_m)]

    rows = [[r.key.map, r.key.fusion, r.key.interpolation or "–", _fmt(r.key.d_s, 1), r.key.boundary,
             *cells(r.calibration), *cells(r.calibration_correct)]
            for r in sorted(results, key=_sort_key) if r.calibration is not None]
    if not rows:
        return ""
    columns = ["points", "within 1σ [%]", "within 2σ [%]", "mean σ [m]", "mean error [m]"]
    header = ["map", "fusion", "interp.", "d_s [m]", "boundary", *columns, *(f"correct {c}" for c in columns)]
    return ("Errors of the points against the lateral 1σ the fusion states for them (68 % / 95 % when calibrated): "
            "all fused points, and the correct fusions' alone (the coop truly continues the ego's lane; a false "
            "fusion's association error is no part of any stated σ).\n\n" + _table(header, rows))


def extended_markdown(results: Sequence[ScenarioResult]) -> str:
    """One table per (vehicles, history, exchange): errors of all and of the correct fusions,
    perception range and message cost, per map, scenario and boundary."""
    groups: dict[tuple[int, float, str], list[ScenarioResult]] = {}
    for r in sorted(results, key=_sort_key):
        groups.setdefault((r.key.vehicles, r.key.history_m, r.key.exchange), []).append(r)
    header = ["map", "fusion", "interp.", "d_s [m]", "boundary", "mean [m]", "max [m]", "p95 [m]",
              "correct mean / max / p95 [m]", "range [m]", "fused / evaluated", "bytes / msg", "bytes / s"]
    parts = []
    for (vehicles, history, exchange), group in sorted(groups.items()):
        rows = [[r.key.map, r.key.fusion, r.key.interpolation or "–", _fmt(r.key.d_s, 1), r.key.boundary,
                 _fmt(r.mean_error_m), _fmt(r.max_error_m), _fmt(r.p95_error_m),
                 " / ".join(_fmt(v) for v in (r.correct_mean_error_m, r.correct_max_error_m, r.correct_p95_error_m)),
                 _fmt(r.perception_range_m, 1), f"{r.fused_frames} / {r.frames}", _fmt(r.bytes_per_message, 0),
                 _fmt(r.bytes_per_second, 0)] for r in group]
        parts.append(f"### {vehicles} vehicle(s), history {history:g} m, exchange {exchange or 'none'}\n\n"
                     + _table(header, rows) + "\n")
    return "".join(parts)
def association_markdown(results: Sequence[ScenarioResult]) -> str:
    """The fusibility decisions per scenario (left-border records; both borders share them):
    precision, recall, true fusions on the ego's route / a branch, false fusions by kind,
    then one precision / recall point per confidence threshold, then the errors of the true
    fusions on the ego's own route and on another branch per border. "" when no scenario
    decided."""
    rows, curve, routes = [], [], []
    for r in sorted(results, key=_sort_key):
        k = r.key
        if r.by_route:
            routes.append([k.map, k.fusion, k.interpolation or "–", _fmt(k.d_s, 1), k.boundary,
                           *(f"{e.fused} / {_fmt(e.mean_error_m)} / {_fmt(e.max_error_m)} / {_fmt(e.p95_error_m)}"
                             for _, e in r.by_route)])
        if k.boundary != "left" or not (r.fused_by_relation or r.false_by_relation or r.by_confidence):
            continue
        name = [k.map, k.fusion, k.interpolation or "–", _fmt(k.d_s, 1)]
        fused = dict(r.fused_by_relation)
        rows.append([*name, _fmt(r.fusibility_precision), _fmt(r.fusibility_recall),
                     _fmt(r.fusibility_recall_detected), str(fused.get("own", 0)),
                     str(fused.get("branch", 0)),
                     ", ".join(f"{kind}: {count}" for kind, count in r.false_by_relation) or "–"])
        if r.by_confidence:
            curve.append([*name, *(f"{_fmt(p)} / {_fmt(q)}" for _, p, q in r.by_confidence)])
    if not rows:
        return ""
    text = ("Pairs valid by the paper's rule (`lane_relation`, the ego's detection counted to the sensor's "
            "nominal range); recall given detections: over those of them whose detections as made overlap "
            "(convoy) or leave a gap 0 < d_s <= d_i (spline), \"–\" when unknown (docs/metrics.md); false "
            "fusions by kind of pair.\n\n"
            + _table(["map", "fusion", "interp.", "d_s [m]", "precision", "recall", "recall given detections",
                      "fused own route", "fused branch", "false fusions"], rows))
    if curve:
        text += ("\nPrecision / recall when only decisions of at least this association confidence count "
                 "as fusible:\n\n" + _table(["map", "fusion", "interp.", "d_s [m]",
                                               *(f"≥ {t:g}" for t in CONFIDENCE_THRESHOLDS)], curve))
    if routes:
        text += ("\nErrors of the true fusions by where the coop drives: on the ego's own route, or on another "
                 "branch of a fork (fused / mean / max / p95 [m]):\n\n"
                 + _table(["map", "fusion", "interp.", "d_s [m]", "boundary",
                           *(group.replace("_", " ") for group in ROUTE_GROUPS)], routes))
    return text


def _paper_errors(road: str, key: ScenarioKey) -> tuple[float, float]:
    """The paper's (mean, max) error for a scenario, NaN where the paper gives none."""
    if key.fusion != "spline" or key.d_s == PAPER_SPLINE_D_S_M[road]:
        return PAPER_TABLE_II[(road, key.fusion)][key.boundary]
    return PAPER_SPLINE_TEXT.get((road, key.d_s), (math.nan, math.nan))


def _paper_range(key: ScenarioKey) -> float:
    if key.fusion == "spline":
        return PAPER_SPLINE_RANGE_M.get(key.d_s, math.nan)
    return PAPER_PERCEPTION_RANGE_M[key.fusion]


def paper_comparison_markdown(results: Sequence[ScenarioResult], road_types: Mapping[str, str]) -> str:
    """Our results side by side with the paper's Table II (errors, perception range) and
    the figures its text quotes for other gaps, for the maps in ``road_types`` (map ->
    "straight" | "right_curve_90" | "rural"); "–" where the paper gives no figure."""
    for name, road in road_types.items():
        if road not in PAPER_SPLINE_D_S_M:
            raise ReportError(f"road type of map {name!r}: expected one of {tuple(PAPER_SPLINE_D_S_M)}, got {road!r}")
    rows = []
    for r in sorted(results, key=_sort_key):
        road = road_types.get(r.key.map)
        if road is None:
            continue
        paper_mean, paper_max = _paper_errors(road, r.key)
        rows.append([r.key.map, road, r.key.fusion, r.key.interpolation or "–", _fmt(r.key.d_s, 1), r.key.boundary,
                     _fmt(r.mean_error_m), _fmt(paper_mean), _fmt(r.max_error_m), _fmt(paper_max),
                     _fmt(r.perception_range_m, 1), _fmt(_paper_range(r.key), 0)])
    return ("Paper: Table II (mean = its eq. 1 \"MSE\", max, perception range) and the figures its text "
            "quotes for other gaps.\n\n"
            + _table(["map", "road type", "fusion", "interp.", "d_s [m]", "boundary", "mean [m]", "paper mean [m]",
                      "max [m]", "paper max [m]", "range [m]", "paper range [m]"], rows))


def write_summary_md(path: str | os.PathLike[str], results: Sequence[ScenarioResult], *, partial: bool = False,
                     road_types: Mapping[str, str] | None = None) -> None:
    """Writes ``summary.md`` atomically (see :func:`summary_markdown`)."""
    atomic_write_text(path, summary_markdown(results, partial=partial, road_types=road_types))


def write_report(out_dir: str | os.PathLike[str], accumulators: Sequence[ScenarioAccumulator], *,
                 partial: bool = False, road_types: Mapping[str, str] | None = None) -> list[ScenarioResult]:
    """Writes ``metrics.json``, ``summary.md``, ``frames.csv`` and ``frames.parquet`` into ``out_dir``; returns
    the results. ``partial`` marks the report of an interrupted run."""
    out = Path(out_dir)
    if not out.is_dir():
        raise ReportError(f"{out}: output folder does not exist")
    results = scenario_results(accumulators)
    write_frames(out / "frames.csv", out / "frames.parquet", accumulators)
    write_summary_md(out / "summary.md", results, partial=partial, road_types=road_types)
    write_metrics_json(out / "metrics.json", results, partial=partial)
    return results
