"""Seeded mutation fuzzer of the map commands: mutated OpenDRIVE maps through ``cold-maps
info``, ``cold-maps export`` (CSV and GeoJSON) and, for a sample of cases, ``cold-maps
check`` (which converts the map to Lanelet2) and ``cold-eval``.

Each case takes one of the maps (``maps/*.xodr`` and any ``--map``), applies one to three
mutations (a numeric attribute set to NaN, ±inf, 0, a negative, 1e308, 1e-300, 5e-324,
2^31, text or a far-off offset; an attribute or element deleted, duplicated or moved; an
id reference left dangling; the file truncated; bytes flipped), and runs the commands in
worker processes, each case under a time limit (the worker is killed when it passes) and
an address-space limit (``resource.setrlimit``). Case ``i`` of seed ``S`` is the same map
on every run.

Outcomes per case, the worst of its commands:
    ok     exit 0, nothing on stderr, every number in the outputs finite;
    error  exit non-zero, exactly one line on stderr (no traceback, no warning), no output
           file left behind;
    nan    exit 0 with NaN or infinity in an output (stdout, CSV, GeoJSON, metrics.json,
           frames.csv);
    noisy  exit 0 with something on stderr (a warning);
    crash  an exception out of ``main``, a traceback or several lines on stderr, an output
           file left after a failure, or a dead worker;
    hang   the case passed its time limit.
Every case that is not ok or error is written to ``--failures`` (the map and a JSON note).

Usage: ``python tools/fuzz_maps.py --seed 1 --cases 20000 --seconds 3000 --workers 2``.
Exit status 0 when no case is nan, noisy, crash or hang, 1 otherwise.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import csv
import io
import json
import os
import queue
import random
import re
import resource
import select
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Final, Sequence

from lxml import etree

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parent.parent
OUTCOMES: Final[tuple[str, ...]] = ("ok", "error", "nan", "noisy", "crash", "hang")
FAILURES: Final[frozenset[str]] = frozenset({"nan", "noisy", "crash", "hang"})
NUMERIC_VALUES: Final[tuple[str, ...]] = (
    "nan", "NaN", "inf", "-inf", "0", "-0", "-1", "1e308", "-1e308", "1e-300", "5e-324", "2147483648", "1e8",
    "3.3e7", "abc", "", " 1", "0x10",
)  # fmt: skip
ID_ATTRIBUTES: Final[frozenset[str]] = frozenset(
    {"elementId", "incomingRoad", "connectingRoad", "linkedRoad", "junction", "id", "from", "to"}
)
TREE_MUTATIONS: Final[tuple[str, ...]] = (
    "numeric", "numeric", "numeric", "scale", "far", "delete_attribute", "delete_element", "duplicate", "reorder",
    "dangling",
)  # fmt: skip
TRUNCATE_PROBABILITY: Final[float] = 0.05
FLIP_PROBABILITY: Final[float] = 0.05
_NUMBER: Final[re.Pattern[str]] = re.compile(r"^\s*[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?\s*$")
_NON_FINITE_WORD: Final[re.Pattern[str]] = re.compile(r"(?<![\w.])[-+]?(nan|inf|infinity)(?![\w])", re.IGNORECASE)


# ---- mutation -------------------------------------------------------------------------------


@dataclass(frozen=True)
class Case:
    """One mutated map.

    Fields:
        index: case number (with the seed it determines everything else).
        source: the map it was made from.
        mutations: what was changed, one description each.
        data: the mutated file's bytes.
        evaluate: also run ``cold-eval`` on it.
    """

    index: int
    source: Path
    mutations: tuple[str, ...]
    data: bytes
    evaluate: bool


def _numeric_attributes(root: etree._Element) -> list[tuple[etree._Element, str]]:
    return [(e, name) for e in root.iter() if isinstance(e.tag, str)
            for name, value in e.attrib.items() if _NUMBER.match(value) and name not in ID_ATTRIBUTES]


def _mutate_tree(root: etree._Element, kind: str, rng: random.Random) -> str:
    """Applies one mutation of ``kind`` to the tree and describes it."""
    elements = [e for e in root.iter() if isinstance(e.tag, str) and e is not root]
    if kind in ("numeric", "scale", "far"):
        candidates = _numeric_attributes(root)
        if kind == "far":
            candidates = [(e, n) for e, n in candidates if n in ("x", "y", "s", "length", "a", "sOffset")] or candidates
        if not candidates:
            return f"{kind}: no numeric attribute left"
        element, name = rng.choice(candidates)
        old = element.get(name)
        if kind == "numeric":
            new = rng.choice(NUMERIC_VALUES)
        elif kind == "scale":
            new = repr(float(old) * rng.choice((-1.0, 1e3, 1e5, 1e-5, 1e154)))
        else:
            new = repr(float(old) + rng.choice((1e5, 1e7, -1e7, 1e12)))
        element.set(name, new)
        return f"{kind}: <{element.tag}> line {element.sourceline} {name}={old!r} -> {new!r}"
    if kind == "delete_attribute":
        with_attributes = [e for e in elements if e.attrib]
        if not with_attributes:
            return f"{kind}: no attribute left"
        element = rng.choice(with_attributes)
        name = rng.choice(sorted(element.attrib))
        del element.attrib[name]
        return f"delete_attribute: <{element.tag}> line {element.sourceline} {name}"
    if kind == "dangling":
        candidates = [(e, n) for e in elements for n in e.attrib if n in ID_ATTRIBUTES]
        if not candidates:
            return f"{kind}: no id left"
        element, name = rng.choice(candidates)
        new = rng.choice(("999999", "-7", "missing"))
        element.set(name, new)
        return f"dangling: <{element.tag}> line {element.sourceline} {name} -> {new!r}"
    if not elements:
        return f"{kind}: no element left"
    element = rng.choice(elements)
    parent = element.getparent()
    if kind == "delete_element":
        parent.remove(element)
        return f"delete_element: <{element.tag}> line {element.sourceline}"
    if kind == "duplicate":
        element.addnext(copy.deepcopy(element))
        return f"duplicate: <{element.tag}> line {element.sourceline}"
    siblings = list(parent)
    parent.remove(element)
    position = rng.randrange(len(siblings))
    parent.insert(position, element)
    return f"reorder: <{element.tag}> line {element.sourceline} to position {position}"


def make_case(index: int, seed: int, sources: Sequence[Path], eval_every: int) -> Case:
    """Case ``index`` of ``seed``: the same map on every run."""
    rng = random.Random(f"{seed}:{index}")
    source = sources[rng.randrange(len(sources))]
    root = etree.fromstring(source.read_bytes(), etree.XMLParser(resolve_entities=False, no_network=True))
    mutations = [_mutate_tree(root, rng.choice(TREE_MUTATIONS), rng) for _ in range(rng.randint(1, 3))]
    data = etree.tostring(root, xml_declaration=True, encoding="UTF-8")
    if rng.random() < TRUNCATE_PROBABILITY:
        cut = rng.randrange(len(data))
        data = data[:cut]
        mutations.append(f"truncate at byte {cut}")
    if rng.random() < FLIP_PROBABILITY and data:
        flipped = bytearray(data)
        for _ in range(rng.randint(1, 4)):
            at = rng.randrange(len(flipped))
            flipped[at] ^= 1 << rng.randrange(8)
            mutations.append(f"flip byte {at}")
        data = bytes(flipped)
    evaluate = eval_every > 0 and index % eval_every == eval_every - 1
    return Case(index, source, tuple(mutations), data, evaluate)


# ---- classification (worker side) -----------------------------------------------------------


@dataclass(frozen=True)
class Verdict:
    """What one command did with a case.

    Fields:
        command: the command line (program and arguments after it).
        outcome: one of ``OUTCOMES``.
        detail: the stderr line, or what was wrong.
    """

    command: str
    outcome: str
    detail: str


def _finite_json(text: str) -> bool:
    def refuse(constant: str) -> float:
        raise ValueError(constant)

    try:
        json.loads(text, parse_constant=refuse)
    except ValueError:
        return False
    return True


def _finite_csv(text: str, numeric_columns: int) -> bool:
    """No NaN or infinity among the last ``numeric_columns`` fields of any row."""
    tail = "(?:,[^,\n]*)" + "{0," + str(numeric_columns - 1) + "}"
    return re.search(r"(?im),[-+]?(?:nan|inf|infinity)" + tail + "$", text) is None


def _finite_info(text: str) -> bool:
    free_text = ("map:", "name:", "vendor:", "geoReference:")
    return not any(_NON_FINITE_WORD.search(line) for line in text.splitlines() if not line.startswith(free_text))


def _frames_csv_finite(text: str) -> bool:
    rows = list(csv.reader(io.StringIO(text)))
    return not any(_NON_FINITE_WORD.fullmatch(cell.strip()) for row in rows[1:] for cell in row)


def classify(command: str, run: Callable[[], int], outputs: Sequence[Path],
             finite: Callable[[str, dict[Path, str]], bool], successes: tuple[int, ...] = (0,)) -> Verdict:
    """Runs ``run`` (a CLI ``main``) with stdout and stderr captured and classifies it.

    ``finite(stdout, {output: text})`` says whether a successful run's outputs are finite;
    ``successes`` are the exit statuses of a run that did its job.
    """
    out, err = io.StringIO(), io.StringIO()

    def show(message, category, filename, lineno, file=None, line=None) -> None:  # type: ignore[no-untyped-def]
        err.write(warnings.formatwarning(message, category, filename, lineno, line))

    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err), warnings.catch_warnings():
            warnings.simplefilter("always")
            warnings.showwarning = show
            status = run()
    except BaseException as exc:
        if isinstance(exc, KeyboardInterrupt):
            raise
        return Verdict(command, "crash", f"{type(exc).__name__} out of main: {' '.join(str(exc).split())[:300]}")
    lines = err.getvalue().splitlines()
    left = [p for p in outputs if p.exists() and p.is_file()]
    if status not in successes:
        if len(lines) != 1 or "Traceback" in lines[0] or "Warning" in lines[0]:
            return Verdict(command, "crash", f"exit {status} with {len(lines)} stderr lines: {lines[:6]}")
        if left:
            return Verdict(command, "crash", f"exit {status} but left {[str(p) for p in left]}: {lines[0]}")
        return Verdict(command, "error", lines[0])
    if lines:
        return Verdict(command, "noisy", f"exit 0 with stderr: {lines[:6]}")
    texts = {p: p.read_text(errors="replace") for p in left}
    if not finite(out.getvalue(), texts):
        return Verdict(command, "nan", "NaN or infinity in the output")
    return Verdict(command, "ok", "")


def run_commands(path: Path, work: Path, evaluate: bool, step_m: float, geojson: bool = True) -> list[Verdict]:
    """The commands on one map file (``geojson``: also that export; ``evaluate``: also
    ``cold-eval``), exports every ``step_m``; outputs go to ``work`` (emptied first)."""
    from cold_maps.cli import evaluate as cold_eval
    from cold_maps.cli import maps
    from cold_maps.groundtruth.check import EXIT_UNTRUSTWORTHY

    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    csv_out, geojson_out = work / "borders.csv", work / "borders.geojson"
    columns = len(maps.CSV_HEADER) - maps.CSV_HEADER.index("s")
    verdicts = [
        classify("cold-maps info", lambda: maps.main(["info", str(path)]), [], lambda out, _: _finite_info(out)),
        classify("cold-maps export csv",
                 lambda: maps.main(["export", str(path), "--step", str(step_m), "-o", str(csv_out)]), [csv_out],
                 lambda _, texts: all(_finite_csv(t, columns) for t in texts.values())),
    ]
    if geojson:
        verdicts.append(classify(
            "cold-maps export geojson",
            lambda: maps.main(["export", str(path), "--step", str(step_m), "--format", "geojson", "--crs", "local",
                               "-o", str(geojson_out)]),
            [geojson_out], lambda _, texts: all(_finite_json(t) for t in texts.values())))
    if evaluate and all(v.outcome == "ok" for v in verdicts):
        verdicts.append(classify("cold-maps check", lambda: maps.main(["check", str(path)]), [],
                                 lambda out, _: _finite_info(out), successes=(0, EXIT_UNTRUSTWORTHY)))
        run_dir = work / "eval"
        argv = ["--map", str(path), "--frames", "5", "--routes", "1", "--no-plots", "--out", str(run_dir)]
        outputs = [run_dir / name for name in ("metrics.json", "frames.csv", "summary.md", "run.mcap")]

        def eval_finite(_: str, texts: dict[Path, str]) -> bool:
            return all(_finite_json(t) if p.suffix == ".json" else _frames_csv_finite(t)
                       for p, t in texts.items() if p.suffix in (".json", ".csv"))

        verdicts.append(classify("cold-eval", lambda: cold_eval.main(argv), outputs, eval_finite))
    return verdicts


def _address_space_bytes() -> int:
    with open("/proc/self/statm") as stream:
        return int(stream.read().split()[0]) * resource.getpagesize()


def worker(memory_mb: int) -> None:
    """Reads JSON case requests on stdin, answers one JSON line per case on stdout."""
    import logging

    logging.disable(logging.CRITICAL)
    import cold_maps.cli.evaluate
    import cold_maps.cli.maps  # noqa: F401

    hard = resource.getrlimit(resource.RLIMIT_AS)[1]
    answer = sys.stdout
    sys.stdout = sys.stderr
    for request in sys.stdin:
        job = json.loads(request)
        soft = _address_space_bytes() + memory_mb * 1024 * 1024
        resource.setrlimit(resource.RLIMIT_AS, (soft if hard == resource.RLIM_INFINITY else min(soft, hard), hard))
        try:
            verdicts = run_commands(Path(job["path"]), Path(job["work"]), job["evaluate"], job["step"],
                                    job["geojson"])
        finally:
            resource.setrlimit(resource.RLIMIT_AS, (hard, hard))
        answer.write(json.dumps([v.__dict__ for v in verdicts]) + "\n")
        answer.flush()


# ---- driver ---------------------------------------------------------------------------------


@dataclass
class Report:
    """Counts of a fuzz run.

    Fields:
        outcomes: cases per outcome.
        by_mutation: (mutation kind, outcome) -> cases.
        failures: notes of the failing cases (written to the failures folder).
        cases: cases run.
        evaluated: cases that went through cold-eval.
        seconds: wall time.
    """

    outcomes: Counter[str] = field(default_factory=Counter)
    by_mutation: Counter[tuple[str, str]] = field(default_factory=Counter)
    failures: list[dict[str, object]] = field(default_factory=list)
    cases: int = 0
    evaluated: int = 0
    seconds: float = 0.0

    @property
    def failed(self) -> int:
        """Cases whose outcome is nan, noisy, crash or hang."""
        return sum(self.outcomes[o] for o in FAILURES)

    def lines(self) -> list[str]:
        """The printed summary."""
        counts = ", ".join(f"{o} {self.outcomes[o]}" for o in OUTCOMES)
        kinds = sorted({k for k, _ in self.by_mutation})
        table = [f"  {k:<17}" + " ".join(f"{o} {self.by_mutation[k, o]:>5}" for o in OUTCOMES) for k in kinds]
        return [f"{self.cases} cases ({self.evaluated} through cold-eval) in {self.seconds:.0f} s: {counts}",
                "by mutation kind:", *table]


class _Worker:
    """One worker process; restarted after a hang or a death."""

    def __init__(self, memory_mb: int, cache: Path) -> None:
        self.memory_mb = memory_mb
        self.cache = cache
        self.process: subprocess.Popen[str] | None = None

    def start(self) -> subprocess.Popen[str]:
        if self.process is None or self.process.poll() is not None:
            env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(PROJECT_ROOT), os.environ.get("PYTHONPATH")])),
                   "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "default",
                   "COLD_MAPS_CACHE_DIR": str(self.cache)}
            self.process = subprocess.Popen(
                [sys.executable, str(Path(__file__).resolve()), "--worker", "--memory-mb", str(self.memory_mb)],
                stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True, env=env)
        return self.process

    def run(self, job: dict[str, object], timeout_s: float) -> list[dict[str, str]] | str:
        """The verdicts, or "hang" / "crash" when the worker passed the time or died."""
        process = self.start()
        assert process.stdin is not None and process.stdout is not None
        try:
            process.stdin.write(json.dumps(job) + "\n")
            process.stdin.flush()
        except BrokenPipeError:
            self.stop()
            return "crash"
        ready, _, _ = select.select([process.stdout], [], [], timeout_s)
        if not ready:
            self.stop()
            return "hang"
        line = process.stdout.readline()
        if not line:
            self.stop()
            return "crash"
        return json.loads(line)

    def stop(self) -> None:
        if self.process is not None:
            self.process.kill()
            self.process.wait()
            self.process = None


def _outcome(verdicts: list[dict[str, str]]) -> str:
    return max((v["outcome"] for v in verdicts), key=OUTCOMES.index)


def fuzz(sources: Sequence[Path], *, seed: int, cases: int, seconds: float, workers: int = 1,
         case_timeout_s: float = 20.0, eval_timeout_s: float = 300.0, memory_mb: int = 2048, eval_every: int = 0,
         step_m: float = 0.1, geojson_every: int = 1, failures: Path | None = None, progress: Callable[[Report], None] | None = None) -> Report:
    """Runs up to ``cases`` cases, stopping dispatch after ``seconds``; returns the counts.

    Every case runs ``info`` and the CSV export; every ``geojson_every``-th also the GeoJSON
    export, every ``eval_every``-th (0: none) also ``cold-eval``."""
    report = Report()
    start = time.monotonic()
    pending: queue.Queue[int] = queue.Queue()
    for index in range(cases):
        pending.put(index)
    lock = threading.Lock()
    scratch = Path(tempfile.mkdtemp(prefix="fuzz_maps-"))

    def serve(slot: int) -> None:
        runner = _Worker(memory_mb, scratch / "cache")
        try:
            while time.monotonic() - start < seconds:
                try:
                    index = pending.get_nowait()
                except queue.Empty:
                    return
                case = make_case(index, seed, sources, eval_every)
                path = scratch / f"w{slot}" / f"case{index}.xodr"
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(case.data)
                job = {"path": str(path), "work": str(scratch / f"w{slot}" / "out"), "evaluate": case.evaluate,
                       "step": step_m, "geojson": index % geojson_every == 0}
                answer = runner.run(job, eval_timeout_s if case.evaluate else case_timeout_s)
                verdicts = [{"command": "worker", "outcome": answer, "detail": ""}] if isinstance(answer, str) else answer
                outcome = _outcome(verdicts)
                with lock:
                    _record(report, case, outcome, verdicts, failures)
                    if progress is not None:
                        progress(report)
                path.unlink()
        finally:
            runner.stop()

    threads = [threading.Thread(target=serve, args=(slot,)) for slot in range(workers)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    shutil.rmtree(scratch, ignore_errors=True)
    report.seconds = time.monotonic() - start
    return report


def _record(report: Report, case: Case, outcome: str, verdicts: list[dict[str, str]], failures: Path | None) -> None:
    report.cases += 1
    report.evaluated += int(any(v["command"] == "cold-eval" for v in verdicts))
    report.outcomes[outcome] += 1
    for kind in {m.split(":")[0].split(" ")[0] for m in case.mutations}:
        report.by_mutation[kind, outcome] += 1
    if outcome not in FAILURES:
        return
    note = {"case": case.index, "source": str(case.source), "outcome": outcome, "mutations": list(case.mutations),
            "verdicts": [v for v in verdicts if v["outcome"] in FAILURES]}
    report.failures.append(note)
    if failures is not None:
        failures.mkdir(parents=True, exist_ok=True)
        stem = failures / f"case{case.index:06d}-{outcome}"
        stem.with_suffix(".xodr").write_bytes(case.data)
        stem.with_suffix(".json").write_text(json.dumps(note, indent=1) + "\n")


def default_maps() -> list[Path]:
    """The bundled maps."""
    return sorted((PROJECT_ROOT / "maps").glob("*.xodr"))


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point; returns 0 when no case failed."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--cases", type=int, default=1000, help="cases to run at most")
    parser.add_argument("--seconds", type=float, default=600.0, help="stop starting cases after this (s)")
    parser.add_argument("--workers", type=int, default=1, help="worker processes")
    parser.add_argument("--map", action="append", type=Path, default=[], help="also mutate this map (repeatable)")
    parser.add_argument("--case-timeout", type=float, default=20.0, help="limit per case (s)")
    parser.add_argument("--eval-timeout", type=float, default=300.0, help="limit per case through cold-eval (s)")
    parser.add_argument("--memory-mb", type=int, default=2048, help="address space a case may add (MB)")
    parser.add_argument("--step", type=float, default=0.1, help="export step (m)")
    parser.add_argument("--geojson-every", type=int, default=1, help="every Nth case also exports GeoJSON")
    parser.add_argument("--eval-every", type=int, default=250, help="every Nth case also through cold-eval (0: none)")
    parser.add_argument("--failures", type=Path, default=Path("out/fuzz_maps"), help="folder for failing cases")
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        worker(args.memory_mb)
        return 0
    last = [time.monotonic()]

    def progress(report: Report) -> None:
        if time.monotonic() - last[0] > 30.0:
            last[0] = time.monotonic()
            print(f"... {report.cases} cases: " + ", ".join(f"{o} {report.outcomes[o]}" for o in OUTCOMES),
                  file=sys.stderr, flush=True)

    report = fuzz(default_maps() + args.map, seed=args.seed, cases=args.cases, seconds=args.seconds,
                  workers=args.workers, case_timeout_s=args.case_timeout, eval_timeout_s=args.eval_timeout,
                  memory_mb=args.memory_mb, eval_every=args.eval_every, step_m=args.step,
                  geojson_every=args.geojson_every, failures=args.failures, progress=progress)
    print("\n".join(report.lines()))
    for note in report.failures[:20]:
        print(f"case {note['case']} ({Path(str(note['source'])).name}) {note['outcome']}: {note['verdicts']}")
    if report.failures:
        print(f"{len(report.failures)} failing cases written to {args.failures}")
    return 1 if report.failed else 0


if __name__ == "__main__":
    sys.exit(main())
