"""Conventions shared by the command-line tools: logging to stderr, exit statuses, the
one-line report of a failure before any output was written, SIGTERM handled like Ctrl-C,
and a reader that closes the pipe early ending the command quietly."""

from __future__ import annotations

import argparse
import functools
import logging
import os
import signal
import sys
from types import FrameType
from typing import Callable, Final, Sequence

EXIT_FAILURE: Final[int] = 1
EXIT_INTERRUPTED: Final[int] = 130
"""Ctrl-C (SIGINT): 128 + 2."""
EXIT_BROKEN_PIPE: Final[int] = 141
"""The reader of standard output went away (SIGPIPE): 128 + 13, what a shell reports."""
EXIT_TERMINATED: Final[int] = 143
"""SIGTERM (a batch scheduler, ``timeout``, a container stop): 128 + 15."""


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread where Ctrl-C raises ``KeyboardInterrupt``, so a
    terminated run finalises its outputs as partial exactly like an interrupted one."""


def _raise_terminated(signum: int, frame: FrameType | None) -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    raise Terminated()


def interruption(exc: BaseException) -> tuple[str, int]:
    """What ended a run early by a signal, and the exit status: ``terminated`` 143 for
    SIGTERM, ``interrupted`` 130 for Ctrl-C."""
    return ("terminated", EXIT_TERMINATED) if isinstance(exc, Terminated) else ("interrupted", EXIT_INTERRUPTED)


def cli_entry(body: Callable[[Sequence[str] | None], int]) -> Callable[[Sequence[str] | None], int]:
    """Wraps a command's entry point: SIGTERM raises :class:`Terminated` while it runs (the
    previous handler is restored after), and a closed standard output ends it quietly with
    ``EXIT_BROKEN_PIPE`` instead of an error and a traceback at exit."""

    @functools.wraps(body)
    def main(argv: Sequence[str] | None = None) -> int:
        previous = signal.signal(signal.SIGTERM, _raise_terminated)
        try:
            status = body(argv)
            sys.stdout.flush()
            return status
        except BrokenPipeError:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            return EXIT_BROKEN_PIPE
        finally:
            signal.signal(signal.SIGTERM, previous)

    return main


def configure_logging(verbose: int) -> None:
    """Logging to stderr: warnings, ``-v`` info, ``-vv`` debug."""
    logging.basicConfig(level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)],
                        format="%(levelname)s %(name)s: %(message)s", stream=sys.stderr)


def startup_failure(prog: str, exc: BaseException) -> int:
    """One line on stderr for a failure before any output was written; the exit status."""
    if isinstance(exc, KeyboardInterrupt):
        what, status = interruption(exc)
        print(f"{prog}: {what} before the run started; nothing written", file=sys.stderr)
        return status
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
