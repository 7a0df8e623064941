"""Conventions shared by the command-line tools: logging to stderr, exit statuses and the
one-line report of a failure before any output was written."""

from __future__ import annotations

import argparse
import logging
import sys
from typing import Final

EXIT_FAILURE: Final[int] = 1
EXIT_INTERRUPTED: Final[int] = 130


def configure_logging(verbose: int) -> None:
    """Logging to stderr: warnings, ``-v`` info, ``-vv`` debug."""
    logging.basicConfig(level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)],
                        format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)


def startup_failure(prog: str, exc: BaseException) -> int:
    """One line on stderr for a failure before any output was written; the exit status."""
    if isinstance(exc, KeyboardInterrupt):
        print(f"{prog}: interrupted before the run started; nothing written", file=sys.stderr)
        return EXIT_INTERRUPTED
    logging.getLogger(prog).debug("failed", exc_info=exc)
    print(f"{prog}: {exc}", file=sys.stderr)
    return EXIT_FAILURE


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, got {text}")
    return value


def gap_list(text: str) -> tuple[float, ...]:
    """argparse type: comma-separated spline gaps d_s (m), each > 0."""
    try:
        gaps = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated distances in m, got {text!r}") from None
    if not gaps or any(not 0 < g < 1e4 for g in gaps):
        raise argparse.ArgumentTypeError(f"gaps must be > 0 m, got {text!r}")
    return gaps
