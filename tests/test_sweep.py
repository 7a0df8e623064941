"""``cold-eval sweep``: the grid's cells, resuming after Ctrl-C, the same rows on a Dask
cluster, the summary's safe gap, and methods from outside the package."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest
from batch_outputs import default_sigint, rows_without_runtimes
from conftest import bundled_map

from cold_maps.cli import evaluate
from cold_maps.evaluation.sweep import CELLS_DIR, Cell, load_cell
from cold_maps.evaluation.sweep_report import gap_points, safe_gaps, summary_markdown
from cold_maps.simulation.sensor_profile import CAMERA

GRID = ("--gaps", "20,30,50", "--interpolation", "paper,hermite", "--seeds", "0,1", "--frames", "5", "--routes", "1")
CELLS = 2 * 3 * 2 * 2
ROWS_PER_CELL = 3 * 2  # local, convoy, spline x two borders


def _maps() -> list[str]:
    return [arg for name in ("straight", "curve90") for arg in ("--map", str(bundled_map(name)))]


def _rows(out: Path) -> list[dict]:
    import pyarrow.parquet as pq

    rows = pq.read_table(out / "results.parquet").to_pylist()
    with open(out / "results.csv", newline="") as stream:
        assert len(list(csv.DictReader(stream))) == len(rows)
    return rows


@pytest.fixture(scope="module")
def resumed(tmp_path_factory):
    """A sweep interrupted by SIGINT after a few cells, then run again to the end."""
    out = tmp_path_factory.mktemp("sweep") / "out"
    process = subprocess.Popen([sys.executable, "-m", "cold_maps.cli.evaluate", "sweep", *_maps(), *GRID,
                                "--workers", "1", "--no-plots", "--out", str(out)],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               cwd=Path(__file__).resolve().parents[1],
                               preexec_fn=default_sigint)
    deadline = time.monotonic() + 120
    while (len(list((out / CELLS_DIR).glob("*.json"))) if (out / CELLS_DIR).exists() else 0) < 3 \
            and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.02)
    os.kill(process.pid, signal.SIGINT)
    _, err = process.communicate(timeout=60)
    before = {path: (path.stat().st_ino, path.stat().st_mtime_ns) for path in (out / CELLS_DIR).glob("*.json")}
    partial_rows = _rows(out)
    partial_summary = (out / "summary.md").read_text()
    return out, process.returncode, err, before, partial_rows, partial_summary


def test_an_interrupted_sweep_keeps_its_finished_cells(resumed):
    out, status, err, before, partial_rows, partial_summary = resumed
    assert status == 130 and "Traceback" not in err, err
    assert err.strip().startswith("cold-eval: error: sweep: interrupted") and len(err.strip().splitlines()) == 1, err
    assert 3 <= len(before) < CELLS
    assert len(partial_rows) == ROWS_PER_CELL * len(before)
    assert f"PARTIAL SWEEP: {len(before)} of {CELLS} cells finished" in partial_summary


def test_a_restarted_sweep_computes_only_the_missing_cells(resumed, capsys):
    out, _, _, before, _, _ = resumed
    assert evaluate.main(["sweep", *_maps(), *GRID, "--workers", "1", "--no-plots", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert f"{CELLS - len(before)} cells computed, {len(before)} finished before, {CELLS} in the grid" in printed
    for path, (inode, mtime) in before.items():
        assert (path.stat().st_ino, path.stat().st_mtime_ns) == (inode, mtime)  # not written again
    rows = _rows(out)
    assert len(rows) == CELLS * ROWS_PER_CELL and len(list((out / CELLS_DIR).glob("*.json"))) == CELLS
    grid = [(r["map"], r["cell_d_s_m"], r["cell_interpolation"], r["cell_seed"]) for r in rows[::ROWS_PER_CELL]]
    assert grid == [(m, g, i, s) for m in ("straight", "curve90") for g in (20.0, 30.0, 50.0)
                    for i in ("paper", "hermite") for s in (0, 1)]
    spline = [r for r in rows if r["fusion"] == "spline"]
    assert all(r["interpolation"] == r["cell_interpolation"] and r["d_s"] == r["cell_d_s_m"] for r in spline)
    straight = [r for r in spline if r["map"] == "straight"]
    assert all(r["perception_range_m"] == pytest.approx(60.0 + r["d_s"], abs=0.05) for r in straight)
    assert "PARTIAL" not in (out / "summary.md").read_text()


def test_a_dask_cluster_gives_the_same_rows(resumed, tmp_path):
    from distributed import LocalCluster

    out, _, _, _, _, _ = resumed
    reference = rows_without_runtimes(_rows(out))
    with LocalCluster(n_workers=2, processes=True, threads_per_worker=1, memory_limit="1GiB",
                      dashboard_address=None) as cluster:
        assert evaluate.main(["sweep", *_maps(), *GRID, "--scheduler", cluster.scheduler_address, "--no-plots",
                              "--out", str(tmp_path / "dask")]) == 0
    assert len(reference) == CELLS * ROWS_PER_CELL
    assert rows_without_runtimes(_rows(tmp_path / "dask")) == reference


def test_a_method_from_the_test_suite_is_in_the_sweep_table(tmp_path):
    out = tmp_path / "m"
    method = "fusion_method_example:straight_bridge"
    assert evaluate.main(["sweep", "--map", str(bundled_map("straight")), "--gaps", "30", "--interpolation", "paper",
                          "--method", method, "--frames", "3", "--routes", "1", "--workers", "1", "--out",
                          str(out)]) == 0
    spline = {r["interpolation"]: r for r in _rows(out) if r["fusion"] == "spline" and r["boundary"] == "left"}
    assert set(spline) == {"paper", method}
    assert spline[method]["max_error_m"] < 1e-6 < spline["paper"]["max_error_m"]  # exact on a straight road
    assert f"| straight | {method} | 0 | 0 | 30 |" in (out / "summary.md").read_text()
    assert (out / "plots" / "sweep_straight.png").stat().st_size > 0 and (out / "plots" / "safe_gap.png").exists()


def _row(d_s: float, max_error: float | None, noise: float = 0.0, boundary: str = "left", **sensor: str) -> dict:
    return {**{f"cell_{k}": v for k, v in sensor.items()}, "map": "m", "fusion": "spline", "interpolation": "paper",
            "boundary": boundary, "max_error_m": max_error,
            "p95_error_m": None if max_error is None else max_error / 2, "perception_range_m": 60.0 + d_s,
            "fused_frames": 0 if max_error is None else 1, "frames": 1, "cell_noise_sigma_m": noise,
            "cell_pose_sigma_xy_m": 0.0, "cell_d_s_m": d_s}


def test_the_safe_gap_is_the_longest_gap_within_0_75_m():
    rows = [_row(10, 0.2), _row(20, 0.5), _row(20, 0.74, boundary="right"), _row(30, 0.76), _row(50, None),
            _row(10, 0.9, noise=0.05), _row(20, 0.8, noise=0.05)]
    points = gap_points(rows)
    assert [(p.d_s_m, p.max_error_m) for p in points if p.noise_sigma_m == 0] == [
        (10, 0.2), (20, 0.74), (30, 0.76), (50, None)]
    assert safe_gaps(points) == {("m", "paper", "ideal", 0.0, 0.0): 20.0, ("m", "paper", "ideal", 0.05, 0.0): None}
    text = summary_markdown(rows, cells=3, finished=2)
    assert "| m | paper | 0 | 0 | 20 |" in text and "| m | paper | 0.05 | 0 | none |" in text
    assert "PARTIAL SWEEP: 2 of 3 cells finished" in text


def test_a_sensor_axis_keeps_its_cells_apart_and_shows_in_the_summary():
    """Rows of two sensors at one level are two points; the summary gains a sensor column."""
    rows = [_row(20, 0.5, sensor="ideal"), _row(20, 0.9, sensor="camera"), _row(10, 0.6, sensor="camera")]
    assert safe_gaps(gap_points(rows)) == {("m", "paper", "camera", 0.0, 0.0): 10.0,
                                           ("m", "paper", "ideal", 0.0, 0.0): 20.0}
    text = summary_markdown(rows, cells=2, finished=2)
    assert "| m | paper | camera | 0 | 0 | 20 | 0.900 |" in text and "| m | paper | ideal | 0 | 0 | 20 |" in text


def test_a_cell_is_keyed_by_its_parameters_and_the_map_bytes(tmp_path):
    cell = Cell("a/m.xodr", "m", "0" * 64, 20.0, "paper", 0.0, 0.0, 0, 5, 1)
    assert replace(cell, map_path="b/m.xodr").key == cell.key  # a moved map is the same cell
    assert len({cell.key, replace(cell, map_sha256="1" * 64).key, replace(cell, seed=1).key,
                replace(cell, d_s_m=30.0).key, replace(cell, sensor=CAMERA).key,
                replace(cell, sensor=replace(CAMERA, max_range_m=60.0)).key}) == 6
    assert replace(cell, sensor=CAMERA).params()["cell_sensor"] == "camera"
    (tmp_path / CELLS_DIR).mkdir()
    (tmp_path / CELLS_DIR / f"{cell.key}.json").write_text('{"cell": {}, "rows": []}')
    assert load_cell(tmp_path, cell) is None  # another cell's file under this key is not trusted


def test_a_missing_map_is_one_line_on_stderr(tmp_path, capsys):
    status = evaluate.main(["sweep", "--map", str(tmp_path / "nope.xodr"), "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert status == 1 and "nope.xodr" in err and err.count("\n") == 0
    assert not (tmp_path / "out").exists()


def test_a_bad_sweep_sensor_is_a_usage_error(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        evaluate.main(["sweep", "--map", "m.xodr", "--sensor", "ideal,lidar", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err.strip()
    assert exit_.value.code == 2 and "unknown sensor 'lidar'" in err and "\n" not in err
