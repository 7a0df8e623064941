"""tools/compare_recordings.py: two recordings of the same messages started at different
stamp bases compare equal; one changed coordinate, one missing message count."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cold_maps.recording.recorder import Recorder
from conftest import load_tool

compare_recordings = load_tool("compare_recordings")

LEFT = np.column_stack((np.linspace(0.0, 30.0, 31), np.full(31, 1.75)))
RIGHT = LEFT - [0.0, 3.5]


def record(path: Path, stamp_base_ns: int, frames: int = 3, shift_m: float = 0.0) -> Path:
    with Recorder(path, map_path="m.xodr", stamp_base_ns=stamp_base_ns) as recorder:
        for frame in range(frames):
            pose = (10.0 * frame, 0.0, 0.1)
            recorder.write_detection(frame / 10, frame, "ego", pose, LEFT, RIGHT, ego=True)
            recorder.write_gt(frame / 10, {"left": LEFT + [shift_m if frame == 1 else 0.0, 0.0]})
            recorder.write_fused(frame / 10, {})
            recorder.write_metrics(frame / 10, frame, {"error_m": 0.01 * frame})
    return path


def test_same_messages_at_other_stamp_bases_compare_equal(tmp_path: Path) -> None:
    base = record(tmp_path / "a.mcap", 1_000_000_000_000)
    later = record(tmp_path / "b.mcap", 1_700_000_000_123_456_789)
    assert compare_recordings.compare(base, later) == 0


def test_a_moved_line_and_a_missing_frame_are_counted(tmp_path: Path) -> None:
    base = record(tmp_path / "a.mcap", 0)
    assert compare_recordings.compare(base, record(tmp_path / "moved.mcap", 5, shift_m=1e-3)) == 1
    # the last frame's 6 messages (raw detection, /tf, detection scene, GT, fused, metrics) are missing
    assert compare_recordings.compare(base, record(tmp_path / "short.mcap", 0, frames=2)) == 6
