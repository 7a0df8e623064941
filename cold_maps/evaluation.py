"""Batch evaluation: drives on a map, lane detections, fusion per frame, errors against GT.

For every frame of every drive each vehicle senses its lane (``LaneSensor`` on the
OpenDRIVE map, optional seeded error models), the ego's detection is measured alone
(``local``) and fused with every other present vehicle for each scenario (``convoy``;
``spline`` per interpolation and gap d_s). Fused lanes are measured against Lanelet2
ground truth (``converters.load_lanelet2``, matched by ``gt_matching``) by closest-point
distances to the GT borders resampled every 0.02 m; the fusion's decision is scored
against the true lane relation of the pair (:func:`cold_maps.drive.lane_relation`).

Results go into a :class:`Collector` (``report.ScenarioAccumulator`` per scenario key,
runtimes, one overlay per scenario), optionally also frame by frame into an MCAP
``Recorder``.
"""

from __future__ import annotations

import logging
import math
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Final, Literal, Sequence

import numpy as np

import fusion
from cold_maps.drive import (
    CONVOY_HEADWAY_M,
    DEFAULT_SPEED_MPS,
    FRAME_RATE_HZ,
    Drive,
    DriveError,
    VehicleState,
    build_drive,
    covering_routes,
    lane_relation,
    required_route_length,
    route_from_start,
)
from cold_maps.lane_graph import LaneGraph, LaneKey, build_lane_graph
from cold_maps.lane_strip import NDArrayFloat
from cold_maps.report import ScenarioAccumulator, ScenarioKey, FrameRecord
from cold_maps.sensor import SENSOR_RANGE_M, LaneSensor, vehicle_to_world
from cold_maps.sensor_errors import SensorErrorModel

if TYPE_CHECKING:
    from cold_maps.recording import Recorder
    from gt_matching import GroundTruth, LaneMatch

LOG = logging.getLogger("cold_maps.evaluation")

INTERPOLATIONS: Final[tuple[str, ...]] = ("paper", "hermite")
MATCH_CACHE_SIZE: Final[int] = 16
"""Reference lanes whose GT match ``GroundTruthMeter`` keeps (a frame has a handful)."""
OVERLAY_MARGIN_M: Final[float] = 10.0
"""The overlay plot shows the GT this far (m) around the detections and the fused lane."""
DETECTION_DECIMALS: Final[int] = 6
"""Detected border points are rounded to 1 µm (the sensor's resolution): the recorded
``cold.LaneDetection`` JSON is then short and exactly what was fused."""
RELATION_MARGIN_M: Final[float] = 5.0
"""Slack (m) on the longest lane distance at which a coop counts as ahead of the ego."""

FusionName = Literal["local", "convoy", "spline"]

_REASONS: Final[tuple[tuple[str, str], ...]] = (
    ("not ahead", "coop_not_ahead"),
    ("no overlap on the same lane", "other_lane"),
    ("no overlap", "no_overlap"),
    ("no gap", "no_gap"),
    ("exceeds d_i", "gap_too_long"),
    ("not the same direction", "opposite_direction"),
    ("heads", "heading_mismatch"),
    ("matches none", "pose_case"),
    ("another lane", "other_lane"),
)


def reason_category(reason: str) -> str:
    """A short key for a fusion rejection reason (``other`` when unknown)."""
    for needle, category in _REASONS:
        if needle in reason:
            return category
    return "other"


@dataclass(frozen=True)
class Scenario:
    """One fusion set-up evaluated on every frame.

    Fields:
        fusion: ``local`` (ego only), ``convoy`` or ``spline``.
        interpolation: ``paper`` or ``hermite`` for ``spline``, "" otherwise.
        d_s: spline gap between the ego's detection end and the coop's start (m), 0 otherwise.
        lead_m: station distance of the scenario's coop ahead of the ego (m); 0 for local.
    """

    fusion: FusionName
    interpolation: str = ""
    d_s: float = 0.0
    lead_m: float = 0.0

    @property
    def label(self) -> str:
        """``local``, ``convoy`` or ``spline-<interpolation>-d<d_s>``."""
        return self.fusion if self.fusion != "spline" else f"spline-{self.interpolation}-d{self.d_s:g}"

    def key(self, map_name: str, boundary: str) -> ScenarioKey:
        """The report key of one boundary."""
        return ScenarioKey(map_name, self.fusion, self.interpolation, float(self.d_s), boundary)


def scenarios_for(gaps_m: Sequence[float], interpolations: Sequence[str], *,
                  sensor_range_m: float = SENSOR_RANGE_M) -> tuple[Scenario, ...]:
    """local, convoy (headway d_v = 25 m) and spline for each distinct interpolation and gap."""
    for gap in gaps_m:
        if not (math.isfinite(gap) and gap > 0):
            raise ValueError(f"spline gap d_s: expected a finite distance > 0 m, got {gap!r}")
    for name in interpolations:
        if name not in INTERPOLATIONS:
            raise ValueError(f"interpolation: expected one of {INTERPOLATIONS}, got {name!r}")
    splines = [Scenario("spline", name, float(gap), sensor_range_m + gap)
               for name in dict.fromkeys(interpolations) for gap in dict.fromkeys(gaps_m)]
    return (Scenario("local"), Scenario("convoy", lead_m=CONVOY_HEADWAY_M), *splines)


def params_for_gaps(gaps_m: Sequence[float]) -> fusion.FusionParams:
    """Fusion parameters whose longest bridged gap d_i (default 50 m) admits every gap
    asked for, with 1 m to spare (a gap set along the lane is measured as a chord)."""
    return fusion.FusionParams(d_i_m=max(fusion.DEFAULT_PARAMS.d_i_m, max(gaps_m, default=0.0) + 1.0))


@dataclass(frozen=True)
class MapPlan:
    """What to evaluate on one map.

    Fields:
        path: the OpenDRIVE file.
        scenarios: the fusion set-ups.
        frames: frames per drive.
        routes: drives (routes) on the map; None for as many as cover its lanes.
        seed: seed of the route choice and of the error models.
        speed_mps: ego speed (m/s); frames at ``FRAME_RATE_HZ``.
        start_lane: the lane every route starts on, or None for routes spread over the map.
        distractors: add turning coops, adjacent/opposite-lane and behind vehicles.
        errors: sensor error models (all off by default).
        params: fusion parameters.
        road_type: the paper's road type of this map (for the side-by-side), or None.
    """

    path: Path
    scenarios: tuple[Scenario, ...]
    frames: int = 100
    routes: int | None = 3
    seed: int = 0
    speed_mps: float = DEFAULT_SPEED_MPS
    start_lane: LaneKey | None = None
    distractors: bool = True
    errors: SensorErrorModel = SensorErrorModel()
    params: fusion.FusionParams = fusion.DEFAULT_PARAMS
    road_type: str | None = None

    @property
    def name(self) -> str:
        """Map name (file stem)."""
        return self.path.stem

    @property
    def coop_leads_m(self) -> tuple[float, ...]:
        """Distinct coop leads of the scenarios (m)."""
        return tuple(sorted({s.lead_m for s in self.scenarios if s.fusion != "local"}))


@dataclass(frozen=True)
class Measurement:
    """A lane measured against its ground truth (world frame, m).

    Fields:
        left_errors_m, right_errors_m: per detected point, the distance to the GT border
            resampled every ``step_m``.
        left_range_m, right_range_m: length of the lane along its GT border, from the
            projection of its first point to that of its last.
        left_gt, right_gt: the GT borders (``(M, 2)``) the lane was matched to.
        matched: False when the lane does not follow the sender's lane (see gt_matching).
    """

    left_errors_m: NDArrayFloat
    right_errors_m: NDArrayFloat
    left_range_m: float
    right_range_m: float
    left_gt: NDArrayFloat
    right_gt: NDArrayFloat
    matched: bool


class GroundTruthMeter:
    """Closest-point errors of lanes against a ``gt_matching.GroundTruth``
    (``GroundTruth.errors``: per-point distances to the GT borders resampled every
    ``step_m``, samples cached per lanelet; without the other-lane check, which the
    reports do not use). Matches of the last few reference lanes are kept: the scenarios
    of a frame share their coops' true lanes."""

    def __init__(self, ground_truth: GroundTruth) -> None:
        self.ground_truth = ground_truth
        self.step_m = ground_truth.config.step_m
        self._matches: OrderedDict[tuple[bytes, bytes, tuple[float, float, float]], LaneMatch] = OrderedDict()

    def match(self, left: NDArrayFloat, right: NDArrayFloat, pose: tuple[float, float, float]) -> LaneMatch:
        """The GT lanelets and borders of a lane (``gt_matching.GroundTruth.match``), from
        the cache when the same borders and pose were matched lately."""
        left, right = np.asarray(left, dtype=np.float64), np.asarray(right, dtype=np.float64)
        key = (left.tobytes(), right.tobytes(), tuple(pose))
        found = self._matches.get(key)
        if found is None:
            found = self._matches[key] = self.ground_truth.match(left, right, pose)
            if len(self._matches) > MATCH_CACHE_SIZE:
                self._matches.popitem(last=False)
        else:
            self._matches.move_to_end(key)
        return found

    def errors(self, match: LaneMatch, left: NDArrayFloat, right: NDArrayFloat) -> Measurement:
        """Closest-point errors and range of a lane against the GT borders of ``match``."""
        found = self.ground_truth.errors(left, right, match, others=False)
        return Measurement(found.left.distances_m, found.right.distances_m,
                           float(found.left.arc_m[-1] - found.left.arc_m[0]),
                           float(found.right.arc_m[-1] - found.right.arc_m[0]),
                           match.left_gt, match.right_gt, match.matched)

    def measure(self, left: NDArrayFloat, right: NDArrayFloat, pose: tuple[float, float, float], *,
                reference: tuple[NDArrayFloat, NDArrayFloat] | None = None) -> Measurement:
        """Errors of a lane (borders ``(N, 2)`` world frame, driving order) whose sender
        stands at ``pose`` (x m, y m, yaw rad). The GT lanelets are those matched to
        ``reference`` (the borders of the lane the vehicles truly drive, from the drive),
        or to the lane itself; the errors are always against Lanelet2's borders. Raises
        ``gt_matching.MatchingError``."""
        return self.errors(self.match(*(reference or (left, right)), pose), left, right)


@dataclass(frozen=True)
class Overlay:
    """What one frame of a scenario looked like, for the overlay plot (world frame, m).

    Fields:
        frame: frame index; max_error_m: its largest error; gt: GT borders by name;
        detections: sender → (left, right); fused: fused borders by name.
    """

    frame: int
    max_error_m: float
    gt: dict[str, NDArrayFloat]
    detections: dict[str, tuple[NDArrayFloat, NDArrayFloat]]
    fused: dict[str, NDArrayFloat]


@dataclass
class Collector:
    """Everything a run measured so far (filled frame by frame, readable after an interrupt).

    Fields:
        accumulators: one per scenario key, in insertion order.
        fuse_ms: (map, scenario label) → fusion runtimes of the scenario's own coop (ms).
        check_ms: (map, scenario label) → runtimes of the fusibility check alone, the
            overlap check for convoy (ms).
        overlays: (map, scenario label) → the frame with the largest error.
        notes: lines for the summary (routes, lane coverage).
        frames_done: frames evaluated.
    """

    accumulators: dict[ScenarioKey, ScenarioAccumulator] = field(default_factory=dict)
    fuse_ms: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    check_ms: dict[tuple[str, str], list[float]] = field(default_factory=dict)
    overlays: dict[tuple[str, str], Overlay] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    frames_done: int = 0

    def add(self, key: ScenarioKey, record: FrameRecord) -> None:
        """Adds one evaluation to the scenario ``key``."""
        accumulator = self.accumulators.get(key)
        if accumulator is None:
            accumulator = self.accumulators[key] = ScenarioAccumulator(key)
        accumulator.add(record)


@dataclass(frozen=True)
class Sensed:
    """One vehicle's detection in one frame.

    Fields:
        state: where the vehicle is.
        detection: what it sends (reported pose with localisation error, borders in its
            vehicle frame with the sensor errors), or None when the frame was dropped.
    """

    state: VehicleState
    detection: fusion.LaneDetection | None


def sense(state: VehicleState, sensor: LaneSensor, errors: SensorErrorModel, rng: np.random.Generator, *,
          stamp_s: float = 0.0) -> Sensed:
    """The detection of a vehicle: the sensor on its track, then the error models, points
    rounded to 1 µm; the ego's pose carries no localisation error (it is the reference)."""
    raw = sensor.detect(state.track.strip, state.station)
    if raw is None:
        return Sensed(state, None)
    borders = errors.apply(raw.left, raw.right, rng)
    if borders is None:
        return Sensed(state, None)
    borders = tuple(np.round(border, DETECTION_DECIMALS) for border in borders)
    x, y, yaw = (raw.x, raw.y, raw.yaw) if state.role == "ego" else errors.perturb_pose(raw.x, raw.y, raw.yaw, rng)
    pose = fusion.Pose2D(x, y, yaw)
    return Sensed(state, fusion.LaneDetection(pose, borders[0], borders[1], stamp=stamp_s, sender=state.name))


def world_borders(detection: fusion.LaneDetection) -> tuple[NDArrayFloat, NDArrayFloat]:
    """The detection's borders in the world frame (m), from its reported pose."""
    p = detection.pose
    return vehicle_to_world(detection.left, p.x, p.y, p.yaw), vehicle_to_world(detection.right, p.x, p.y, p.yaw)


def _pose(detection: fusion.LaneDetection) -> tuple[float, float, float]:
    return detection.pose.x, detection.pose.y, detection.pose.yaw


class MapEvaluator:
    """Evaluates one :class:`MapPlan`: loads the map and its ground truth, builds the drives
    and runs them frame by frame into a :class:`Collector`.

    Raises ``DriveError`` (no drivable route, route too short) on construction.
    """

    def __init__(self, plan: MapPlan, *, ground_truth: GroundTruth | None = None,
                 graph: LaneGraph | None = None) -> None:
        self.plan = plan
        self.graph = graph or load_graph(plan.path)
        self.rng = np.random.default_rng(plan.seed)
        self.drives, self.coverage = self._drives()
        self._ground_truth = ground_truth
        self.meter: GroundTruthMeter | None = None
        self.sensor = LaneSensor()
        self.relation_max_m = SENSOR_RANGE_M + plan.params.d_i_m + RELATION_MARGIN_M

    @property
    def total_frames(self) -> int:
        """Frames over all drives."""
        return sum(d.frames for d in self.drives)

    def _drives(self) -> tuple[list[Drive], tuple[int, int]]:
        """The drives, and (lanes their routes cover, driving lanes of the map)."""
        plan = self.plan
        leads = plan.coop_leads_m
        distractor_leads = leads if plan.distractors else ()
        length = required_route_length(plan.frames, leads, behind_m=max(distractor_leads, default=0.0),
                                       speed_mps=plan.speed_mps)
        try:
            if plan.start_lane is None:
                routes = covering_routes(self.graph, plan.routes, length, self.rng)
            else:
                routes = [route_from_start(self.graph, plan.start_lane, length, self.rng)
                          for _ in range(plan.routes or 1)]
        except DriveError as exc:
            if exc.longest_m is None:
                raise
            raise DriveError(f"{exc}; {self._length_hint(exc.longest_m)}", longest_m=exc.longest_m) from None
        covered = {lane for route in routes for lane in route}
        drives = [build_drive(self.graph, lanes, plan.frames, coop_leads_m=leads, distractor_leads_m=distractor_leads,
                              rng=self.rng, speed_mps=plan.speed_mps) for lanes in routes]
        return drives, (len(covered), len(self.graph.lanes))

    def _length_hint(self, longest_m: float) -> str:
        """What to change when the longest route (m) is too short for the plan's drives."""
        plan = self.plan
        leads = plan.coop_leads_m
        behind = max(leads, default=0.0) if plan.distractors else 0.0
        one = required_route_length(1, leads, behind_m=behind, speed_mps=plan.speed_mps)
        if longest_m >= one:
            step_m = plan.speed_mps / FRAME_RATE_HZ
            return f"at most {1 + int((longest_m - one) // step_m)} --frames fit"
        what = "shorter --gaps" + (" or --no-distractors" if behind > 0 else "")
        return (f"even one frame needs {one:.0f} m (coops up to {max(leads, default=0.0):g} m ahead, "
                f"{SENSOR_RANGE_M:g} m sensor range" + (f", a vehicle {behind:g} m behind" if behind > 0 else "")
                + f"): use {what}")

    def prepare(self) -> None:
        """Loads (or converts, cached) the Lanelet2 ground truth if not given."""
        if self.meter is not None:
            return
        if self._ground_truth is None:
            from converters import load_lanelet2
            from gt_matching import GroundTruth

            lanelet_map, routing = load_lanelet2(self.plan.path)
            self._ground_truth = GroundTruth(lanelet_map, routing)
        self.meter = GroundTruthMeter(self._ground_truth)

    def run(self, collector: Collector, *, recorder: Recorder | None = None, frame_offset: int = 0,
            on_frame: Callable[[], None] | None = None) -> int:
        """Evaluates every frame of every drive; returns the next free global frame index.

        Frame indices (and MCAP stamps) continue from ``frame_offset`` across drives.
        """
        self.prepare()
        plan = self.plan
        collector.notes.append(
            f"{plan.name}: {len(self.drives)} route(s) of {plan.frames} frames at {plan.speed_mps:g} m/s covering "
            f"{self.coverage[0]} of {self.coverage[1]} driving lanes")
        frame_index = frame_offset
        for drive in self.drives:
            LOG.info("%s: route %s (%.0f m)", plan.name, [tuple(k) for k in drive.ego.lanes], drive.ego.length)
            for frame in range(drive.frames):
                self._frame(collector, drive, frame, frame_index, recorder)
                collector.frames_done += 1
                frame_index += 1
                if on_frame is not None:
                    on_frame()
        unmatched = sum(r.rejected == "no_ground_truth" for key, a in collector.accumulators.items()
                        if key.map == plan.name and key.fusion == "local" and key.boundary == "left"
                        for r in a.records)
        if unmatched:
            note = (f"{plan.name}: no ground truth for {unmatched} of {self.total_frames} ego detections (no "
                    "Lanelet2 lanelet at the pose: the converted map does not overlay the OpenDRIVE map there)")
            LOG.warning(note)
            collector.notes.append(note)
        return frame_index

    def _frame(self, collector: Collector, drive: Drive, frame: int, index: int, recorder: Recorder | None) -> None:
        plan = self.plan
        stamp = index / FRAME_RATE_HZ
        sensed = {name: sense(state, self.sensor, plan.errors, self.rng, stamp_s=stamp)
                  for name, state in drive.states(frame).items()}
        ego = sensed["ego"]
        metrics: dict[str, float | None] = {}
        fused_lines: dict[str, NDArrayFloat] = {}
        gt_lines: dict[str, NDArrayFloat] = {}
        for scenario in plan.scenarios:
            if scenario.fusion == "local":
                lines = self._local(collector, scenario, ego, index, stamp, metrics)
                gt_lines.update(lines)
                continue
            for name, other in sensed.items():
                if name == "ego" or abs(abs(other.state.lead_m) - scenario.lead_m) > 1e-9:
                    continue
                fused = self._pair(collector, scenario, ego, other, index, stamp, metrics)
                if fused is not None:
                    fused_lines[f"{scenario.label}-left"], fused_lines[f"{scenario.label}-right"] = fused
        if recorder is not None:
            for name, item in sensed.items():
                if item.detection is not None:
                    recorder.write_detection(stamp, index, name, _pose(item.detection), item.detection.left,
                                             item.detection.right, ego=name == "ego")
            if gt_lines:
                recorder.write_gt(stamp, gt_lines)
            recorder.write_fused(stamp, fused_lines)
            recorder.write_metrics(stamp, index, metrics)

    def _local(self, collector: Collector, scenario: Scenario, ego: Sensed, index: int, stamp: float,
               metrics: dict[str, float | None]) -> dict[str, NDArrayFloat]:
        keys = [scenario.key(self.plan.name, b) for b in ("left", "right")]
        if ego.detection is None:
            for key in keys:
                collector.add(key, FrameRecord(index, stamp, "ego", "", np.empty(0), rejected="ego_dropped"))
            return {}
        left, right = world_borders(ego.detection)
        state = ego.state
        truth = state.track.borders_between(state.station, state.station + self.sensor.range_m)
        measured = self._measure(left, right, _pose(ego.detection), truth)
        if isinstance(measured, str):
            for key in keys:
                collector.add(key, FrameRecord(index, stamp, "ego", "", np.empty(0), rejected=measured))
            return {}
        self._record(collector, scenario, keys, measured, index, stamp, "ego", "", math.nan, None, None, metrics)
        self._keep_overlay(collector, scenario, index, measured, {"ego": (left, right)}, {})
        shown = np.vstack((left, right))
        low, high = shown.min(axis=0) - OVERLAY_MARGIN_M, shown.max(axis=0) + OVERLAY_MARGIN_M
        return {"left": _crop(measured.left_gt, low, high), "right": _crop(measured.right_gt, low, high)}

    def _measure(self, left: NDArrayFloat, right: NDArrayFloat, pose: tuple[float, float, float],
                 reference: tuple[NDArrayFloat, NDArrayFloat]) -> Measurement | str:
        from gt_matching import MatchingError

        assert self.meter is not None
        try:
            return self.meter.measure(left, right, pose, reference=reference)
        except MatchingError as exc:
            LOG.debug("no ground truth: %s", exc)
            return "no_ground_truth"

    def _pair(self, collector: Collector, scenario: Scenario, ego: Sensed, other: Sensed, index: int, stamp: float,
              metrics: dict[str, float | None]) -> tuple[NDArrayFloat, NDArrayFloat] | None:
        plan = self.plan
        keys = [scenario.key(plan.name, b) for b in ("left", "right")]
        truth = lane_relation(self.graph, ego.state, other.state, self.relation_max_m, self.sensor.range_m)
        main = other.state.role == "coop"
        label = (plan.name, scenario.label)

        def reject(reason: str, predicted: bool | None = None, runtime: float = math.nan) -> None:
            for key in keys:
                collector.add(key, FrameRecord(index, stamp, "ego", other.state.name, np.empty(0), runtime_ms=runtime,
                                               rejected=reason, predicted_fusible=predicted, truly_fusible=truth))

        if ego.detection is None or other.detection is None:
            reject("ego_dropped" if ego.detection is None else "coop_dropped")
            return None
        mode = scenario.fusion
        interpolation = scenario.interpolation or "paper"
        start = time.perf_counter()
        result = fusion.fuse(ego.detection, other.detection, mode=mode, interpolation=interpolation,
                             params=plan.params)
        runtime = (time.perf_counter() - start) * 1e3
        if main:
            start = time.perf_counter()
            fusion.is_fusible(ego.detection, other.detection, plan.params, mode=mode)
            collector.check_ms.setdefault(label, []).append((time.perf_counter() - start) * 1e3)
            collector.fuse_ms.setdefault(label, []).append(runtime)
        if result.kind == "none":
            reject(reason_category(result.reason), False, runtime)
            return None
        measured = self._measure(result.left, result.right, _pose(ego.detection),
                                 self.true_lane(ego.state, other.state))
        if isinstance(measured, str):
            reject(measured, True, runtime)
            return None
        self._record(collector, scenario, keys, measured, index, stamp, "ego", other.state.name, runtime, True,
                     truth, metrics if main else None)
        if main:
            detections = {"ego": world_borders(ego.detection), other.state.name: world_borders(other.detection)}
            self._keep_overlay(collector, scenario, index, measured, detections,
                               {"left": result.left, "right": result.right})
        return result.left, result.right

    def true_lane(self, ego: VehicleState, other: VehicleState) -> tuple[NDArrayFloat, NDArrayFloat]:
        """The lane a fusion of ``other`` into the ego should reproduce: the other's track
        to its detection end when it drives on from the ego's lanes (coop, turn), else the
        ego's own lanes as far ahead."""
        end = ego.station + abs(other.lead_m) + self.sensor.range_m
        if other.role in ("coop", "turn"):
            return other.track.borders_between(ego.station, min(end, other.track.length))
        return ego.track.borders_between(ego.station, min(end, ego.track.length))

    def _record(self, collector: Collector, scenario: Scenario, keys: list[ScenarioKey], measured: Measurement,
                index: int, stamp: float, ego: str, coop: str, runtime: float, predicted: bool | None,
                truth: bool | None, metrics: dict[str, float | None] | None) -> None:
        sides = ((measured.left_errors_m, measured.left_range_m), (measured.right_errors_m, measured.right_range_m))
        for key, (errors, length) in zip(keys, sides):
            collector.add(key, FrameRecord(index, stamp, ego, coop, errors, perception_range_m=length,
                                           runtime_ms=runtime, predicted_fusible=predicted, truly_fusible=truth))
            if metrics is not None:
                prefix = f"{scenario.label}_{key.boundary}".replace("-", "_")
                metrics[f"{prefix}_mean_error_m"] = float(np.mean(errors))
                metrics[f"{prefix}_max_error_m"] = float(np.max(errors))
                metrics[f"{prefix}_range_m"] = length

    def _keep_overlay(self, collector: Collector, scenario: Scenario, index: int, measured: Measurement,
                      detections: dict[str, tuple[NDArrayFloat, NDArrayFloat]], fused: dict[str, NDArrayFloat]) -> None:
        worst = float(max(measured.left_errors_m.max(), measured.right_errors_m.max()))
        label = (self.plan.name, scenario.label)
        kept = collector.overlays.get(label)
        if kept is None or worst > kept.max_error_m:
            shown = np.vstack([*fused.values(), *(b for pair in detections.values() for b in pair)])
            low, high = shown.min(axis=0) - OVERLAY_MARGIN_M, shown.max(axis=0) + OVERLAY_MARGIN_M
            gt = {"left": _crop(measured.left_gt, low, high), "right": _crop(measured.right_gt, low, high)}
            collector.overlays[label] = Overlay(index, worst, gt, detections, fused)


def _crop(line: NDArrayFloat, low: NDArrayFloat, high: NDArrayFloat) -> NDArrayFloat:
    """The stretch of ``line`` from its first to its last point inside the box [low, high],
    plus one point on either side."""
    inside = np.flatnonzero(np.all((line >= low) & (line <= high), axis=1))
    return line if inside.size < 2 else line[max(inside[0] - 1, 0): inside[-1] + 2]


def load_graph(path: Path) -> LaneGraph:
    """The driving-lane graph of an OpenDRIVE file (OpenDriveError when unreadable)."""
    from cold_maps.opendrive.parser import load_opendrive

    return build_lane_graph(load_opendrive(path))
