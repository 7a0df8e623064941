"""``cold-fuse``: re-fusing a cold-eval recording reproduces its errors, detections from
another source are fused, bad recordings are refused with one line."""

from __future__ import annotations

import json

import numpy as np
import pytest
from conftest import bundled_map
from mcap_helpers import read_all, write_v1_recording

from cold_maps.cli import evaluate
from cold_maps.cli import fuse
from cold_maps.recording.recorder import METADATA_STATUS, Recorder, read_detections, read_metadata, read_stamp_base


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    out = tmp_path_factory.mktemp("rec")
    assert evaluate.main(["--map", str(bundled_map("straight")), "--frames", "4", "--routes", "1", "--gaps", "30",
                          "--interpolation", "paper", "--no-distractors", "--no-plots", "--out", str(out)]) == 0
    return out


def _scenarios(folder):
    document = json.loads((folder / "metrics.json").read_text())
    return {(r["fusion"], r["boundary"]): r for r in document["scenarios"]}


def test_refusion_reproduces_cold_eval(recording, tmp_path):
    report = tmp_path / "report"
    status = fuse.main(["--input", str(recording / "run.mcap"), "-o", str(tmp_path / "re.mcap"),
                            "--report", str(report)])
    assert status == 0
    before, after = _scenarios(recording), _scenarios(report)
    for key in (("local", "left"), ("convoy", "right"), ("spline", "left")):
        for metric in ("mean_error_m", "max_error_m", "perception_range_m"):
            assert after[key][metric] == pytest.approx(before[key][metric], abs=1e-9)
        assert after[key]["fused_frames"] == before[key]["fused_frames"] == 4
    frames = list(read_detections(tmp_path / "re.mcap"))
    assert len(frames) == 4 and {d["sender"] for d in frames[0][1]} == {"ego", "coop25", "coop60"}
    assert read_metadata(tmp_path / "re.mcap")[METADATA_STATUS]["status"] == "complete"


def _history_run(out, *history):
    assert evaluate.main(["--map", str(bundled_map("straight")), "--frames", "4", "--routes", "1", "--gaps", "30",
                          "--interpolation", "paper", "--no-distractors", "--no-plots", "--noise", "0.05",
                          *history, "--out", str(out)]) == 0
    return out


def test_refusion_reproduces_the_history_fusion_of_the_run(tmp_path):
    """cold-eval --history 100 records each coop's lane history in run.mcap; cold-fuse fuses
    with it and reproduces the run's errors and ranges exactly (with 5 cm noise and drift, so
    a fusion without the histories would differ: the run without --history, same detections,
    shows it)."""
    run = _history_run(tmp_path / "run", "--history", "100", "--drift")
    report = tmp_path / "report"
    assert fuse.main(["--input", str(run / "run.mcap"), "-o", str(tmp_path / "re.mcap"), "--report", str(report)]) == 0
    before, after, plain = _scenarios(run), _scenarios(report), _scenarios(_history_run(tmp_path / "plain"))
    for key in (("local", "left"), ("convoy", "right"), ("spline", "left"), ("spline", "right")):
        for metric in ("mean_error_m", "max_error_m", "perception_range_m"):
            assert after[key][metric] == pytest.approx(before[key][metric], abs=1e-9)
        assert after[key]["fused_frames"] == before[key]["fused_frames"] == 4
    assert abs(plain[("spline", "left")]["max_error_m"] - before[("spline", "left")]["max_error_m"]) > 1e-3
    (_, detections), *_ = read_detections(run / "run.mcap")
    histories = {d["sender"]: d["history"] for d in detections}
    assert histories["ego"] is None and all(histories[c] is not None for c in ("coop25", "coop60"))
    assert histories["coop60"].left[-1] == pytest.approx((0.0, 2.0), abs=0.3)  # ends at the coop, lane 4 m wide


def test_fuses_detections_from_another_source(tmp_path):
    """Two straight detections written by hand: 'car0' at x = 0 and 'car1' at x = 20 m,
    lane borders at y = ±2 m; convoy fusion spans x = 0 ... 50 m."""
    path = tmp_path / "other.mcap"
    xs = np.arange(0.0, 30.01, 0.1)
    left, right = np.column_stack((xs, np.full_like(xs, 2.0))), np.column_stack((xs, np.full_like(xs, -2.0)))
    with Recorder(path) as recorder:
        for frame in range(3):
            recorder.write_detection(frame * 0.1, frame, "car0", (0.0, 0.0, 0.0), left, right, ego=True)
            recorder.write_detection(frame * 0.1, frame, "car1", (20.0, 0.0, 0.0), left, right)
    out = tmp_path / "fused.mcap"
    assert fuse.main(["--input", str(path), "-o", str(out), "--ego", "car0"]) == 0
    _, messages, _ = read_all(out)
    fused = [m for topic, _, m, _ in messages if topic == "/fused"]
    assert len(fused) == 3
    line = next(e for e in fused[0].entities if e.id == "car1-left").lines[0].points
    assert (line[0].x, line[-1].x) == pytest.approx((0.0, 50.0))
    assert all(p.y == pytest.approx(2.0) for p in line)
    assert read_stamp_base(out) == read_stamp_base(path)


def test_version_1_recording_is_fused_like_version_2(tmp_path):
    """The same detections in a version-1 file (float stamps, JSON only) and in a version-2
    file fuse to the same report; the output keeps the input's stamps (base 0 for v1)."""
    xs = np.arange(0.0, 30.01, 0.1)
    left, right = np.column_stack((xs, np.full_like(xs, 2.0))), np.column_stack((xs, np.full_like(xs, -2.0)))
    detections = [(frame * 0.1, frame, sender, pose, left, right) for frame in range(3)
                  for sender, pose in (("car0", (0.0, 0.0, 0.0)), ("car1", (20.0, 0.0, 0.1)))]
    (tmp_path / "v1").mkdir()
    (tmp_path / "v2").mkdir()
    old, new = tmp_path / "v1" / "rec.mcap", tmp_path / "v2" / "rec.mcap"
    write_v1_recording(old, detections)
    with Recorder(new) as recorder:
        for stamp, frame, sender, pose, l, r in detections:
            recorder.write_detection(stamp, frame, sender, pose, l, r, ego=sender == "car0")
    reports = []
    for path in (old, new):
        out = path.with_name("fused.mcap")
        assert fuse.main(["--input", str(path), "-o", str(out), "--ego", "car0", "--report",
                          str(path.with_name("report"))]) == 0
        rows = [row.split(",") for row in path.with_name("report").joinpath("frames.csv").read_text().splitlines()]
        runtime = rows[0].index("runtime_ms")
        reports.append([row[:runtime] + row[runtime + 1:] for row in rows])
        assert [f for f, _ in read_detections(out)] == [0, 1, 2]
    assert reports[0] == reports[1] and len(reports[0]) > 3
    _, messages, _ = read_all(old.with_name("fused.mcap"))
    assert [t for topic, _, _, t in messages if topic == "/metrics"] == [0, 100_000_000, 200_000_000]


def _fails(capsys, argv):
    status = fuse.main(argv)
    err = capsys.readouterr().err.strip()
    assert status == 1 and "\n" not in err and "Traceback" not in err
    return err


def test_not_an_mcap(tmp_path, capsys):
    bad = tmp_path / "bad.mcap"
    bad.write_text("hello")
    assert "not an MCAP" in _fails(capsys, ["--input", str(bad), "-o", str(tmp_path / "o.mcap")])
    assert not (tmp_path / "o.mcap").exists()


def test_foreign_mcap(tmp_path, capsys):
    from mcap.writer import Writer

    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema(name="x", encoding="jsonschema", data=b"{}")
        channel = writer.register_channel(topic="/camera", message_encoding="json", schema_id=schema)
        writer.add_message(channel, log_time=0, publish_time=0, data=b"{}")
        writer.finish()
    assert "/cold/detections" in _fails(capsys, ["--input", str(foreign), "-o", str(tmp_path / "o.mcap")])


def test_same_input_and_output_and_unwritable_output(recording, tmp_path, capsys):
    rec = str(recording / "run.mcap")
    assert "overwrite" in _fails(capsys, ["--input", rec, "-o", rec])
    assert "cannot create" in _fails(capsys, ["--input", rec, "-o", str(tmp_path / "missing" / "o.mcap")])
