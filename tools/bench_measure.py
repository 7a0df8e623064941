"""Ground-truth measuring benchmark: the ``GroundTruthMeter.measure`` calls of a real
``cold-eval`` run (default: CARLA Town01, default plan) replayed on a fresh meter, CPU time
per frame, with a baseline commit replaying the same calls in the same run.

The calls are captured from one in-process ``cold-eval --workers 1 --no-plots --no-mcap``
run (``--args`` adds options); each replay pass builds a fresh ``gt_matching.GroundTruth``
(like the evaluator: ``prepare_all=False``, the engine's ground truth) and meter, so lazy
preparation within the frame loop counts as it does in a run. Printed: CPU ms per frame
(mean / σ / max over the passes' per-frame sums), and a SHA-256 digest of every
``Measurement`` field of every call: the baseline's must be the same.

Each pass runs in a fresh interpreter; the sides (this checkout one by one, in
``GroundTruthMeter.measure_many`` blocks of N frames for each ``--block N``, and the
``--baseline-ref`` commit the same ways: it needs ``measure_many`` for ``--block``) alternate,
so all see the same load. Usage: ``python
tools/bench_measure.py [--map MAP.xodr] [--args "--frames 100"] [--repeat 3]
[--baseline-ref 0abd8c1] [--block 1 --block 20] [--save calls.pkl | --calls calls.pkl]``.
"""

from __future__ import annotations

import argparse
import hashlib
import io
import json
import os
import pickle
import shlex
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from dataclasses import fields
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_MAP = ROOT.parent / "shared" / "maps" / "carla" / "Town01.xodr"

Call = tuple[int, Any, Any, tuple[float, float, float], Any]
"""One measure call: frame number (in run order), left, right, pose, reference."""


def capture(map_path: Path, extra: list[str]) -> list[Call]:
    """The lanes one in-process ``cold-eval`` run of ``map_path`` measures (those of each
    frame the evaluator fuses), as ``measure`` calls."""
    sys.path.insert(0, str(ROOT))
    from cold_maps.cli import evaluate
    from cold_maps.evaluation.evaluator import MapEvaluator

    calls: list[Call] = []
    frames = [0]
    fuse_frame = MapEvaluator._fuse_frame

    def recorded(self: Any, *args: Any, **kwargs: Any) -> Any:
        frames[0] += 1
        fused = fuse_frame(self, *args, **kwargs)
        for _, lane, _ in fused.steps:
            if lane is not None:
                left, right, pose, reference = lane
                copy = None if reference is None else tuple(np.array(side) for side in reference)
                calls.append((frames[0], np.array(left), np.array(right), tuple(pose), copy))
        return fused

    MapEvaluator._fuse_frame = recorded  # type: ignore[method-assign]
    try:
        with tempfile.TemporaryDirectory(prefix="bench-measure-") as out:
            status = evaluate.main(["--map", str(map_path), "--workers", "1", "--no-plots", "--no-mcap",
                                    "--no-progress", "--out", out, *extra])
    finally:
        MapEvaluator._fuse_frame = fuse_frame  # type: ignore[method-assign]
    if status:
        raise SystemExit(f"cold-eval failed with status {status}")
    return calls


def _digest(measured: Any, hasher: Any) -> None:
    """Feeds every field of a ``Measurement`` (or the error text) to ``hasher``."""
    if isinstance(measured, str):
        hasher.update(measured.encode())
        return
    for item in fields(measured):
        value = getattr(measured, item.name)
        hasher.update(np.ascontiguousarray(value).tobytes() if isinstance(value, np.ndarray) else repr(value).encode())


def replay(map_path: Path, calls: list[Call], repeat: int, block: int = 0) -> tuple[list[float], str]:
    """CPU ms of the measure calls per frame over ``repeat`` passes, and the digest of the
    results; ``block`` > 0: the calls of every ``block`` frames in one ``measure_many``
    (their time spread evenly over those frames)."""
    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from cold_maps.groundtruth.meter import GroundTruthMeter
    from cold_maps.network.lane_graph import load_graph
    from converters import load_lanelet2
    from gt_matching import GroundTruth, MatchingError

    graph = load_graph(map_path)
    lanelet_map, routing = load_lanelet2(map_path, converter=converter_named("engine", graph.odr_map))
    frames = max(call[0] for call in calls)
    per_frame: list[float] = []
    digest = ""
    for _ in range(repeat):
        meter = GroundTruthMeter(GroundTruth(lanelet_map, routing, prepare_all=False))
        hasher = hashlib.sha256()
        spent = np.zeros(frames + 1)
        if block:
            for first in range(1, frames + 1, block):
                chosen = [call for call in calls if first <= call[0] < first + block]
                start = time.process_time()
                found = meter.measure_many([call[1:] for call in chosen])
                spent[first:first + block] += (time.process_time() - start) / len(spent[first:first + block])
                for measured in found:
                    _digest(str(measured) if isinstance(measured, MatchingError) else measured, hasher)
        else:
            for frame, left, right, pose, reference in calls:
                start = time.process_time()
                try:
                    measured: Any = meter.measure(left, right, pose, reference=reference)
                except MatchingError as exc:
                    measured = str(exc)
                spent[frame] += time.process_time() - start
                _digest(measured, hasher)
        per_frame.extend((spent[1:] * 1e3).tolist())
        digest = hasher.hexdigest()
    return per_frame, digest


def summary(label: str, per_frame: list[float], digest: str) -> str:
    """One report line."""
    return (f"  {label:12s} {statistics.fmean(per_frame):7.3f} / {statistics.pstdev(per_frame):6.3f} / "
            f"{max(per_frame):7.3f} CPU ms per frame   digest {digest[:16]}")


def side_pass(code: Path, map_path: Path, calls_file: Path, block: int) -> tuple[list[float], str]:
    """One replay pass on the code in ``code`` (a fresh interpreter with it first on the path)."""
    done = subprocess.run([sys.executable, __file__, "--map", str(map_path), "--replay", str(calls_file),
                           "--code", str(code), "--block", str(block)], check=False, capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(code)})
    if done.returncode:
        raise SystemExit(f"replay on {code} failed: {done.stderr.strip().splitlines()[-1:]}")
    found = json.loads(done.stdout)
    return found["per_frame"], found["digest"]


def compare(map_path: Path, calls: list[Call], repeat: int, ref: str | None, blocks: list[int]) -> list[str]:
    """Report lines: the calls replayed ``repeat`` times on this checkout (one by one, and in
    ``measure_many`` blocks of each of ``blocks`` frames) and, with ``ref``, the same ways on
    that commit's code (``git archive`` extracted to a temporary folder), the sides
    alternating so that all see the same load."""
    with tempfile.TemporaryDirectory(prefix="bench-measure-") as folder:
        calls_file = Path(folder) / "calls.pkl"
        with calls_file.open("wb") as stream:
            pickle.dump(calls, stream)
        sides = {"current": (ROOT, 0), **{f"block {block}": (ROOT, block) for block in blocks}}
        if ref:
            archive = subprocess.run(["git", "-C", str(ROOT), "archive", "--format=tar", ref], capture_output=True,
                                     check=True).stdout
            with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
                tar.extractall(Path(folder) / "baseline", filter="tar")
            sides[ref] = (Path(folder) / "baseline", 0)
            sides.update({f"{ref} block {block}": (Path(folder) / "baseline", block) for block in blocks})
        found: dict[str, tuple[list[float], set[str]]] = {name: ([], set()) for name in sides}
        for _ in range(repeat):
            for name, (code, block) in sides.items():
                per_frame, digest = side_pass(code, map_path, calls_file, block)
                found[name][0].extend(per_frame)
                found[name][1].add(digest)
    lines = [summary(name, per_frame, "/".join(sorted(digests))) for name, (per_frame, digests) in found.items()]
    if ref:
        for name, (_, block) in sides.items():
            if not name.startswith(ref):
                baseline = ref if not block else f"{ref} block {block}"
                same = found[name][1] == found[ref][1]
                ratio = statistics.fmean(found[baseline][0]) / statistics.fmean(found[name][0])
                lines.append(f"  ratio {baseline} / {name}: {ratio:.2f}x; results {'identical' if same else 'DIFFER'}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--map", type=Path, default=DEFAULT_MAP)
    parser.add_argument("--args", default="", help="extra cold-eval options of the captured run")
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--baseline-ref", help="also replay the calls on this git commit's code")
    parser.add_argument("--calls", type=Path, help="the calls captured earlier (--save), instead of a run")
    parser.add_argument("--save", type=Path, help="keep the captured calls in this file")
    parser.add_argument("--block", type=int, action="append", default=[],
                        help="also replay in measure_many blocks of this many frames (repeatable)")
    parser.add_argument("--replay", type=Path, help=argparse.SUPPRESS)
    parser.add_argument("--code", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    map_path = args.map.resolve()
    if args.replay:
        sys.path.insert(0, args.code)
        with args.replay.open("rb") as stream:
            calls = pickle.load(stream)
        per_frame, digest = replay(map_path, calls, 1, args.block[0] if args.block else 0)
        print(json.dumps({"per_frame": per_frame, "digest": digest}))
        return 0
    if args.calls:
        with args.calls.open("rb") as stream:
            calls = pickle.load(stream)
    else:
        calls = capture(map_path, shlex.split(args.args))
    if args.save:
        with args.save.open("wb") as stream:
            pickle.dump(calls, stream)
    print(f"{map_path.name} {args.args}: {len(calls)} measure calls over {max(c[0] for c in calls)} frames, "
          f"{args.repeat} passes per side (alternating)", flush=True)
    print("\n".join(compare(map_path, calls, args.repeat, args.baseline_ref, args.block)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
