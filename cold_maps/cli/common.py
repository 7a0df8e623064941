"""Conventions shared by the command-line tools: logging to stderr, exit statuses and the
one-line report of a failure before any output was written."""

from __future__ import annotations

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
