"""Benchmark: ``cold-eval`` on a map with one far-off road against the same map without it.

The far-off map is the bundled map (default curve90) plus a copy of its first road moved
``--offset`` m east (default 1e7 m). Both maps are evaluated once to fill the conversion
cache, then ``--repeat`` times each, alternating, in this process with ``--frames`` frames
per route and no plots or MCAP. Prints mean, σ and max wall time (s) of both and their
ratio of means; the work should follow the geometry, not the distance between roads.

Usage: ``python tools/bench_far_road.py [--map maps/curve90.xodr] [--frames 20] [--repeat 3]``.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import io
import statistics
import sys
import tempfile
import time
from pathlib import Path

from lxml import etree

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from cold_maps.cli import evaluate  # noqa: E402


def with_far_road(source: Path, target: Path, offset_m: float) -> Path:
    """Writes ``source`` plus a copy of its first road ``offset_m`` east (id "far") to ``target``."""
    root = etree.fromstring(source.read_bytes())
    road = root.find("road")
    far = copy.deepcopy(road)
    far.set("id", "far")
    far.set("name", "far")
    for record in far.find("planView"):
        record.set("x", repr(float(record.get("x")) + offset_m))
    road.addnext(far)
    target.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8"))
    return target


def run_once(path: Path, frames: int, out: Path) -> float:
    """Wall time (s) of one ``cold-eval`` run; raises when it fails."""
    argv = ["--map", str(path), "--frames", str(frames), "--no-plots", "--no-mcap", "--out", str(out)]
    start = time.perf_counter()
    with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()) as err:
        status = evaluate.main(argv)
    if status != 0:
        raise RuntimeError(f"cold-eval failed on {path}: {err.getvalue().strip()}")
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    """Prints the table; 0."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=ROOT / "maps" / "curve90.xodr")
    parser.add_argument("--offset", type=float, default=1e7, help="how far east the copy lies (m)")
    parser.add_argument("--frames", type=int, default=20)
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_far_road-") as folder:
        work = Path(folder)
        plain = work / f"{args.map.stem}.xodr"
        plain.write_bytes(args.map.read_bytes())
        far = with_far_road(args.map, work / f"{args.map.stem}_far.xodr", args.offset)
        times: dict[Path, list[float]] = {plain: [], far: []}
        for path in times:
            run_once(path, args.frames, work / "out")
        for _ in range(args.repeat):
            for path, found in times.items():
                found.append(run_once(path, args.frames, work / "out"))
    print(f"cold-eval --frames {args.frames}, {args.repeat} runs each (s):")
    print(f"{'map':<28} {'mean':>8} {'sigma':>8} {'max':>8}")
    for path, found in times.items():
        sigma = statistics.stdev(found) if len(found) > 1 else 0.0
        print(f"{path.name:<28} {statistics.mean(found):8.2f} {sigma:8.2f} {max(found):8.2f}")
    ratio = statistics.mean(times[far]) / statistics.mean(times[plain])
    print(f"far-off road / without it: {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
