"""cold-eval with chains, lane history and messages: the extended metrics records, the
summary table and plot, and the default run left exactly as it was."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import bundled_map

from cold_maps.cli import evaluate
from cold_maps.evaluation.report import FrameRecord, ScenarioAccumulator, ScenarioKey, ScenarioResult
from cold_maps.evaluation.scenarios import Scenario, extended_scenarios

EXTENDED = {"vehicles", "history_m", "exchange", "bytes_per_message", "bytes_per_second", "correct_only"}


def _accumulator(vehicles):
    acc = ScenarioAccumulator(ScenarioKey("m", "spline", "hermite", 20.0, "left", vehicles, 100.0, "bezier"))
    acc.add(FrameRecord(0, 0.0, "ego", "coop50", np.array([0.1, 0.3]), perception_range_m=80.0, truly_fusible=True,
                        predicted_fusible=True))
    acc.add(FrameRecord(1, 0.1, "ego", "turn50", np.array([2.0]), perception_range_m=80.0, truly_fusible=False,
                        predicted_fusible=True))
    acc.add_traffic(120, 0.1)
    acc.add_traffic(0, 0.1)
    acc.add_traffic(200, 0.1)
    return acc


def test_extended_record_correct_only_and_traffic():
    result = _accumulator(3).result()
    assert result.max_error_m == 2.0 and result.correct_max_error_m == pytest.approx(0.3)
    assert result.correct_mean_error_m == pytest.approx(0.2)
    assert result.bytes_per_message == pytest.approx(160.0) and result.bytes_per_second == pytest.approx(1066.667, 1e-4)
    record = result.to_dict()
    assert EXTENDED <= set(record) and record["vehicles"] == 3 and record["exchange"] == "bezier"
    assert ScenarioResult.from_dict(json.loads(json.dumps(record))) == result


def test_default_record_has_no_extended_keys():
    record = _accumulator(0).result().to_dict()
    assert not EXTENDED & set(record)
    assert math.isnan(ScenarioResult.from_dict(record).bytes_per_message)


def test_extended_scenarios_add_chains_per_length():
    base = (Scenario("local"), Scenario("spline", "paper", 20.0, 50.0))
    out = extended_scenarios(base, coops=3, history_m=100.0, exchange="")
    assert [(s.fusion, s.vehicles) for s in out] == [("local", 1), ("spline", 2), ("spline", 3), ("spline", 4)]
    assert out[-1].chain_leads_m == (50.0, 100.0, 150.0) and out[-1].label == "spline-paper-d20-v4"
    with pytest.raises(ValueError, match="coops"):
        extended_scenarios(base, coops=0, history_m=0.0, exchange="")


@pytest.fixture(scope="module")
def cooperative_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("coop") / "out"
    status = evaluate.main(["--map", str(bundled_map("curve90")), "--frames", "6", "--routes", "1", "--gaps", "20",
                            "--interpolation", "hermite", "--coops", "2", "--history", "60", "--exchange", "bezier",
                            "--no-distractors", "--no-mcap", "--out", str(out)])
    return status, out


def test_cooperative_run_records_chains_history_and_messages(cooperative_run):
    status, out = cooperative_run
    assert status == 0
    records = json.loads((out / "metrics.json").read_text())["scenarios"]
    chains = [r for r in records if r["vehicles"] == 3 and r["fusion"] == "spline"]
    pairs = [r for r in records if r["vehicles"] == 2 and r["fusion"] == "spline"]
    assert chains and pairs and all(EXTENDED <= set(r) for r in records)
    for chain, pair in zip(chains, pairs):
        assert chain["history_m"] == 60.0 and chain["exchange"] == "bezier"
        assert chain["fused_frames"] > 0
        assert chain["perception_range_m"] > pair["perception_range_m"] + 40.0  # one more coop, 50 m further
        assert 0 < pair["bytes_per_message"] < 2000 and pair["bytes_per_second"] > 0
        assert chain["correct_only"]["max_error_m"] < 0.5
    summary = (out / "summary.md").read_text()
    assert "### 3 vehicle(s), history 60 m, exchange bezier" in summary
    assert (out / "plots" / "error_vs_range_curve90.png").stat().st_size > 1000


def test_cli_rejects_bad_cooperation_values(capsys):
    with pytest.raises(SystemExit):
        evaluate.main(["--map", "x.xodr", "--history", "-5"])
    with pytest.raises(SystemExit):
        evaluate.main(["--map", "x.xodr", "--exchange", "json"])
    assert "--history" in capsys.readouterr().err


def test_cli_rejects_options_without_their_feature(tmp_path, capsys):
    """Options that need another are a bad command line: exit 2, one line, nothing written."""
    map_path = str(bundled_map("straight"))
    assert evaluate.main(["--map", map_path, "--drift", "--out", str(tmp_path / "a")]) == 2
    assert "--history" in capsys.readouterr().err
    assert evaluate.main(["--map", map_path, "--loss", "0.2", "--out", str(tmp_path / "b")]) == 2
    err = capsys.readouterr().err
    assert "--exchange" in err and len(err.strip().splitlines()) == 1 and err.strip().endswith("(see cold-eval --help)")
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()
