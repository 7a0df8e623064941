"""tools/fuzz_maps.py: its mutator is seeded, its verdicts catch what they claim to, and a
small seeded budget over the bundled maps finds no crash, hang, NaN or noisy stderr."""

from __future__ import annotations

import sys
import warnings
from pathlib import Path

from conftest import load_tool

fuzz_maps = load_tool("fuzz_maps")
SEED = 16
BUDGET_CASES = 36


def test_cases_are_seeded() -> None:
    sources = fuzz_maps.default_maps()
    assert len(sources) == 5
    first = fuzz_maps.make_case(3, SEED, sources, eval_every=0)
    again = fuzz_maps.make_case(3, SEED, sources, eval_every=0)
    other = fuzz_maps.make_case(4, SEED, sources, eval_every=0)
    assert first.data == again.data and first.mutations == again.mutations
    assert first.data != other.data
    assert 1 <= len(first.mutations) <= 5
    assert first.data != first.source.read_bytes()


def test_eval_every_selects_every_nth_case() -> None:
    sources = fuzz_maps.default_maps()
    chosen = [i for i in range(12) if fuzz_maps.make_case(i, SEED, sources, eval_every=4).evaluate]
    assert chosen == [3, 7, 11]


def _verdict(tmp_path: Path, status: int, stderr: str = "", csv_text: str | None = None, leave: bool = False,
             warn: bool = False) -> str:
    output = tmp_path / "out.csv"

    def run() -> int:
        if csv_text is not None or leave:
            output.write_text(csv_text or "s,x,y,z\n")
        if warn:
            warnings.warn("overflow encountered in multiply", RuntimeWarning)
        sys.stderr.write(stderr)
        return status

    finite = lambda _, texts: all(fuzz_maps._finite_csv(t, 4) for t in texts.values())
    return fuzz_maps.classify("test", run, [output], finite).outcome


def test_verdicts(tmp_path: Path) -> None:
    assert _verdict(tmp_path, 0, csv_text="s,x,y,z\n0.0,1.0,2.0,3.0\n") == "ok"
    assert _verdict(tmp_path, 0, csv_text="s,x,y,z\n0.0,nan,2.0,3.0\n") == "nan"
    assert _verdict(tmp_path, 0, csv_text="s,x,y,z\n0.0,1.0,-inf,3.0\n") == "nan"
    assert _verdict(tmp_path, 0, csv_text="s,x,y,z\n0.0,1.0,2.0,3.0\n0.1,1.0,2.0,NaN\n") == "nan"
    assert fuzz_maps._finite_csv("id,s,x\nnan,1.0,2.0\n", 2)  # a road called nan is no number
    assert _verdict(tmp_path, 0, csv_text="s,x,y,z\n0.0,1.0,2.0,3.0\n", warn=True) == "noisy"
    (tmp_path / "out.csv").unlink()
    assert _verdict(tmp_path, 1, "cold-maps: error: bad map\n") == "error"
    assert _verdict(tmp_path, 1, "cold-maps: error: bad map\nmore\n") == "crash"
    assert _verdict(tmp_path, 1, "cold-maps: error: bad map\n", leave=True) == "crash"
    (tmp_path / "out.csv").unlink()
    assert _verdict(tmp_path, 1, "Traceback (most recent call last):\n") == "crash"


def test_exception_out_of_main_is_a_crash(tmp_path: Path) -> None:
    def run() -> int:
        raise MemoryError

    assert fuzz_maps.classify("test", run, [], lambda *_: True).outcome == "crash"


def test_finite_json_and_info() -> None:
    assert fuzz_maps._finite_json('{"a": [1.0, 2.5]}')
    assert not fuzz_maps._finite_json('{"a": NaN}')
    assert not fuzz_maps._finite_json('{"a": -Infinity}')
    assert fuzz_maps._finite_info("name: nan road\ndriving lanes: 0.331 km")
    assert not fuzz_maps._finite_info("name: x\ndriving lanes: nan km")


def test_small_budget_finds_no_failure(tmp_path: Path) -> None:
    report = fuzz_maps.fuzz(fuzz_maps.default_maps(), seed=SEED, cases=BUDGET_CASES, seconds=120.0, workers=1,
                            step_m=1.0, failures=tmp_path / "failures")
    assert report.cases == BUDGET_CASES, report.lines()
    assert report.failed == 0, report.failures
    assert report.outcomes["ok"] > 0 and report.outcomes["error"] > 0, report.lines()
    assert not (tmp_path / "failures").exists()


def test_worker_hang_and_death_are_reported(tmp_path: Path) -> None:
    worker = fuzz_maps._Worker(memory_mb=256, cache=tmp_path)
    job = {"path": "/nonexistent", "work": str(tmp_path / "work"), "evaluate": False, "step": 1.0, "geojson": False}
    try:
        assert worker.run(job, 0.0) == "hang"  # nothing answers in no time (it is still importing)
        assert worker.process is None
        assert worker.run({"path": "/nonexistent"}, 60.0) == "crash"  # a malformed job kills the worker
        assert worker.run(job, 60.0)[0]["outcome"] == "error"  # restarted: the missing file is a clean error
    finally:
        worker.stop()
