"""tools/bench_stages.py: exclusive time per stage (a nested stage counts for itself only,
the rest is ``other``), and every stage's functions of this checkout found, wrapped and put back."""

from __future__ import annotations

import pytest

from conftest import load_tool

bench_stages = load_tool("bench_stages")


class FakeTimer:
    """A clock that advances by ``step`` s on every reading."""

    def __init__(self, step: float) -> None:
        self.now, self.step = 0.0, step

    def __call__(self) -> float:
        self.now += self.step
        return self.now


def test_nested_stages_count_exclusively_and_the_rest_is_other() -> None:
    timer = FakeTimer(1.0)
    clock = bench_stages.StageClock(timer)
    inner = clock.wrap("ground truth", lambda: timer() and None)  # one reading inside: 1 s more
    outer = clock.wrap("fusion", lambda: inner())
    clock.take()
    outer()
    totals = clock.take()
    # readings: enter fusion (other +1), enter GT (fusion +1), inner body reading, leave GT (GT +2),
    # leave fusion (fusion +1), take (other +1)
    assert totals["fusion"] == pytest.approx(2.0)
    assert totals["ground truth"] == pytest.approx(2.0)
    assert totals["other"] == pytest.approx(2.0)
    assert sum(totals.values()) == pytest.approx(6.0)
    assert set(totals) == set(bench_stages.STAGES)


def test_a_stage_that_raises_still_ends() -> None:
    clock = bench_stages.StageClock(FakeTimer(0.5))

    def fail() -> None:
        raise ValueError("boom")

    clock.take()
    with pytest.raises(ValueError):
        clock.wrap("sensing", fail)()
    totals = clock.take()
    assert totals["sensing"] == pytest.approx(0.5)
    assert totals["other"] == pytest.approx(1.0)


def test_every_stage_has_targets_wrapped_where_the_evaluator_finds_them() -> None:
    import cold_maps.evaluation.evaluator as evaluator
    import cold_maps.simulation.detection as detection
    from cold_maps.groundtruth.meter import GroundTruthMeter

    functions = {id(getattr(detection, name, None)) for name in ("sense", "sense_block")} - {id(None)}
    bound = {name: value for name, value in vars(evaluator).items() if id(value) in functions}
    measure = GroundTruthMeter.__dict__["measure"]
    clock = bench_stages.StageClock(FakeTimer(1.0))
    try:
        missing = bench_stages.install(clock)
        for stage, targets in bench_stages.STAGE_TARGETS.items():
            assert set(targets) - set(missing), f"no function of stage {stage} found"
        assert bound, "the evaluator calls no sensing function by name"
        for name, original in bound.items():
            assert getattr(evaluator, name).__wrapped__ is original is getattr(detection, name).__wrapped__
        assert GroundTruthMeter.__dict__["measure"].__wrapped__ is measure
    finally:
        clock.restore()
    assert all(getattr(evaluator, name) is original for name, original in bound.items())
    assert GroundTruthMeter.__dict__["measure"] is measure
