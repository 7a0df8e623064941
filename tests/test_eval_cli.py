"""``cold-eval`` end to end: output files and their schema, the paper's figures on the
bundled maps, bad input, interrupts and crashes."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest
from batch_outputs import stalled_run
from conftest import bundled_map

from cold_maps.cli import evaluate
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.recording.recorder import METADATA_STATUS, read_detections, read_metadata

RECORD_KEYS = {"map", "fusion", "interpolation", "d_s", "boundary", "mean_error_m", "rmse_m", "max_error_m",
               "p95_error_m", "perception_range_m", "frames", "fused_frames", "runtime_ms", "rejected", "fusibility",
               "perception_range_distribution_m", "by_distance", "stopping", "end_reasons"}


@pytest.fixture(scope="module")
def straight_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("straight") / "out"
    status = evaluate.main(["--map", str(bundled_map("straight")), "--frames", "4", "--routes", "2", "--gaps", "30",
                            "--out", str(out)])
    return status, out


def _records(out: Path) -> dict:
    document = json.loads((out / "metrics.json").read_text())
    return document, {(r["map"], r["fusion"], r["interpolation"], r["d_s"], r["boundary"]): r
                      for r in document["scenarios"]}


def test_outputs_and_metrics_schema(straight_run):
    status, out = straight_run
    assert status == 0
    document, records = _records(out)
    assert document["partial"] is False
    assert len(records) == 2 * (1 + 1 + 2)  # local, convoy, spline paper and hermite at d_s = 30
    for record in records.values():
        assert RECORD_KEYS <= set(record)
        assert set(record["runtime_ms"]) == {"mean", "std", "max"}
    with open(out / "frames.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert len(rows) == sum(r["frames"] for r in records.values())
    summary = (out / "summary.md").read_text()
    assert "| straight | spline | hermite | 30.0 | left |" in summary and "Runtime (Table I)" in summary
    plots = {p.name for p in (out / "plots").iterdir()}
    assert {"errors_straight_convoy.png", "overlay_straight_spline-paper-d30.png"} <= plots


def test_what_cold_adds_on_the_straight_road(straight_run):
    """Ideal sensor on a straight road at 10 m/s, default stopping distance d = 43.7 m: the
    ego alone (30 m) never knows its lane out to d, the convoy (55 m) always does; the ego's
    detections all end at the sensor's range; only the spline lane (90 m) has far points."""
    _, out = straight_run
    _, records = _records(out)
    local, convoy = records[("straight", "local", "", 0.0, "left")], records[("straight", "convoy", "", 0.0, "left")]
    spline = records[("straight", "spline", "paper", 30.0, "left")]
    assert local["stopping"]["distance_m"] == pytest.approx(1.1 * (10 * 2.5 + 100 / 6.8))
    assert (local["stopping"]["share"], convoy["stopping"]["share"]) == (0.0, 1.0)
    assert local["stopping"]["frames"] == local["frames"] == 8
    assert local["end_reasons"] == {"range": 8} and convoy["end_reasons"] == {}
    assert local["perception_range_distribution_m"]["p50"] == pytest.approx(30.0, abs=0.01)
    assert local["by_distance"]["far"]["points"] == 0
    assert convoy["by_distance"]["far"]["points"] == pytest.approx(8 * 150, abs=8)
    assert spline["by_distance"]["far"]["points"] > 0 and spline["by_distance"]["far"]["max_error_m"] < 0.05
    assert "stopping distance d = 1.1·(v·t_r + v²/(2a)) = 43.7 m" in (out / "summary.md").read_text()


def test_mcap_channels_and_detections(straight_run):
    _, out = straight_run
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as stream:
        summary = make_reader(stream).get_summary()
    topics = {c.topic for c in summary.channels.values()}
    assert {"/gt", "/fused", "/metrics", "/cold/detections", "/detections/ego", "/detections/coop60"} <= topics
    frames = list(read_detections(out / "run.mcap"))
    assert [f for f, _ in frames] == list(range(8))  # 2 routes x 4 frames, indices continue across routes
    assert all(d["left"].shape[1] == 2 for _, group in frames for d in group)
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "complete"


def test_paper_figures(tmp_path):
    out = tmp_path / "paper"
    # 25 m per frame over each whole route (the default is 1 m per frame at 10 m/s)
    assert evaluate.main(["--paper", "--speed", "250", "--no-mcap", "--no-plots", "--out", str(out)]) == 0
    _, records = _records(out)

    def worst(map_name, fusion, interpolation, d_s, key="max_error_m"):
        return max(records[(map_name, fusion, interpolation, d_s, b)][key] for b in ("left", "right"))

    for interpolation in ("paper", "hermite"):
        for d_s, reach in ((30.0, 90.0), (50.0, 110.0)):
            assert worst("straight", "spline", interpolation, d_s) <= 0.05
            reached = worst("straight", "spline", interpolation, d_s, "perception_range_m")
            assert reached == pytest.approx(reach, abs=0.5)
            record = records[("straight", "spline", interpolation, d_s, "left")]
            assert record["fused_frames"] == record["frames"] == 36  # d_s = 50 m is within d_i
    for map_name in ("straight", "curve90", "rural"):
        # convoy fusion keeps the local error; local range 30 m, convoy 55 m
        assert worst(map_name, "convoy", "", 0.0) == pytest.approx(worst(map_name, "local", "", 0.0), abs=0.002)
        assert worst(map_name, "convoy", "", 0.0, "perception_range_m") == pytest.approx(55.0, abs=1.0)
    assert worst("curve90", "spline", "hermite", 20.0) <= 0.25
    assert worst("rural", "spline", "hermite", 20.0) <= 0.25
    assert 0.2 < worst("curve90", "spline", "paper", 20.0) < 1.2  # the paper: 0.7 m
    summary = (out / "summary.md").read_text()
    assert "Table II vs the paper, `hermite` interpolation" in summary and "Longest gap" in summary


def _one_line_error(capsys, status):
    err = capsys.readouterr().err.strip()
    assert status == 1 and err.count("\n") == 0 and "Traceback" not in err
    return err


def test_missing_map(tmp_path, capsys):
    status = evaluate.main(["--map", str(tmp_path / "nope.xodr"), "--out", str(tmp_path / "out")])
    assert "nope.xodr" in _one_line_error(capsys, status)
    assert not (tmp_path / "out" / "metrics.json").exists()


def test_route_too_short(tmp_path, capsys):
    status = evaluate.main(["--map", str(bundled_map("curve90")), "--frames", "5000", "--out", str(tmp_path / "o")])
    assert "no drivable route" in _one_line_error(capsys, status)
    assert not (tmp_path / "o" / "metrics.json").exists()


def test_unwritable_output_folder(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("x")
    status = evaluate.main(["--map", str(bundled_map("curve90")), "--out", str(blocker / "out")])
    assert "output folder" in _one_line_error(capsys, status)


@pytest.mark.parametrize("exception, code", [(KeyboardInterrupt, 130), (RuntimeError, 1)])
def test_interrupt_or_crash_leaves_partial_outputs(tmp_path, monkeypatch, capsys, exception, code):
    original = MapEvaluator._finish_frame
    calls = []

    def failing(self, *args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise exception("stop")
        return original(self, *args, **kwargs)

    monkeypatch.setattr(MapEvaluator, "_finish_frame", failing)
    out = tmp_path / "out"
    status = evaluate.main(["--map", str(bundled_map("curve90")), "--frames", "10", "--routes", "1", "--out", str(out)])
    assert status == code
    assert "partial" in capsys.readouterr().err
    document, records = _records(out)
    assert document["partial"] is True
    assert records[("curve90", "local", "", 0.0, "left")]["frames"] == 2
    assert "PARTIAL RUN" in (out / "summary.md").read_text()
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "partial"
    assert not (out / "run.mcap.partial").exists()


def test_interrupt_while_drawing_plots_rewrites_the_report_as_partial(tmp_path, monkeypatch, capsys):
    """Ctrl-C after the last frame, while the plots are drawn: the report is rewritten as
    partial, this run's plots (and a killed worker's temporary file) are removed, one line."""
    from cold_maps.evaluation import plots

    drawn = []

    def interrupted(path, *args, **kwargs):
        drawn.append(path)
        if len(drawn) == 2:
            path.with_name(f".{path.name}.abc123.part").write_bytes(b"half a PNG")
            raise KeyboardInterrupt
        path.write_bytes(b"PNG")

    monkeypatch.setattr(plots, "plot_error_series", interrupted)
    _assert_interrupted_after_the_frames(tmp_path / "out", capsys, frames=6, routes=1, workers=1)
    assert len(drawn) == 2


def _assert_interrupted_after_the_frames(out, capsys, *, frames: int, routes: int, workers: int) -> None:
    """A curve90 run interrupted after its last frame: exit 130 with one line, a partial
    report of every frame without plots, the recording complete."""
    status = evaluate.main(["--map", str(bundled_map("curve90")), "--frames", str(frames), "--routes", str(routes),
                            "--workers", str(workers), "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert status == 130 and err == f"cold-eval: error: interrupted; partial report in {out}"
    document, records = _records(out)
    assert document["partial"] is True and records[("curve90", "local", "", 0.0, "left")]["frames"] == frames * routes
    assert "PARTIAL RUN" in (out / "summary.md").read_text()
    assert not (out / "plots").exists()
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "complete"  # every frame was recorded


def test_interrupt_while_the_run_workers_exit_rewrites_the_report_as_partial(tmp_path, monkeypatch, capsys):
    """Ctrl-C after the last frame of a run in two workers, while its workers exit before
    the plot workers start: a partial report without plots, one line, exit 130."""
    from cold_maps.evaluation import parallel

    class Interrupted:
        def __init__(self, run, workers):
            self.run = run

        def __enter__(self):
            raise KeyboardInterrupt

        def __exit__(self, *exc_info):
            return False

    monkeypatch.setattr(parallel, "plot_pool", Interrupted)
    _assert_interrupted_after_the_frames(tmp_path / "out", capsys, frames=20, routes=2, workers=2)


def test_signals_are_held_inside_signals_ignored():
    import os
    import signal

    from cold_maps.common.signals import signals_ignored

    # A suite started in the background (`pytest &`) inherits SIGINT ignored: set Python's own handler.
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with signals_ignored():
            os.kill(os.getpid(), signal.SIGINT)  # dropped, not raised
            assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        with pytest.raises(KeyboardInterrupt):
            os.kill(os.getpid(), signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, inherited)


@pytest.mark.parametrize("signal_name, status, word", [("SIGINT", 130, "interrupted"),
                                                       ("SIGTERM", 143, "terminated")])
def test_signal_finalises_the_recording(tmp_path, signal_name, status, word):
    """A real Ctrl-C (SIGINT) or SIGTERM (a scheduler, ``timeout``, a container stop) on
    the command line: exit 130 / 143 with one line on stderr, MCAP finalised as partial,
    report marked partial."""
    import os
    import signal

    out = tmp_path / "out"
    process = stalled_run(["--map", str(bundled_map("rural")), "--frames", "1500", "--routes", "1", "--no-plots",
                           "--out", str(out)], tmp_path / "stalled", processes=1)
    os.kill(process.pid, getattr(signal, signal_name))
    _, err = process.communicate(timeout=60)
    assert process.returncode == status, err
    assert err.strip().startswith(f"cold-eval: error: {word}") and len(err.strip().splitlines()) == 1, err
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "partial"
    document, _ = _records(out)
    assert document["partial"] is True


def test_false_fusions_are_counted_and_kept_apart():
    import numpy as np

    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.report import FrameRecord, ScenarioKey
    from cold_maps.evaluation.run import false_fusion_markdown

    collector = Collector()
    key = ScenarioKey("m", "spline", "paper", 20.0, "left")
    collector.add(key, FrameRecord(0, 0.0, "ego", "coop", np.array([0.1, 0.3]), predicted_fusible=True,
                                   truly_fusible=True))
    collector.add(key, FrameRecord(0, 0.0, "ego", "adjacent", np.array([3.5]), predicted_fusible=True,
                                   truly_fusible=False))
    collector.add(key, FrameRecord(1, 0.1, "ego", "opposite", np.empty(0), rejected="opposite_direction",
                                   predicted_fusible=False, truly_fusible=False))
    assert "| m | spline | paper | 20 | left | 2 | 1 | 0.200 | 0.300 |" in false_fusion_markdown(collector)


def test_a_run_without_fusions_says_so_instead_of_empty_tables(tmp_path):
    import numpy as np

    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.report import FrameRecord, ScenarioKey, runtime_markdown
    from cold_maps.evaluation.run import NO_FUSIONS, false_fusion_markdown, write_outputs

    collector = Collector()
    collector.add(ScenarioKey("m", "local", "", 0.0, "left"), FrameRecord(0, 0.0, "ego", "", np.array([0.01])))
    results = [a.result() for a in collector.accumulators.values()]
    assert false_fusion_markdown(collector) == "" and runtime_markdown(results, collector.check_ms) == ""
    write_outputs(tmp_path, collector, partial=False, plots=False, sections=[("Longest gap", "")])
    summary = (tmp_path / "summary.md").read_text()
    assert summary.count(f"\n\n{NO_FUSIONS}") == 2
    assert "| map | scenario | fusion mean" not in summary and "| fused | false fusions |" not in summary


def test_stamp_base_sets_the_log_times(tmp_path):
    """--stamp-base 1700000000.25: frame i is logged at that time plus i / 10 Hz, exactly in ns."""
    from mcap.reader import make_reader

    out = tmp_path / "out"
    assert evaluate.main(["--map", str(bundled_map("straight")), "--frames", "3", "--routes", "1", "--gaps", "30",
                          "--interpolation", "paper", "--no-plots", "--stamp-base", "1700000000.25",
                          "--out", str(out)]) == 0
    with open(out / "run.mcap", "rb") as stream:
        summary = make_reader(stream).get_summary()
    assert summary.statistics.message_start_time == 1_700_000_000_250_000_000
    assert summary.statistics.message_end_time == 1_700_000_000_250_000_000 + 200_000_000
    assert read_metadata(out / "run.mcap")["cold.run"]["stamp_base_ns"] == "1700000000250000000"
    assert [d["stamp_s"] for _, group in read_detections(out / "run.mcap") for d in group[:1]] == [0.0, 0.1, 0.2]


@pytest.mark.parametrize("value", ["-1", "nan", "soon", "1e12"])
def test_bad_stamp_base_is_a_usage_error(value, capsys):
    with pytest.raises(SystemExit) as exit_info:
        evaluate.main(["--map", "x.xodr", "--stamp-base", value])
    assert exit_info.value.code == 2 and "--stamp-base" in capsys.readouterr().err


def test_unscored_evaluations_are_said_to_match_no_ground_truth():
    """Over 1 % of a map's evaluations rejected gt_unmatched: a warning with the count and
    the matcher's reasons (a lane the GT covers can still fail to match, e.g. where a
    lanelet overlaps itself)."""
    import numpy as np

    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.report import FrameRecord, ScenarioKey
    from cold_maps.evaluation.trust import GT_UNMATCHED, UNMATCHED_SHARE_LIMIT, unmatched_warnings

    collector = Collector()
    key = ScenarioKey("m", "local", "", 0.0, "left")
    for frame in range(98):
        collector.add(key, FrameRecord(frame, 0.0, "ego", "", np.array([0.01])))
    for frame in (98, 99):
        collector.add(key, FrameRecord(frame, 0.0, "ego", "", np.empty(0), rejected=GT_UNMATCHED,
                                       gt_unmatched="off_lane"))
    assert 2 / 100 > UNMATCHED_SHARE_LIMIT
    assert unmatched_warnings(collector) == [
        "m: 2 of 100 evaluations (2.0%) not scored, no ground-truth lanelets matched the detected lane (off_lane: 2)"]


@pytest.mark.parametrize(("unscored", "total", "flagged"), [(1, 100, False), (2, 200, False), (2, 199, True),
                                                            (3, 100, True), (0, 100, False)])
def test_a_map_is_flagged_only_above_one_percent_of_unscored_evaluations(unscored, total, flagged):
    """Every unscored evaluation counts (GT that does not cover the lane, the map broken
    under it, no lanelet at the pose), over every scenario and side of the map; other
    rejections (no lane produced) are evaluations but not unscored ones."""
    import numpy as np

    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.report import FrameRecord, ScenarioKey
    from cold_maps.evaluation.trust import GT_UNMATCHED, MAP_BROKEN, NO_GROUND_TRUTH, unmatched_warnings

    collector = Collector()
    keys = [ScenarioKey("m", "local", "", 0.0, "left"), ScenarioKey("m", "convoy", "", 25.0, "right")]
    kinds = [(NO_GROUND_TRUTH, ""), (GT_UNMATCHED, MAP_BROKEN), (GT_UNMATCHED, "off_lane")]
    for frame in range(total):
        key = keys[frame % 2]
        if frame < unscored:
            rejected, why = kinds[frame % 3]
            record = FrameRecord(frame, 0.0, "ego", "", np.empty(0), rejected=rejected, gt_unmatched=why)
        elif frame % 5 == 0:
            record = FrameRecord(frame, 0.0, "ego", "coop25", np.empty(0), rejected="no_overlap")
        else:
            record = FrameRecord(frame, 0.0, "ego", "", np.array([0.01]))
        collector.add(key, record)
    warnings = unmatched_warnings(collector)
    assert bool(warnings) == flagged
    if flagged:
        assert warnings[0].startswith(f"m: {unscored} of {total} evaluations ({unscored / total:.1%}) not scored")
        assert f"{NO_GROUND_TRUTH}: 1" in warnings[0]
