"""Batch evaluation: drives on a map, lane detections, fusion per frame, errors against GT.

For every frame of every drive each vehicle senses its lane on the OpenDRIVE map (the
plan's sensor profile: the ideal ``LaneSensor``, or a ``CameraSensor`` the other vehicles
can hide the lane from; optional seeded error models), the ego's detection is measured
alone (``local``) and fused with every other present vehicle for each scenario (``convoy``;
``spline`` per interpolation and gap d_s). Fused lanes are measured against Lanelet2
ground truth (``converters.load_lanelet_map`` of the plan's converter, by default built from
the map engine, matched by ``gt_matching``) by closest-point
distances to the GT borders resampled every 0.02 m; the fusion's decision is scored
against the true lane relation of the pair (:func:`cold_maps.simulation.drive.lane_relation`).

Results go into a :class:`Collector` (``report.ScenarioAccumulator`` per scenario key,
runtimes, one overlay per scenario), optionally also frame by frame into an MCAP
``Recorder``.
"""

from __future__ import annotations

import gc
import logging
import math
import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import TYPE_CHECKING, Callable, Final, Iterator, NamedTuple

import numpy as np

import fusion
from fusion.fusibility import max_gap_m, signed_gap_m
from fusion.uncertainty import own_variances
from cold_maps.common.memory import release_free_heap
from cold_maps.evaluation.collector import Collector, Overlay
from cold_maps.evaluation.fit import fit_plan
from cold_maps.evaluation.methods import resolve_method
from cold_maps.evaluation.report import FrameRecord, ScenarioKey
from cold_maps.evaluation.safety import LANE_ACCURACY_M, STOPPING_FORMULA
from cold_maps.evaluation.scenarios import MapPlan, Scenario, reason_category
from cold_maps.evaluation.trust import (
    GT_UNMATCHED,
    MAP_BROKEN,
    NO_GROUND_TRUTH,
    BrokenStretches,
    broken_stretches,
    check_driven,
    driven_lanes,
)
from cold_maps.groundtruth.meter import GroundTruthMeter, Lane, Measurement
from cold_maps.network.lane_graph import LaneGraph, load_graph
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.network.routing import longest_route_lengths
from cold_maps.simulation.detection import Sensed, detection_pose, sense_block, world_borders
from cold_maps.simulation.exchange import LaneExchange
from cold_maps.simulation.drive import (
    FRAME_RATE_HZ,
    Drive,
    DriveError,
    VehicleState,
    build_drive,
    covering_routes,
    lane_relation,
    relation_kind,
    require_driving_lanes,
    route_from_start,
)
from cold_maps.simulation.lane_model_error import LaneModelErrorSampler
from cold_maps.simulation.neighbours import NeighbourSensor
from cold_maps.simulation.camera import lane_sensor
from cold_maps.simulation.sensor import SENSOR_RANGE_M
from cold_maps.simulation.sensor_errors import SensorErrorModel

if TYPE_CHECKING:
    from cold_maps.recording.recorder import Recorder
    from gt_matching import GroundTruth

LOG = logging.getLogger("cold_maps.evaluation")

OVERLAY_MARGIN_M: Final[float] = 10.0
"""The overlay plot shows the GT this far (m) around the detections and the fused lane."""
RELATION_MARGIN_M: Final[float] = 5.0
"""Slack (m) on the longest lane distance at which a coop counts as ahead of the ego."""
BLOCK_FRAMES: Final[int] = 25
"""Frames of a drive whose vehicle states and detections are computed at once, as arrays
(:meth:`Drive.states_block`, :func:`sense_block`), and whose lanes are measured in one
:meth:`GroundTruthMeter.measure_many`; the fusion stays per frame. A block's detections,
fused lanes and their temporary arrays are held together (on Town04 1 to 2 MB per
frame): the block size bounds that, not the results, which are the same for any size."""
FRAME_LOOP_GC_THRESHOLD: Final[int] = 10_000
"""Allocations of objects the cyclic garbage collector tracks (net of those freed) between
two collections of its young generation while a drive's frames run (Python's default: 700).
A block of frames holds about 9 000 such objects until it is recorded (Town01, the default
scenarios): the default collected them about once a frame in vain."""
Finish = Callable[[Measurement | str | None], dict[str, NDArrayFloat]]
"""Records a frame's scenario from its lane's measurement (None when it has no lane to
measure) and gives the lines the MCAP shows for it (name → ``(N, 2)`` world frame)."""


@dataclass
class _FusedFrame:
    """A frame fused but not yet recorded.

    Fields:
        index, stamp: global frame index and its time, s.
        sensed: the vehicles' detections (after the exchange).
        steps: per scenario (and coop), the lines dict its MCAP lines go to, the lane to
            measure (None: none) and what records its measurement.
        metrics, fused_lines, gt_lines: what the MCAP gets of the frame, filled as it is recorded.
    """

    index: int
    stamp: float
    sensed: dict[str, Sensed]
    steps: list[tuple[dict[str, NDArrayFloat], Lane | None, Finish]] = field(default_factory=list)
    metrics: dict[str, float | None] = field(default_factory=dict)
    fused_lines: dict[str, NDArrayFloat] = field(default_factory=dict)
    gt_lines: dict[str, NDArrayFloat] = field(default_factory=dict)


@dataclass(frozen=True, slots=True)
class _Names:
    """What one scenario's results are named on the map evaluated.

    Fields:
        keys: the report keys of its left and right boundary.
        label: (map name, scenario label): the key of its check runtimes and overlay.
        lines: the MCAP names of its fused left and right border.
        prefixes: the MCAP metrics' name prefixes of its left and right boundary.
    """

    keys: tuple[ScenarioKey, ScenarioKey]
    label: tuple[str, str]
    lines: tuple[str, str]
    prefixes: tuple[str, str]


class _PairStep:
    """What records the fusion of one pair in one scenario (:meth:`MapEvaluator._pair`) once its
    lane is measured: a :data:`Finish`, one object where closures made a cell per name they
    held (most of the objects a frame left to the cyclic garbage collector).

    Fields:
        evaluator, collector: what records it, and where.
        scenario, names: the scenario and its :class:`_Names`.
        index, stamp: global frame index and its time, s.
        ego, other: the pair's detections as sensed.
        truth, relation, detected: ``FrameRecord.truly_fusible``, ``relation`` and
            ``detected_fusible`` of the pair.
        metrics: the frame's MCAP metrics, for the scenario's coop (None: a distractor).
        runtime, result: the fusion's runtime (ms) and result (None: not fused).
        refused: (reason, predicted, runtime ms, confidence) of a pair rejected before any lane
            was measured (a detection missing, a pair the fusion refused), else None.
    """

    __slots__ = ("evaluator", "collector", "scenario", "names", "index", "stamp", "ego", "other", "truth",
                 "relation", "detected", "metrics", "runtime", "result", "refused")

    def __init__(self, evaluator: MapEvaluator, collector: Collector, scenario: Scenario, index: int, stamp: float,
                 ego: Sensed, other: Sensed, truth: bool, relation: str, detected: bool | None) -> None:
        self.evaluator, self.collector, self.scenario = evaluator, collector, scenario
        self.names = evaluator._names(scenario)
        self.index, self.stamp, self.ego, self.other = index, stamp, ego, other
        self.truth, self.relation, self.detected = truth, relation, detected
        self.metrics: dict[str, float | None] | None = None
        self.runtime = math.nan
        self.result: fusion.FusionResult | None = None
        self.refused: tuple[str, bool | None, float, float] | None = None

    def __call__(self, measured: Measurement | str | None) -> dict[str, NDArrayFloat]:
        """Records the pair from its lane's measurement (None when it has none); the MCAP
        lines of the fused lane."""
        if self.refused is not None:
            return self.reject(*self.refused)
        result = self.result
        assert measured is not None and result is not None
        if isinstance(measured, str) or measured.gt_unmatched:
            rejected, why = _rejection(measured)
            return self.reject(rejected, True, self.runtime, result.confidence, why)
        evaluator, collector, scenario, name = self.evaluator, self.collector, self.scenario, self.other.state.name
        evaluator._record(collector, scenario, self.names.keys, measured, self.index, self.stamp, "ego", name,
                          self.runtime, True, self.truth, self.metrics, relation=self.relation,
                          confidence=result.confidence, sigmas=(result.left_sigma, result.right_sigma),
                          detected=self.detected)
        evaluator._keep_overlay(collector, scenario, self.index, measured,
                                {"ego": self.ego.detection, name: self.other.detection},  # type: ignore[dict-item]
                                {"left": result.left, "right": result.right})
        return dict(zip(self.names.lines, (result.left, result.right)))

    def reject(self, reason: str, predicted: bool | None = None, runtime: float = math.nan,
               confidence: float = math.nan, why: str = "") -> dict[str, NDArrayFloat]:
        """Records the pair without a lane, ``FrameRecord.rejected`` ``reason``; no MCAP lines."""
        record = FrameRecord.trusted(self.index, self.stamp, "ego", self.other.state.name, _NO_ERRORS,
                                     runtime_ms=runtime, rejected=reason, predicted_fusible=predicted,
                                     truly_fusible=self.truth, gt_unmatched=why, relation=self.relation,
                                     confidence=confidence, stopping=self.evaluator.stopping,
                                     detected_fusible=self.detected)
        for key in self.names.keys:  # one record for both boundaries: immutable, and the same without a lane
            self.collector.add(key, record)
        return {}


class _Worst(NamedTuple):
    """A scenario's frame with the largest error so far, not yet drawn as its :class:`Overlay`
    (:meth:`MapEvaluator._draw_overlays`): ``frame`` its index, ``max_error_m`` that error (m),
    ``measured`` its lane's measurement, ``detections`` the senders' detections by name,
    ``fused`` the fused borders by name (world frame)."""

    frame: int
    max_error_m: float
    measured: Measurement
    detections: dict[str, fusion.LaneDetection]
    fused: dict[str, NDArrayFloat]


_NO_ERRORS: Final[NDArrayFloat] = np.empty(0)
_NO_ERRORS.flags.writeable = False
"""The error samples of every record without a lane (read-only, shared)."""


class MapEvaluator:
    """Evaluates one :class:`MapPlan`: loads the map and its ground truth, builds the drives
    and runs them frame by frame into a :class:`Collector`. Each drive is a work unit
    (:meth:`run_drive`): its sensor error models draw from its own generator, spawned from
    the plan's seed after the route choice, so drives can run in any process in any order.

    Raises ``DriveError`` (no drivable route, not even for the local scenario) on
    construction; on a map too small for the whole plan it evaluates what fits
    (``evaluation.fit``, ``fit_notes``).
    """

    def __init__(self, plan: MapPlan, *, ground_truth: GroundTruth | None = None,
                 graph: LaneGraph | None = None) -> None:
        self.plan = plan
        self.graph = graph or load_graph(plan.path)
        self.rng = np.random.default_rng(plan.seed)
        self.fit_notes: tuple[str, ...] = ()
        self.sensor = lane_sensor(plan.sensor, self.graph)
        self.drives, self.coverage = self._drives()
        self.drive_rngs = self.rng.spawn(len(self.drives))
        self.lane_errors = (None if plan.sensor.lane_error.is_zero else
                            [LaneModelErrorSampler(plan.sensor.lane_error, plan.seed, i)
                             for i in range(len(self.drives))])
        """The lane-model error of each drive, or None when the plan has none."""
        self.stopping = self.plan.stopping.at(self.plan.speed_mps)
        self._ground_truth = ground_truth
        self.meter: GroundTruthMeter | None = None
        self.neighbours = NeighbourSensor(self.graph, plan.lanes) if plan.lanes > 0 else None
        self.relation_max_m = SENSOR_RANGE_M + plan.params.d_i_m + RELATION_MARGIN_M
        self.exchange = (LaneExchange(plan.history_m, plan.odometry, plan.messages, plan.errors, plan.seed)
                         if plan.history_m > 0 or plan.messages.enabled else None)
        self._scenario_names: dict[Scenario, _Names] = {}
        self._relations: dict[str, tuple[bool, str]] = {}
        """The frame's :meth:`_relation` by vehicle name."""
        self._true_lanes: dict[str, tuple[NDArrayFloat, NDArrayFloat]] = {}
        """The frame's :meth:`true_lane` by vehicle name."""
        self._worst: dict[tuple[str, str], _Worst] = {}
        """Per (map, scenario label) the drive's frame that is to be its overlay, not yet drawn."""

    @property
    def total_frames(self) -> int:
        """Frames over all drives."""
        return sum(d.frames for d in self.drives)

    def _drives(self) -> tuple[list[Drive], tuple[int, int]]:
        """The drives, and (lanes their routes cover, driving lanes of the map). Fits the
        plan to the map's longest route first (``evaluation.fit``): ``self.plan`` then
        holds only what fits, ``self.fit_notes`` says what was left out."""
        plan = self.plan
        require_driving_lanes(self.graph)
        longest = longest_route_lengths(self.graph)
        if plan.start_lane is None:
            fitted = fit_plan(plan, max(longest.values()), where=str(plan.path))
        else:
            if plan.start_lane not in longest:
                raise DriveError(f"{plan.path}: start lane {tuple(plan.start_lane)} is not in the lane graph")
            fitted = fit_plan(plan, longest[plan.start_lane], where=f"{plan.path} from lane {tuple(plan.start_lane)}")
        self.plan = plan = fitted.plan
        self.fit_notes = fitted.notes
        if plan.start_lane is None:
            routes = covering_routes(self.graph, plan.routes, fitted.needed_m, self.rng)
        else:
            routes = [route_from_start(self.graph, plan.start_lane, fitted.needed_m, self.rng)
                      for _ in range(plan.routes or 1)]
        covered = {lane for route in routes for lane in route}
        leads = (*plan.coop_leads_m, *plan.chain_leads_m)
        drives = [build_drive(self.graph, lanes, plan.frames, coop_leads_m=leads,
                              distractor_leads_m=fitted.distractor_leads_m, rng=self.rng, speed_mps=plan.speed_mps,
                              reach_m=self.sensor.reach_m)
                  for lanes in routes]
        return drives, (len(covered), len(self.graph.lanes))

    def prepare(self) -> None:
        """Loads (or converts, cached) the Lanelet2 ground truth if not given, and with the
        engine's finds where the map is broken (:attr:`broken`): here, so that the worker
        processes forked after it share them instead of each finding them again."""
        if self.meter is not None:
            return
        if self._ground_truth is None:
            from cold_maps.groundtruth.lanelet2_from_engine import converter_named
            from converters import load_lanelet_map
            from gt_matching import GroundTruth

            converter = converter_named(self.plan.ground_truth, self.graph.odr_map)
            self._ground_truth = GroundTruth(load_lanelet_map(self.plan.path, converter=converter), prepare_all=False)
        self.meter = GroundTruthMeter(self._ground_truth)
        if self.plan.ground_truth == "engine":
            self.broken  # noqa: B018 - computed now (a cached property)

    @cached_property
    def broken(self) -> BrokenStretches:
        """Where the map is broken (``trust.broken_stretches``): evaluations over it are not
        scored with the engine's ground truth."""
        return broken_stretches(self.graph)

    @cached_property
    def gt_warning(self) -> str | None:
        """Why crdesigner's ground truth of the driven lanes is not trustworthy
        (``cold-maps check`` on them), or None (always, with the engine's ground truth: it is
        judged per evaluation, see ``trust``); computed once, where the run's notes are
        written (never in the worker processes, which only evaluate drives)."""
        if self.plan.ground_truth == "engine":
            return None
        self.prepare()
        assert self._ground_truth is not None
        return check_driven(self.plan.name, self.graph, self._ground_truth.lanelet_map,
                            self._ground_truth.routing_graph, driven_lanes(self.drives))

    def run(self, collector: Collector, *, recorder: Recorder | None = None, frame_offset: int = 0,
            on_frame: Callable[[], None] | None = None) -> int:
        """Evaluates every frame of every drive; returns the next free global frame index.

        Frame indices (and MCAP stamps) continue from ``frame_offset`` across drives.
        """
        self.prepare()
        self.note_drives(collector)
        frame_index = frame_offset
        for drive in range(len(self.drives)):
            frame_index = self.run_drive(drive, collector, recorder=recorder, frame_offset=frame_index,
                                         on_frame=on_frame)
        self.note_unmatched(collector)
        return frame_index

    def note_drives(self, collector: Collector) -> None:
        """Notes what of the plan did not fit the map, this map's drives and the lanes they
        cover, a loop shorter than the farthest detection, and why the ground truth of the
        driven lanes is not trustworthy (if it is not)."""
        plan = self.plan
        collector.notes.extend(self.fit_notes)
        if self.fit_notes:
            collector.reduced_maps.append(plan.name)
        distinct = len({drive.ego.lanes for drive in self.drives})
        repeats = (f" ({distinct} distinct: a repeated route drives the same lanes again, with fresh draws of any "
                   "sensor errors)" if distinct < len(self.drives) else "")
        collector.notes.append(
            f"{plan.name}: {len(self.drives)} route(s) of {plan.frames} frames at {plan.speed_mps:g} m/s covering "
            f"{self.coverage[0]} of {self.coverage[1]} driving lanes{repeats}; ground truth: Lanelet2 built by "
            f"{GROUND_TRUTHS.get(plan.ground_truth, plan.ground_truth)}")
        rule = self.stopping.rule
        collector.notes.append(
            f"{plan.name}: stopping distance {STOPPING_FORMULA} = {self.stopping.distance_m:.1f} m at "
            f"v {plan.speed_mps:g} m/s, t_r {rule.reaction_time_s:g} s, a {rule.deceleration_mps2:g} m/s²")
        if plan.sensor.kind != "ideal":
            collector.notes.append(f"{plan.name}: {plan.sensor.describe()}")
        loop_m = min(d.ego.shortest_loop_m for d in self.drives)
        farthest_m = max(plan.coop_leads_m, default=0.0) + self.sensor.range_m
        if loop_m < farthest_m:
            collector.notes.append(
                f"{plan.name}: a route circles a loop of {loop_m:.1f} m; a vehicle whose stretch from the ego to the "
                f"end of the farther detection (up to {farthest_m:g} m) circles it is absent in that frame")
        if plan.ground_truth == "engine" and self.broken.reasons:
            shown = "; ".join(self.broken.reasons[:5])
            more = f" and {len(self.broken.reasons) - 5} more" if len(self.broken.reasons) > 5 else ""
            collector.notes.append(f"{plan.name}: the map is broken at {len(self.broken.reasons)} place(s), evaluations "
                                   f"over them are not scored ({MAP_BROKEN}): {shown}{more}")
        if self.gt_warning is not None:
            LOG.warning(self.gt_warning)
            collector.gt_warnings.append(self.gt_warning)

    def run_drive(self, drive_index: int, collector: Collector, *, recorder: Recorder | None = None,
                  frame_offset: int = 0, on_frame: Callable[[], None] | None = None,
                  frames: range | None = None) -> int:
        """Evaluates the ``frames`` (default: all) of one drive, whose frame 0 has the global
        index ``frame_offset`` (a work unit: its error models draw from the drive's own
        generator; a part of a drive only when :attr:`frames_independent`); returns the
        global index after the last frame."""
        self.prepare()
        drive = self.drives[drive_index]
        frames = range(drive.frames) if frames is None else frames
        collector.drives[(self.plan.name, drive_index)] = (frame_offset, drive.frames)
        if frames.start == 0:
            LOG.info("%s: route %s (%.0f m)", self.plan.name, [tuple(k) for k in drive.ego.lanes], drive.ego.length)
        with _frame_loop_gc():
            try:
                self._run_blocks(drive, drive_index, frames, collector, recorder, frame_offset, on_frame)
            finally:
                self._draw_overlays(collector)
        return frame_offset + frames.stop

    def _run_blocks(self, drive: Drive, drive_index: int, frames: range, collector: Collector,
                    recorder: Recorder | None, frame_offset: int, on_frame: Callable[[], None] | None) -> None:
        """The frame loop of :meth:`run_drive`: its ``frames`` in blocks of :data:`BLOCK_FRAMES`."""
        lane_error = None if self.lane_errors is None else self.lane_errors[drive_index]
        for first in range(frames.start, frames.stop, BLOCK_FRAMES):
            block = range(first, min(first + BLOCK_FRAMES, frames.stop))
            sensed = sense_block(drive.states_block(block), self.sensor, self.plan.errors,
                                 self.drive_rngs[drive_index],
                                 stamps_s=[(frame_offset + frame) / FRAME_RATE_HZ for frame in block],
                                 neighbours=self.neighbours, lane_error=lane_error)
            fused = [self._fuse_frame(collector, drive_index, frame_offset + frame, frame_sensed)
                     for frame, frame_sensed in zip(block, sensed)]
            measured = iter(self._measure_many([lane for frame in fused for _, lane, _ in frame.steps
                                                if lane is not None]))
            for frame in fused:
                self._finish_frame(frame, measured, recorder)
                collector.frames_done += 1
                if on_frame is not None:
                    on_frame()
            del sensed
            release_free_heap()

    @property
    def frames_independent(self) -> bool:
        """Whether a frame can be evaluated without the frames before it: the sensor error
        models are off (nothing draws from the drive's generator, no lane-model error
        evolves) and no history or message exchange carries state from frame to frame."""
        return self.exchange is None and self.plan.errors == SensorErrorModel() and self.lane_errors is None

    def note_unmatched(self, collector: Collector) -> None:
        """Notes (and logs) the ego detections of this map without ground truth, if any."""
        plan = self.plan
        unmatched = sum(rejected == NO_GROUND_TRUTH for key, a in collector.accumulators.items()
                        if key.map == plan.name and key.fusion == "local" and key.boundary == "left"
                        for rejected in a.records.values("rejected"))
        if unmatched:
            note = (f"{plan.name}: no ground truth for {unmatched} of {self.total_frames} ego detections (no "
                    "Lanelet2 lanelet at the pose: the converted map does not overlay the OpenDRIVE map there)")
            LOG.warning(note)
            collector.notes.append(note)

    def _fuse_frame(self, collector: Collector, drive_index: int, index: int,
                    sensed: dict[str, Sensed]) -> _FusedFrame:
        """One frame (global index ``index``) of drive ``drive_index`` from its vehicles'
        detections ``sensed`` (:func:`sense_block`): all pairs fused, their lanes to measure
        and what records them (:meth:`_finish_frame`, after the lanes of the whole block are
        measured in one :meth:`GroundTruthMeter.measure_many`)."""
        plan = self.plan
        stamp = index / FRAME_RATE_HZ
        self._relations.clear()
        self._true_lanes.clear()
        sent: dict[str, int] = {}
        if self.exchange is not None:
            sensed, sent = self.exchange.apply(drive_index, sensed, stamp)
        ego = sensed["ego"]
        frame = _FusedFrame(index, stamp, sensed)
        for scenario in plan.scenarios:
            if scenario.fusion == "local":
                frame.steps.append((frame.gt_lines, *self._local(collector, scenario, ego, index, stamp,
                                                                 frame.metrics)))
                continue
            if scenario.vehicles > 2:
                frame.steps.append((frame.fused_lines, *self._chain(collector, scenario, sensed, index, stamp, sent)))
                continue
            for name, other in sensed.items():
                if name == "ego" or abs(abs(other.state.lead_m) - scenario.lead_m) > 1e-9:
                    continue
                if name in sent:
                    for key in self._keys(scenario):
                        collector.add_traffic(key, sent[name], 1.0 / FRAME_RATE_HZ)
                frame.steps.append((frame.fused_lines, *self._pair(collector, scenario, ego, other, index, stamp,
                                                                   frame.metrics)))
        return frame

    def _finish_frame(self, frame: _FusedFrame, measured: Iterator[Measurement | str],
                      recorder: Recorder | None) -> None:
        """Records a fused frame in scenario order, its lanes' measurements taken from
        ``measured`` in turn, and writes it to the ``recorder``."""
        for lines, lane, finish in frame.steps:
            lines.update(finish(None if lane is None else next(measured)))
        if recorder is not None:
            stamp, index = frame.stamp, frame.index
            for name, item in frame.sensed.items():
                if item.detection is not None:
                    recorder.write_detection(stamp, index, name, detection_pose(item.detection), item.detection.left,
                                             item.detection.right, ego=name == "ego", lanes=item.detection)
            if frame.gt_lines:
                recorder.write_gt(stamp, frame.gt_lines)
            recorder.write_fused(stamp, frame.fused_lines)
            recorder.write_metrics(stamp, index, frame.metrics)

    def _local(self, collector: Collector, scenario: Scenario, ego: Sensed, index: int, stamp: float,
               metrics: dict[str, float | None]) -> tuple[Lane | None, Finish]:
        """The ego's own detection: the lane to measure (None when there is no detection) and
        what records its measurement, giving the GT lines of the MCAP."""
        keys = self._keys(scenario)

        def reject(rejected: str, why: str = "") -> dict[str, NDArrayFloat]:
            record = FrameRecord.trusted(index, stamp, "ego", "", _NO_ERRORS, rejected=rejected, gt_unmatched=why,
                                         end_reason=ego.end_reason, stopping=self.stopping)
            for key in keys:
                collector.add(key, record)
            return {}

        if ego.detection is None:
            return None, lambda _: reject(ego.missing("ego"))
        detection = ego.detection
        left, right = world_borders(detection)
        state = ego.state
        truth = state.track.borders_between(state.station, state.station + self.sensor.range_m)

        def finish(measured: Measurement | str | None) -> dict[str, NDArrayFloat]:
            assert measured is not None
            if isinstance(measured, str) or measured.gt_unmatched:
                return reject(*_rejection(measured))
            own = own_variances(detection)
            self._record(collector, scenario, keys, measured, index, stamp, "ego", "", math.nan, None, None, metrics,
                         end_reason=ego.end_reason,
                         sigmas=(None, None) if own is None else (np.sqrt(own[0].world), np.sqrt(own[1].world)))
            self._keep_overlay(collector, scenario, index, measured, {"ego": detection}, {})
            shown = np.vstack((left, right))
            low, high = shown.min(axis=0) - OVERLAY_MARGIN_M, shown.max(axis=0) + OVERLAY_MARGIN_M
            return {"left": _crop(measured.left_gt, low, high), "right": _crop(measured.right_gt, low, high)}

        return (left, right, detection_pose(detection), truth), finish

    def _measure_many(self, lanes: list[Lane]) -> list[Measurement | str]:
        """The measurement of each lane (:meth:`GroundTruthMeter.measure_many`), or why it has
        none: ``NO_GROUND_TRUTH`` when no GT matches, ``MAP_BROKEN`` over a broken map."""
        from gt_matching import MatchingError

        assert self.meter is not None
        found: list[Measurement | str] = []
        for (left, right, _, _), measured in zip(lanes, self.meter.measure_many(lanes)):
            if isinstance(measured, MatchingError):
                LOG.debug("no ground truth: %s", measured)
                found.append(NO_GROUND_TRUTH)
            elif not measured.gt_unmatched and self.plan.ground_truth == "engine" and self.broken.over(left, right):
                found.append(replace(measured, gt_unmatched=MAP_BROKEN))
            else:
                found.append(measured)
        return found

    def _pair(self, collector: Collector, scenario: Scenario, ego: Sensed, other: Sensed, index: int, stamp: float,
              metrics: dict[str, float | None]) -> tuple[Lane | None, Finish]:
        """The fusion of ``other`` into the ego: the fused lane to measure (None when there is
        none) and what records its measurement, giving the fused lines of the MCAP."""
        plan = self.plan
        truth, relation = self._relation(ego.state, other.state)
        step = _PairStep(self, collector, scenario, index, stamp, ego, other, truth, relation,
                         self._detected(truth, ego, other, scenario.fusion))
        if ego.detection is None or other.detection is None:
            step.refused = (ego.missing("ego") if ego.detection is None else other.missing("coop"), None, math.nan,
                            math.nan)
            return None, step
        mode = scenario.fusion
        interpolation = scenario.interpolation or "paper"
        start = time.perf_counter()
        if plan.history_m > 0:
            result = fusion.fuse_history(ego.detection, other.detection, mode=mode, interpolation=interpolation,
                                         params=plan.params)
        elif mode == "spline":
            result = resolve_method(interpolation)(ego.detection, other.detection, plan.params)
        else:
            result = fusion.fuse(ego.detection, other.detection, mode=mode, interpolation=interpolation,
                                 params=plan.params)
        step.runtime = (time.perf_counter() - start) * 1e3
        step.result = result
        if other.state.role == "coop":
            step.metrics = metrics
            start = time.perf_counter()
            fusion.is_fusible(ego.detection, other.detection, plan.params, mode=mode)
            collector.add_check_ms(step.names.label, (time.perf_counter() - start) * 1e3)
        if result.kind == "none":
            step.refused = (reason_category(result.reason), False, step.runtime, 0.0)
            return None, step
        return ((result.left, result.right, detection_pose(ego.detection),
                 self._frame_true_lane(ego.state, other.state)), step)

    def _chain(self, collector: Collector, scenario: Scenario, sensed: dict[str, Sensed], index: int, stamp: float,
               sent: dict[str, int]) -> tuple[Lane | None, Finish]:
        """A chain of the ego and the scenario's coops (:func:`fusion.fuse_chain`), when all of
        them are present; a chain that ends early is rejected with its failing link's reason.
        The chained lane to measure (None when there is none) and what records its measurement."""
        plan = self.plan
        keys = self._keys(scenario)
        members = [sensed.get(f"coop{lead:g}") for lead in scenario.chain_leads_m]
        ego = sensed["ego"]
        if any(member is None for member in members):
            return None, lambda _: {}
        coops = [member for member in members if member is not None]
        for coop in coops:
            if coop.state.name in sent:
                for key in keys:
                    collector.add_traffic(key, sent[coop.state.name], 1.0 / FRAME_RATE_HZ)
        links = list(zip([ego, *coops], coops))
        valid = [lane_relation(self.graph, a.state, b.state, self.relation_max_m, self.sensor.range_m)
                 for a, b in links]
        truth = all(valid)
        found = [self._detected(link_truth, a, b, scenario.fusion) for link_truth, (a, b) in zip(valid, links)]
        detected = None if None in found else all(found)
        last = coops[-1].state.name

        def reject(reason: str, predicted: bool | None = None, runtime: float = math.nan,
                   why: str = "") -> dict[str, NDArrayFloat]:
            record = FrameRecord.trusted(index, stamp, "ego", last, _NO_ERRORS, runtime_ms=runtime, rejected=reason,
                                         predicted_fusible=predicted, truly_fusible=truth, gt_unmatched=why,
                                         stopping=self.stopping, detected_fusible=detected)
            for key in keys:
                collector.add(key, record)
            return {}

        if ego.detection is None or any(c.detection is None for c in coops):
            reason = (ego.missing("ego") if ego.detection is None
                      else next(c for c in coops if c.detection is None).missing("coop"))
            return None, lambda _: reject(reason)
        ego_detection = ego.detection
        start = time.perf_counter()
        chain = fusion.fuse_chain(ego.detection, [c.detection for c in coops if c.detection is not None],
                                  mode=scenario.fusion, interpolation=scenario.interpolation or "paper",
                                  params=plan.params)
        runtime = (time.perf_counter() - start) * 1e3
        if chain.vehicles < scenario.vehicles:
            return None, lambda _: reject(reason_category(chain.reason), False, runtime)

        def finish(measured: Measurement | str | None) -> dict[str, NDArrayFloat]:
            assert measured is not None
            if isinstance(measured, str) or measured.gt_unmatched:
                rejected, why = _rejection(measured)
                return reject(rejected, True, runtime, why)
            self._record(collector, scenario, keys, measured, index, stamp, "ego", last, runtime, True, truth, None,
                         sigmas=(chain.left_sigma, chain.right_sigma), detected=detected)
            detections = {c.state.name: c.detection for c in coops if c.detection is not None}
            self._keep_overlay(collector, scenario, index, measured, {"ego": ego_detection, **detections},
                               {"left": chain.left, "right": chain.right})
            return {}

        return ((chain.left, chain.right, detection_pose(ego.detection),
                 self._frame_true_lane(ego.state, coops[-1].state)), finish)

    def _keys(self, scenario: Scenario) -> tuple[ScenarioKey, ScenarioKey]:
        """The report keys of the scenario's left and right boundary on this map."""
        return self._names(scenario).keys

    def _names(self, scenario: Scenario) -> _Names:
        """The scenario's :class:`_Names` on this map, made once."""
        names = self._scenario_names.get(scenario)
        if names is None:
            label = scenario.label
            names = self._scenario_names[scenario] = _Names(
                (scenario.key(self.plan.name, "left"), scenario.key(self.plan.name, "right")),
                (self.plan.name, label), (f"{label}-left", f"{label}-right"),
                tuple(f"{label}_{side}".replace("-", "_") for side in ("left", "right")))  # type: ignore[arg-type]
        return names

    def _relation(self, ego: VehicleState, other: VehicleState) -> tuple[bool, str]:
        """Whether ``other`` is truly on a trajectory of the ego (:func:`lane_relation`) and
        the kind of the pair (:func:`relation_kind`); once per frame and vehicle."""
        found = self._relations.get(other.name)
        if found is None:
            truth = lane_relation(self.graph, ego, other, self.relation_max_m, self.sensor.range_m)
            found = self._relations[other.name] = (truth, relation_kind(ego, other, truth))
        return found

    def _detected(self, truth: bool, ego: Sensed, other: Sensed, mode: str) -> bool | None:
        """Whether ``other`` is truly on a trajectory of the ego (``truth``, :meth:`_relation`)
        and the two detections as the sensors made them admit the paper's rule for ``mode``:
        they overlap (convoy) or leave a gap 0 < d_s <= d_i (spline), the gap d_s measured as
        the rule measures it between the lanes the sensors read before any error model
        (:attr:`Sensed.read_ends`). None when either vehicle sent no detection or the
        detections fused are not the sensors' (a lane history or message exchange)."""
        if self.exchange is not None or ego.detection is None or other.detection is None:
            return None
        if not truth:
            return False
        assert ego.read_ends is not None and other.read_ends is not None
        (p_end, t_end), (p_start, _) = ego.read_ends[1], other.read_ends[0]
        gap = signed_gap_m(p_end, t_end, p_start)
        return gap <= 0.0 if mode == "convoy" else 0.0 < gap <= max_gap_m(self.plan.params)

    def _frame_true_lane(self, ego: VehicleState, other: VehicleState) -> tuple[NDArrayFloat, NDArrayFloat]:
        """:meth:`true_lane`, once per frame and vehicle."""
        found = self._true_lanes.get(other.name)
        if found is None:
            found = self._true_lanes[other.name] = self.true_lane(ego, other)
        return found

    def true_lane(self, ego: VehicleState, other: VehicleState) -> tuple[NDArrayFloat, NDArrayFloat]:
        """The lane a fusion of ``other`` into the ego should reproduce: the other's track
        to its detection end when it drives on from the ego's lanes (coop, turn), else the
        ego's own lanes as far ahead."""
        end = ego.station + abs(other.lead_m) + self.sensor.range_m
        if other.role in ("coop", "turn"):
            return other.track.borders_between(ego.station, min(end, other.track.length))
        return ego.track.borders_between(ego.station, min(end, ego.track.length))

    def _record(self, collector: Collector, scenario: Scenario, keys: tuple[ScenarioKey, ...], measured: Measurement,
                index: int, stamp: float, ego: str, coop: str, runtime: float, predicted: bool | None,
                truth: bool | None, metrics: dict[str, float | None] | None, *, relation: str = "",
                confidence: float = math.nan, end_reason: str = "",
                sigmas: tuple[NDArrayFloat | None, NDArrayFloat | None] = (None, None),
                detected: bool | None = None) -> None:
        sides = ((measured.left_errors_m, measured.left_range_m), (measured.right_errors_m, measured.right_range_m))
        known = measured.known_to_m(LANE_ACCURACY_M)
        prefixes = self._names(scenario).prefixes
        for key, (errors, length), near, sigma, prefix in zip(keys, sides, measured.near_points(), sigmas, prefixes):
            collector.add(key, FrameRecord.trusted(index, stamp, ego, coop, errors, perception_range_m=length,
                                                   runtime_ms=runtime, predicted_fusible=predicted,
                                                   truly_fusible=truth, relation=relation, confidence=confidence,
                                                   end_reason=end_reason, near_points=near, known_to_m=known,
                                                   stopping=self.stopping, sigma_m=sigma, detected_fusible=detected))
            if metrics is not None:  # np.mean and np.max as they compute them, without their wrappers
                metrics[f"{prefix}_mean_error_m"] = float(np.add.reduce(errors)) / errors.size
                metrics[f"{prefix}_max_error_m"] = float(np.maximum.reduce(errors))
                metrics[f"{prefix}_range_m"] = length

    def _keep_overlay(self, collector: Collector, scenario: Scenario, index: int, measured: Measurement,
                      detections: dict[str, fusion.LaneDetection], fused: dict[str, NDArrayFloat]) -> None:
        """Keeps this frame as the scenario's overlay when its error is the largest so far
        (drawn when the drive ends, :meth:`_draw_overlays`)."""
        largest = np.maximum.reduce
        worst = float(max(largest(measured.left_errors_m), largest(measured.right_errors_m)))
        label = self._names(scenario).label
        kept = self._worst.get(label) or collector.overlays.get(label)
        if kept is None or worst > kept.max_error_m:
            self._worst[label] = _Worst(index, worst, measured, detections, fused)

    def _draw_overlays(self, collector: Collector) -> None:
        """The kept frames as the scenarios' overlays in ``collector`` (the senders' detections
        drawn in the world frame, the GT cropped around them and the fused lane)."""
        for label, (index, worst, measured, detections, fused) in self._worst.items():
            borders = {name: world_borders(detection) for name, detection in detections.items()}
            shown = np.vstack([*fused.values(), *(b for pair in borders.values() for b in pair)])
            low, high = shown.min(axis=0) - OVERLAY_MARGIN_M, shown.max(axis=0) + OVERLAY_MARGIN_M
            gt = {"left": _crop(measured.left_gt, low, high), "right": _crop(measured.right_gt, low, high)}
            collector.overlays[label] = Overlay(index, worst, gt, borders, fused)
        self._worst.clear()


GROUND_TRUTHS: Final[dict[str, str]] = {
    "engine": "the map engine (its borders and lane graph)",
    "crdesigner": "commonroad-scenario-designer",
}
"""How each ``MapPlan.ground_truth`` is named in the notes."""


@contextmanager
def _frame_loop_gc() -> Iterator[None]:
    """The cyclic garbage collector set for a drive's frames until exit: the objects alive on
    entry (the lane graph, the ground truth, ...) moved out of its reach (``gc.freeze``, then
    ``gc.unfreeze``), so that its collections do not scan them each time (on Town01 that took
    0.26 ms per frame), and its young generation collected every
    :data:`FRAME_LOOP_GC_THRESHOLD` allocations. Left as it is while some caller froze objects."""
    if gc.get_freeze_count():
        yield
        return
    threshold = gc.get_threshold()
    gc.freeze()
    gc.set_threshold(FRAME_LOOP_GC_THRESHOLD, *threshold[1:])
    try:
        yield
    finally:
        gc.set_threshold(*threshold)
        gc.unfreeze()


def _rejection(measured: Measurement | str) -> tuple[str, str]:
    """(``FrameRecord.rejected``, ``FrameRecord.gt_unmatched``) of a lane without a score:
    no ground truth at all, or a GT that does not cover it ("gt_unmatched" and why)."""
    if isinstance(measured, str):
        return measured, ""
    return GT_UNMATCHED, measured.gt_unmatched


def _crop(line: NDArrayFloat, low: NDArrayFloat, high: NDArrayFloat) -> NDArrayFloat:
    """The stretch of ``line`` from its first to its last point inside the box [low, high],
    plus one point on either side."""
    inside = np.flatnonzero(np.all((line >= low) & (line <= high), axis=1))
    return line if inside.size < 2 else line[max(inside[0] - 1, 0): inside[-1] + 2]
