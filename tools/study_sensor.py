"""Sensor study (issue 26, deliverable 5): what CoLD adds under a camera that fails, against
the ideal sensor, on real and bundled maps.

For every map × sensor (``ideal``, ``camera``) × lane history (none, ``--history 100``) it
runs ``cold-eval`` in this process (``cold_maps.cli.evaluate.main``, ``--no-mcap
--no-plots``, the same routes, frames, gaps and seed for all) and reads each run's
``metrics.json``. Per map, sensor and scenario (local, convoy, spline ``paper`` and
``hermite`` at every gap; fusions with and without history) it reports:

- range p5 / p50 (m): ``perception_range_distribution_m``, the smaller of the two borders';
- stop: ``stopping.share``, the share of frames whose lane is known within 0.75 m out to
  the stopping distance;
- correct max / p95 (m): the errors of the fusions the ground truth calls correct (coop
  truly on one of the ego's routes): ``correct_only`` where cold-eval writes it (with a
  history), else the larger of the ``by_route`` groups' (``own_route``, ``branch``); the
  larger of the two borders'; local rows show the local detection's own ``max_error_m`` /
  ``p95_error_m``;
- ends: ``end_reasons`` of the local detections (counts per reason, left border; the
  right one's are the same frames).

Writes ``study.json`` (every figure, how it was made: command lines, version, seed, map
sha256) and ``study.md`` (the tables) to ``--out``; the cold-eval outputs stay beside them.

Usage: ``python tools/study_sensor.py [--out out/study-sensor] [--routes 2] [--frames 100]
[--gaps 20,30] [--seed 0] [--workers 2] [--maps NAME,...]``. Maps it cannot find are
skipped with a note (CARLA and esmini maps live outside the project).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import math
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import cold_maps  # noqa: E402
from cold_maps.cli import evaluate  # noqa: E402

SHARED: Final[Path] = ROOT.parent / "shared" / "maps"
SENSORS: Final[tuple[str, ...]] = ("ideal", "camera")
HISTORIES_M: Final[tuple[int, ...]] = (0, 100)


@dataclass(frozen=True)
class StudyMap:
    """One map of the study.

    Fields:
        name: short name used in the tables.
        path: the OpenDRIVE file.
        unseen: True for a map the camera sensor was not developed on (marked in the tables).
    """

    name: str
    path: Path
    unseen: bool


MAPS: Final[tuple[StudyMap, ...]] = (
    StudyMap("Town01", SHARED / "carla" / "Town01.xodr", False),
    StudyMap("Town04", SHARED / "carla" / "Town04.xodr", False),
    StudyMap("junction", ROOT / "maps" / "junction.xodr", False),
    StudyMap("rural", ROOT / "maps" / "rural.xodr", False),
    StudyMap("fabriksgatan", SHARED / "esmini" / "fabriksgatan.xodr", False),
    StudyMap("soderleden", SHARED / "esmini" / "soderleden.xodr", False),
    StudyMap("multi_intersections", SHARED / "esmini" / "multi_intersections.xodr", True),
    StudyMap("e6mini", SHARED / "esmini" / "e6mini.xodr", True),
)


def sha256(path: Path) -> str:
    """Hex sha256 of a file's bytes."""
    return hashlib.sha256(path.read_bytes()).hexdigest()


def shown(path: Path) -> str:
    """``path`` relative to the project (``maps/…`` for the bundled maps, ``../shared/…``
    for the shared ones) when inside it or its parent folder, else as given."""
    resolved = path.resolve()
    if resolved.is_relative_to(ROOT):
        return str(resolved.relative_to(ROOT))
    return f"../{resolved.relative_to(ROOT.parent)}" if resolved.is_relative_to(ROOT.parent) else str(path)


def run_eval(argv: list[str]) -> tuple[int, str, float]:
    """``cold-eval argv`` in this process: (exit status, its stderr, wall seconds)."""
    err = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(err):
        status = evaluate.main(argv)
    return status, err.getvalue().strip(), time.perf_counter() - start


def _pair(records: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {r["boundary"]: r for r in records}


def _worst(values: list[float | None], pick: Any) -> float | None:
    finite = [v for v in values if v is not None and math.isfinite(v)]
    return pick(finite) if finite else None


def correct_errors(record: dict[str, Any]) -> dict[str, float | None]:
    """Max and p95 error (m) of a fusion record's correct fusions: ``correct_only`` (written
    with a history or chains), else the larger of the ``by_route`` groups' (``own_route``,
    ``branch``; the pooled p95 of both is not in the file)."""
    if "correct_only" in record:
        return record["correct_only"]
    groups = [g for g in record.get("by_route", {}).values() if g["fused"]]
    return {name: _worst([g[name] for g in groups], max) for name in ("max_error_m", "p95_error_m")}


def scenario_label(record: dict[str, Any]) -> str:
    """local / convoy / spline-paper-d20 …"""
    if record["fusion"] == "spline":
        return f"spline-{record['interpolation']}-d{record['d_s']:g}"
    return str(record["fusion"])


def rows_of(metrics: dict[str, Any], history_m: int) -> list[dict[str, Any]]:
    """The study's rows of one run's ``metrics.json`` (see the module): one per scenario,
    both borders combined; local rows only from the run without history."""
    groups: dict[tuple[str, float, str], list[dict[str, Any]]] = {}
    for record in metrics["scenarios"]:
        groups.setdefault((record["fusion"], record["d_s"], record["interpolation"]), []).append(record)
    rows = []
    for records in groups.values():
        first = records[0]
        local = first["fusion"] == "local"
        if local and history_m:
            continue
        sides = _pair(records)
        ranges = [r["perception_range_distribution_m"] for r in records]
        errors = [r if local else correct_errors(r) for r in records]
        stop = first.get("stopping") or {}
        rows.append({
            "scenario": scenario_label(first), "history_m": 0 if local else history_m,
            "range_p5_m": _worst([d.get("p5") for d in ranges], min),
            "range_p50_m": _worst([d.get("p50") for d in ranges], min),
            "stopping_share": stop.get("share"), "stopping_distance_m": stop.get("distance_m"),
            "frames": first["frames"], "fused_frames": first["fused_frames"],
            "max_error_m": _worst([e.get("max_error_m") for e in errors], max),
            "p95_error_m": _worst([e.get("p95_error_m") for e in errors], max),
            "end_reasons": dict(sides.get("left", first).get("end_reasons", {})) if local else {},
            "rejected": dict(first.get("rejected", {})),
        })
    return rows


def _num(value: float | None, digits: int = 1) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def markdown(study: dict[str, Any]) -> str:
    """The tables of ``study.json`` (one per map)."""
    lines = ["# Sensor study: ideal vs camera", "",
             f"Made by `{study['command']}` (cold-maps {study['version']}, seed {study['seed']}); "
             f"cold-eval options: `{study['eval_options']}`. Range p5/p50: the smaller border's; max/p95: correct "
             "fusions only (`correct_only`, without history the larger `by_route` group's; local rows: the local detection), the larger border's; stop: share of "
             "frames with the lane known within 0.75 m out to the stopping distance; ends: why the local "
             "detections ended (frames).", ""]
    for entry in study["maps"]:
        mark = " (not developed on)" if entry["unseen"] else ""
        lines += [f"## {entry['name']}{mark}", "", f"`{entry['path']}`, sha256 `{entry['sha256']}`", ""]
        if entry.get("error"):
            lines += [f"Not run: {entry['error']}", ""]
            continue
        lines += ["| sensor | scenario | history [m] | range p5 [m] | range p50 [m] | stop | max [m] | p95 [m] | "
                  "fused / frames | ends |", "|---|---|---|---|---|---|---|---|---|---|"]
        for row in entry["rows"]:
            ends = ", ".join(f"{k} {v}" for k, v in sorted(row["end_reasons"].items())) or "–"
            lines.append(f"| {row['sensor']} | {row['scenario']} | {row['history_m'] or '–'} | "
                         f"{_num(row['range_p5_m'])} | {_num(row['range_p50_m'])} | {_num(row['stopping_share'], 2)} | "
                         f"{_num(row['max_error_m'], 2)} | {_num(row['p95_error_m'], 2)} | "
                         f"{row['fused_frames']} / {row['frames']} | {ends} |")
        lines.append("")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("out/study-sensor"), help="output folder")
    parser.add_argument("--routes", default="2", help="cold-eval --routes (default 2)")
    parser.add_argument("--frames", default="100", help="cold-eval --frames (default 100)")
    parser.add_argument("--gaps", default="20,30", help="cold-eval --gaps (default 20,30)")
    parser.add_argument("--seed", default="0", help="cold-eval --seed (default 0)")
    parser.add_argument("--workers", default="2", help="cold-eval --workers (default 2)")
    parser.add_argument("--maps", default="", help="comma-separated map names (default: all)")
    args = parser.parse_args(argv)
    wanted = [m for m in args.maps.split(",") if m]
    unknown = sorted(set(wanted) - {m.name for m in MAPS})
    if unknown:
        parser.error(f"--maps: unknown map(s) {', '.join(unknown)} (known: {', '.join(m.name for m in MAPS)})")
    options = ["--routes", args.routes, "--frames", args.frames, "--gaps", args.gaps, "--seed", args.seed,
               "--interpolation", "both", "--workers", args.workers, "--no-mcap", "--no-plots", "-q"]
    study: dict[str, Any] = {
        "command": shlex.join(["python", "tools/study_sensor.py", *(argv if argv is not None else sys.argv[1:])]),
        "version": cold_maps.__version__, "seed": int(args.seed), "eval_options": shlex.join(options), "maps": []}
    for spec in MAPS:
        if wanted and spec.name not in wanted:
            continue
        entry: dict[str, Any] = {"name": spec.name, "path": shown(spec.path), "unseen": spec.unseen, "rows": [],
                                 "runs": []}
        study["maps"].append(entry)
        if not spec.path.is_file():
            entry |= {"sha256": None, "error": f"{spec.path} not found"}
            print(f"{spec.name}: skipped, {spec.path} not found", file=sys.stderr)
            continue
        entry["sha256"] = sha256(spec.path)
        for sensor in SENSORS:
            for history in HISTORIES_M:
                out = args.out / spec.name / sensor / f"history{history}"
                run_argv = ["--map", str(spec.path), "--sensor", sensor, *options, "--out", str(out)]
                run_argv += ["--history", str(history)] if history else []
                status, err, seconds = run_eval(run_argv)
                entry["runs"].append({"cold_eval": shlex.join(["cold-eval", *run_argv]), "status": status,
                                      "seconds": round(seconds, 1)})
                print(f"{spec.name} {sensor} history {history}: exit {status} in {seconds:.0f} s", file=sys.stderr)
                if status != 0:
                    entry["error"] = f"cold-eval exit {status}: {err.splitlines()[-1] if err else ''}"
                    continue
                metrics = json.loads((out / "metrics.json").read_text())
                entry["rows"] += [{"sensor": sensor} | row for row in rows_of(metrics, history)]
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "study.json").write_text(json.dumps(study, indent=1) + "\n")
    (args.out / "study.md").write_text(markdown(study) + "\n")
    print(f"study: {args.out / 'study.md'}, {args.out / 'study.json'}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
