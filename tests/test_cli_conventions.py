"""One command-line convention for ``cold-maps``, ``cold-eval``, ``cold-eval sweep`` and
``cold-fuse``: ``--version``, ``-v/-vv`` and ``-q``, defaults in the help, usage errors and
runtime errors as ONE line ``PROG: error: [SUBCOMMAND: ]...`` (exit 2 and 1), and progress that never garbles the
terminal: no stale characters, log records never glued onto a bar, ``--no-progress``."""

from __future__ import annotations

import argparse
import io
import logging
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import PROJECT_ROOT, bundled_map

import cold_maps
from cold_maps.cli import evaluate, fuse, maps, sweep
from cold_maps.cli.common import MAX_GAP_M, DefaultsHelpFormatter, Terminated, cli_entry, configure_logging, gap_list
from cold_maps.common.progress import ProgressBar, Spinner


@dataclass(frozen=True)
class Cli:
    """One command under test.

    Fields:
        prog: its name.
        module: ``python -m`` module.
        ok: arguments of a quick successful run, given a tmp folder and a recording.
        broken: arguments of a run that fails at run time (a missing input), given a tmp folder.
        parsers: its argument parsers (every subcommand's too).
        command: arguments before every other (a subcommand with its own options).
    """

    prog: str
    module: str
    ok: Callable[[Path, Path], list[str]]
    broken: Callable[[Path], list[str]]
    parsers: Callable[[], list[argparse.ArgumentParser]]
    command: tuple[str, ...] = ()


def _maps_parsers() -> list[argparse.ArgumentParser]:
    found = [maps.build_parser()]
    for command in maps.COMMANDS:
        parser = maps.build_parser(selected=command.name)
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        found.append(sub.choices[command.name])
    return found


STRAIGHT = str(bundled_map("straight"))
CLIS = (
    Cli("cold-maps", "cold_maps.cli.maps", lambda tmp, rec: ["export", STRAIGHT, "-o", str(tmp / "b.csv")],
        lambda tmp: ["info", str(tmp / "none.xodr")], _maps_parsers),
    Cli("cold-eval", "cold_maps.cli.evaluate",
        lambda tmp, rec: ["--map", STRAIGHT, "--frames", "2", "--routes", "1", "--gaps", "30", "--no-distractors",
                          "--no-plots", "--no-mcap", "--out", str(tmp / "out")],
        lambda tmp: ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "out")], lambda: [evaluate.build_parser()]),
    Cli("cold-fuse", "cold_maps.cli.fuse", lambda tmp, rec: ["--input", str(rec), "-o", str(tmp / "re.mcap"), "--no-gt"],
        lambda tmp: ["--input", str(tmp / "none.mcap"), "-o", str(tmp / "re.mcap")], lambda: [fuse.build_parser()]),
    Cli("cold-eval sweep", "cold_maps.cli.evaluate",
        lambda tmp, rec: ["--map", STRAIGHT, "--gaps", "30", "--interpolation", "paper", "--frames", "2", "--routes",
                          "1", "--workers", "1", "--no-plots", "--out", str(tmp / "sweep")],
        lambda tmp: ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "sweep")], lambda: [sweep.build_parser()],
        command=("sweep",)),
)
IDS = [cli.prog for cli in CLIS]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("rec")
    assert evaluate.main(["--map", STRAIGHT, "--frames", "3", "--routes", "1", "--gaps", "30", "--no-distractors",
                          "--no-plots", "-q", "--out", str(out)]) == 0
    return out / "run.mcap"


def _run(cli: Cli, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", cli.module, *cli.command, *args], capture_output=True, text=True,
                          cwd=PROJECT_ROOT, timeout=120, check=False)


def _one_error_line(result: subprocess.CompletedProcess[str], prog: str) -> str:
    program, _, command = prog.partition(" ")
    prefix = f"{program}: error: " + (f"{command}: " if command else "")
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]


@pytest.mark.parametrize("cli", CLIS, ids=IDS)
def test_version(cli: Cli) -> None:
    result = _run(cli, "--version")
    assert (result.returncode, result.stdout, result.stderr) == (0, f"{cli.prog} {cold_maps.__version__}\n", "")


@pytest.mark.parametrize("cli", CLIS, ids=IDS)
def test_usage_errors_are_one_line_with_exit_2(cli: Cli, tmp_path: Path, recording: Path) -> None:
    for args in ([*cli.ok(tmp_path, recording), "--no-such-option"], ["-v", "-q", *cli.ok(tmp_path, recording)]):
        result = _run(cli, *args)
        assert result.returncode == 2 and result.stdout == ""
        line = _one_error_line(result, cli.prog)
        assert line.endswith("--help)") and ("--no-such-option" in line or "not allowed with" in line), line


@pytest.mark.parametrize("cli", CLIS, ids=IDS)
def test_runtime_errors_are_one_line_with_exit_1(cli: Cli, tmp_path: Path) -> None:
    result = _run(cli, *cli.broken(tmp_path))
    assert result.returncode == 1 and result.stdout == ""
    assert "none." in _one_error_line(result, cli.prog)


@pytest.mark.parametrize("cli", CLIS, ids=IDS)
def test_quiet_prints_nothing_and_verbose_logs_to_stderr(cli: Cli, tmp_path: Path, recording: Path) -> None:
    quiet = _run(cli, "-q", *cli.ok(tmp_path, recording))
    assert (quiet.returncode, quiet.stdout, quiet.stderr) == (0, "", "")
    for flags in (["-v"], ["-vv"]):
        loud = _run(cli, *flags, *cli.ok(tmp_path, recording))
        assert loud.returncode == 0, loud.stderr
        result = loud.stdout.splitlines()
        assert len(result) == 1 and result[0].startswith(f"{cli.prog}") and " -> " in result[0], loud.stdout
        assert all(line.split(" ", 1)[0] in ("DEBUG", "INFO", "WARNING") for line in loud.stderr.splitlines())


@pytest.mark.parametrize("cli", CLIS, ids=IDS)
def test_help_shows_every_default(cli: Cli) -> None:
    """Every option whose default is not "absent" or "off" names it in its help."""
    checked, example = 0, None
    for parser in cli.parsers():
        assert parser.formatter_class is DefaultsHelpFormatter
        formatter = DefaultsHelpFormatter(parser.prog)
        for action in parser._actions:
            if action.option_strings and action.default not in (None, False, argparse.SUPPRESS) \
                    and action.help != argparse.SUPPRESS and not isinstance(action, argparse._HelpAction):
                text = formatter._get_help_string(action) or ""
                assert "default" in text, (parser.prog, action.option_strings, text)
                checked += 1
                if example is None and isinstance(action.default, (str, int, float, Path)):
                    example = (parser.prog, action.default)  # shown as itself (a tuple is shown as written)
    assert example is not None
    shown = " ".join(_run(cli, *example[0].removeprefix(cli.prog).split(), "--help").stdout.split())
    assert f"default: {example[1]})" in shown or f"default {example[1]}" in shown, shown


def visible(output: str) -> list[str]:
    """The lines a terminal shows after ``output``: ``\\r`` returns to column 0, ``ESC [K``
    erases to the end of the line, other characters overwrite."""
    lines, line, column, i = [], [], 0, 0
    while i < len(output):
        if output.startswith("\x1b[K", i):
            del line[column:]
            i += 3
            continue
        char = output[i]
        if char == "\n":
            lines.append("".join(line))
            line, column = [], 0
        elif char == "\r":
            column = 0
        else:
            line[column:column + 1] = [char]
            column += 1
        i += 1
    return [*lines, "".join(line)]


class Terminal(io.StringIO):
    """A stream that says it is a terminal."""

    def isatty(self) -> bool:
        return True


def test_visible_follows_carriage_returns_and_erasure() -> None:
    assert visible("ETA 10 s\rETA 9 s") == ["ETA 9 ss"]
    assert visible("ETA 10 s\rETA 9 s\x1b[K\nnext") == ["ETA 9 s", "next"]


def test_bar_leaves_no_stale_characters() -> None:
    terminal = Terminal()
    with ProgressBar(3, "run", stream=terminal, min_interval_s=0.0) as bar:
        bar.update()
        terminal.write("\r" + "x" * 120)  # what a longer earlier draw left on the line
        bar.update(2)
    shown = visible(terminal.getvalue())
    assert shown[0].startswith("run [") and shown[0].endswith("3/3  ETA 00:00"), shown


@pytest.fixture
def root_logging():
    root = logging.getLogger()
    handlers, level = list(root.handlers), root.level
    yield
    root.handlers[:] = handlers
    root.setLevel(level)


def test_log_records_never_glue_onto_a_bar(monkeypatch: pytest.MonkeyPatch, root_logging: None) -> None:
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    configure_logging(1)
    with ProgressBar(4, "run", stream=terminal, min_interval_s=0.0) as bar:
        bar.update()
        logging.getLogger("cold-test").info("halfway there")
        bar.update(3)
    shown = visible(terminal.getvalue())
    assert "INFO cold-test: halfway there" in shown, shown
    assert shown[-2].startswith("run [") and "4/4" in shown[-2]


def test_spinner_shows_elapsed_time_and_clears_its_line(monkeypatch: pytest.MonkeyPatch,
                                                       root_logging: None) -> None:
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    configure_logging(1)
    with Spinner("converting", stream=terminal, delay_s=0.0, interval_s=0.01):
        time.sleep(0.1)
        logging.getLogger("cold-test").info("crdesigner done")
        time.sleep(0.05)
    assert "converting  00:00" in terminal.getvalue()
    shown = visible(terminal.getvalue())
    assert "INFO cold-test: crdesigner done" in shown and shown[-1].strip() == "", shown
    silent = io.StringIO()
    with Spinner("converting", stream=silent, delay_s=0.0, interval_s=0.01):
        time.sleep(0.05)
    assert silent.getvalue() == ""


@pytest.mark.parametrize("flags, drawn", [([], True), (["--no-progress"], False), (["-q"], False)])
def test_refusion_shows_progress_unless_switched_off(flags: list[str], drawn: bool, recording: Path, tmp_path: Path,
                                                     monkeypatch: pytest.MonkeyPatch, root_logging: None) -> None:
    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert fuse.main(["--input", str(recording), "-o", str(tmp_path / "re.mcap"), "--no-gt", *flags]) == 0
    shown = visible(terminal.getvalue())
    assert any(line.startswith("cold-fuse [") and "/" in line for line in shown) is drawn, shown


@pytest.mark.parametrize(("signal_error", "status", "what"), [(KeyboardInterrupt, 130, "interrupted"),
                                                               (Terminated, 143, "terminated")])
def test_an_interruption_the_command_does_not_handle_is_one_line(signal_error: type[BaseException], status: int,
                                                                 what: str, capsys: pytest.CaptureFixture[str]) -> None:
    """Ctrl-C or SIGTERM landing where no command handles it (e.g. while a sweep imports
    pyarrow to write its tables) ends with one stderr line and 128 + signal, no traceback."""

    @cli_entry("cold-eval sweep")
    def body(argv: object) -> int:
        raise signal_error()

    assert body([]) == status
    assert capsys.readouterr().err == f"cold-eval: error: sweep: {what}\n"


@pytest.mark.parametrize("text", ["0", "-5", "nan", "inf", "1e308", "10000", "20,1e4"])
def test_a_gap_out_of_range_names_both_bounds(text: str) -> None:
    """``--gaps`` refuses d_s outside (0, MAX_GAP_M) with a message that states both
    bounds (a huge finite gap is not "≤ 0"); gaps inside pass unchanged."""
    with pytest.raises(argparse.ArgumentTypeError, match=rf"> 0 m and < {MAX_GAP_M:g} m, got '{text}'"):
        gap_list(text)
    assert gap_list("0.5,9999") == (0.5, 9999.0)


@pytest.mark.parametrize(("args", "message"), [
    (["--seed", "-1"], "argument --seed: expected an integer >= 0, got -1"),
    (["--routes", "1001"], "argument --routes: expected an integer from 1 to 1000, got 1001"),
    (["--routes", "x"], "argument --routes: expected an integer, got 'x'"),
    (["--lanes", "9"], "argument --lanes: expected an integer from 0 to 8, got 9"),
    (["--history", "1e308"], "argument --history: expected a number >= 0 and < 1e+06, got 1e308"),
    (["sweep", "--seeds", "0,-2"], "sweep: argument --seeds: seeds must be >= 0, got '0,-2'"),
    (["sweep", "--routes", "5000"], "sweep: argument --routes: expected an integer from 1 to 1000, got 5000"),
    (["sweep", "--noise", "0,1001"], "sweep: argument --noise: σ must be >= 0 and <= 1000 m, got '0,1001'"),
])
def test_hostile_numbers_are_usage_errors_that_name_the_option(args: list[str], message: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """Bounds on counts and amounts are checked on the command line (exit 2, one line, the
    option named), before anything runs: 1e9 routes used to draw routes for hours."""
    command, rest = (args[:1], args[1:]) if args[0] == "sweep" else ([], args)
    with pytest.raises(SystemExit) as usage:
        evaluate.main([*command, "--map", str(bundled_map("straight")), "--out", str(tmp_path / "o"), *rest])
    assert usage.value.code == 2
    help_command = "cold-eval sweep" if command else "cold-eval"
    assert capsys.readouterr().err.splitlines() == [f"cold-eval: error: {message} (see {help_command} --help)"]
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(("args", "message"), [
    (["--speed", "1e308"], "speed must be > 0 and <= 1000 m/s"),
    (["--noise", "1e308"], "SensorErrorModel.noise_sigma_m: must be within ±1000 m"),
    (["--pose-xy", "1e308"], "SensorErrorModel.pose_sigma_xy_m: must be within ±1000 m"),
    (["--lateral-offset=-1e308"], "SensorErrorModel.lateral_offset_m: must be within ±1000 m"),
])
def test_hostile_amounts_fail_before_the_run_with_nothing_written(args: list[str], message: str, tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    """A σ or speed of 1e308 used to overflow mid-run (NaN detections, "run failed", a
    partial report); now it is refused before anything is written."""
    status = evaluate.main(["--map", str(bundled_map("straight")), "--out", str(tmp_path / "o"), "--frames", "3", *args])
    assert status == 1
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("cold-eval: error: ") and message in lines[0], lines
    assert not (tmp_path / "o").exists()
