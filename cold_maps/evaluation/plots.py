"""PNG plots of a run (matplotlib, Agg canvas, imported lazily).

- :func:`plot_frame_errors`: mean and max error per frame for each boundary (the paper's Fig. 7),
  a dotted line and a label where each route (drive) starts; :func:`plot_error_series` with
  one series per method compares the methods of a scenario kind on one axis (log scale when
  the errors span :data:`LOG_SPAN_RATIO` or more).
- :func:`plot_error_vs_range`: max error of every fusion against its perception range, per
  chain length.
- :func:`plot_frame_overlay`: GT, ego and cooperative detections and the fused lane of one
  frame in the world frame, equal aspect (the paper's Fig. 8).
- :func:`plot_reliability`: observed against stated coverage of the lanes' stated σ (only
  where they state one), of all fused points and of the correct fusions'.

Colours match the Foxglove channels of :mod:`cold_maps.recording.recorder`.
"""

from __future__ import annotations

import heapq
import itertools
import math
import os
import struct
import zlib
from dataclasses import dataclass
from typing import Any, Final, Iterator, Mapping, Sequence

import numpy as np
import numpy.typing as npt

from cold_maps.evaluation.columns import nulls, to_numpy
from cold_maps.evaluation.records import list_values
from cold_maps.evaluation.report import ScenarioAccumulator, atomic_write_bytes
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.recording.recorder import COLOR_COOP, COLOR_EGO, COLOR_FUSED, COLOR_GT
from cold_maps.simulation.sensor_errors import check_polyline

FIGURE_SIZE_IN: Final[tuple[float, float]] = (8.0, 4.5)
DPI: Final[int] = 100
OVERLAY_VIEW_MARGIN_M: Final[float] = 10.0
PNG_COMPRESS_LEVEL: Final[int] = 1
"""zlib level of the PNGs: fastest, about 20 % larger files than the default 6."""
PNG_SIGNATURE: Final[bytes] = b"\x89PNG\r\n\x1a\n"
METRES_PER_INCH: Final[float] = 0.0254
AXES_BOX: Final[tuple[float, float, float, float]] = (0.09, 0.11, 0.98, 0.92)
"""Left, bottom, right, top edge of the axes area (figure fractions): room for the tick
labels, axis labels and title, fixed instead of measuring the text (``tight_layout``)."""


RELIABILITY_SIGMAS: Final[NDArrayFloat] = np.linspace(0.1, 3.0, 30)
"""The multiples k of the stated σ at which the reliability plot compares coverages."""
CORRECT_SUFFIX: Final[str] = ", correct fusions"
"""Appended to a scenario's label for the reliability curve of its correct fusions alone."""
LOG_SPAN_RATIO: Final[float] = 100.0
"""Errors whose largest and smallest positive value differ by this factor or more are drawn
on a log scale."""
LOG_FLOOR_M: Final[float] = 1e-4
"""On a log error axis, errors below this (m; the detections are rounded to 1 µm, so smaller
ones are numerical noise) are drawn at it, the axis starting there."""
ROUTE_LINE_COLOR: Final[str] = "0.4"


_AXES: dict[str, Any] = {}
"""Per plot kind, the axes this process draws that kind on again: the figure, its labels,
grid, ticks and their text layouts are kept, each plot replaces the lines and legend."""


def preload() -> None:
    """Imports matplotlib's figure and Agg canvas now (before the plots, in a process whose
    cores are busy with the run's units)."""
    _figure()


def _axes(kind: str, xlabel: str, ylabel: str) -> Any:
    """The axes for a plot of ``kind`` (in :data:`AXES_BOX`, labelled, with a grid),
    without the lines and legend of the previous plot, autoscaling on."""
    axes = _AXES.get(kind)
    if axes is None:
        axes = _AXES[kind] = _figure().add_subplot()
        axes.set_xlabel(xlabel)
        axes.set_ylabel(ylabel)
        axes.grid(True, alpha=0.3)
    else:
        for line in [*axes.lines, *axes.texts]:
            line.remove()
        axes.set_yscale("linear")
        if axes.get_legend() is not None:
            axes.get_legend().remove()
        axes.set_autoscale_on(True)
    return axes


def _figure(boxed: bool = True) -> Any:
    """A figure on the Agg canvas; ``boxed``: its axes fill :data:`AXES_BOX`."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=FIGURE_SIZE_IN, dpi=DPI)
    FigureCanvasAgg(figure)
    if boxed:
        left, bottom, right, top = AXES_BOX
        figure.subplots_adjust(left=left, bottom=bottom, right=right, top=top)
    return figure


def _save(figure: Any, path: str | os.PathLike[str]) -> None:
    """The figure drawn on its Agg canvas and written as :func:`png` (what ``savefig`` draws)."""
    import matplotlib

    figure.canvas.draw()
    atomic_write_bytes(path, png(np.asarray(figure.canvas.buffer_rgba()),
                                 f"Matplotlib version{matplotlib.__version__}, https://matplotlib.org/"))


def png(rgba: npt.NDArray[np.uint8], software: str) -> bytes:
    """An ``(H, W, 4)`` RGBA image as PNG with the chunks matplotlib's writes (the
    ``Software`` text, :data:`DPI` as pHYs): rows unfiltered, zlib level
    :data:`PNG_COMPRESS_LEVEL` (a third of the time PIL's adaptive filters take, same pixels)."""
    height, width, _ = rgba.shape
    rows = np.zeros((height, 1 + 4 * width), dtype=np.uint8)  # a 0 byte (no filter) before each row
    rows[:, 1:] = rgba.reshape(height, -1)
    per_metre = round(DPI / METRES_PER_INCH)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    return (PNG_SIGNATURE + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 6, 0, 0, 0))
            + chunk(b"tEXt", b"Software\0" + software.encode("latin-1"))
            + chunk(b"pHYs", struct.pack(">IIB", per_metre, per_metre, 1))
            + chunk(b"IDAT", zlib.compress(rows.tobytes(), PNG_COMPRESS_LEVEL)) + chunk(b"IEND", b""))


@dataclass(frozen=True)
class ErrorSeries:
    """The error per frame of one scenario (usually one boundary of one fusion).

    Fields:
        label: its name in the legend.
        frames: frame indices of its evaluations.
        means, maxima: mean and max error of each evaluation (m), NaN without a lane.
    """

    label: str
    frames: NDArrayFloat
    means: NDArrayFloat
    maxima: NDArrayFloat

    @classmethod
    def of(cls, scenario: ScenarioAccumulator) -> ErrorSeries:
        """The series of a scenario's records."""
        return cls.pooled(f"{scenario.key.fusion} {scenario.key.boundary}", [scenario])

    @classmethod
    def pooled(cls, label: str, scenarios: Sequence[ScenarioAccumulator], *, own_only: bool = False) -> ErrorSeries:
        """One series over the records of ``scenarios`` (usually both borders of one method;
        ``own_only``: only the ego's own coops, :func:`is_own_coop`): per frame the mean and the
        max of all their errors. Streamed from the records' columns, a frame at a time (each
        scenario's records are in frame order)."""
        frames, means, maxima = [], [], []
        merged = heapq.merge(*(_frame_errors(s, own_only) for s in scenarios), key=lambda item: item[0])
        for frame, group in itertools.groupby(merged, key=lambda item: item[0]):
            errors = np.concatenate([e for _, e in group])
            frames.append(frame)
            means.append(errors.mean() if errors.size else np.nan)
            maxima.append(errors.max() if errors.size else np.nan)
        return cls(label, np.array(frames, dtype=float), np.array(means, dtype=float), np.array(maxima, dtype=float))


def is_own_coop(coop: str) -> bool:
    """Whether a record's coop is the ego alone ("") or one of its own coops (not a distractor)."""
    return coop == "" or coop.startswith("coop")


def _frame_errors(scenario: ScenarioAccumulator, own_only: bool) -> Iterator[tuple[int, NDArrayFloat]]:
    """(frame, errors m) of each of a scenario's records, in order."""
    for batch in scenario.records.batches(("frame", "coop", "errors_m")):
        values, offsets = list_values(batch.column("errors_m"))
        for i, (frame, coop) in enumerate(zip(batch.column("frame").to_pylist(), batch.column("coop").to_pylist())):
            if not own_only or is_own_coop(coop):
                yield frame, values[offsets[i]:offsets[i + 1]]


def plot_frame_errors(path: str | os.PathLike[str], scenarios: Sequence[ScenarioAccumulator], title: str = "",
                      route_starts: Sequence[int] = ()) -> None:
    """Mean (solid) and max (dashed) error per frame (m) of each scenario, usually the left
    and right boundary of one fusion; frames without a lane are gaps; a route starts at
    each of ``route_starts`` (global frame indices)."""
    if not scenarios:
        raise ValueError("plot_frame_errors: no scenarios to plot")
    plot_error_series(path, [ErrorSeries.of(s) for s in scenarios],
                      title=title or f"error per frame: {scenarios[0].key.map}", route_starts=route_starts)


def _split_routes(frames: NDArrayFloat, values: NDArrayFloat, starts: Sequence[int]) -> tuple[NDArrayFloat, NDArrayFloat]:
    """``frames`` and ``values`` with a NaN point before each route start, so no line joins
    the last frame of one route to the first of the next."""
    cuts = np.searchsorted(frames, [s for s in starts if frames.size and frames[0] < s <= frames[-1]])
    return np.insert(frames, cuts, np.asarray(frames)[cuts] - 0.5), np.insert(values, cuts, np.nan)


def plot_error_series(path: str | os.PathLike[str], series: Sequence[ErrorSeries], title: str,
                      route_starts: Sequence[int] = ()) -> None:
    """:func:`plot_frame_errors` of the series: a dotted line labelled "route k" where each
    route starts (``route_starts``, more than one), lines broken there; a log error axis from
    :data:`LOG_FLOOR_M` when the errors span :data:`LOG_SPAN_RATIO` or more above it."""
    axes = _axes("errors", "frame", "error [m]")
    positive = np.concatenate([np.concatenate((line.means, line.maxima)) for line in series]) if series else np.empty(0)
    positive = np.maximum(positive[np.isfinite(positive)], LOG_FLOOR_M)
    log = positive.size > 0 and positive.max() >= LOG_SPAN_RATIO * positive.min()
    for index, line in enumerate(series):
        color = f"C{index}"
        for values, style, what in ((line.means, "-", "mean"), (line.maxima, "--", "max")):
            frames, shown = _split_routes(line.frames, np.maximum(values, LOG_FLOOR_M) if log else values,
                                          route_starts)
            axes.plot(frames, shown, color=color, linestyle=style, label=f"{line.label} {what}")
    axes.relim()
    axes.autoscale_view()
    if log:
        axes.set_yscale("log")
        axes.set_ylim(bottom=LOG_FLOOR_M * 0.8)
    else:
        axes.set_ylim(bottom=0.0)
    if len(route_starts) > 1:
        for number, start in enumerate(route_starts, 1):
            axes.axvline(start, color=ROUTE_LINE_COLOR, linestyle=":", linewidth=1.0)
            axes.text(start, 1.0, f" route {number}", transform=axes.get_xaxis_transform(), va="top", ha="left",
                      fontsize="small", color=ROUTE_LINE_COLOR)
    # y given: matplotlib skips measuring the tick labels to lift the title above a y-axis offset
    # text, which this axis never has (it starts at 0, or is logarithmic): the same pixels, faster
    axes.set_title(title + (f" (log scale, errors < {LOG_FLOOR_M * 1e3:g} mm drawn at it)" if log else ""), y=1.0)
    axes.legend(loc="upper right", fontsize="small")
    _save(axes.figure, path)


def plot_frame_overlay(path: str | os.PathLike[str], *, gt: Mapping[str, NDArrayFloat],
                       detections: Mapping[str, tuple[NDArrayFloat, NDArrayFloat]],
                       fused: Mapping[str, NDArrayFloat], ego: str = "ego", title: str = "") -> None:
    """GT borders, each sender's (left, right) detection and the fused borders of one frame.

    All polylines are ``(N, 2)`` in the world frame (m); ``ego`` names the ego sender. The
    view frames the detections and the fused lane (``OVERLAY_VIEW_MARGIN_M`` around them);
    the GT is drawn where it passes through that view.
    """
    layers: list[tuple[NDArrayFloat, tuple[float, ...], str, float, str]] = []
    for name, points in gt.items():
        layers.append((check_polyline(f"gt {name}", points), COLOR_GT, "-", 4.0, "ground truth"))
    for sender, borders in detections.items():
        color = COLOR_EGO if sender == ego else COLOR_COOP
        for side, points in zip(("left", "right"), borders):
            layers.append((check_polyline(f"{sender} {side}", points), color, "-", 2.0, f"detection {sender}"))
    for name, points in fused.items():
        layers.append((check_polyline(f"fused {name}", points), COLOR_FUSED, "--", 1.5, "fused"))
    if not layers:
        raise ValueError("plot_frame_overlay: nothing to plot")
    axes = _axes("overlay", "x (east) [m]", "y (north) [m]")
    labelled: set[str] = set()
    for points, color, style, width, label in layers:
        axes.plot(points[:, 0], points[:, 1], color=color, linestyle=style, linewidth=width,
                  label=None if label in labelled else label)
        labelled.add(label)
    framed = [points for points, _, _, _, label in layers if label != "ground truth"] or [layers[0][0]]
    low = np.min([p.min(axis=0) for p in framed], axis=0) - OVERLAY_VIEW_MARGIN_M
    high = np.max([p.max(axis=0) for p in framed], axis=0) + OVERLAY_VIEW_MARGIN_M
    axes.set_xlim(low[0], high[0])
    axes.set_ylim(low[1], high[1])
    axes.set_aspect("equal", adjustable="box")
    axes.set_title(title)
    axes.legend(loc="best", fontsize="small")
    _save(axes.figure, path)


def range_points(scenarios: Sequence[ScenarioAccumulator]) -> dict[int, NDArrayFloat]:
    """Per vehicle count (chain length): (perception range m, max error m, 1.0 if the pair
    is truly on one lane else 0.0) of every fused evaluation with a finite range, ``(N, 3)``."""
    groups: dict[int, list[NDArrayFloat]] = {}
    for scenario in scenarios:
        points = groups.setdefault(scenario.key.vehicles, [])
        for batch in scenario.records.batches(("perception_range_m", "max_error_m", "truly_fusible", "errors_m")):
            ranges = to_numpy(batch.column("perception_range_m"))
            chosen = (np.diff(list_values(batch.column("errors_m"))[1]) > 0) & np.isfinite(ranges)
            truly = to_numpy(batch.column("truly_fusible"), fill=False).astype(float)
            maxima = to_numpy(batch.column("max_error_m"))
            points.append(np.column_stack((ranges[chosen], maxima[chosen], truly[chosen])))
    return {vehicles: np.concatenate(points).reshape(-1, 3) if points else np.empty((0, 3))
            for vehicles, points in groups.items()}


def plot_error_vs_range(path: str | os.PathLike[str], groups: Mapping[int, NDArrayFloat], title: str = "") -> None:
    """Max error (m) of every fused evaluation against its perception range (m), one colour per
    vehicle count (chain length); correct fusions filled, the others hollow. ``groups``: the
    scenarios' :func:`range_points`."""
    if not any(len(values) for values in groups.values()):
        raise ValueError("plot_error_vs_range: no fused evaluation to plot")
    figure = _figure(boxed=False)
    axes = figure.add_subplot()
    for index, (vehicles, values) in enumerate(sorted(groups.items())):
        right = values[:, 2] > 0
        color = f"C{index}"
        axes.scatter(values[right, 0], values[right, 1], s=8, color=color, label=f"{vehicles} vehicle(s)")
        if (~right).any():
            axes.scatter(values[~right, 0], values[~right, 1], s=8, facecolors="none", edgecolors=color,
                         label=f"{vehicles} vehicle(s), not on one lane")
    axes.set_xlabel("perception range [m]")
    axes.set_ylabel("max error per fusion [m]")
    axes.set_title(title)
    axes.legend(fontsize="small")
    axes.grid(True, alpha=0.3)
    _save(figure, path)


def reliability_points(scenarios: Sequence[ScenarioAccumulator]) -> dict[str, NDArrayFloat]:
    """Per scenario label (boundaries pooled): ``(K, 2)`` stated coverage of ±kσ for Gaussian
    errors, erf(k/√2), and the observed share of the points whose error is at most kσ, for k
    in :data:`RELIABILITY_SIGMAS`; only scenarios whose fused records state σ. Scenarios whose
    records know their truth (fusions) add the label + :data:`CORRECT_SUFFIX`: the correct
    fusions' points alone (absent when none states σ)."""
    within: dict[str, tuple[list[int], list[int]]] = {}  # label -> (count within kσ per k, [points])
    for scenario in scenarios:
        for batch in scenario.records.batches(("errors_m", "sigma_m", "truly_fusible")):
            errors, offsets = list_values(batch.column("errors_m"))
            sigmas, sigma_offsets = list_values(batch.column("sigma_m"))
            stated = (np.diff(offsets) > 0) & ~nulls(batch.column("sigma_m"))
            if not stated.any():
                continue
            truth = batch.column("truly_fusible")
            chosen = {scenario.key.label: stated}
            if truth.null_count < len(truth):
                chosen[scenario.key.label + CORRECT_SUFFIX] = stated & to_numpy(truth, fill=False)
            for label, mask in chosen.items():
                e = errors[offsets[0]:offsets[-1]][np.repeat(mask, np.diff(offsets))]
                s = sigmas[sigma_offsets[0]:sigma_offsets[-1]][np.repeat(mask, np.diff(sigma_offsets))]
                counts, total = within.setdefault(label, ([0] * len(RELIABILITY_SIGMAS), [0]))
                for index, k in enumerate(RELIABILITY_SIGMAS):
                    counts[index] += int(np.count_nonzero(e <= k * s))
                total[0] += e.size
    stated_share = np.array([math.erf(k / math.sqrt(2.0)) for k in RELIABILITY_SIGMAS])
    return {label: np.column_stack((stated_share, np.array(counts, dtype=float) / total[0]))
            for label, (counts, total) in within.items() if total[0]}


def plot_reliability(path: str | os.PathLike[str], curves: Mapping[str, NDArrayFloat], title: str = "") -> None:
    """Reliability of the stated σ: observed against stated coverage of ±kσ, one line per
    scenario (``curves``: :func:`reliability_points`; its correct fusions dashed in the same
    colour), the diagonal where they are calibrated (above it: the σ is conservative, below:
    overconfident)."""
    if not curves:
        raise ValueError("plot_reliability: no scenario states σ")
    figure = _figure(boxed=False)
    axes = figure.add_subplot()
    axes.plot([0.0, 1.0], [0.0, 1.0], color="0.5", linestyle=":", label="calibrated")
    colours = {label: f"C{index}" for index, label in enumerate(sorted(
        {label.removesuffix(CORRECT_SUFFIX) for label in curves}))}
    for label, points in sorted(curves.items()):
        correct = label.endswith(CORRECT_SUFFIX)
        axes.plot(points[:, 0], points[:, 1], color=colours[label.removesuffix(CORRECT_SUFFIX)],
                  marker="" if correct else ".", linestyle="--" if correct else "-", label=label)
    axes.set_xlabel("stated coverage of ±kσ (Gaussian)")
    axes.set_ylabel("observed share within kσ")
    axes.set_xlim(0.0, 1.0)
    axes.set_ylim(0.0, 1.0)
    axes.set_title(title)
    axes.legend(fontsize="small", loc="lower right")
    axes.grid(True, alpha=0.3)
    _save(figure, path)
