"""Batch evaluation: drives on a map, lane detections, fusion per frame, errors against GT.

For every frame of every drive each vehicle senses its lane (``LaneSensor`` on the
OpenDRIVE map, optional seeded error models), the ego's detection is measured alone
(``local``) and fused with every other present vehicle for each scenario (``convoy``;
``spline`` per interpolation and gap d_s). Fused lanes are measured against Lanelet2
ground truth (``converters.load_lanelet2``, matched by ``gt_matching``) by closest-point
distances to the GT borders resampled every 0.02 m; the fusion's decision is scored
against the true lane relation of the pair (:func:`cold_maps.simulation.drive.lane_relation`).

Results go into a :class:`Collector` (``report.ScenarioAccumulator`` per scenario key,
runtimes, one overlay per scenario), optionally also frame by frame into an MCAP
``Recorder``.
"""

from __future__ import annotations

import logging
import math
import time
from typing import TYPE_CHECKING, Callable, Final

import numpy as np

import fusion
from cold_maps.evaluation.collector import Collector, Overlay
from cold_maps.evaluation.report import FrameRecord, ScenarioKey
from cold_maps.evaluation.scenarios import MapPlan, Scenario, reason_category
from cold_maps.groundtruth.meter import GroundTruthMeter, Measurement
from cold_maps.network.lane_graph import LaneGraph, load_graph
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.detection import Sensed, detection_pose, sense, world_borders
from cold_maps.simulation.drive import (
    FRAME_RATE_HZ,
    Drive,
    DriveError,
    VehicleState,
    build_drive,
    covering_routes,
    lane_relation,
    relation_kind,
    required_route_length,
    route_from_start,
)
from cold_maps.simulation.neighbours import NeighbourSensor
from cold_maps.simulation.sensor import SENSOR_RANGE_M, LaneSensor

if TYPE_CHECKING:
    from cold_maps.recording.recorder import Recorder
    from gt_matching import GroundTruth

LOG = logging.getLogger("cold_maps.evaluation")

OVERLAY_MARGIN_M: Final[float] = 10.0
"""The overlay plot shows the GT this far (m) around the detections and the fused lane."""
RELATION_MARGIN_M: Final[float] = 5.0
"""Slack (m) on the longest lane distance at which a coop counts as ahead of the ego."""


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
        self.neighbours = NeighbourSensor(self.graph, plan.lanes) if plan.lanes > 0 else None
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
        sensed = {name: sense(state, self.sensor, plan.errors, self.rng, stamp_s=stamp, neighbours=self.neighbours)
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
                    recorder.write_detection(stamp, index, name, detection_pose(item.detection), item.detection.left,
                                             item.detection.right, ego=name == "ego", lanes=item.detection)
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
        measured = self._measure(left, right, detection_pose(ego.detection), truth)
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
        relation = relation_kind(ego.state, other.state, truth)
        main = other.state.role == "coop"
        label = (plan.name, scenario.label)

        def reject(reason: str, predicted: bool | None = None, runtime: float = math.nan,
                   confidence: float = math.nan) -> None:
            for key in keys:
                collector.add(key, FrameRecord(index, stamp, "ego", other.state.name, np.empty(0), runtime_ms=runtime,
                                               rejected=reason, predicted_fusible=predicted, truly_fusible=truth,
                                               relation=relation, confidence=confidence))

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
            reject(reason_category(result.reason), False, runtime, 0.0)
            return None
        measured = self._measure(result.left, result.right, detection_pose(ego.detection),
                                 self.true_lane(ego.state, other.state))
        if isinstance(measured, str):
            reject(measured, True, runtime, result.confidence)
            return None
        self._record(collector, scenario, keys, measured, index, stamp, "ego", other.state.name, runtime, True,
                     truth, metrics if main else None, relation=relation, confidence=result.confidence)
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
                truth: bool | None, metrics: dict[str, float | None] | None, *, relation: str = "",
                confidence: float = math.nan) -> None:
        sides = ((measured.left_errors_m, measured.left_range_m), (measured.right_errors_m, measured.right_range_m))
        for key, (errors, length) in zip(keys, sides):
            collector.add(key, FrameRecord(index, stamp, ego, coop, errors, perception_range_m=length,
                                           runtime_ms=runtime, predicted_fusible=predicted, truly_fusible=truth,
                                           relation=relation, confidence=confidence))
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
