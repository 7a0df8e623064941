"""Fusibility of today's association on generated map families: precision, recall, false fusions.

For each family of ``tools/map_families.py`` the first ``--maps`` seeds of a seed set are
generated into ``OUT/maps``; every configuration (a list of ``cold-eval`` options,
:data:`CONFIGURATIONS`, more with ``--add-config``) runs one ``cold-eval`` over a family's maps
(a library call: noise-free, ``--interpolation paper`` since the decision does not depend
on the interpolation, no MCAP, no plots) into ``OUT/runs/<configuration>/<family>``. The
decisions (frames x vehicle pairs, one per pair: the left-border records) of all maps of a
family are pooled per fusion (convoy; spline per d_s) and configuration: precision, recall,
false fusions by kind of pair. The false fusion rate of a family and configuration is its
false fusions over its fusions, convoy and spline at every d_s pooled.

Seed sets (:data:`SEED_SETS`) are disjoint: association thresholds are chosen on ``tune``
and reported on ``report``. Outputs: ``OUT/study.json`` and ``OUT/study.md``, both stating
how they were made (command, seed set and seeds, version, commit, runtime); the JSON also
holds each run's notes (routes, lane coverage).

Usage: ``python tools/study_families.py --out out/study --seed-set tune --maps 5 [--frames 60]
[--family ramps ...] [--config lanes0 ...] [--add-config 'camera=--sensor camera --lanes 1']
[--association separation]``
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import json
import math
import platform
import shlex
import subprocess
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Iterable, Mapping, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import map_families  # noqa: E402

from cold_maps.cli.common import positive_int  # noqa: E402
from fusion.types import ASSOCIATION_RULES  # noqa: E402

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
SEED_SETS: Final[Mapping[str, range]] = {"tune": range(0, 10_000), "report": range(10_000, 20_000)}
"""Disjoint seed ranges: thresholds are chosen on ``tune``, reported on ``report``."""
CONFIGURATIONS: Final[Mapping[str, tuple[str, ...]]] = {
    "lanes0": ("--lanes", "0"),
    "lanes1": ("--lanes", "1"),
}
"""Configuration name → the cold-eval options that make it (noise-free)."""
BASE_ARGS: Final[tuple[str, ...]] = ("--interpolation", "paper", "--no-mcap", "--no-plots")
STUDY_SCHEMA_VERSION: Final[int] = 1


@dataclass(frozen=True)
class Counts:
    """Fusibility decisions against the ground truth.

    Fields:
        true_positive: pairs fused that truly continue the ego's lane.
        false_positive: pairs fused that do not (false fusions).
        false_negative: pairs rejected that truly continue it.
        true_negative: pairs rejected that do not.
        false_by_kind: (kind of pair, count) of the false fusions, sorted by kind.
        detected: truly fusible pairs whose detections as made admit the paper's rule
            (``FrameRecord.detected_fusible``).
        detected_fused: those of them fused.
    """

    true_positive: int = 0
    false_positive: int = 0
    false_negative: int = 0
    true_negative: int = 0
    false_by_kind: tuple[tuple[str, int], ...] = ()
    detected: int = 0
    detected_fused: int = 0

    def __add__(self, other: Counts) -> Counts:
        kinds = Counter(dict(self.false_by_kind)) + Counter(dict(other.false_by_kind))
        return Counts(self.true_positive + other.true_positive, self.false_positive + other.false_positive,
                      self.false_negative + other.false_negative, self.true_negative + other.true_negative,
                      tuple(sorted(kinds.items())), self.detected + other.detected,
                      self.detected_fused + other.detected_fused)

    @property
    def decisions(self) -> int:
        """Decisions counted."""
        return self.true_positive + self.false_positive + self.false_negative + self.true_negative

    @property
    def fusions(self) -> int:
        """Pairs fused."""
        return self.true_positive + self.false_positive

    @property
    def precision(self) -> float:
        """True fusions over fusions; NaN without fusions."""
        return _ratio(self.true_positive, self.fusions)

    @property
    def recall(self) -> float:
        """True fusions over truly fusible pairs; NaN without any."""
        return _ratio(self.true_positive, self.true_positive + self.false_negative)

    @property
    def recall_detected(self) -> float:
        """Fusions over the truly fusible pairs whose detections admit the paper's rule; NaN
        without any."""
        return _ratio(self.detected_fused, self.detected)

    def to_dict(self) -> dict[str, Any]:
        """The JSON record (NaN as null)."""
        return {"decisions": self.decisions, "true_positive": self.true_positive,
                "false_positive": self.false_positive, "false_negative": self.false_negative,
                "true_negative": self.true_negative, "precision": _finite(self.precision),
                "recall": _finite(self.recall), "recall_detected": _finite(self.recall_detected),
                "detected": self.detected, "detected_fused": self.detected_fused,
                "false_by_kind": dict(self.false_by_kind)}


def _ratio(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def counts_of(records: Iterable[Any]) -> Counts:
    """The :class:`Counts` of ``evaluation.report.FrameRecord`` s (records without a
    decision or without ground truth are left out)."""
    tp = fp = fn = tn = detected = detected_fused = 0
    kinds: Counter[str] = Counter()
    for record in records:
        predicted, truth = record.predicted_fusible, record.truly_fusible
        if predicted is None or truth is None:
            continue
        tp, fp = tp + (predicted and truth), fp + (predicted and not truth)
        fn, tn = fn + (not predicted and truth), tn + (not predicted and not truth)
        if predicted and not truth:
            kinds[record.relation or "unknown"] += 1
        if record.detected_fusible:
            detected, detected_fused = detected + 1, detected_fused + predicted
    return Counts(tp, fp, fn, tn, tuple(sorted(kinds.items())), detected, detected_fused)


def confidence_curve(records: Sequence[Any]) -> list[dict[str, Any]]:
    """Precision and recall when only fusions of at least each association confidence of
    ``evaluation.report.CONFIDENCE_THRESHOLDS`` count (the report's rule)."""
    from cold_maps.evaluation.report import CONFIDENCE_THRESHOLDS

    scored = [(r.confidence if r.predicted_fusible else -math.inf, bool(r.truly_fusible)) for r in records
              if r.predicted_fusible is not None and r.truly_fusible is not None
              and (not r.predicted_fusible or math.isfinite(r.confidence))]
    truths = sum(truth for _, truth in scored)
    curve = []
    for threshold in CONFIDENCE_THRESHOLDS:
        kept = [truth for confidence, truth in scored if confidence >= threshold]
        curve.append({"threshold": threshold, "precision": _finite(_ratio(sum(kept), len(kept))),
                      "recall": _finite(_ratio(sum(kept), truths))})
    return curve


def fusion_label(fusion: str, d_s: float) -> str:
    """``convoy`` or ``spline d_s=<m>``."""
    return "convoy" if fusion == "convoy" else f"spline d_s={d_s:g}"


def run_family(paths: Sequence[Path], config_args: Sequence[str], out: Path, *, frames: int | None,
               routes: str | None, workers: int | None
               ) -> tuple[dict[tuple[str, str], list[Any]], list[str], list[str]]:
    """One cold-eval over ``paths`` with ``config_args`` into ``out``: the left-border
    records per (map, fusion label) of the coop scenarios, the run's warnings (ground truth
    not trustworthy, plans reduced to fit a map) and its notes (routes, lane coverage).
    RuntimeError when the run fails."""
    from cold_maps.cli import evaluate
    from cold_maps.common.provenance import make_provenance, recorded_params
    from cold_maps.evaluation.parallel import default_workers
    from cold_maps.evaluation.run import RunOptions, run_evaluation
    from cold_maps.evaluation.trust import run_warnings

    argv = [arg for path in paths for arg in ("--map", str(path))]
    argv += [*BASE_ARGS, *config_args, "--out", str(out)]
    argv += ["--frames", str(frames)] if frames else []
    argv += ["--routes", str(routes)] if routes else []
    args = evaluate.build_parser().parse_args(argv)
    plans = evaluate._plans(args)
    provenance = make_provenance(evaluate.PROG, argv, recorded_params(vars(args), evaluate.UNRECORDED),
                                 inputs=[("map", plan.path) for plan in plans])
    run = run_evaluation(plans, RunOptions(out=out, mcap=False, plots=False, provenance=provenance,
                                           workers=workers or default_workers()))
    if run.error is not None:
        raise RuntimeError(f"cold-eval on {out} failed: {type(run.error).__name__}: {run.error}")
    found: dict[tuple[str, str], list[Any]] = {}
    for key, accumulator in sorted(run.collector.accumulators.items(), key=lambda item: repr(item[0])):
        if key.fusion != "local" and key.boundary == "left":
            found.setdefault((key.map, fusion_label(key.fusion, key.d_s)), []).extend(accumulator.records)
    reduced = [f"reduced to fit: {name}" for name in run.collector.reduced_maps]
    return found, [*run_warnings(run.collector), *reduced], list(run.collector.notes)


def _git_commit() -> str:
    try:
        commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=PROJECT_ROOT, capture_output=True, text=True,
                                check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=PROJECT_ROOT,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return commit + (" (uncommitted changes)" if dirty else "")


def _fmt(value: float | None, digits: int = 3) -> str:
    return "–" if value is None or not math.isfinite(value) else f"{value:.{digits}f}"


def markdown(study: Mapping[str, Any]) -> str:
    """``study.md``: how it was made, precision / recall per family x fusion x configuration,
    false fusion rates, the worst maps."""
    made = study["made"]
    configs = list(made["configurations"])
    lines = [
        "# Fusibility on generated map families",
        "",
        f"Made by `{made['command']}` on {made['date_utc']} (cold-maps {made['version']}, commit {made['commit']}, "
        f"{made['runtime_s']:.0f} s). Seed set `{made['seed_set']}`, seeds {made['seeds']} per family "
        f"(odd seeds left-hand traffic); maps from `tools/map_families.py`. Each configuration is one "
        f"`cold-eval` per family with {' '.join(BASE_ARGS)} and: "
        + "; ".join(f"`{name}` = `{' '.join(args) or '(defaults)'}`" for name, args in made["configurations"].items())
        + f"; frames {made['frames'] or 'default (at most 100)'}, routes {made['routes'] or 'default (3)'}. "
        "Precision = true fusions / fusions, recall = true fusions / truly fusible pairs, recall given "
        "detections = fusions / truly fusible pairs whose detections as made overlap (convoy) or leave a gap "
        "0 < d_s <= d_i (spline), pooled over the family's maps (one decision per frame and vehicle pair).",
        "",
        "| family | fusion | " + " | ".join(f"{c} precision | {c} recall | {c} recall given detections"
                                           for c in configs) + " |",
        "| --- | --- | " + " | ".join("---: | ---: | ---:" for _ in configs) + " |",
    ]
    for family, cells in study["families"].items():
        for label in cells["fusions"]:
            row = [family, label]
            for config in configs:
                counts = cells["fusions"][label].get(config, {})
                row += [_fmt(counts.get("precision")), _fmt(counts.get("recall")),
                        _fmt(counts.get("recall_detected"))]
            lines.append("| " + " | ".join(row) + " |")
    lines += ["", "False fusion rate = false fusions / fusions (convoy and spline at every d_s pooled); "
              "the kinds of pair that were falsely fused.", "",
              "| family | configuration | decisions | fusions | false fusions | false fusion rate | kinds |",
              "| --- | --- | ---: | ---: | ---: | ---: | --- |"]
    for family, cells in study["families"].items():
        for config in configs:
            total = cells["total"].get(config)
            if total is None:
                continue
            kinds = ", ".join(f"{kind} {count}" for kind, count in total["false_by_kind"].items()) or "–"
            fusions = total["true_positive"] + total["false_positive"]
            lines.append(f"| {family} | {config} | {total['decisions']} | {fusions} | {total['false_positive']} | "
                         f"{_fmt(_ratio(total['false_positive'], fusions), 4)} | {kinds} |")
    worst = sorted(((m["precision"], name, config) for name, per_config in study["maps"].items()
                    for config, m in per_config.items() if m["precision"] is not None))[:10]
    lines += ["", "Lowest precision per map (all fusions pooled):", "",
              "| map | configuration | precision |", "| --- | --- | ---: |"]
    lines += [f"| {name} | {config} | {_fmt(precision)} |" for precision, name, config in worst]
    warned = [f"- {family}, {config}: {text}" for family, per_config in study["warnings"].items()
              for config, texts in per_config.items() for text in texts]
    lines += ["", "Run warnings (ground truth, plans reduced to fit a map):", "", *(warned or ["- none"])]
    return "\n".join(lines) + "\n"


def study(out: Path, families: Sequence[str], seeds: Sequence[int], configurations: Mapping[str, Sequence[str]], *,
          frames: int | None, routes: str | None, workers: int | None, seed_set: str,
          command: str) -> dict[str, Any]:
    """Generates the maps, runs every configuration on every family, writes ``study.json``
    and ``study.md`` into ``out``; the study record."""
    from cold_maps import __version__
    from converters.atomic_io import atomic_output

    started, commit = time.monotonic(), _git_commit()
    maps = {family: map_families.write_maps(out / "maps", [family], seeds) for family in families}
    result: dict[str, Any] = {"families": {}, "maps": {}, "warnings": {}, "notes": {}}
    runtimes: dict[str, dict[str, float]] = {}
    for family in families:
        fusions: dict[str, dict[str, Any]] = {}
        totals: dict[str, Counts] = {}
        for config, config_args in configurations.items():
            began = time.monotonic()
            records, warnings, notes = run_family(maps[family], config_args, out / "runs" / config / family, frames=frames,
                                 routes=routes, workers=workers)
            runtimes.setdefault(family, {})[config] = round(time.monotonic() - began, 1)
            print(f"study_families: {family} {config}: {runtimes[family][config]:.0f} s", file=sys.stderr)
            result["notes"].setdefault(family, {})[config] = notes
            if warnings:
                result["warnings"].setdefault(family, {})[config] = warnings
            by_label: dict[str, list[Any]] = {}
            by_map: dict[str, Counts] = {}
            for (map_name, label), found in records.items():
                by_label.setdefault(label, []).extend(found)
                by_map[map_name] = by_map.get(map_name, Counts()) + counts_of(found)
            for label in sorted(by_label, key=lambda text: (text != "convoy", len(text), text)):
                counts = counts_of(by_label[label])
                fusions.setdefault(label, {})[config] = counts.to_dict() | {
                    "by_confidence": confidence_curve(by_label[label])}
                totals[config] = totals.get(config, Counts()) + counts
            for map_name, counts in by_map.items():
                result["maps"].setdefault(map_name, {})[config] = counts.to_dict()
        result["families"][family] = {"fusions": fusions,
                                      "total": {config: counts.to_dict() for config, counts in totals.items()}}
    result = {
        "schema_version": STUDY_SCHEMA_VERSION,
        "made": {
            "command": command, "date_utc": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M"),
            "version": __version__, "commit": commit, "python": platform.python_version(),
            "seed_set": seed_set, "seeds": _seed_text(seeds), "families": list(families),
            "configurations": {name: list(args) for name, args in configurations.items()},
            "base_args": list(BASE_ARGS), "frames": frames, "routes": routes,
            "runtime_s": round(time.monotonic() - started, 1), "runtime_per_run_s": runtimes,
            "map_sha256": {path.stem: hashlib.sha256(path.read_bytes()).hexdigest()
                           for paths in maps.values() for path in paths},
        },
    } | result
    with atomic_output(out / "study.json") as handle:
        handle.write(json.dumps(result, indent=1, allow_nan=False) + "\n")
    with atomic_output(out / "study.md") as handle:
        handle.write(markdown(result))
    return result


def _seed_text(seeds: Sequence[int]) -> str:
    ordered = sorted(seeds)
    if len(ordered) > 1 and ordered == list(range(ordered[0], ordered[-1] + 1)):
        return f"{ordered[0]}-{ordered[-1]}"
    return ",".join(map(str, ordered))


def _configuration(text: str) -> tuple[str, tuple[str, ...]]:
    name, sep, args = text.partition("=")
    if not sep or not name.strip():
        raise argparse.ArgumentTypeError(f"--add-config: expected NAME=COLD-EVAL OPTIONS, got {text!r}")
    return name.strip(), tuple(shlex.split(args))


def _routes(text: str) -> str:
    return text if text == "all" else str(positive_int(text))


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry point; returns the exit status (2 for a bad command line)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--seed-set", choices=tuple(SEED_SETS), required=True,
                        help="tune: choose thresholds on it; report: report on it")
    parser.add_argument("--maps", type=positive_int, default=5, help="maps per family: the set's first seeds (default 5)")
    parser.add_argument("--family", action="append", choices=map_families.FAMILIES,
                        help="family (repeatable; default: all)")
    parser.add_argument("--config", action="append", choices=tuple(CONFIGURATIONS),
                        help="configuration (repeatable; default: all)")
    parser.add_argument("--add-config", action="append", type=_configuration, default=[], metavar="NAME=OPTIONS",
                        help="another configuration: a name and its cold-eval options")
    parser.add_argument("--association", choices=ASSOCIATION_RULES, default=None,
                        help="cold-eval --association added to every configuration (default: cold-eval's)")
    parser.add_argument("--frames", type=positive_int, default=None, help="frames per drive (default: cold-eval's)")
    parser.add_argument("--routes", type=_routes, default=None,
                        help="drives per map, or 'all' to cover every lane (default: cold-eval's)")
    parser.add_argument("--workers", type=positive_int, default=None, help="worker processes (default: the cores)")
    args = parser.parse_args(argv)
    configurations = {name: CONFIGURATIONS[name] for name in args.config or CONFIGURATIONS} | dict(args.add_config)
    if args.association is not None:
        configurations = {name: (*options, "--association", args.association)
                          for name, options in configurations.items()}
    seed_range = SEED_SETS[args.seed_set]
    if args.maps > len(seed_range):
        parser.error(f"--maps: the seed set {args.seed_set} holds {len(seed_range)} seeds")
    seeds = list(seed_range[:args.maps])
    command = shlex.join(["python", "tools/study_families.py", *(sys.argv[1:] if argv is None else argv)])
    try:
        result = study(args.out, args.family or map_families.FAMILIES, seeds, configurations, frames=args.frames,
                       routes=args.routes, workers=args.workers, seed_set=args.seed_set, command=command)
    except (OSError, RuntimeError, ValueError) as error:
        print(f"study_families: {error}", file=sys.stderr)
        return 1
    print(f"study_families: {len(result['maps'])} maps, {result['made']['runtime_s']:.0f} s -> "
          f"{args.out / 'study.md'}, {args.out / 'study.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
