"""Atomic output files: mode from the umask, nothing left behind on failure."""

from __future__ import annotations

import os
import stat
from pathlib import Path

import pytest

from converters.atomic_io import atomic_output


@pytest.mark.parametrize("umask", [0o022, 0o077])
def test_finished_file_has_the_umask_mode_and_no_temporary_is_left(tmp_path: Path, umask: int) -> None:
    old = os.umask(umask)
    try:
        with atomic_output(tmp_path / "out.txt") as stream:
            stream.write("a,b\n")
    finally:
        os.umask(old)
    assert (tmp_path / "out.txt").read_text() == "a,b\n"
    assert stat.S_IMODE((tmp_path / "out.txt").stat().st_mode) == 0o666 & ~umask
    assert os.listdir(tmp_path) == ["out.txt"]


def test_failure_keeps_the_old_file_and_removes_the_temporary(tmp_path: Path) -> None:
    target = tmp_path / "out.bin"
    target.write_bytes(b"old")
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_output(target, "wb") as stream:
            stream.write(b"new, half written")
            raise RuntimeError("boom")
    assert target.read_bytes() == b"old"
    assert os.listdir(tmp_path) == ["out.bin"]
