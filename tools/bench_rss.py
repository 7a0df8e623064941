"""Peak RSS of a short and a long cold-eval drive side by side, and their ratio.

Runs ``cold-eval`` (this checkout, ``python -m cold_maps.cli.evaluate``) once per frame count
in a child process and reads the child's own peak resident set size from ``os.wait4``
(``ru_maxrss``, KiB on Linux). Issue 27's goal: a 10 000-frame drive on Town04 within 1.2x of a
300-frame one::

    python tools/bench_rss.py --map /work/shared/maps/carla/Town04.xodr --frames 300 10000
    python tools/bench_rss.py ... --outputs      # with run.mcap and the plots (default: --no-mcap --no-plots)

Prints one line per run (frames, peak RSS MB, user+system CPU s, wall s) and the ratio of
the last to the first.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Final

ROOT: Final[Path] = Path(__file__).resolve().parent.parent
KIB_PER_MB: Final[float] = 1000.0 / 1.024
"""ru_maxrss is in KiB on Linux: KiB per MB (10^6 bytes)."""


def peak_rss(command: list[str]) -> tuple[float, float, float, int]:
    """(peak RSS MB, CPU s, wall s, exit code) of ``command`` run as a child process."""
    start = time.perf_counter()
    child = subprocess.Popen(command, cwd=ROOT, env=os.environ | {"PYTHONPATH": str(ROOT)},
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(child.pid, 0)
    child.returncode = os.waitstatus_to_exitcode(status)
    if child.returncode:
        sys.stderr.write(child.stderr.read().decode(errors="replace") if child.stderr else "")
    return usage.ru_maxrss / KIB_PER_MB, usage.ru_utime + usage.ru_stime, time.perf_counter() - start, child.returncode


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--map", required=True, type=Path, help="OpenDRIVE map")
    parser.add_argument("--frames", type=int, nargs="+", default=[300, 10000], help="frame counts, in order")
    parser.add_argument("--routes", type=int, default=1)
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--outputs", action="store_true", help="write run.mcap and the plots too")
    args = parser.parse_args(argv)
    if not args.map.is_file():
        parser.error(f"--map {args.map}: no such file")
    peaks = []
    with tempfile.TemporaryDirectory(prefix="bench-rss-") as folder:
        for frames in args.frames:
            command = [sys.executable, "-m", "cold_maps.cli.evaluate", "--map", str(args.map.resolve()),
                       "--routes", str(args.routes), "--workers", str(args.workers), "--frames", str(frames),
                       "--no-progress", "--out", str(Path(folder) / f"f{frames}")]
            command += [] if args.outputs else ["--no-mcap", "--no-plots"]
            rss, cpu, wall, code = peak_rss(command)
            if code:
                print(f"frames {frames}: cold-eval exited {code}", file=sys.stderr)
                return 1
            peaks.append(rss)
            print(f"frames {frames:6d}: peak RSS {rss:8.1f} MB, CPU {cpu:7.1f} s, wall {wall:7.1f} s"
                  f" ({'with MCAP and plots' if args.outputs else '--no-mcap --no-plots'})", flush=True)
    print(f"ratio {args.frames[-1]} / {args.frames[0]} frames: {peaks[-1] / peaks[0]:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
