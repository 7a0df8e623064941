"""Benchmark of converters.load_lanelet2: cold conversion and cache hit, mean/σ/max.

Wall-clock times depend on what else runs on the machine; the cache hit is also given
in CPU time of this process. Side by side in the same run: the cold conversion split into its stages (crdesigner
OpenDRIVE → CommonRoad, our OSM build, lanelet2 load + routing graph), and the cache hit
against its floor (lanelet2.io.load of the cached file alone).

    .venv/bin/python tools/bench_convert.py [MAP.xodr ...] [--cold-runs 1] [--hit-runs 10]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

PROJECT_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT_ROOT))
DEFAULT_MAPS = [PROJECT_ROOT.parent / "shared" / "maps" / "carla" / f"Town0{i}.xodr" for i in (1, 4)]


def timed(action: Callable[[], object], runs: int, clock: Callable[[], float] = time.perf_counter) -> list[float]:
    """Seconds of ``runs`` calls on ``clock`` (wall clock by default)."""
    times = []
    for _ in range(runs):
        start = clock()
        action()
        times.append(clock() - start)
    return times


def row(label: str, times: list[float]) -> str:
    sigma = statistics.stdev(times) if len(times) > 1 else 0.0
    return f"  {label:<34} n={len(times):<3} mean {statistics.mean(times):8.3f} s  σ {sigma:7.3f} s  max {max(times):8.3f} s"


def bench(xodr: Path, cold_runs: int, hit_runs: int) -> None:
    import lanelet2.io

    from converters import frame, load_lanelet2
    from converters.cache import cache_path
    from converters.crdesigner_bridge import crdesigner_version, odr_to_lanelets
    from converters.osm import build_osm

    print(f"{xodr.name} ({xodr.stat().st_size / 1e6:.1f} MB)")
    with tempfile.TemporaryDirectory(prefix="bench-convert-") as folder:
        stages: dict[str, list[float]] = {"crdesigner OpenDRIVE → CommonRoad": [], "OSM build": [], "load + routing graph": []}
        for _ in range(cold_runs):
            start = time.perf_counter()
            lanelets, geo = odr_to_lanelets(xodr)
            built = time.perf_counter()
            data = build_osm(lanelets, geo_reference=geo, source=str(xodr))
            osm = Path(folder) / "stage.osm"
            osm.write_bytes(data)
            written = time.perf_counter()
            load_lanelet2(osm)
            stages["crdesigner OpenDRIVE → CommonRoad"].append(built - start)
            stages["OSM build"].append(written - built)
            stages["load + routing graph"].append(time.perf_counter() - written)
        print(row("cold: load_lanelet2(cache=False)", timed(lambda: load_lanelet2(xodr, cache=False), cold_runs)))
        for label, times in stages.items():
            print(row(f"  stage: {label}", times))
        cache = Path(folder) / "cache"
        load_lanelet2(xodr, cache_dir=cache)
        print(row("cache hit: load_lanelet2", timed(lambda: load_lanelet2(xodr, cache_dir=cache), hit_runs)))
        hit_cpu = timed(lambda: load_lanelet2(xodr, cache_dir=cache), hit_runs, time.process_time)
        print(row("cache hit: load_lanelet2 (CPU time)", hit_cpu))
        cached = str(cache_path(xodr.read_bytes(), crdesigner_version(), cache))
        print(row("  floor: lanelet2.io.load only", timed(lambda: lanelet2.io.load(cached, frame.projector()), hit_runs)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("maps", nargs="*", type=Path, default=DEFAULT_MAPS)
    parser.add_argument("--cold-runs", type=int, default=1)
    parser.add_argument("--hit-runs", type=int, default=10)
    args = parser.parse_args(argv)
    for xodr in args.maps:
        if not xodr.is_file():
            print(f"bench_convert: {xodr} not found", file=sys.stderr)
            return 1
        bench(xodr, args.cold_runs, args.hit_runs)
    return 0


if __name__ == "__main__":
    sys.exit(main())
