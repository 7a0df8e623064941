"""``cold-fuse``: fusion re-run on recorded lane detections.

Reads the ``/cold/detections`` channel (``cold.LaneDetection``, see
:mod:`cold_maps.recording.recorder`) of an MCAP file written by ``cold-eval`` or by any other source
in that format (recording version 1, 2 or 3), or an ASAM OSI trace (``.osi``) of
``cold-eval --osi`` (:mod:`cold_maps.recording.osi`), fuses the ego's detection (sender ``--ego``)
with every other sender's of the same frame (with the sender's lane history when the
recording carries one, :func:`fusion.fuse_history`, as ``cold-eval --history`` fused it), and
writes a new MCAP (version 3, on the input's stamp base): the detections again, the fused
lanes on ``/fused`` and per-frame metrics on ``/metrics``. With ``--map`` (or the map named in
the recording's ``cold.run`` metadata) the local and fused lanes are measured against Lanelet2
ground truth; ``--report DIR`` writes summary.md, metrics.json and frames.csv there
(fusion ``convoy`` when the detections overlap, else ``spline``; d_s 0 = all gaps pooled).
Exit 0; 1 with one line on stderr for bad input or a crash; 130 when interrupted.
"""

from __future__ import annotations

import argparse
import logging
import math
import sys
import time
from pathlib import Path
from typing import Any, Final, Sequence

import numpy as np

from cold_maps.cli.common import builds, cli_entry, finite_number, make_parser, validated

PROG: Final[str] = "cold-fuse"
UNRECORDED: Final[frozenset[str]] = frozenset({"verbose", "quiet", "no_progress"})
"""Options that change no result, left out of the provenance parameters."""


def build_parser() -> argparse.ArgumentParser:
    """The ``cold-fuse`` argument parser."""
    from fusion import DEFAULT_PARAMS, FusionParams

    parser = make_parser(PROG, "Fuse recorded lane detections (cold.LaneDetection) again.", progress=True)
    parser.add_argument("--input", required=True, type=Path, metavar="REC.mcap|TRACE.osi",
                        help="recording to read: a cold-eval run.mcap, or an OSI trace of cold-eval --osi (a name "
                             "ending in .osi)")
    parser.add_argument("-o", "--output", required=True, type=Path, metavar="OUT.mcap", help="recording to write")
    parser.add_argument("--ego", default="ego", help="sender id of the ego vehicle (default ego)")
    parser.add_argument("--mode", choices=("auto", "convoy", "spline"), default="auto", help="fusion mode")
    parser.add_argument("--interpolation", choices=("paper", "hermite"), default="paper", help="spline interpolation")
    parser.add_argument("--max-gap", type=validated(finite_number, builds(FusionParams, "d_i_m")), default=None,
                        metavar="D_I", help="longest gap d_i bridged by spline fusion in m (default "
                                            f"{DEFAULT_PARAMS.d_i_m:g}, the fusion default)")
    parser.add_argument("--map", type=Path, default=None, help="OpenDRIVE map for ground truth (default: the "
                        "recording's cold.run map, or an OSI trace's GroundTruth.map_reference, when it names one "
                        "readable file)")
    parser.add_argument("--no-gt", action="store_true", help="do not measure against ground truth")
    parser.add_argument("--report", type=Path, default=None,
                        help="folder for summary.md, metrics.json, frames.csv (default: none, no report)")
    return parser


def is_osi_trace(path: Path) -> bool:
    """Whether ``cold-fuse`` reads ``path`` as an OSI trace (its name ends in ``.osi``)."""
    return path.suffix.lower() == ".osi"


def _map_path(args: argparse.Namespace) -> Path | None:
    from cold_maps.recording.recorder import METADATA_RUN, read_metadata

    if args.no_gt:
        return None
    if args.map is not None:
        return args.map
    if is_osi_trace(args.input):
        from cold_maps.recording.osi import first_map_reference

        named = first_map_reference(args.input)
    else:
        named = read_metadata(args.input).get(METADATA_RUN, {}).get("map", "")
    path = Path(named) if named else None
    return path if path is not None and path.suffix == ".xodr" and path.is_file() else None


def _meter(map_path: Path | None) -> Any:
    if map_path is None:
        return None
    from cold_maps.groundtruth.lanelet2_from_engine import engine_converter
    from cold_maps.groundtruth.meter import GroundTruthMeter
    from converters import load_lanelet_map
    from gt_matching import GroundTruth

    return GroundTruthMeter(GroundTruth(load_lanelet_map(map_path, converter=engine_converter()), prepare_all=False))


class Refuser:
    """Fuses and measures recorded frames into a collector and a recorder.

    Fields (attributes): ``ego`` sender id, fusion ``mode``, ``interpolation`` and ``params``,
    ``meter`` (a ``GroundTruthMeter`` or None), ``map_name`` for the report, ``collector``.
    """

    def __init__(self, ego: str, mode: str, interpolation: str, meter: Any, map_name: str, params: Any) -> None:
        from cold_maps.evaluation.collector import Collector

        self.ego, self.mode, self.interpolation, self.params = ego, mode, interpolation, params
        self.meter, self.map_name = meter, map_name
        self.collector = Collector()
        self.frames_without_ego = 0

    def frame(self, frame: int, detections: list[dict[str, Any]], recorder: Any) -> None:
        """Fuses one recorded frame and writes it to ``recorder``."""
        import fusion
        from cold_maps.evaluation.scenarios import reason_category

        stamp = detections[0]["stamp_s"]
        lanes = {d["sender"]: fusion.LaneDetection(fusion.Pose2D(**d["pose"]), d["left"], d["right"], stamp=stamp,
                                                   sender=d["sender"], neighbours=d["neighbours"],
                                                   road_edges=d["road_edges"], branches=d["branches"],
                                                   history=d["history"], left_sigma=d.get("left_sigma"),
                                                   right_sigma=d.get("right_sigma"))
                 for d in detections}
        for d in detections:
            recorder.write_detection(stamp, frame, d["sender"], tuple(d["pose"].values()), d["left"], d["right"],
                                     ego=d["sender"] == self.ego, lanes=lanes[d["sender"]])
        ego = lanes.get(self.ego)
        if ego is None:
            self.frames_without_ego += 1
            recorder.write_fused(stamp, {})
            return
        pose = (ego.pose.x, ego.pose.y, ego.pose.yaw)
        metrics: dict[str, float | None] = {}
        fused_lines = {}
        local = self._measure(*_world(ego), pose)
        self._add("local", frame, stamp, "", local, math.nan, "", None)
        for sender, coop in lanes.items():
            if sender == self.ego:
                continue
            start = time.perf_counter()
            result = fusion.fuse_history(ego, coop, mode=self.mode, interpolation=self.interpolation,
                                         params=self.params)
            runtime = (time.perf_counter() - start) * 1e3
            kind = "convoy" if result.gap_m <= 0.0 else "spline"
            metrics[f"{sender}_gap_m"] = result.gap_m
            metrics[f"{sender}_runtime_ms"] = runtime
            if result.kind == "none":
                self._add(kind, frame, stamp, sender, None, runtime, reason_category(result.reason), False)
                continue
            fused_lines.update({f"{sender}-left": result.left, f"{sender}-right": result.right})
            ego_left, ego_right = _world(ego)
            coop_left, coop_right = _world(coop)
            reference = (np.vstack((ego_left, coop_left)), np.vstack((ego_right, coop_right)))
            measured = self._measure(result.left, result.right, pose, reference)
            self._add(kind, frame, stamp, sender, measured, runtime, "", True)
            if _scored(measured):
                metrics[f"{sender}_left_max_error_m"] = float(np.max(measured.left_errors_m))
                metrics[f"{sender}_right_max_error_m"] = float(np.max(measured.right_errors_m))
        recorder.write_fused(stamp, fused_lines)
        recorder.write_metrics(stamp, frame, metrics)

    def _measure(self, left: np.ndarray, right: np.ndarray, pose: tuple[float, float, float],
                 reference: tuple[np.ndarray, np.ndarray] | None = None) -> Any:
        """The lane's ``Measurement`` (``gt_unmatched`` names why the lanelets matched to
        ``reference`` do not cover it: without the drive's true path a spline across a
        junction may cut the corner by more than the matcher's 1.5 m and is then not
        measured), or None without a map, or ``no_ground_truth`` (no lanelet at the pose).
        ``reference`` defaults to the lane; for a fused lane it is the ego's and the coop's
        detections."""
        from gt_matching import MatchingError

        if self.meter is None:
            return None
        try:
            measured = self.meter.measure(left, right, pose, reference=reference)
        except MatchingError:
            return "no_ground_truth"
        return measured

    def _add(self, fusion_name: str, frame: int, stamp: float, coop: str, measured: Any, runtime: float,
             rejected: str, predicted: bool | None) -> None:
        from cold_maps.evaluation.report import FrameRecord, ScenarioKey
        from cold_maps.evaluation.trust import GT_UNMATCHED
        from cold_maps.evaluation.safety import LANE_ACCURACY_M

        interpolation = self.interpolation if fusion_name == "spline" else ""
        why = ""
        if isinstance(measured, str):
            rejected = measured
        elif measured is not None and measured.gt_unmatched:
            rejected, why = GT_UNMATCHED, measured.gt_unmatched
        for boundary in ("left", "right"):
            key = ScenarioKey(self.map_name, fusion_name, interpolation, 0.0, boundary)
            if _scored(measured):
                left = boundary == "left"
                record = FrameRecord(frame, stamp, self.ego, coop, measured.left_errors_m if left else
                                     measured.right_errors_m, perception_range_m=measured.left_range_m if left
                                     else measured.right_range_m, runtime_ms=runtime, predicted_fusible=predicted,
                                     near_points=measured.near_points()[0 if left else 1],
                                     known_to_m=measured.known_to_m(LANE_ACCURACY_M))
            else:
                record = FrameRecord(frame, stamp, self.ego, coop, np.empty(0), runtime_ms=runtime,
                                     rejected=rejected or "not_measured", predicted_fusible=predicted,
                                     gt_unmatched=why)
            self.collector.add(key, record)


def _scored(measured: Any) -> bool:
    """Whether ``measured`` (what ``Refuser._measure`` returned) is a lane's score: a
    ``Measurement`` whose ground truth covers the lane."""
    return not isinstance(measured, str) and measured is not None and not measured.gt_unmatched


def _world(detection: Any) -> tuple[np.ndarray, np.ndarray]:
    from cold_maps.simulation.detection import world_borders

    return world_borders(detection)


def _detection_count(path: Path) -> int:
    """Number of ``/cold/detections`` messages in the recording's summary statistics, or of
    messages in an OSI trace's sidecar (0 if unknown)."""
    from mcap.reader import make_reader

    if is_osi_trace(path):
        from cold_maps.recording.osi import read_sidecar

        messages = read_sidecar(path).get("messages", 0)
        return messages if isinstance(messages, int) and messages > 0 else 0

    from cold_maps.recording.recorder import TOPIC_RAW_DETECTIONS

    with open(path, "rb") as stream:
        summary = make_reader(stream).get_summary()
    if summary is None or summary.statistics is None:
        return 0
    counts = summary.statistics.channel_message_counts
    return sum(counts.get(c.id, 0) for c in summary.channels.values() if c.topic == TOPIC_RAW_DETECTIONS)


def _read_input(path: Path) -> tuple[Any, int]:
    """The frames of detections of the recording or OSI trace ``path`` (as
    ``recorder.read_detections`` yields them) and its stamp base (ns since the Unix epoch;
    an OSI trace's sidecar's, 0 without one)."""
    if is_osi_trace(path):
        from cold_maps.recording.osi import read_osi_detections, read_sidecar

        base = read_sidecar(path).get("stamp_base_ns", 0)
        if isinstance(base, bool) or not isinstance(base, int) or base < 0:
            raise ValueError(f"{path}.json: stamp_base_ns: expected an integer >= 0, got {base!r}")
        return read_osi_detections(path), base
    from cold_maps.recording.recorder import read_detections, read_stamp_base

    return read_detections(path), read_stamp_base(path)


@cli_entry(PROG)
def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``cold-fuse``; returns the exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    args = build_parser().parse_args(argv)
    from cold_maps.cli.common import (configure_logging, fail, interruption, progress_stream, result_line,
                                      startup_failure)
    from cold_maps.common.progress import ProgressBar
    from cold_maps.common.provenance import make_provenance, recorded_params
    from cold_maps.recording.recorder import Recorder

    configure_logging(args.verbose, args.quiet)
    error: BaseException | None = None
    try:
        if args.input.resolve() == args.output.resolve():
            raise ValueError(f"{args.output}: output would overwrite the input recording")
        frames, stamp_base_ns = _read_input(args.input)
        detections_total = _detection_count(args.input)
        map_path = _map_path(args)
        import fusion

        params = fusion.DEFAULT_PARAMS if args.max_gap is None else fusion.FusionParams(d_i_m=args.max_gap)
        refuser = Refuser(args.ego, args.mode, args.interpolation, _meter(map_path),
                          map_path.stem if map_path else args.input.stem, params)
        report_dir = None
        if args.report is not None:
            from cold_maps.evaluation.run import prepare_out_dir

            report_dir = prepare_out_dir(args.report)
        provenance = make_provenance(PROG, argv, recorded_params({**vars(args), "d_i_m": params.d_i_m}, UNRECORDED),
                                     inputs=[("input", args.input), *([("map", map_path)] if map_path else [])])
        recorder = Recorder(args.output, map_path=map_path or "", params=provenance.params,
                            stamp_base_ns=stamp_base_ns).__enter__()
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - bad input is reported as one line
        return startup_failure(PROG, exc)
    count = 0
    try:
        with ProgressBar(max(detections_total, 1), PROG, stream=progress_stream(args)) as bar:
            for frame, detections in frames:
                refuser.frame(frame, detections, recorder)
                count += 1
                bar.update(len(detections))
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - outputs are finalised as partial
        error = exc
        logging.getLogger(PROG).debug("run ended early", exc_info=True)
    recorder.__exit__(type(error) if error is not None else None, error, None)
    if report_dir is not None:
        from cold_maps.evaluation.run import write_outputs

        write_outputs(report_dir, refuser.collector, partial=error is not None, plots=False, program=PROG,
                      provenance=provenance)
    if isinstance(error, KeyboardInterrupt):
        what, status = interruption(error)
        return fail(PROG, f"{what} after {count} frames; {args.output} finalised as partial", status)
    if error is not None:
        return fail(PROG, f"{error}; {args.output} finalised as partial")
    from cold_maps.evaluation.trust import verdict

    result_line(args, PROG, f"{count} frames fused -> {args.output}"
                + (f" ({refuser.frames_without_ego} without ego '{args.ego}')" if refuser.frames_without_ego else "")
                + verdict(refuser.collector))
    return 0


if __name__ == "__main__":
    sys.exit(main())
