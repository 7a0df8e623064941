"""Whole-run benchmark: ``cold-eval`` of this checkout against the code of a git commit,
side by side in one run (default: CARLA Town01, MCAP and plots on, baseline 83adffc).

Each side is installed into a temporary venv: the baseline from a temporary ``git worktree``
at ``--baseline-ref``, the current side from this working tree (uncommitted changes
included), both with ``pip install --no-deps --no-build-isolation -e``. The venvs reuse the
dependencies already installed for the interpreter running this script: a ``deps.pth`` in
each venv names that interpreter's site-packages (a plain path entry, so no ``.pth`` file
there runs and an editable cold-maps installed there stays out of the way). Nothing is
downloaded; the temporary folder is removed at the end (``--keep`` keeps it).

Each side first runs once untimed (it fills its own conversion cache, ``COLD_MAPS_CACHE_DIR``
in the temporary folder), then the sides alternate ``--repeat`` times. Printed per side:
wall time and CPU time of the child (user + sys) as mean / σ / max in s, the ratio
baseline / current of the means, and the load average before and after (other processes
share the CPU: compare CPU times when the load is high).

Usage: ``python tools/bench_eval.py [--map MAP.xodr] [--baseline-ref 83adffc] [--repeat 3]
[--args "--frames 100"] [--current-args "--workers 1"] [--keep]``.
"""

from __future__ import annotations

import argparse
import os
import resource
import shlex
import shutil
import statistics
import subprocess
import sys
import sysconfig
import tempfile
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MAP = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"
DEFAULT_BASELINE_REF = "83adffc"
SCRIPT = "cold-eval"


@dataclass(frozen=True)
class Side:
    """One side of the comparison.

    Fields:
        name: ``current`` or ``baseline``.
        source: the checkout installed (m).
        python: the venv's interpreter.
        cache: its conversion cache folder.
        args: its extra ``cold-eval`` arguments.
    """

    name: str
    source: Path
    python: Path
    cache: Path
    args: tuple[str, ...]


def _run(command: list[str], **kwargs: object) -> None:
    result = subprocess.run(command, capture_output=True, text=True, **kwargs)  # type: ignore[call-overload]
    if result.returncode != 0:
        tail = (result.stderr or result.stdout).strip().splitlines()[-1:] or [""]
        raise SystemExit(f"bench_eval: {shlex.join(command)} failed ({result.returncode}): {tail[0]}")


def make_venv(source: Path, folder: Path) -> Path:
    """A venv in ``folder`` with ``source`` installed editable and the running
    interpreter's packages as its dependencies; returns its python."""
    _run([sys.executable, "-m", "venv", "--without-pip", str(folder)])
    python = folder / "bin" / "python"
    purelib = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             capture_output=True, text=True, check=True).stdout.strip()
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    Path(purelib, "deps.pth").write_text("".join(f"{path}\n" for path in sorted(ours)))
    _run([sys.executable, "-m", "pip", "--python", str(python), "install", "--quiet", "--no-deps",
          "--no-build-isolation", "--no-index", "-e", str(source)])
    return python


def entry_point(source: Path) -> str:
    """``module:function`` of the ``cold-eval`` script in ``source``'s pyproject.toml."""
    with open(source / "pyproject.toml", "rb") as stream:
        return tomllib.load(stream)["project"]["scripts"][SCRIPT]


def run_once(side: Side, map_path: Path, common: list[str], out: Path) -> tuple[float, float]:
    """Wall and child CPU time (s) of one ``cold-eval`` run of ``side``."""
    module, function = entry_point(side.source).split(":")
    code = f"import sys; from {module} import {function} as main; sys.exit(main())"
    command = [str(side.python), "-c", code, "--map", str(map_path), "--out", str(out), *common, *side.args]
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env["COLD_MAPS_CACHE_DIR"] = str(side.cache)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    result = subprocess.run(command, capture_output=True, text=True, env=env, cwd=side.source)
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if result.returncode != 0:
        tail = result.stderr.strip().splitlines()[-1:] or [""]
        raise SystemExit(f"bench_eval: {side.name} cold-eval failed ({result.returncode}): {tail[0]}")
    shutil.rmtree(out)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return wall, cpu


def _stats(values: list[float]) -> str:
    sigma = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.fmean(values):7.2f} / {sigma:5.2f} / {max(values):7.2f}"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--baseline-ref", default=DEFAULT_BASELINE_REF)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--args", default="", help="extra cold-eval arguments for both sides (one string)")
    parser.add_argument("--current-args", default="", help="extra cold-eval arguments for the current side only")
    parser.add_argument("--keep", action="store_true", help="keep the temporary folder")
    args = parser.parse_args(argv)
    if not args.map.is_file():
        raise SystemExit(f"bench_eval: {args.map}: no such map")
    if args.repeat < 1:
        raise SystemExit("bench_eval: --repeat must be >= 1")
    common = shlex.split(args.args)
    work = Path(tempfile.mkdtemp(prefix="bench_eval-"))
    worktree = work / "baseline-src"
    try:
        _run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(worktree), args.baseline_ref])
        commit = subprocess.run(["git", "-C", str(worktree), "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, check=True).stdout.strip()
        sides = [Side("baseline", worktree, make_venv(worktree, work / "venv-baseline"), work / "cache-baseline", ()),
                 Side("current", ROOT, make_venv(ROOT, work / "venv-current"), work / "cache-current",
                      tuple(shlex.split(args.current_args)))]
        for side in sides:
            run_once(side, args.map.resolve(), common, work / f"warm-{side.name}")
        load_before = os.getloadavg()
        times: dict[str, list[tuple[float, float]]] = {side.name: [] for side in sides}
        for index in range(args.repeat):
            for side in sides:
                times[side.name].append(run_once(side, args.map.resolve(), common, work / f"out-{side.name}-{index}"))
        load_after = os.getloadavg()
    finally:
        if not args.keep:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(worktree)],
                           capture_output=True)
            shutil.rmtree(work, ignore_errors=True)
    print(f"cold-eval --map {args.map.name} {args.args}".rstrip() + f": {args.repeat} runs per side, "
          f"{os.cpu_count()} cores; load average before {load_before[0]:.2f}, after {load_after[0]:.2f}")
    print(f"  {'side':30s} {'wall s: mean / σ / max':>26s}   {'CPU s: mean / σ / max':>26s}")
    for side in sides:
        label = f"{side.name} ({commit if side.name == 'baseline' else 'this tree'})"
        label += f" {' '.join(side.args)}" if side.args else ""
        walls, cpus = [w for w, _ in times[side.name]], [c for _, c in times[side.name]]
        print(f"  {label:30s} {_stats(walls):>26s}   {_stats(cpus):>26s}")
    base, current = times["baseline"], times["current"]
    wall_ratio = statistics.fmean(w for w, _ in base) / statistics.fmean(w for w, _ in current)
    cpu_ratio = statistics.fmean(c for _, c in base) / statistics.fmean(c for _, c in current)
    print(f"  speed-up baseline / current: wall {wall_ratio:.2f}x, CPU {cpu_ratio:.2f}x")
    return 0


if __name__ == "__main__":
    sys.exit(main())
