"""The evaluator's frame loop: the cyclic garbage collector it runs with (and gives back as it
was), and the scenario overlays it draws when a drive ends, also one cut short."""

from __future__ import annotations

import gc

import pytest
from conftest import bundled_map

from cold_maps.cli.evaluate import _plans, build_parser
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.evaluator import FRAME_LOOP_GC_THRESHOLD, MapEvaluator


def _evaluator() -> MapEvaluator:
    args = build_parser().parse_args(["--map", str(bundled_map("curve90")), "--frames", "30", "--routes", "1"])
    return MapEvaluator(_plans(args)[0])


def test_a_drive_runs_with_the_older_objects_frozen_and_gives_the_collector_back() -> None:
    evaluator = _evaluator()
    evaluator.prepare()
    threshold, frozen = gc.get_threshold(), gc.get_freeze_count()
    if frozen:
        pytest.skip("objects were frozen before the test: the evaluator leaves the collector alone then")
    seen: list[tuple[int, int]] = []
    evaluator.run_drive(0, Collector(), on_frame=lambda: seen.append((gc.get_freeze_count(), gc.get_threshold()[0])))
    assert len(seen) == 30
    assert all(count > 0 and young == FRAME_LOOP_GC_THRESHOLD for count, young in seen)
    assert gc.get_threshold() == threshold and gc.get_freeze_count() == 0


def test_a_callers_frozen_objects_and_threshold_are_left_alone() -> None:
    evaluator = _evaluator()
    evaluator.prepare()
    threshold = gc.get_threshold()
    gc.freeze()
    try:
        seen: list[int] = []
        evaluator.run_drive(0, Collector(), on_frame=lambda: seen.append(gc.get_threshold()[0]))
        assert seen == [threshold[0]] * 30
        assert gc.get_freeze_count() > 0  # still the caller's: not unfrozen
    finally:
        gc.unfreeze()


def test_a_drive_cut_short_draws_the_overlays_of_the_frames_it_recorded(monkeypatch) -> None:
    """An exception in frame 12 of 30: the overlays are those of a drive of its first 11 frames."""
    whole = _evaluator()
    short = Collector()
    whole.run_drive(0, short, frames=range(11))
    cut = _evaluator()
    original = MapEvaluator._finish_frame
    done: list[int] = []

    def failing(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        if len(done) == 11:
            raise RuntimeError("stop")
        done.append(1)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(MapEvaluator, "_finish_frame", failing)
    collector = Collector()
    with pytest.raises(RuntimeError):
        cut.run_drive(0, collector)
    assert short.overlays and list(collector.overlays) == list(short.overlays)
    assert [(o.frame, o.max_error_m) for o in collector.overlays.values()] == [
        (o.frame, o.max_error_m) for o in short.overlays.values()]
    assert not cut._worst
