"""Benchmark of the ground-truth conversion, both converters side by side in one run:
cold conversion and cache hit, mean/σ/max.

Per converter (engine: the map engine's borders and lane graph; crdesigner:
commonroad-scenario-designer) the cold ``cold-maps convert`` (our reader, then the
conversion, ``cache=False``) and its stages (lanelets, OSM build, lanelet2 load + routing
graph), the cache hit (also in CPU time of this process) against its floor
(lanelet2.io.load of the cached file alone); then the engine's cold time as a share of
crdesigner's, in wall-clock and in CPU time of the same runs. Wall-clock times depend on
what else runs on the machine; on a shared machine compare the CPU times.

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


def timed(action: Callable[[], object], runs: int, cpu: bool = False) -> list[float]:
    """Seconds of ``runs`` calls: wall clock, or CPU time of this process with ``cpu``."""
    return timed_both(action, runs)[1 if cpu else 0]


def timed_both(action: Callable[[], object], runs: int) -> tuple[list[float], list[float]]:
    """Wall-clock and CPU seconds (this process, all its threads) of the same ``runs`` calls."""
    wall, cpu = [], []
    for _ in range(runs):
        start, start_cpu = time.perf_counter(), time.process_time()
        action()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return wall, cpu


def row(label: str, times: list[float]) -> str:
    sigma = statistics.stdev(times) if len(times) > 1 else 0.0
    return f"  {label:<34} n={len(times):<3} mean {statistics.mean(times):8.3f} s  σ {sigma:7.3f} s  max {max(times):8.3f} s"


def bench_converter(xodr: Path, name: str, folder: Path, cold_runs: int, hit_runs: int) -> tuple[float, float]:
    """Print one converter's rows; return its mean cold ``cold-maps convert`` wall and CPU times (s)."""
    import lanelet2.io

    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from cold_maps.opendrive.parser import load_opendrive
    from converters import convert, frame, load_lanelet2
    from converters.cache import cache_path
    from converters.osm import build_osm

    print(f"  converter {name}")
    stages: dict[str, list[float]] = {"lanelets": [], "OSM build": [], "load + routing graph": []}
    for _ in range(cold_runs):
        start = time.perf_counter()
        converter = converter_named(name, load_opendrive(xodr))
        lanelets, geo = converter.lanelets(xodr, False)
        built = time.perf_counter()
        data = build_osm(lanelets, geo_reference=geo, source=str(xodr), merge_tolerance_m=converter.merge_tolerance_m,
                         join_tolerance_m=converter.join_tolerance_m, simplify_tolerance_m=converter.simplify_tolerance_m)
        osm = folder / f"stage-{name}.osm"
        osm.write_bytes(data)
        written = time.perf_counter()
        load_lanelet2(osm)
        stages["lanelets"].append(built - start)
        stages["OSM build"].append(written - built)
        stages["load + routing graph"].append(time.perf_counter() - written)

    def cold_convert() -> None:
        convert(xodr, folder / f"{name}.osm", cache=False, converter=converter_named(name, load_opendrive(xodr)))

    cold, cold_cpu = timed_both(cold_convert, cold_runs)
    print(row("cold: cold-maps convert --no-cache", cold))
    print(row("cold: the same in CPU time", cold_cpu))
    for label, times in stages.items():
        print(row(f"  stage: {label}", times))
    cache = folder / "cache"
    converter = converter_named(name)
    load_lanelet2(xodr, cache_dir=cache, converter=converter)
    print(row("cache hit: load_lanelet2", timed(lambda: load_lanelet2(xodr, cache_dir=cache, converter=converter), hit_runs)))
    hit_cpu = timed(lambda: load_lanelet2(xodr, cache_dir=cache, converter=converter), hit_runs, cpu=True)
    print(row("cache hit: load_lanelet2 (CPU time)", hit_cpu))
    cached = str(cache_path(xodr.read_bytes(), converter.version, cache, kind=converter.kind))
    print(row("  floor: lanelet2.io.load only", timed(lambda: lanelet2.io.load(cached, frame.projector()), hit_runs)))
    return statistics.mean(cold), statistics.mean(cold_cpu)


def bench(xodr: Path, cold_runs: int, hit_runs: int) -> None:
    print(f"{xodr.name} ({xodr.stat().st_size / 1e6:.1f} MB)")
    with tempfile.TemporaryDirectory(prefix="bench-convert-") as folder:
        engine = bench_converter(xodr, "engine", Path(folder), cold_runs, hit_runs)
        crdesigner = bench_converter(xodr, "crdesigner", Path(folder), cold_runs, hit_runs)
    for clock, index in (("wall clock", 0), ("CPU time", 1)):
        print(f"  engine cold convert / crdesigner cold convert ({clock}): {engine[index]:.3f} s / "
              f"{crdesigner[index]:.3f} s = {100.0 * engine[index] / crdesigner[index]:.1f} %")


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
