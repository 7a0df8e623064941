"""PNG plots: real PNG files of the expected size, each layer drawn in its colour."""

from __future__ import annotations

import math
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from cold_maps.evaluation.plots import DPI, FIGURE_SIZE_IN, plot_frame_errors, plot_frame_overlay
from cold_maps.evaluation.report import FrameRecord, ScenarioAccumulator, ScenarioKey
from cold_maps.recording.recorder import COLOR_COOP, COLOR_EGO, COLOR_FUSED, COLOR_GT

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC and data[12:16] == b"IHDR"
    return struct.unpack(">II", data[16:24])


def colour_pixels(path: Path, rgb: tuple[float, ...]) -> int:
    from matplotlib.image import imread

    image = imread(path)[..., :3]
    return int(np.sum(np.all(np.abs(image - np.array(rgb[:3])) < 0.02, axis=-1)))


def arc(radius: float, offset: float, start: float, length: float) -> np.ndarray:
    """A right curve (centre at (0, -radius)) offset to the left by ``offset`` m."""
    theta = np.linspace(start / radius, (start + length) / radius, 200)
    r = radius + offset
    return np.column_stack((r * np.sin(theta), r * np.cos(theta) - radius))


@pytest.fixture(scope="module")
def scenarios() -> list[ScenarioAccumulator]:
    rng = np.random.default_rng(0)
    out = []
    for boundary in ("left", "right"):
        acc = ScenarioAccumulator(ScenarioKey("rural", "spline", "paper", 20.0, boundary))
        for frame in range(60):
            errors = np.abs(rng.normal(0.0, 0.05, 300)) if frame % 10 else np.empty(0)
            acc.add(FrameRecord(frame, 0.1 * frame, "ego", "coop1", errors, rejected="" if frame % 10 else "gap"))
        out.append(acc)
    return out


def test_error_per_frame_plot_is_a_png_of_the_figure_size(tmp_path, scenarios):
    path = tmp_path / "errors.png"
    plot_frame_errors(path, scenarios, title="rural, spline, d_s = 20 m")
    assert png_size(path) == (FIGURE_SIZE_IN[0] * DPI, FIGURE_SIZE_IN[1] * DPI)
    assert 10_000 < path.stat().st_size < 1_000_000
    assert colour_pixels(path, (0.121569, 0.466667, 0.705882)) > 200  # the first series' colour (C0) is drawn
    with pytest.raises(ValueError, match="no scenarios"):
        plot_frame_errors(tmp_path / "none.png", [])


def test_overlay_draws_each_layer_in_its_colour(tmp_path):
    radius, half = 40.0, 1.75
    gt = {"left": arc(radius, half, 0.0, 90.0), "right": arc(radius, -half, 0.0, 90.0)}
    detections = {"ego": (arc(radius, half, 0.0, 30.0), arc(radius, -half, 0.0, 30.0)),
                  "coop1": (arc(radius, half, 55.0, 30.0), arc(radius, -half, 55.0, 30.0))}
    fused = {"left": arc(radius, half + 0.3, 30.0, 25.0), "right": arc(radius, -half + 0.3, 30.0, 25.0)}
    path = tmp_path / "overlay.png"
    plot_frame_overlay(path, gt=gt, detections=detections, fused=fused, title="frame 65")
    assert png_size(path) == (FIGURE_SIZE_IN[0] * DPI, FIGURE_SIZE_IN[1] * DPI)
    assert 10_000 < path.stat().st_size < 1_000_000
    for colour in (COLOR_GT, COLOR_EGO, COLOR_COOP, COLOR_FUSED):
        assert colour_pixels(path, colour) > 50, colour
    without_fused = tmp_path / "no_fused.png"
    plot_frame_overlay(without_fused, gt=gt, detections=detections, fused={})
    assert colour_pixels(without_fused, COLOR_FUSED) == 0


def test_overlay_rejects_bad_polylines_by_name(tmp_path):
    bad = np.array([[0.0, 0.0], [1.0, math.nan]])
    with pytest.raises(ValueError, match="coop1 right: polyline contains NaN"):
        plot_frame_overlay(tmp_path / "x.png", gt={}, detections={"coop1": (np.zeros((2, 2)) + [[0, 0], [1, 0]], bad)},
                           fused={})
    with pytest.raises(ValueError, match="nothing to plot"):
        plot_frame_overlay(tmp_path / "x.png", gt={}, detections={}, fused={})
    assert not (tmp_path / "x.png").exists()


def test_heavy_dependencies_are_imported_lazily():
    code = ("import sys, cold_maps.evaluation.plots, cold_maps.recording.recorder, cold_maps.evaluation.report, cold_maps.simulation.sensor_errors, "
            "cold_maps.common.progress; print(sorted(m for m in ('matplotlib', 'mcap', 'foxglove', 'shapely', 'orjson') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


def test_a_plot_drawn_after_another_equals_it_drawn_first(tmp_path, scenarios):
    """Each process keeps one axes per plot kind: nothing of a previous plot (lines, legend,
    limits, title) shows in the next one."""
    from matplotlib.image import imread

    from cold_maps.evaluation import plots

    radius, half = 40.0, 1.75
    small = {"gt": {"left": arc(radius, half, 0.0, 90.0)}, "detections": {"ego": (arc(radius, half, 0.0, 30.0),
                                                                                  arc(radius, -half, 0.0, 30.0))},
             "fused": {}}
    large = {"gt": {"left": arc(2 * radius, half, 0.0, 150.0)}, "fused": {"left": arc(2 * radius, 0.5, 0.0, 120.0)},
             "detections": {"coop9": (arc(2 * radius, half, 60.0, 30.0), arc(2 * radius, -half, 60.0, 30.0))}}
    one = [scenarios[0]]
    shifted = [ScenarioAccumulator(s.key, [FrameRecord(r.frame + 500, r.stamp_s, r.ego, r.coop, 3.0 * r.errors_m,
                                                       rejected=r.rejected) for r in s.records]) for s in scenarios]
    draws = [("errors", lambda path: plot_frame_errors(path, one, title="first")),
             ("errors", lambda path: plot_frame_errors(path, shifted, title="second")),
             ("overlay", lambda path: plot_frame_overlay(path, title="first", **small)),
             ("overlay", lambda path: plot_frame_overlay(path, title="second", **large))]
    for index, (_, draw) in enumerate(draws):
        draw(tmp_path / f"after_{index}.png")
    for index, (kind, draw) in enumerate(draws):
        plots._AXES.pop(kind, None)  # a fresh figure for this plot
        draw(tmp_path / f"fresh_{index}.png")
        after, fresh = imread(tmp_path / f"after_{index}.png"), imread(tmp_path / f"fresh_{index}.png")
        assert after.shape == fresh.shape and np.array_equal(after, fresh), index
    assert not np.array_equal(imread(tmp_path / "fresh_0.png"), imread(tmp_path / "fresh_1.png"))


def test_png_decodes_to_the_same_pixels_with_matplotlib_s_chunks():
    import io

    from PIL import Image

    from cold_maps.evaluation.plots import png

    rgba = np.random.default_rng(3).integers(0, 256, size=(7, 5, 4), dtype=np.uint8)
    image = Image.open(io.BytesIO(png(rgba, "Matplotlib version9, https://matplotlib.org/")))
    assert image.mode == "RGBA" and image.size == (5, 7)
    np.testing.assert_array_equal(np.asarray(image), rgba)
    assert image.info["Software"] == "Matplotlib version9, https://matplotlib.org/"
    assert image.info["dpi"] == pytest.approx((DPI, DPI), abs=1e-3)


def test_a_pooled_series_merges_the_scenarios_frame_by_frame():
    """Per frame the mean and max of the own coops' errors of both scenarios; a distractor's
    record is left out, a frame whose records hold no error is NaN."""
    from cold_maps.evaluation.plots import ErrorSeries

    left = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"))
    right = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "right"))
    left.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.1, 0.3])))
    left.add(FrameRecord(0, 0.0, "ego", "adjacent_left", np.array([9.0])))  # a distractor
    left.add(FrameRecord(2, 0.2, "ego", "coop1", np.empty(0), rejected="gap"))
    left.add(FrameRecord(5, 0.5, "ego", "coop1", np.array([0.4])))
    right.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.2])))
    right.add(FrameRecord(1, 0.1, "ego", "coop2", np.array([0.6, 0.8])))
    right.add(FrameRecord(5, 0.5, "ego", "", np.array([1.0])))
    series = ErrorSeries.pooled("both", [left, right], own_only=True)
    assert series.frames.tolist() == [0.0, 1.0, 2.0, 5.0]
    np.testing.assert_allclose(series.means, [0.2, 0.7, np.nan, 0.7])
    np.testing.assert_allclose(series.maxima, [0.3, 0.8, np.nan, 1.0])
    assert ErrorSeries.pooled("all", [left], own_only=False).maxima[0] == 9.0
