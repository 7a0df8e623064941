"""Outputs of ``cold-eval`` runs with their runtimes taken out, for comparing runs that
must agree (worker counts, Dask against processes); Ctrl-C of a child process, and runs
that surely still run when the test interrupts them."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any


def metrics_without_runtimes(out: Path) -> dict[str, Any]:
    """``metrics.json`` without the ``runtime_ms`` fields and the provenance's command line
    (which names ``--workers`` and the output folder when they differ)."""
    document = json.loads((out / "metrics.json").read_text())
    document.get("provenance", {}).pop("command", None)
    document.get("provenance", {}).get("params", {}).pop("out", None)
    for record in document["scenarios"]:
        del record["runtime_ms"]
    return document


def rows_without_runtimes(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The rows without their ``runtime_ms*`` columns."""
    return [{k: v for k, v in row.items() if not k.startswith("runtime_ms")} for row in rows]


def frames_without_runtimes(out: Path) -> list[dict[str, Any]]:
    """``frames.csv`` rows in file order without the ``runtime_ms`` column."""
    with open(out / "frames.csv", newline="") as stream:
        return rows_without_runtimes(list(csv.DictReader(stream)))


def mcap_messages(out: Path) -> list[tuple[str, int, bytes]]:
    """(topic, log time ns, payload) of every message of ``run.mcap`` in file order."""
    from mcap.reader import make_reader

    with open(out / "run.mcap", "rb") as stream:
        return [(channel.topic, message.log_time, message.data)
                for _, channel, message in make_reader(stream).iter_messages(log_time_order=False)]


def default_sigint() -> None:
    """``preexec_fn`` of a child that the test interrupts: Ctrl-C raises KeyboardInterrupt
    there even when the tests run in a background job (which ignores SIGINT, and children
    inherit that)."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


STALLED_WAIT_S = 120.0
"""How long :func:`stalled_run` waits for the run's processes to stall (s)."""


def stalled_run(args: list[str], stall_dir: Path, processes: int) -> subprocess.Popen[str]:
    """``cold-eval ARGS --method fusion_method_example:stalls`` in a child process (SIGINT
    default, stderr piped), returned once ``processes`` of its processes (the workers, or
    the run itself in one process) sleep inside that method: the run cannot end before the
    test signals it, however slow the machine."""
    import fusion_method_example

    tests = Path(__file__).resolve().parent
    stall_dir.mkdir(parents=True, exist_ok=True)
    env = os.environ | {fusion_method_example.STALL_DIR_ENV: str(stall_dir),
                        "PYTHONPATH": os.pathsep.join(filter(None, [str(tests), os.environ.get("PYTHONPATH")]))}
    process = subprocess.Popen([sys.executable, "-m", "cold_maps.cli.evaluate", *args,
                                "--method", "fusion_method_example:stalls"],
                               stderr=subprocess.PIPE, text=True, cwd=tests.parent, env=env, preexec_fn=default_sigint)
    deadline = time.monotonic() + STALLED_WAIT_S
    while len(list(stall_dir.iterdir())) < processes and time.monotonic() < deadline and process.poll() is None:
        time.sleep(0.05)
    if len(list(stall_dir.iterdir())) < processes:
        process.kill()
        _, err = process.communicate()
        raise AssertionError(f"the run did not stall in {processes} processes: {err}")
    return process
