"""repr of FusionResult and LaneDetection: one short line whatever the number of points,
with the counts the arrays hold."""

from __future__ import annotations

import numpy as np
import pytest

import fusion
from fusion import LaneDetection, Pose2D, Source

MAX_REPR_CHARS = 300


def _detection(x: float, length_m: float, **kwargs) -> LaneDetection:
    ahead = np.arange(0.0, length_m, 0.1)
    return LaneDetection(Pose2D(x, 0.0, 0.0), np.column_stack((ahead, np.full_like(ahead, 2.0))),
                         np.column_stack((ahead, np.full_like(ahead, -2.0))), **kwargs)


@pytest.mark.parametrize("length_m", [30.0, 3000.0])
def test_spline_result_repr_counts_the_sources(length_m: float) -> None:
    ego, coop = _detection(0.0, length_m, sender="ego"), _detection(length_m + 20.0, length_m, sender="coop")
    result = fusion.fuse(ego, coop, interpolation="hermite")
    text = repr(result)
    counts = {source: int(np.count_nonzero(result.left_source == source)) for source in Source}
    assert counts[Source.EGO] == counts[Source.COOP] == round(length_m / 0.1)
    assert counts[Source.INTERPOLATED] > 0
    assert text.startswith(f"FusionResult(kind='spline', gap_m={result.gap_m:.3f}, ")
    assert (f"left: {len(result.left)} points (EGO {counts[Source.EGO]}, INTERPOLATED "
            f"{counts[Source.INTERPOLATED]}, COOP {counts[Source.COOP]})") in text
    assert "reason=" not in text and text.endswith(f"confidence={result.confidence:.3f}, lanes: 0, sigma: no)")
    assert len(text) < MAX_REPR_CHARS and "\n" not in text and "[" not in text


def test_refused_result_repr_says_why_and_sigma() -> None:
    ego = _detection(0.0, 30.0, left_sigma=np.full(300, 0.05), right_sigma=np.full(300, 0.05))
    turned = LaneDetection(Pose2D(50.0, 30.0, 2.0), ego.left, ego.right)
    result = fusion.fuse(ego, turned)
    text = repr(result)
    assert result.kind == "none" and result.reason
    assert f"kind='none', reason={result.reason!r}, " in text
    assert "left: 300 points (EGO 300), right: 300 points (EGO 300)" in text
    assert result.left_sigma is not None and text.endswith("sigma: yes)")  # the ego's σ carried through


def test_detection_repr_is_one_short_line() -> None:
    detection = _detection(12.5, 5000.0, sender="coop", stamp=1.5, pose_cov=np.diag([0.01, 0.01, 1e-4]))
    text = repr(detection)
    assert text == ("LaneDetection(sender='coop', stamp=1.5 s, pose=(12.500 m, 0.000 m, 0.0000 rad), left: 50000 "
                    "points, right: 50000 points, neighbours: 0, branches: 0, road_edges: no, history: no, "
                    "sigma: no, pose_cov: yes)")
