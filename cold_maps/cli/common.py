"""Conventions shared by the command-line tools ``cold-maps``, ``cold-eval`` (and ``cold-eval
sweep``) and ``cold-fuse``: one parser factory (``--version``, ``-v/-vv``, ``-q``,
``--no-progress``, defaults in the help, help text without markup, usage errors as one line
with exit 2), argparse types that check a value with the configuration's own validation (a
bad value is a usage error whichever layer bounds it; :class:`UsageError` for options that
contradict each other), logging to
stderr around progress bars, one error prefix ``PROG: error: [SUBCOMMAND: ]message``, exit
statuses, SIGTERM handled like Ctrl-C, and a reader that closes the pipe early ending the
command quietly."""

from __future__ import annotations

import argparse
import functools
import io
import logging
import math
import os
import re
import signal
import sys
from types import FrameType
from typing import Callable, Final, Sequence, TextIO, TypeVar

T = TypeVar("T")

EXIT_FAILURE: Final[int] = 1
EXIT_USAGE: Final[int] = 2
"""A bad command line (argparse's convention)."""
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


def _exit_now(status: int) -> None:
    """Ends the program with ``status`` once its outputs are written, without the interpreter's
    exit handlers: an interruption can leave a lock of a worker pool's bookkeeping thread
    held (a signal landing inside a ``with lock:``), and joining that thread at exit would
    then hang for ever."""
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(status)


def interruption(exc: BaseException) -> tuple[str, int]:
    """What ended a run early by a signal, and the exit status: ``terminated`` 143 for
    SIGTERM, ``interrupted`` 130 for Ctrl-C."""
    return ("terminated", EXIT_TERMINATED) if isinstance(exc, Terminated) else ("interrupted", EXIT_INTERRUPTED)


CliBody = Callable[[Sequence[str] | None], int]


def _out_of_memory_line(prog: str) -> bytes:
    """The out-of-memory line without the limit, encoded in advance: written when even
    formatting the full line runs out of memory."""
    program, _, command = prog.partition(" ")
    where = f"{command}: " if command else ""
    return f"{program}: error: {where}out of memory\n".encode()


def _fail_out_of_memory(prog: str, last_resort: bytes) -> int:
    """One line for a run that ran out of memory, naming the limit; ``last_resort`` written
    straight to file descriptor 2 when the line cannot be formatted or printed either (at
    the very edge of a limit), never an exception reaching the interpreter, whose
    traceback printing would fail and dump the exception object instead."""
    try:
        return fail(prog, f"out of memory ({memory_limit()})")
    except MemoryError:
        try:
            os.write(2, last_resort)
        except OSError:
            pass
        return EXIT_FAILURE


def cli_entry(prog: str) -> Callable[[CliBody], CliBody]:
    """Wraps the entry point of the command ``prog``: SIGTERM raises :class:`Terminated`
    while it runs (the previous handler is restored after); an interruption the command
    does not handle itself ends it with one line on stderr (``PROG: error: interrupted``)
    and 130 / 143 instead of a traceback; a closed standard output ends it quietly with
    ``EXIT_BROKEN_PIPE`` instead of an error and a traceback at exit. Run as the program
    (``argv`` None), an interrupted command exits at once after its outputs are written
    (:func:`_exit_now`); called with ``argv`` (tests, other Python code) it returns. Running
    out of memory ends it with one line naming the memory limit (:func:`memory_limit`),
    written once the failed work's data is freed."""

    last_resort = _out_of_memory_line(prog)

    def wrap(body: CliBody) -> CliBody:
        @functools.wraps(body)
        def main(argv: Sequence[str] | None = None) -> int:
            previous = signal.signal(signal.SIGTERM, _raise_terminated)
            out_of_memory = False
            try:
                status = body(argv)
                sys.stdout.flush()
            except BrokenPipeError:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, sys.stdout.fileno())
                return EXIT_BROKEN_PIPE
            except KeyboardInterrupt as exc:
                what, status = interruption(exc)
                status = fail(prog, what, status)
            except MemoryError:
                out_of_memory = True  # reported below: here its traceback still holds the data that filled memory
            finally:
                signal.signal(signal.SIGTERM, previous)
            if out_of_memory:
                status = _fail_out_of_memory(prog, last_resort)
            if argv is None and status in (EXIT_INTERRUPTED, EXIT_TERMINATED):
                _exit_now(status)
            return status

        return main

    return wrap


class UsageError(ValueError):
    """A bad command line found after parsing (options that contradict each other): reported
    like argparse's own usage errors, ``PROG: error: message (see PROG --help)``, exit 2."""


def usage_failure(prog: str, exc: UsageError) -> int:
    """One line on stderr for a :class:`UsageError`; ``EXIT_USAGE``."""
    return fail(prog, f"{exc} (see {prog} --help)", EXIT_USAGE)


class CliParser(argparse.ArgumentParser):
    """ArgumentParser that reports a usage error as ONE line on stderr,
    ``PROG: error: [SUBCOMMAND: ]message (see PROG [SUBCOMMAND] --help)``, and exits 2."""

    def error(self, message: str) -> None:  # type: ignore[override]
        sys.exit(usage_failure(self.prog, UsageError(message)))


def takes_value(action: argparse.Action) -> bool:
    """Whether an option reads a value from the command line (not a flag, a counter,
    ``--help`` or ``--version``)."""
    return bool(action.option_strings) and action.nargs != 0


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Appends ``(default: X)`` to the help of an option that takes a value, unless the help
    names its default already. An option whose default is None (computed, or off) must name
    its effective default in its help text (tests/test_cli_conventions.py checks every one)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help
        if not text or "default" in text or not takes_value(action) or action.default in (None, argparse.SUPPRESS):
            return text
        return f"{text} (default: %(default)s)"


_ROLE = re.compile(r":[a-z]+(?::[a-z]+)?:`~?([^`<]*?)(?:\s*<[^>]*>)?`")


def plain(text: str) -> str:
    """``text`` (a docstring's paragraph) without reStructuredText markup, on one line:
    ``:func:`name``` → name, double back-quotes dropped."""
    return " ".join(_ROLE.sub(r"\1", text).replace("``", "").split())


def make_parser(prog: str, description: str, *, progress: bool) -> CliParser:
    """The parser every command starts from: ``--version``, ``-v/--verbose`` (count),
    ``-q/--quiet`` and, when the command draws progress bars, ``--no-progress``.
    ``description`` may be a docstring's paragraph: its markup is dropped (:func:`plain`)."""
    parser = CliParser(prog=prog, description=plain(description), formatter_class=DefaultsHelpFormatter)
    add_version_option(parser, prog)
    add_output_options(parser, progress=progress)
    return parser


def add_version_option(parser: argparse.ArgumentParser, prog: str) -> None:
    """``--version``: prints ``PROG VERSION`` and exits 0 (on a subcommand too)."""
    from cold_maps import __version__

    parser.add_argument("--version", action="version", version=f"{prog} {__version__}")


def add_output_options(parser: argparse.ArgumentParser, *, progress: bool, inherited: bool = False) -> None:
    """``-v/--verbose``, ``-q/--quiet`` (mutually exclusive) and optionally ``--no-progress``.
    ``inherited``: on a subcommand whose parent parser has them too; not given there, they
    keep the parent's value."""

    def default(value: object) -> object:
        return argparse.SUPPRESS if inherited else value

    loudness = parser.add_mutually_exclusive_group()
    loudness.add_argument("-v", "--verbose", action="count", default=default(0),
                          help="log what happens to stderr (-vv: debug)")
    loudness.add_argument("-q", "--quiet", action="store_true", default=default(False),
                          help="no result line, no progress bar, no warnings; errors still on stderr")
    if progress:
        parser.add_argument("--no-progress", action="store_true", default=default(False),
                            help="no progress bar (drawn only when stderr is a terminal anyway)")


def progress_stream(args: argparse.Namespace) -> TextIO:
    """Where the progress bars of a run draw: stderr, or under ``--quiet``/``--no-progress``
    a stream that is no terminal (bars draw only on a terminal, so none is drawn)."""
    return io.StringIO() if args.quiet or getattr(args, "no_progress", False) else sys.stderr


def result_line(args: argparse.Namespace, prog: str, message: str) -> None:
    """The one line on stdout that reports a command's success, ``PROG: message``, unless ``--quiet``."""
    if not args.quiet:
        print(f"{prog}: {message}")


class _BarAwareHandler(logging.Handler):
    """Writes each record to the current ``sys.stderr`` through ``tqdm.write``, which
    clears the progress bars on it and draws them again below the line; on a terminal the
    line is cleared first too, so a record never glues onto a bar drawn by other means."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            from tqdm import tqdm

            from cold_maps.common.progress import ERASE_LINE_END, is_terminal

            stream = sys.stderr
            clear = "\r" + ERASE_LINE_END if is_terminal(stream) else ""
            tqdm.write(clear + self.format(record), file=stream)
        except Exception:  # noqa: BLE001 - logging's own convention for a failing handler
            self.handleError(record)


def configure_logging(verbose: int, quiet: bool = False) -> None:
    """Logging to stderr, around progress bars: warnings, ``-v`` info, ``-vv`` debug,
    ``-q`` errors only. Replaces the handlers a previous call installed."""
    level = logging.ERROR if quiet else (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]
    handler = _BarAwareHandler()
    handler.setFormatter(logging.Formatter("%(levelname)s %(name)s: %(message)s"))
    root = logging.getLogger()
    for old in [h for h in root.handlers if isinstance(h, _BarAwareHandler)]:
        root.removeHandler(old)
    root.addHandler(handler)
    root.setLevel(level)


def one_line(exc: BaseException | str) -> str:
    """An exception's (or a text's) message on one line; the exception's type when it has none."""
    text = " ".join(str(exc).split())
    return text or (type(exc).__name__ if isinstance(exc, BaseException) else "")


def fail(prog: str, message: str, status: int = EXIT_FAILURE) -> int:
    """``PROG: error: message`` as one line on stderr (``PROG SUBCOMMAND`` as
    ``PROG: error: SUBCOMMAND: message``); returns ``status``."""
    program, _, command = prog.partition(" ")
    where = f"{command}: " if command else ""
    print(f"{program}: error: {where}{one_line(message)}", file=sys.stderr)
    return status


def memory_limit() -> str:
    """The memory the process may use, in words: ``ulimit -v``/``-d``, the cgroup's
    ``memory.max``, else the machine's memory."""
    import resource

    gib = 2.0**30
    for which, name in ((resource.RLIMIT_AS, "address space, ulimit -v"), (resource.RLIMIT_DATA, "data, ulimit -d")):
        soft, _ = resource.getrlimit(which)
        if soft != resource.RLIM_INFINITY:
            return f"limit {soft / gib:.3g} GiB of {name}"
    try:
        with open("/sys/fs/cgroup/memory.max", encoding="ascii") as stream:
            cgroup = stream.read().strip()
    except OSError:
        cgroup = "max"
    if cgroup.isdigit():
        return f"limit {int(cgroup) / gib:.3g} GiB, cgroup memory.max"
    return f"the machine has {os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / gib:.3g} GiB"


def startup_failure(prog: str, exc: BaseException) -> int:
    """One line on stderr for a failure before any output was written; the exit status
    (``EXIT_USAGE`` for a :class:`UsageError`; a ``MemoryError`` is raised again, for
    :func:`cli_entry` to report once freed)."""
    if isinstance(exc, MemoryError):
        raise exc
    if isinstance(exc, UsageError):
        return usage_failure(prog, exc)
    if isinstance(exc, KeyboardInterrupt):
        what, status = interruption(exc)
        return fail(prog, f"{what} before the run started; nothing written", status)
    logging.getLogger(prog).debug("failed", exc_info=exc)
    return fail(prog, one_line(exc))


def int_in(low: int, high: int | None = None) -> Callable[[str], int]:
    """argparse type: an integer from ``low`` to ``high`` (no upper bound when None)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
        if value < low or (high is not None and value > high):
            bounds = f">= {low}" if high is None else f"from {low} to {high}"
            raise argparse.ArgumentTypeError(f"expected an integer {bounds}, got {text}")
        return value

    return parse


positive_int = int_in(1)
"""argparse type: an integer >= 1."""


def finite_number(text: str) -> float:
    """argparse type: a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text}")
    return value


_FIELD_PREFIX = re.compile(r"^[A-Za-z_]\w*\.[A-Za-z_]\w*:\s*")


def validated(parse: Callable[[str], T], check: Callable[[T], object]) -> Callable[[str], T]:
    """argparse type: ``parse``, then ``check`` the value with the validation of the
    configuration it feeds (:func:`builds`, :func:`within`). A ValueError of ``check`` becomes
    the usage error (exit 2, the option named by argparse), so each bound lives in one place."""

    def parse_checked(text: str) -> T:
        value = parse(text)
        try:
            check(value)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(_FIELD_PREFIX.sub("", one_line(exc))) from None
        return value

    return parse_checked


def builds(model: Callable[..., object], field: str) -> Callable[[object], object]:
    """A check for :func:`validated`: the configuration ``model(field=value)`` is built, and
    refuses the value itself (e.g. ``builds(SensorErrorModel, "noise_sigma_m")``)."""
    return lambda value: model(**{field: value})


def within(low: float, high: float, unit: str, *, low_open: bool = False) -> Callable[[float], None]:
    """A check for :func:`validated`: ``low <= value <= high`` (``low < value`` when
    ``low_open``); pass the bound constants the configuration uses."""

    def check(value: float) -> None:
        if not (low < value if low_open else low <= value) or value > high:
            raise ValueError(f"expected {'>' if low_open else '>='} {low:g} and <= {high:g} {unit}, got {value:g}")

    return check


def fusion_method(name: str) -> str:
    """argparse type: a fusion method name that resolves (``cold_maps.evaluation.methods``:
    a registered name or ``package.module:function``, looked up in the installed packages
    and the current folder); the name as given."""
    from cold_maps.evaluation.methods import MethodError, resolve_method

    try:
        resolve_method(name)
    except MethodError as exc:
        raise argparse.ArgumentTypeError(one_line(exc)) from None
    return name


MAX_GAP_M: Final[float] = 1e4
"""Largest spline gap d_s a command line accepts (m): far beyond any road a sensor of 30 m
bridges, small enough that stations and drive lengths stay exact."""


def gap_list(text: str) -> tuple[float, ...]:
    """argparse type: comma-separated spline gaps d_s (m), each > 0 and < ``MAX_GAP_M``."""
    try:
        gaps = tuple(float(part) for part in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated distances in m, got {text!r}") from None
    if not gaps or any(not 0 < g < MAX_GAP_M for g in gaps):
        raise argparse.ArgumentTypeError(f"gaps must be > 0 m and < {MAX_GAP_M:g} m, got {text!r}")
    return gaps


def add_converter_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    """``--converter engine|crdesigner``: the ground truth's converter, engine by default."""
    from cold_maps.groundtruth.lanelet2_from_engine import CONVERTERS

    parser.add_argument("--converter", choices=CONVERTERS, default=CONVERTERS[0], help=help_text)
