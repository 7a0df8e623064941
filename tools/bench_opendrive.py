"""Benchmark: parse an OpenDRIVE map and sample every driving-lane border every 0.1 m.

Prints mean, σ and max over --repeat runs of parse, sample and their total (in-process,
geometry caches cleared between runs), and in the same run a baseline: the same work
done by commonroad-scenario-designer's parser and parametric-lane border evaluation
(the independent implementation of tools/crosscheck_opendrive.py).

Usage: bench_opendrive.py [MAP.xodr] [--repeat 5] [--step 0.1] [--baseline-repeat 1]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Callable, Final, Iterable

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
DEFAULT_MAP: Final[Path] = PROJECT_ROOT.parent / "shared" / "maps" / "carla" / "Town04.xodr"
for entry in (PROJECT_ROOT, PROJECT_ROOT / "tools"):
    if str(entry) not in sys.path:
        sys.path.insert(0, str(entry))

from cold_maps.opendrive.errors import OpenDriveError  # noqa: E402
from cold_maps.opendrive.geometry.cubic_curve import arc_length_table  # noqa: E402
from cold_maps.opendrive.parser import load_opendrive  # noqa: E402
from cold_maps.opendrive.sampling import sample_road  # noqa: E402


def stats_line(label: str, seconds: list[float]) -> str:
    """'label: mean … s  σ … s  max … s  (n runs)'."""
    sigma = statistics.stdev(seconds) if len(seconds) > 1 else 0.0
    return (
        f"{label:<38} mean {statistics.fmean(seconds):8.4f} s   σ {sigma:7.4f} s   "
        f"max {max(seconds):8.4f} s   ({len(seconds)} runs)"
    )


def timed(action: Callable[[], object]) -> tuple[float, object]:
    start = time.perf_counter()
    result = action()
    return time.perf_counter() - start, result


def run_ours(path: Path, step: float) -> tuple[float, float, int, int]:
    """(parse s, sample s, lanes, points per border) of one cold run."""
    arc_length_table.cache_clear()
    parse_s, odr_map = timed(lambda: load_opendrive(path))
    sample_s, samples = timed(lambda: [b for road in odr_map.roads.values() for b in sample_road(road, step)])
    return parse_s, sample_s, len(samples), sum(b.s.size for b in samples)


def run_baseline(path: Path, step: float) -> tuple[float, int]:
    """(seconds, points per border) of crdesigner parsing and sampling every driving lane."""
    from crosscheck_opendrive import _their_borders

    seconds, borders = timed(lambda: _their_borders(path, step, ("driving",), {}))
    return seconds, sum(inner.shape[0] for inner, _ in borders.values())


def main(argv: Iterable[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("map", nargs="?", type=Path, default=DEFAULT_MAP, help="OpenDRIVE file (default: Town04)")
    parser.add_argument("--repeat", type=int, default=5, help="runs of our engine")
    parser.add_argument("--step", type=float, default=0.1, help="sampling step along s (m)")
    parser.add_argument("--baseline-repeat", type=int, default=1, help="runs of the crdesigner baseline (0: skip)")
    args = parser.parse_args(list(argv) if argv is not None else None)
    if args.repeat < 1 or args.baseline_repeat < 0 or not args.step > 0.0:
        print("bench_opendrive: --repeat >= 1, --baseline-repeat >= 0 and --step > 0 required", file=sys.stderr)
        return 2
    try:
        runs = [run_ours(args.map, args.step) for _ in range(args.repeat)]
    except (OSError, OpenDriveError) as error:
        print(f"bench_opendrive: {error}", file=sys.stderr)
        return 1
    parse, sample, lanes, points = zip(*runs)
    total = [p + s for p, s in zip(parse, sample)]
    print(f"{args.map.name}: {lanes[0]} driving lanes, {points[0]} points per border, step {args.step} m")
    print(stats_line("cold_maps parse", list(parse)))
    print(stats_line("cold_maps sample", list(sample)))
    print(stats_line("cold_maps parse + sample", total))
    if args.baseline_repeat:
        baseline = [run_baseline(args.map, args.step) for _ in range(args.baseline_repeat)]
        seconds = [b[0] for b in baseline]
        print(stats_line("crdesigner parse + sample (baseline)", seconds))
        print(f"baseline points per border: {baseline[0][1]}; speed-up {statistics.fmean(seconds) / statistics.fmean(total):.1f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
