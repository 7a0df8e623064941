"""The report of a sweep: ``summary.md`` and plots over the rows of its finished cells.

Per map, spline method and level (lane sensor, sensor noise σ, coop pose σ), against the gap d_s
(the sensor shown only when some cell's is not the default ``ideal``):
the largest error (max over seeds and both borders), the 95th percentile (likewise the
worst), the mean perception range, and the safe gap: the longest d_s whose largest error
stays within ``SAFE_MAX_ERROR_M`` (the paper's criterion).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Sequence

from cold_maps.common.provenance import Provenance
from cold_maps.evaluation.plots import LOG_SPAN_RATIO
from cold_maps.simulation.sensor_profile import DEFAULT_PROFILE
from converters.atomic_io import atomic_output

SAFE_MAX_ERROR_M: Final[float] = 0.75
"""A gap is safe when the fused lane's largest error stays within this (m), as in the paper."""
SUMMARY_NAME: Final[str] = "summary.md"
PLOTS_DIR: Final[str] = "plots"
MAP_PLOT: Final[str] = "sweep_{map}.png"
"""File name (in ``PLOTS_DIR``) of a map's plot against the gap."""
SAFE_GAP_PLOT: Final[str] = "safe_gap.png"
CELL_DRIVE_NOTE: Final[str] = (
    "Drive length: each cell is evaluated with its own gap alone, and its drive is as long as that gap's coop "
    "needs; a gap's results therefore do not change when other gaps are asked for, but different gaps are "
    "measured on drives of different length (unlike `cold-eval --gaps`, whose drives follow the longest gap).\n")


@dataclass(frozen=True)
class GapPoint:
    """One map, method, sensor, error level and gap, over its seeds and both borders.

    Fields:
        map: map name; interpolation: the spline method; sensor: the lane sensor
        profile's name; noise_sigma_m, pose_sigma_xy_m:
        the error level (m); d_s_m: the gap (m); max_error_m, p95_error_m: the worst over
        seeds and borders (m, None when nothing was fused); range_m: mean perception range
        (m, None when nothing was fused); fused_frames, frames: summed.
    """

    map: str
    interpolation: str
    sensor: str
    noise_sigma_m: float
    pose_sigma_xy_m: float
    d_s_m: float
    max_error_m: float | None
    p95_error_m: float | None
    range_m: float | None
    fused_frames: int
    frames: int

    @property
    def level(self) -> str:
        """The error level as a label, after the sensor's name unless it is the default."""
        sensor = "" if self.sensor == DEFAULT_PROFILE else f"{self.sensor}, "
        return f"{sensor}noise {self.noise_sigma_m:g} m, pose {self.pose_sigma_xy_m:g} m"


def _worst(values: list[Any]) -> float | None:
    found = [v for v in values if v is not None]
    return max(found) if found else None


def gap_points(rows: Sequence[dict[str, Any]]) -> list[GapPoint]:
    """The spline rows aggregated per map, method, sensor (rows without one: the default),
    error level and gap, sorted."""
    groups: dict[tuple[str, str, str, float, float, float], list[dict[str, Any]]] = {}
    for row in rows:
        if row["fusion"] == "spline":
            key = (row["map"], row["interpolation"], row.get("cell_sensor", DEFAULT_PROFILE), row["cell_noise_sigma_m"],
                   row["cell_pose_sigma_xy_m"], row["cell_d_s_m"])
            groups.setdefault(key, []).append(row)
    points = []
    for key, group in sorted(groups.items()):
        ranges = [r["perception_range_m"] for r in group if r["perception_range_m"] is not None]
        points.append(GapPoint(*key, _worst([r["max_error_m"] for r in group]),
                               _worst([r["p95_error_m"] for r in group]),
                               sum(ranges) / len(ranges) if ranges else None,
                               sum(r["fused_frames"] for r in group), sum(r["frames"] for r in group)))
    return points


def safe_gaps(points: Sequence[GapPoint]) -> dict[tuple[str, str, str, float, float], float | None]:
    """(map, method, sensor, noise σ, pose σ) → the longest d_s (m) whose largest error is
    within ``SAFE_MAX_ERROR_M``, None when no gap is."""
    found: dict[tuple[str, str, str, float, float], float | None] = {}
    for p in points:
        key = (p.map, p.interpolation, p.sensor, p.noise_sigma_m, p.pose_sigma_xy_m)
        found.setdefault(key, None)
        if p.max_error_m is not None and p.max_error_m <= SAFE_MAX_ERROR_M:
            found[key] = max(found[key] or 0.0, p.d_s_m)
    return found


def _number(value: float | None, digits: int = 3) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


INTERRUPTED_WRITING: Final[str] = ("**PARTIAL: interrupted while the tables were written; results.parquet, "
                                    "results.csv and the plots are not written (the finished cells are kept): run "
                                    "the same command again to write them.**\n\n")
"""The status line of a summary whose tables an interrupt cut short."""


def summary_markdown(rows: Sequence[dict[str, Any]], *, cells: int, finished: int, interrupted: bool = False,
                     provenance: Provenance | None = None) -> str:
    """The sweep's summary: how it was made (``provenance``), the error and range table
    against d_s and the safe gaps. ``interrupted``: the tables and plots were not written
    (:data:`INTERRUPTED_WRITING`)."""
    points = gap_points(rows)
    sensors = any(p.sensor != DEFAULT_PROFILE for p in points)
    sensor_head, sensor_rule = ("sensor | ", "---|") if sensors else ("", "")

    def column(sensor: str) -> str:
        return f"{sensor} | " if sensors else ""

    status = "" if finished == cells else f"**PARTIAL SWEEP: {finished} of {cells} cells finished.**\n\n"
    status += INTERRUPTED_WRITING if interrupted else ""
    made = "" if provenance is None else provenance.markdown() + "\n"
    lines = [f"# Sweep\n\n{status}{made}{finished} of {cells} cells, {len(rows)} rows. Errors are the worst over "
             "seeds and both borders, the range their mean; results.csv / results.parquet carry each cell's "
             "parameters (`cell_*`, its map's sha256, the version that computed it).\n\n"
             f"{CELL_DRIVE_NOTE}\n## Spline fusion against the gap d_s\n\n"
             f"| map | method | {sensor_head}noise σ [m] | pose σ [m] | d_s [m] | max error [m] | p95 error [m] | "
             f"range [m] | fused / evaluated |\n|---|---|{sensor_rule}---|---|---|---|---|---|---|"]
    lines += [f"| {p.map} | {p.interpolation} | {column(p.sensor)}{p.noise_sigma_m:g} | {p.pose_sigma_xy_m:g} | "
              f"{p.d_s_m:g} | "
              f"{_number(p.max_error_m)} | {_number(p.p95_error_m)} | {_number(p.range_m, 1)} | "
              f"{p.fused_frames} / {p.frames} |" for p in points]
    lines.append(f"\n## Safe gap (longest d_s with max error <= {SAFE_MAX_ERROR_M:g} m)\n\n"
                 f"| map | method | {sensor_head}noise σ [m] | pose σ [m] | safe d_s [m] |\n"
                 f"|---|---|{sensor_rule}---|---|---|")
    lines += [f"| {m} | {method} | {column(sensor)}{noise:g} | {pose:g} | {'none' if gap is None else f'{gap:g}'} |"
              for (m, method, sensor, noise, pose), gap in sorted(safe_gaps(points).items())]
    return "\n".join(lines) + "\n"


def write_plots(out: Path, rows: Sequence[dict[str, Any]]) -> list[Path]:
    """Per map ``plots/sweep_<map>.png`` (max error, p95 error and range against d_s, one
    line per method and error level; an error panel whose values span ``LOG_SPAN_RATIO`` or
    more on a log scale, so one outlier does not flatten the rest) and ``plots/safe_gap.png``
    (safe gap per error level as bars on a categorical axis, "none" written where no gap is
    safe); returns the files."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    points = gap_points(rows)
    folder = out / PLOTS_DIR
    folder.mkdir(exist_ok=True)
    written = []
    for map_name in dict.fromkeys(p.map for p in points):
        figure, axes = plt.subplots(1, 3, figsize=(15, 4.5))
        lines: dict[tuple[str, str], list[GapPoint]] = {}
        for p in points:
            if p.map == map_name:
                lines.setdefault((p.interpolation, p.level), []).append(p)
        for (method, level), line in lines.items():
            for axis, values in zip(axes, ([p.max_error_m for p in line], [p.p95_error_m for p in line],
                                           [p.range_m for p in line])):
                axis.plot([p.d_s_m for p in line], [float("nan") if v is None else v for v in values], marker="o",
                          label=f"{method}, {level}")
        for index, (axis, title) in enumerate(zip(axes, ("max error [m]", "p95 error [m]", "perception range [m]"))):
            log = index < 2 and _spans_decades([v for line in lines.values() for p in line
                                                for v in ((p.max_error_m, p.p95_error_m)[index],)])
            if log:
                axis.set_yscale("log")
            axis.set_xlabel("gap d_s [m]")
            axis.set_title(f"{map_name}: {title}" + (" (log scale)" if log else ""))
            axis.grid(True, alpha=0.3)
        axes[0].axhline(SAFE_MAX_ERROR_M, color="grey", linestyle="--", linewidth=1)
        axes[0].legend(fontsize="small")
        written.append(_save(figure, folder / MAP_PLOT.format(map=map_name)))
    gaps = safe_gaps(points)
    if gaps:
        written.append(_safe_gap_plot(plt, gaps, folder / SAFE_GAP_PLOT))
    return written


def _spans_decades(values: Sequence[float | None]) -> bool:
    """Whether the positive ``values`` span ``LOG_SPAN_RATIO`` or more."""
    positive = [v for v in values if v is not None and v > 0]
    return bool(positive) and max(positive) >= LOG_SPAN_RATIO * min(positive)


def _safe_gap_plot(plt: Any, gaps: dict[tuple[str, str, str, float, float], float | None], path: Path) -> Path:
    """Bars of the safe gap per error level (categories, in grid order), one per map, method
    and sensor side by side; "none" written where no gap is safe."""
    figure, axis = plt.subplots(figsize=(8, 4.5))
    levels = list(dict.fromkeys(f"{noise:g} / {pose:g}" for (_, _, _, noise, pose) in gaps))
    series: dict[tuple[str, str, str], dict[str, float | None]] = {}
    for (map_name, method, sensor, noise, pose), gap in gaps.items():
        series.setdefault((map_name, method, sensor), {})[f"{noise:g} / {pose:g}"] = gap
    width = 0.8 / len(series)
    for index, ((map_name, method, sensor), values) in enumerate(series.items()):
        positions = [k + (index - (len(series) - 1) / 2) * width for k in range(len(levels))]
        heights = [values.get(level) for level in levels]
        axis.bar(positions, [0.0 if h is None else h for h in heights], width=width, color=f"C{index}",
                 label=f"{map_name}, {method}" + ("" if sensor == DEFAULT_PROFILE else f", {sensor}"))
        for x, level, height in zip(positions, levels, heights):
            if level in values and height is None:
                axis.text(x, 0.0, "none", rotation=90, ha="center", va="bottom", fontsize="small", color=f"C{index}")
    axis.set_xticks(range(len(levels)), levels)
    axis.set_xlabel("error level: noise σ / pose σ [m] (categories)")
    axis.set_ylabel(f"safe gap d_s [m] (max error <= {SAFE_MAX_ERROR_M:g} m)")
    axis.grid(True, axis="y", alpha=0.3)
    axis.legend(fontsize="small")
    return _save(figure, path)


def _save(figure: Any, path: Path) -> Path:
    import matplotlib.pyplot as plt

    figure.tight_layout()
    with atomic_output(path, "wb") as stream:
        figure.savefig(stream, format="png", dpi=100)
    plt.close(figure)
    return path


def write_report(out: Path, rows: Sequence[dict[str, Any]], *, cells: int, finished: int, plots: bool = True,
                 interrupted: bool = False, provenance: Provenance | None = None) -> None:
    """``summary.md`` (atomically, opening with ``provenance``) and, unless ``plots`` is False,
    the plots; ``interrupted`` marks the summary of a sweep whose tables were not written."""
    with atomic_output(out / SUMMARY_NAME) as stream:
        stream.write(summary_markdown(rows, cells=cells, finished=finished, interrupted=interrupted,
                                      provenance=provenance))
    if plots and rows:
        write_plots(out, rows)


def discard_outputs(out: Path) -> None:
    """Removes the tables and plots of ``out`` (``atomic_output`` leaves no half-written
    file), and ``plots/`` when nothing else is left in it: what an interrupt cut short must
    not stand beside a partial summary as if complete, nor a previous run's as if current."""
    from cold_maps.evaluation.sweep import RESULTS_CSV, RESULTS_PARQUET

    for name in (RESULTS_PARQUET, RESULTS_CSV):
        (out / name).unlink(missing_ok=True)
    folder = out / PLOTS_DIR
    if folder.is_dir():
        for path in (*folder.glob(MAP_PLOT.format(map="*")), folder / SAFE_GAP_PLOT):
            path.unlink(missing_ok=True)
        if not any(folder.iterdir()):
            folder.rmdir()
