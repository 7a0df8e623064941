"""``cold-eval --workers``: drives in worker processes give the same outputs as one process;
fusion methods named on the command line or registered as entry points."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from batch_outputs import frames_without_runtimes, mcap_messages, metrics_without_runtimes, stalled_run
from conftest import BUNDLED_MAPS_DIR, bundled_map

from cold_maps.cli import evaluate
from cold_maps.evaluation import methods
from cold_maps.recording.recorder import METADATA_STATUS, read_detections, read_metadata

BUNDLED = ("straight", "curve90", "rural", "junction", "highway")


def _run(out: Path, maps: list[Path], workers: int, *extra: str) -> Path:
    argv = [arg for path in maps for arg in ("--map", str(path))]
    # one log-time base for both runs (the default is each run's own wall-clock start)
    assert evaluate.main([*argv, "--workers", str(workers), "--out", str(out), "--no-plots", "--stamp-base", "0",
                          *extra]) == 0
    return out


def _assert_same_outputs(one: Path, two: Path) -> None:
    assert metrics_without_runtimes(one) == metrics_without_runtimes(two)
    assert frames_without_runtimes(one) == frames_without_runtimes(two)
    messages = mcap_messages(one)
    assert messages == mcap_messages(two)
    stamps = [stamp for _, stamp, _ in messages]
    assert stamps == sorted(stamps)


def test_two_workers_agree_with_one_on_the_bundled_maps_with_error_models(tmp_path):
    maps = [bundled_map(name) for name in BUNDLED]
    errors = ("--noise", "0.02", "--pose-xy", "0.1", "--drop", "0.1")
    common = ("--frames", "4", "--routes", "2", "--gaps", "20,50", *errors)
    one = _run(tmp_path / "one", maps, 1, *common)
    two = _run(tmp_path / "two", maps, 2, *common)
    _assert_same_outputs(one, two)
    frames = [frame for frame, _ in read_detections(two / "run.mcap")]
    assert frames == list(range(len(BUNDLED) * 2 * 4))  # indices continue across drives and maps
    notes = [line for line in (two / "summary.md").read_text().splitlines() if "route(s) of" in line]
    assert [line.split(":")[0] for line in notes] == [f"- {name}" for name in BUNDLED]
    dropped = json.loads((one / "metrics.json").read_text())["scenarios"][0]["rejected"]
    assert dropped.get("ego_dropped", 0) > 0  # the error models drew in the workers too


def test_two_workers_agree_with_one_with_chains_history_and_lossy_messages(tmp_path):
    """History, odometry drift and message losses draw from per-drive generators: the
    drives give the same results in any process."""
    maps = [bundled_map(name) for name in ("curve90", "rural")]
    common = ("--frames", "5", "--routes", "2", "--gaps", "20", "--interpolation", "hermite", "--coops", "2",
              "--history", "60", "--drift", "--exchange", "bezier", "--loss", "0.3", "--no-distractors")
    _assert_same_outputs(_run(tmp_path / "one", maps, 1, *common), _run(tmp_path / "two", maps, 2, *common))


def test_two_workers_agree_with_one_on_town01(tmp_path, town01_path):
    common = ("--frames", "15", "--routes", "3")
    _assert_same_outputs(_run(tmp_path / "one", [town01_path], 1, *common),
                         _run(tmp_path / "two", [town01_path], 2, *common))


def _evaluators(*argv: str) -> list:
    from cold_maps.evaluation.evaluator import MapEvaluator

    return [MapEvaluator(plan) for plan in evaluate._plans(evaluate.build_parser().parse_args(list(argv)))]


def test_drives_with_independent_frames_are_cut_into_frame_ranges():
    from cold_maps.evaluation.parallel import UNITS_PER_WORKER, most_units, work_units

    straight, rural = bundled_map("straight"), bundled_map("rural")
    evaluators = _evaluators("--map", str(straight), "--map", str(rural), "--frames", "45", "--routes", "1")
    assert all(e.frames_independent for e in evaluators) and [e.total_frames for e in evaluators] == [45, 45]
    units = work_units(evaluators, 2)
    # 2 drives, 2 workers: 2 * UNITS_PER_WORKER / 2 ranges per drive, at most one per 10 frames (4)
    assert UNITS_PER_WORKER >= 4 and len(units) == 8
    for map_index in (0, 1):
        ranges = [(u.first, u.stop) for u in units if u.map_index == map_index]
        assert ranges == [(0, 11), (11, 22), (22, 34), (34, 45)]  # rounded quarters, contiguous
    assert {u.frame_offset for u in units if u.map_index == 1} == {45}  # global indices continue
    assert most_units(evaluators) == 8 and most_units(evaluators[:1]) == 4  # one drive still uses 4 workers
    noisy = _evaluators("--map", str(straight), "--frames", "45", "--routes", "2", "--noise", "0.02")
    assert not noisy[0].frames_independent and most_units(noisy) == 2
    assert [(u.drive, u.first, u.stop, u.frame_offset) for u in work_units(noisy, 2)] == [(0, 0, 45, 0),
                                                                                            (1, 0, 45, 45)]


def test_long_drives_are_cut_into_units_of_at_most_max_unit_frames(monkeypatch):
    from cold_maps.evaluation import parallel

    monkeypatch.setattr(parallel, "MIN_UNIT_FRAMES", 1)
    monkeypatch.setattr(parallel, "MAX_UNIT_FRAMES", 5)
    evaluators = _evaluators("--map", str(bundled_map("straight")), "--frames", "45", "--routes", "2")
    units = parallel.work_units(evaluators, 2)  # 2 drives, 2 workers: 6 units per drive without the cap
    assert [(u.drive, u.first, u.stop) for u in units] == [(d, k * 5, k * 5 + 5) for d in (0, 1) for k in range(9)]


def test_two_workers_agree_with_one_when_drives_are_cut_into_frame_ranges(tmp_path):
    """One drive, cut into 4 frame ranges on the 2 workers."""
    common = ("--frames", "40", "--routes", "1", "--gaps", "20")
    maps = [bundled_map("rural")]
    _assert_same_outputs(_run(tmp_path / "one", maps, 1, *common), _run(tmp_path / "two", maps, 2, *common))


def test_plots_drawn_by_two_workers_are_those_of_one_process(tmp_path):
    """The plot workers (forked after the run's workers exit, from a parent that imported
    matplotlib while the units ran) draw the same PNG bytes as a run in one process."""
    drawn = {}
    for workers in (1, 2):
        out = tmp_path / str(workers)
        assert evaluate.main(["--map", str(bundled_map("rural")), "--frames", "20", "--routes", "2", "--gaps", "20",
                              "--workers", str(workers), "--no-mcap", "--out", str(out)]) == 0
        drawn[workers] = {path.name: path.read_bytes() for path in (out / "plots").glob("*.png")}
    assert len(drawn[1]) >= 6 and drawn[1] == drawn[2]


def test_sigint_with_workers_leaves_partial_outputs(tmp_path):
    """Ctrl-C of a run in two workers: exit 130, the finished drives in a valid partial MCAP
    and a partial report, no worker left behind."""
    import os
    import signal
    import subprocess
    import time

    out = tmp_path / "out"
    process = stalled_run(["--map", str(bundled_map("rural")), "--frames", "600", "--routes", "3", "--workers", "2",
                           "--no-plots", "--out", str(out)], tmp_path / "stalled", processes=2)
    children = [int(pid) for pid in subprocess.run(["pgrep", "-P", str(process.pid)], capture_output=True,
                                                   text=True).stdout.split()]
    assert len(children) >= 2  # the two workers (and multiprocessing's resource tracker)
    os.kill(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 130, err
    assert err.strip().startswith("cold-eval: error: interrupted") and len(err.strip().splitlines()) == 1, err
    assert read_metadata(out / "run.mcap")[METADATA_STATUS]["status"] == "partial"
    assert json.loads((out / "metrics.json").read_text())["partial"] is True
    deadline = time.monotonic() + 10
    while any(Path(f"/proc/{pid}").exists() for pid in children) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(Path(f"/proc/{pid}").exists() for pid in children)


def test_a_method_named_on_the_command_line_is_evaluated_beside_the_builtins(tmp_path):
    out = _run(tmp_path / "m", [bundled_map("straight")], 1, "--frames", "3", "--routes", "1", "--gaps", "30",
               "--method", "fusion_method_example:straight_bridge", "--method", "fusion_method_example:never_fuses")
    records = {(r["interpolation"], r["boundary"]): r for r in json.loads((out / "metrics.json").read_text())["scenarios"]
               if r["fusion"] == "spline"}
    assert {name for name, _ in records} == {"paper", "hermite", "fusion_method_example:straight_bridge",
                                             "fusion_method_example:never_fuses"}
    for boundary in ("left", "right"):
        bridge, paper = records[("fusion_method_example:straight_bridge", boundary)], records[("paper", boundary)]
        assert bridge["max_error_m"] < 1e-6  # a straight segment is exact on a straight road
        assert bridge["perception_range_m"] == pytest.approx(90.0, abs=0.05)  # 30 m ego + 30 m gap + 30 m coop
        assert bridge["fused_frames"] == paper["fused_frames"] == 3 and bridge["rejected"] == paper["rejected"]
        refused = records[("fusion_method_example:never_fuses", boundary)]
        assert refused["fused_frames"] == 0 and refused["rejected"] == {"other": refused["frames"]}


@pytest.mark.parametrize("name, message", [("nowhere_module:f", "no module nowhere_module in the installed packages"),
                                           ("fusion_method_example:missing", "has no missing"),
                                           ("not_registered", "not registered")])
def test_a_bad_method_name_is_one_line_on_stderr(tmp_path, capsys, name, message):
    """A method that does not resolve is a bad command line: exit 2, one line naming ``--method``."""
    with pytest.raises(SystemExit) as usage:
        evaluate.main(["--map", str(BUNDLED_MAPS_DIR / "straight.xodr"), "--method", name,
                       "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert usage.value.code == 2 and err.count("\n") == 0 and message in err and name in err
    assert err.startswith("cold-eval: error: argument --method: ") and err.endswith("(see cold-eval --help)")
    assert not (tmp_path / "out").exists()


def test_entry_points_register_methods(tmp_path, monkeypatch):
    """A distribution's ``cold_maps.fusion_methods`` entry point (a dist-info on sys.path)
    resolves by name; the built-ins resolve without installed metadata."""
    import fusion_method_example

    info = tmp_path / "my_methods-1.0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: my-methods\nVersion: 1.0\n")
    (info / "entry_points.txt").write_text(
        "[cold_maps.fusion_methods]\nbridge = fusion_method_example:straight_bridge\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    methods.resolve_method.cache_clear()
    try:
        assert methods.resolve_method("bridge") is fusion_method_example.straight_bridge
        assert methods.registered_methods()["bridge"] == "fusion_method_example:straight_bridge"
    finally:
        methods.resolve_method.cache_clear()
    assert methods.resolve_method("paper") is methods.paper
    assert methods.resolve_method("cold_maps.evaluation.methods:hermite") is methods.hermite
