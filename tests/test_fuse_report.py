"""``cold-fuse --report``: a report that agrees with itself and is its own, on a recording of
a small ``cold-eval`` run on the junction map (whose spline fusions across the junction
leave lanes the ground truth does not cover)."""

from __future__ import annotations

import contextlib
import io
import json
import re
from pathlib import Path

import pytest
from conftest import bundled_map

from cold_maps.cli import evaluate, fuse
from cold_maps.evaluation.run import UNKNOWN_RELATIONS


@pytest.fixture(scope="module")
def refused(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """The report folder of ``cold-fuse`` on the recording, and its result line."""
    root = tmp_path_factory.mktemp("fuse-report")
    assert evaluate.main(["--map", str(bundled_map("junction")), "--frames", "30", "--routes", "2", "--no-plots",
                          "--workers", "1", "-q", "--out", str(root / "eval")]) == 0
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout):
        assert fuse.main(["--input", str(root / "eval" / "run.mcap"), "-o", str(root / "f.mcap"), "--report",
                          str(root / "R"), "--no-progress"]) == 0
    return root / "R", stdout.getvalue()


def test_the_summary_is_cold_fuses_own(refused: tuple[Path, str]) -> None:
    report, _ = refused
    assert (report / "summary.md").read_text().startswith("# cold-fuse summary\n")


def test_false_fusions_do_not_deny_the_fused_pairs(refused: tuple[Path, str]) -> None:
    """The section said "None: no pair was fused" below a table of fused pairs; a recording
    has no true lane relation, so it says the false fusions are not determined, counting the
    pairs the table shows fused."""
    report, _ = refused
    summary = (report / "summary.md").read_text()
    scenarios = json.loads((report / "metrics.json").read_text())["scenarios"]
    fused_pairs = sum(s["fused_frames"] for s in scenarios if s["fusion"] != "local" and s["boundary"] == "left")
    assert fused_pairs > 0
    section = summary.split("## False fusions\n\n", 1)[1]
    assert "no pair was fused" not in section
    assert section.startswith(UNKNOWN_RELATIONS.format(fused=fused_pairs))


def test_unmatched_ground_truth_is_explained_everywhere(refused: tuple[Path, str]) -> None:
    """"GROUND TRUTH NOT TRUSTWORTHY … (: 324)" had an empty reason, metrics.json no
    ``gt_unmatched`` breakdown and the result line no verdict: each unscored lane now names
    why (the meter's reasons), the breakdown sums to the rejections, and the result line
    carries the summary's warning."""
    report, line = refused
    scenarios = json.loads((report / "metrics.json").read_text())["scenarios"]
    unmatched = [s for s in scenarios if s["rejected"].get("gt_unmatched")]
    assert unmatched
    for scenario in unmatched:
        breakdown = scenario["gt_unmatched"]
        assert sum(breakdown.values()) == scenario["rejected"]["gt_unmatched"]
        assert set(breakdown) <= {"off_lane", "past_gt_end"}, breakdown
    summary = (report / "summary.md").read_text()
    warning = re.search(r"\*\*GROUND TRUTH NOT TRUSTWORTHY on this run:\*\*\n\n- (.+)\n", summary)
    assert warning is not None and "(: " not in warning.group(1)
    total = sum(s["rejected"]["gt_unmatched"] for s in unmatched)
    assert f"{total} of " in warning.group(1)
    assert line.startswith("cold-fuse: 60 frames fused -> ")
    assert line.rstrip("\n").endswith(f"; GROUND TRUTH NOT TRUSTWORTHY: {warning.group(1)}")
