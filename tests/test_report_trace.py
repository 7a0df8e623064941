"""Reports a researcher can read and trace: the overlay is the worst frame, routes and
methods are told apart in the plots, sweep plots survive outliers and draw categories as
categories, the summary explains its columns, and every output says how it was made."""

from __future__ import annotations

import csv
import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.cli import evaluate, fuse
from cold_maps.evaluation import plots, sweep_report
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import MapEvaluator
from cold_maps.evaluation.plots import LOG_SPAN_RATIO, ErrorSeries, plot_error_series
from cold_maps.evaluation.report import (
    REJECTION_REASONS,
    FrameRecord,
    ScenarioAccumulator,
    ScenarioKey,
    read_metrics_json,
    summary_markdown,
)
from cold_maps.evaluation.run import plot_jobs
from cold_maps.simulation.sensor_profile import IDEAL
from conftest import bundled_map

JUNCTION = bundled_map("junction")
STRAIGHT = bundled_map("straight")


@pytest.fixture(scope="module")
def junction_run() -> Collector:
    """The junction's three routes with distractors, convoy and a spline gap with two methods."""
    args = evaluate.build_parser().parse_args(["--map", str(JUNCTION), "--out", "unused", "--gaps", "30"])
    (plan,) = evaluate._plans(args)
    collector = Collector()
    MapEvaluator(plan).run(collector)
    return collector


def _job(jobs, prefix: str):
    return [job for job in jobs if job.args[0].name.startswith(prefix)]


def test_the_overlay_is_the_frame_of_the_scenarios_max_error(junction_run, tmp_path):
    """The frame the overlay plot draws holds the max error the summary gives for its
    scenario (over both borders and every pair, distractors included)."""
    results = {}
    for key, accumulator in junction_run.accumulators.items():
        result = accumulator.result()
        if math.isfinite(result.max_error_m):
            results[(key.map, key.label)] = max(results.get((key.map, key.label), 0.0), result.max_error_m)
    jobs = _job(plot_jobs(tmp_path, junction_run), "overlay_")
    assert len(jobs) == len(results) >= 4
    for job in jobs:
        job()
        title = plots._AXES["overlay"].get_title()  # what the plot function drew
        label = next(lbl for (_, lbl) in results if job.args[0].name == f"overlay_junction_{lbl}.png")
        frame = int(title.split("frame ")[1].split(",")[0])
        worst = results[("junction", label)]
        assert f"max error {worst:.3f} m" in title
        at_frame = max(float(r.errors_m.max()) for key, a in junction_run.accumulators.items()
                       if key.label == label for r in a.records if r.fused and r.frame == frame)
        assert at_frame == pytest.approx(worst, abs=0.0)


def test_errors_plots_mark_each_route_and_break_their_lines_there(junction_run, tmp_path):
    starts = junction_run.route_starts("junction")
    assert starts == [0, 100, 200]  # three drives of 100 frames one after the other
    job = _job(plot_jobs(tmp_path, junction_run), "errors_junction_convoy")[0]
    job()
    axes = plots._AXES["errors"]
    assert [t.get_text().strip() for t in axes.texts] == ["route 1", "route 2", "route 3"]
    verticals = sorted(line.get_xdata()[0] for line in axes.lines if len(set(line.get_xdata())) == 1)
    assert verticals == starts
    for line in axes.lines:
        x, y = np.asarray(line.get_xdata(), float), np.asarray(line.get_ydata(), float)
        if len(x) > 2:
            for start in starts[1:]:
                before = np.flatnonzero(x < start)[-1]
                assert math.isnan(y[before]), "a line joins the end of one route to the next"


def test_one_figure_per_spline_kind_compares_the_methods_on_one_axis(junction_run, tmp_path):
    jobs = _job(plot_jobs(tmp_path, junction_run), "methods_")
    assert [job.args[0].name for job in jobs] == ["methods_junction_spline-d30.png"]
    jobs[0]()
    labels = {text.get_text() for text in plots._AXES["errors"].get_legend().get_texts()}
    assert labels == {"paper mean", "paper max", "hermite mean", "hermite max"}


@pytest.mark.parametrize(("high", "scale"), [(LOG_SPAN_RATIO * 0.01 * 1.01, "log"), (0.5, "linear")])
def test_errors_spanning_decades_are_drawn_on_a_log_scale(tmp_path, high, scale):
    frames = np.arange(4.0)
    series = [ErrorSeries("a", frames, np.full(4, 0.01), np.full(4, 0.02)),
              ErrorSeries("b", frames, np.full(4, 0.01), np.array([0.02, high, 0.02, 0.02]))]
    plot_error_series(tmp_path / "e.png", series, "t")
    assert plots._AXES["errors"].get_yscale() == scale


def _sweep_rows() -> list[dict]:
    rows = []
    for noise in (0.0, 0.05):
        for d_s in (20.0, 50.0):
            worst = 72.7 if (noise, d_s) == (0.05, 50.0) else 0.01 * d_s / 20.0
            for boundary in ("left", "right"):
                rows.append({"map": "m", "fusion": "spline", "interpolation": "paper", "boundary": boundary,
                             "max_error_m": worst, "p95_error_m": worst / 2, "perception_range_m": 80.0 + d_s,
                             "fused_frames": 10, "frames": 10, "cell_noise_sigma_m": noise,
                             "cell_pose_sigma_xy_m": 0.0, "cell_d_s_m": d_s})
    return rows


def test_sweep_plots_survive_an_outlier_and_draw_levels_as_categories(tmp_path, monkeypatch):
    drawn = {}

    def keep(figure, path):
        drawn[path.name] = figure
        return path

    monkeypatch.setattr(sweep_report, "_save", keep)
    sweep_report.write_plots(tmp_path, _sweep_rows())
    errors = drawn["sweep_m.png"].axes
    assert [errors[0].get_yscale(), errors[1].get_yscale(), errors[2].get_yscale()] == ["log", "log", "linear"]
    safe = drawn["safe_gap.png"].axes[0]
    assert [t.get_text() for t in safe.get_xticklabels()] == ["0 / 0", "0.05 / 0"]
    assert not safe.lines  # bars, no line joining the levels
    heights = [patch.get_height() for patch in safe.patches]
    assert heights == [50.0, 20.0]  # level 0: every gap safe; level 0.05: only 20 m
    assert "none" not in [t.get_text() for t in safe.texts]
    rows = [dict(r, max_error_m=72.7) if r["cell_noise_sigma_m"] == 0.05 else r for r in _sweep_rows()]
    drawn.clear()
    sweep_report.write_plots(tmp_path, rows)
    assert [t.get_text() for t in drawn["safe_gap.png"].axes[0].texts] == ["none"]


def _accumulator(key: ScenarioKey, rejected: str) -> ScenarioAccumulator:
    accumulator = ScenarioAccumulator(key)
    accumulator.add(FrameRecord(0, 0.0, "ego", "coop", np.array([0.1, 0.2]), perception_range_m=60.0,
                                runtime_ms=2.0))
    accumulator.add(FrameRecord(1, 0.1, "ego", "coop", np.empty(0), runtime_ms=4.0, rejected=rejected))
    return accumulator


def test_the_summary_explains_its_columns_gives_one_runtime_and_the_vehicles_of_a_chain():
    results = [_accumulator(ScenarioKey("m", "spline", "paper", 30.0, boundary, vehicles), "coop_not_ahead").result()
               for boundary in ("left", "right") for vehicles in (2, 3)]
    text = summary_markdown(results)
    assert "**range**" in text and "**fus. precision / recall**" in text
    assert f"`coop_not_ahead`: {REJECTION_REASONS['coop_not_ahead']}" in text
    assert "| map | fusion | interp. | d_s [m] | vehicles | boundary |" in text
    assert "| m | spline | paper | 30.0 | 3 | left |" in text and "| m | spline | paper | 30.0 | 2 | left |" in text
    assert "runtime" not in text.split("## Results per scenario")[1].split("\n\n")[1]  # not in the results table
    assert "Drive length" in text and "longest gap" in text
    pairs = summary_markdown([_accumulator(ScenarioKey("m", "convoy", "", 0.0, "left"), "no_overlap").result()])
    assert "vehicles |" not in pairs and "Drive length" not in pairs and "`coop_not_ahead`" not in pairs


def test_runtime_section_has_one_row_per_scenario_equal_to_metrics():
    from cold_maps.evaluation.report import runtime_markdown

    results = [_accumulator(ScenarioKey("m", "convoy", "", 0.0, boundary), "no_overlap").result()
               for boundary in ("left", "right")]
    rows = [line for line in runtime_markdown(results, {}).splitlines() if line.startswith("| m |")]
    assert rows == ["| m | convoy | 3.00 / 1.41 / 4.00 | – | 2.23 / 0.42 / 3.66 |"]


def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_cold_eval_and_cold_fuse_outputs_say_how_they_were_made(tmp_path):
    from cold_maps import __version__
    from cold_maps.recording.recorder import read_metadata

    out = tmp_path / "run"
    argv = ["--map", str(STRAIGHT), "--out", str(out), "--frames", "20", "--routes", "1", "--gaps", "30",
            "--interpolation", "paper", "--no-plots", "--no-progress", "--seed", "7", "--sensor", "camera"]
    assert evaluate.main(argv) == 0
    summary = (out / "summary.md").read_text()
    head = summary.split("## Results per scenario")[0]
    assert f"- command: `cold-eval {' '.join(argv)}`" in head
    assert f"cold-maps {__version__}" in head and "- seed: 7" in head
    assert f"`straight.xodr` sha256 `{_sha256(STRAIGHT)}`" in head
    camera = summary.split("- sensor camera")[1].split("\n")[0]
    assert "max_range_m" in camera and "lane_error" in camera
    provenance = json.loads((out / "metrics.json").read_text())["provenance"]
    assert provenance["inputs"] == [{"role": "map", "name": "straight.xodr", "path": str(STRAIGHT),
                                     "sha256": _sha256(STRAIGHT)}]
    assert provenance["seed"] == "7" and provenance["sensor"].startswith("sensor camera")
    assert provenance["params"]["frames"] == "20" and "workers" not in provenance["params"]
    assert json.loads(read_metadata(out / "run.mcap")["cold.run"]["params"]) == provenance["params"]
    assert read_metrics_json(out / "metrics.json")[0]  # the reader takes the new key

    report = tmp_path / "fused"
    fuse_argv = ["--input", str(out / "run.mcap"), "-o", str(tmp_path / "f.mcap"), "--report", str(report),
                 "--map", str(STRAIGHT), "--no-progress"]
    assert fuse.main(fuse_argv) == 0
    text = (report / "summary.md").read_text()
    assert text.startswith("# cold-fuse summary") and f"- command: `cold-fuse {' '.join(fuse_argv)}`" in text
    assert f"- input: `run.mcap` sha256 `{_sha256(out / 'run.mcap')}`" in text
    fused = json.loads((report / "metrics.json").read_text())["provenance"]
    assert fused["program"] == "cold-fuse" and fused["inputs"][0]["sha256"] == _sha256(out / "run.mcap")


def test_sweep_outputs_say_how_they_were_made(tmp_path):
    from cold_maps import __version__

    argv = ["sweep", "--map", str(STRAIGHT), "--gaps", "30", "--interpolation", "paper", "--frames", "15",
            "--routes", "1", "--out", str(tmp_path), "--no-plots", "--workers", "1", "--no-progress"]
    assert evaluate.main(argv) == 0
    summary = (tmp_path / "summary.md").read_text()
    assert f"- command: `cold-eval {' '.join(argv)}`" in summary
    assert f"`straight.xodr` sha256 `{_sha256(STRAIGHT)}`" in summary and f"cold-maps {__version__}" in summary
    with open(tmp_path / "results.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert {r["cell_version"] for r in rows} == {__version__}
    assert {r["cell_map_sha256"] for r in rows} == {_sha256(STRAIGHT)}
    assert {r["cell_sensor_profile"] for r in rows} == {IDEAL.describe()}


def test_false_fusions_of_chains_name_their_vehicles():
    from cold_maps.evaluation.run import false_fusion_markdown

    collector = Collector()
    for vehicles in (2, 3):
        collector.add(ScenarioKey("m", "spline", "paper", 30.0, "left", vehicles),
                      FrameRecord(0, 0.0, "ego", "coop", np.array([0.1 * vehicles]), predicted_fusible=True,
                                  truly_fusible=True))
    text = false_fusion_markdown(collector)
    assert "| d_s [m] | vehicles | boundary |" in text
    assert "| m | spline | paper | 30 | 2 | left | 1 | 0 | 0.200 | 0.200 |" in text
    assert "| m | spline | paper | 30 | 3 | left | 1 | 0 | 0.300 | 0.300 |" in text
