"""One command-line convention for ``cold-maps``, ``cold-eval``, ``cold-eval sweep`` and
``cold-fuse``: ``--version`` on every (sub)command, ``-v/-vv`` and ``-q``, every option's
default in the help, help without markup, synopses that show metavars, usage errors and
runtime errors as ONE line ``PROG: error: [SUBCOMMAND: ]...`` (exit 2 and 1; a bad value is a
usage error whichever layer bounds it), and progress that never garbles the terminal: no
stale characters, log records never glued onto a bar, ``--no-progress``.

The checks walk every parser's actions, so an option added later is checked too; a
(sub)command with options that take a value needs an entry in its ``Cli.inputs``."""

from __future__ import annotations

import argparse
import importlib
import io
import json
import logging
import os
import re
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
from conftest import PROJECT_ROOT, bundled_map

import cold_maps
from cold_maps.cli import evaluate, fuse, maps, sweep
from cold_maps.cli.common import (MAX_GAP_M, DefaultsHelpFormatter, Terminated, cli_entry, configure_logging, gap_list,
                                  takes_value)
from cold_maps.common.progress import ProgressBar, Spinner
from cold_maps.simulation.drive import MAX_SPEED_MPS
from cold_maps.simulation.sensor_errors import MAX_ANGLE_RAD, MAX_ERROR_M


@dataclass(frozen=True)
class Cli:
    """One command under test.

    Fields:
        prog: its name.
        module: ``python -m`` module.
        ok: arguments of a quick successful run, given a tmp folder and a recording.
        broken: arguments of a run that fails at run time (a missing input), given a tmp folder.
        parsers: its argument parsers (every subcommand's too).
        inputs: per parser (its prog), arguments of a run that fails at its missing input
            (``none.*`` in the tmp folder given), for every parser with options that take a value.
        command: arguments before every other (a subcommand with its own options).
    """

    prog: str
    module: str
    ok: Callable[[Path, Path], list[str]]
    broken: Callable[[Path], list[str]]
    parsers: Callable[[], list[argparse.ArgumentParser]]
    inputs: Callable[[Path], dict[str, list[str]]]
    command: tuple[str, ...] = ()

    def status(self, *args: str) -> int:
        """Runs the command in this process (its output is the caller's to capture); the exit
        status, a usage error's ``SystemExit`` included."""
        try:
            return importlib.import_module(self.module).main([*self.command, *args])
        except SystemExit as exc:
            return int(exc.code or 0)


def _maps_parsers() -> list[argparse.ArgumentParser]:
    found = [maps.build_parser()]
    for command in maps.COMMANDS:
        parser = maps.build_parser(selected=command.name)
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        found.append(sub.choices[command.name])
    return found


def _maps_inputs(tmp: Path) -> dict[str, list[str]]:
    missing = str(tmp / "none.xodr")
    return {"cold-maps info": ["info", missing], "cold-maps export": ["export", missing, "-o", str(tmp / "b.csv")],
            "cold-maps convert": ["convert", missing, "-o", str(tmp / "b.osm")], "cold-maps check": ["check", missing]}


STRAIGHT = str(bundled_map("straight"))
CLIS = (
    Cli("cold-maps", "cold_maps.cli.maps", lambda tmp, rec: ["export", STRAIGHT, "-o", str(tmp / "b.csv")],
        lambda tmp: ["info", str(tmp / "none.xodr")], _maps_parsers, _maps_inputs),
    Cli("cold-eval", "cold_maps.cli.evaluate",
        lambda tmp, rec: ["--map", STRAIGHT, "--frames", "2", "--routes", "1", "--gaps", "30", "--no-distractors",
                          "--no-plots", "--no-mcap", "--out", str(tmp / "out")],
        lambda tmp: ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "out")], lambda: [evaluate.build_parser()],
        lambda tmp: {"cold-eval": ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "out")]}),
    Cli("cold-fuse", "cold_maps.cli.fuse", lambda tmp, rec: ["--input", str(rec), "-o", str(tmp / "re.mcap"), "--no-gt"],
        lambda tmp: ["--input", str(tmp / "none.mcap"), "-o", str(tmp / "re.mcap")], lambda: [fuse.build_parser()],
        lambda tmp: {"cold-fuse": ["--input", str(tmp / "none.mcap"), "-o", str(tmp / "re.mcap")]}),
    Cli("cold-eval sweep", "cold_maps.cli.evaluate",
        lambda tmp, rec: ["--map", STRAIGHT, "--gaps", "30", "--interpolation", "paper", "--frames", "2", "--routes",
                          "1", "--workers", "1", "--no-plots", "--out", str(tmp / "sweep")],
        lambda tmp: ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "sweep")], lambda: [sweep.build_parser()],
        lambda tmp: {"cold-eval sweep": ["--map", str(tmp / "none.xodr"), "--out", str(tmp / "sweep")]},
        command=("sweep",)),
)


def _value_options(parser: argparse.ArgumentParser) -> list[argparse.Action]:
    """The options of ``parser`` that take a value."""
    return [action for action in parser._actions if takes_value(action)]


def _required(parser: argparse.ArgumentParser, action: argparse.Action) -> bool:
    """Whether ``action`` must be given: required itself or in a required group of alternatives."""
    return action.required or any(group.required and action in group._group_actions
                                  for group in parser._mutually_exclusive_groups)


def _all_parsers() -> list[tuple[Cli, argparse.ArgumentParser]]:
    return [(cli, parser) for cli in CLIS for parser in cli.parsers()]


PARSER_IDS = [parser.prog for _, parser in _all_parsers()]
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


@pytest.mark.parametrize(("cli", "parser"), _all_parsers(), ids=PARSER_IDS)
def test_every_command_and_subcommand_has_version(cli: Cli, parser: argparse.ArgumentParser,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """``cold-maps info --version`` was a usage error (exit 2)."""
    assert cli.status(*parser.prog.removeprefix(cli.prog).split(), "--version") == 0
    assert capsys.readouterr() == (f"{cli.prog} {cold_maps.__version__}\n", "")


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


@pytest.mark.parametrize(("cli", "parser"), _all_parsers(), ids=PARSER_IDS)
def test_help_shows_every_default(cli: Cli, parser: argparse.ArgumentParser) -> None:
    """Every option that takes a value and may be left out names its default in ``--help``
    (an option whose default is None names the effective one: "default 0: off"), as shown."""
    assert parser.formatter_class is DefaultsHelpFormatter
    formatter = DefaultsHelpFormatter(parser.prog)
    shown = " ".join(parser.format_help().split())
    for action in _value_options(parser):
        if _required(parser, action) or action.help == argparse.SUPPRESS:
            continue
        text = " ".join((formatter._expand_help(action) if action.help else "").split())
        assert re.search(r"\bdefault\b", text) and "default: None" not in text, (action.option_strings, text)
        assert text in shown, (action.option_strings, text)


def test_the_error_options_show_their_effective_default() -> None:
    """The eleven options that showed no default (default None or 0, taken for "off")."""
    parser = evaluate.build_parser()
    formatter = DefaultsHelpFormatter(parser.prog)
    helps = {flag: formatter._expand_help(action) for action in parser._actions for flag in action.option_strings}
    for flag in ("--noise", "--lateral-offset", "--heading-bias", "--range-jitter", "--drop", "--pose-xy", "--pose-yaw",
                 "--drift-heading", "--drift-scale", "--loss", "--latency"):
        assert "(default 0: " in helps[flag], (flag, helps[flag])


MARKUP = re.compile(r"``|:[a-z]+(?::[a-z]+)?:`")
"""reStructuredText in a help text: double back-quotes or a role (``:func:`x```)."""
EXAMPLE_VALUE = re.compile(r"--[a-z][\w-]*[ =]\[?[-+]?\.?\d")
"""An option followed by a number: an example value where a metavar belongs."""


@pytest.mark.parametrize(("cli", "parser"), _all_parsers(), ids=PARSER_IDS)
def test_help_has_no_markup_and_synopses_show_metavars(cli: Cli, parser: argparse.ArgumentParser) -> None:
    """``cold-eval --help`` showed ``:mod:`...```; the sweep's synopsis ``--noise 0,0.02,0.05``
    read as a default (it is 0)."""
    text = parser.format_help()
    assert not MARKUP.search(text), MARKUP.search(text)
    synopsis = " ".join((parser.format_usage() + (parser.description or "")).split())
    assert not EXAMPLE_VALUE.search(synopsis), EXAMPLE_VALUE.search(synopsis)


def test_markup_patterns_catch_what_they_name() -> None:
    from cold_maps.cli.common import plain

    assert MARKUP.search("see :func:`fusion.fuse`") and MARKUP.search("``x``") and not MARKUP.search("a: b `c`")
    assert EXAMPLE_VALUE.search("[--noise 0,0.02]") and not EXAMPLE_VALUE.search("[--noise SIGMA_M,...] [--frames N]")
    assert plain("a ``b`` (:mod:`cold_maps.cli.sweep`), :func:`~x.y`\n z") == "a b (cold_maps.cli.sweep), x.y z"


HOSTILE = ("nan", "inf", "-inf", "1e308", "-1e308", "-1", "0", "x")


@pytest.mark.parametrize(("cli", "parser"), _all_parsers(), ids=PARSER_IDS)
def test_every_bad_value_is_a_usage_error(cli: Cli, parser: argparse.ArgumentParser, tmp_path: Path,
                                          monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str],
                                          root_logging: None) -> None:
    """Every option that takes a value, given each hostile value, is either refused as a
    usage error (exit 2, one line naming the option, "(see PROG --help)") or accepted far
    enough that the run fails at its missing input (exit 1, naming it): no other layer
    refuses a command-line value later with exit 1 (``--noise 1e308`` did). The options
    that name the input (and the output) are left out."""
    options = [action for action in _value_options(parser) if action.help != argparse.SUPPRESS]
    if not options:
        return
    monkeypatch.chdir(tmp_path)  # a relative path value lands here
    base = cli.inputs(tmp_path)[parser.prog]
    refused, tried = 0, 0
    for action in options:
        if set(action.option_strings) & set(base):
            continue
        flag = max(action.option_strings, key=len)
        tried += 1
        for value in HOSTILE:
            status = cli.status(*base, f"{flag}={value}")
            err = capsys.readouterr().err.splitlines()
            assert len(err) == 1, (flag, value, err)
            if status == 2:
                refused += 1
                assert flag in err[0] and err[0].endswith(f"(see {parser.prog} --help)"), (flag, value, err)
            else:
                assert status == 1 and "none." in err[0], (flag, value, status, err)
    assert refused > 0 or tried == 0


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
    before = set(threading.enumerate())
    with Spinner("converting", stream=terminal, delay_s=0.0, interval_s=0.01):
        time.sleep(0.1)
        logging.getLogger("cold-test").info("crdesigner done")
        time.sleep(0.05)
    assert "converting  00:00" in terminal.getvalue()
    shown = visible(terminal.getvalue())
    assert "INFO cold-test: crdesigner done" in shown and shown[-1].strip() == "", shown
    assert set(threading.enumerate()) - before == set()  # its redraw thread joined, no tqdm monitor left
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
    (["sweep", "--noise", "0,1001"], f"sweep: argument --noise: must be within ±{MAX_ERROR_M:g} m, got 1001.0"),
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
    (["--speed", "1e308"], f"argument --speed: expected > 0 and <= {MAX_SPEED_MPS:g} m/s, got 1e+308"),
    (["--speed", "0"], f"argument --speed: expected > 0 and <= {MAX_SPEED_MPS:g} m/s, got 0"),
    (["--noise", "1e308"], f"argument --noise: must be within ±{MAX_ERROR_M:g} m, got 1e+308"),
    (["--pose-xy", "1e308"], f"argument --pose-xy: must be within ±{MAX_ERROR_M:g} m, got 1e+308"),
    (["--lateral-offset=-1e308"], f"argument --lateral-offset: must be within ±{MAX_ERROR_M:g} m, got -1e+308"),
    (["--heading-bias", "4"], f"argument --heading-bias: must be within ±{MAX_ANGLE_RAD:g} rad, got 4.0"),
    (["--drop", "1.5"], "argument --drop: must be <= 1, got 1.5"),
    (["--noise", "nan"], "argument --noise: expected a finite number, got nan"),
    (["--exchange", "sampled", "--loss", "2"], "argument --loss: must be <= 1, got 2.0"),
    (["--exchange", "bezier", "--bezier-tolerance", "0"], "argument --bezier-tolerance: must be > 0"),
])
def test_hostile_amounts_are_usage_errors_before_anything_runs(args: list[str], message: str, tmp_path: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    """A σ or speed of 1e308 used to overflow mid-run, then was refused by the error models
    with exit 1; the option's type now asks the same model (one bound, in one place): exit 2."""
    with pytest.raises(SystemExit) as usage:
        evaluate.main(["--map", str(bundled_map("straight")), "--out", str(tmp_path / "o"), "--frames", "3", *args])
    assert usage.value.code == 2
    lines = capsys.readouterr().err.splitlines()
    assert lines == [f"cold-eval: error: {message} (see cold-eval --help)"], lines
    assert not (tmp_path / "o").exists()


def test_the_documented_noise_overflow_exits_2() -> None:
    result = _run(CLIS[1], "--map", str(bundled_map("junction")), "--noise", "1e308")
    assert result.returncode == 2 and result.stdout == ""
    assert _one_error_line(result, "cold-eval").endswith("(see cold-eval --help)")


def _console_script(tmp_path: Path) -> Path:
    """A script that runs ``cold-eval`` as an installed console script does: its own folder,
    not the current one, is first on ``sys.path``."""
    script = tmp_path / "bin" / "cold-eval-script.py"
    script.parent.mkdir()
    script.write_text("import sys\nfrom cold_maps.cli.evaluate import main\nif __name__ == '__main__':\n"
                      "    sys.exit(main())\n")
    return script


def _run_script(script: Path, cwd: Path, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(PROJECT_ROOT), os.environ.get("PYTHONPATH"))))}
    return subprocess.run([sys.executable, str(script), *args], capture_output=True, text=True, cwd=cwd, env=env,
                          timeout=300, check=False)


@pytest.mark.parametrize("command", [[], ["sweep"]], ids=["cold-eval", "cold-eval sweep"])
def test_method_resolves_from_the_current_folder(command: list[str], tmp_path: Path) -> None:
    """The README's ``--method fusion_method_example:straight_bridge`` run from tests/ (where
    the module is) works as an installed command too, in worker processes (a sweep spawns
    them) as in the main one; the straight segment is exact on the straight road."""
    method = "fusion_method_example:straight_bridge"
    out = tmp_path / "out"
    grid = ["--gaps", "20,30", "--interpolation", "paper", "--workers", "2"] if command else ["--gaps", "30"]
    result = _run_script(_console_script(tmp_path), PROJECT_ROOT / "tests", *command, "--map", STRAIGHT,
                         "--method", method, "--frames", "2", "--routes", "1", "--no-plots", "--out", str(out), *grid,
                         *([] if command else ["--no-distractors", "--no-mcap", "--workers", "2"]))
    assert result.returncode == 0, result.stderr
    if command:
        import csv

        rows = [r for r in csv.DictReader((out / "results.csv").open()) if r["interpolation"] == method]
        errors = [float(r["max_error_m"]) for r in rows]
    else:
        scenarios = json.loads((out / "metrics.json").read_text())["scenarios"]
        errors = [s["max_error_m"] for s in scenarios if s["interpolation"] == method]
    assert errors and max(errors) < 1e-6, errors


def test_a_method_not_found_says_where_it_looked(tmp_path: Path) -> None:
    result = _run_script(_console_script(tmp_path), tmp_path, "--map", STRAIGHT, "--method",
                         "fusion_method_example:straight_bridge", "--out", str(tmp_path / "out"))
    assert result.returncode == 2 and result.stdout == ""
    line = _one_error_line(result, "cold-eval")
    assert line.startswith("cold-eval: error: argument --method: fusion method 'fusion_method_example:straight_bridge'")
    assert f"current folder {tmp_path}" in line and "run from the folder that holds fusion_method_example.py" in line
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("interrupt_at", ["tables written", "first plot", "second plot"])
def test_a_sweep_interrupted_while_writing_marks_what_it_leaves_partial(interrupt_at: str, tmp_path: Path,
                                                                        monkeypatch: pytest.MonkeyPatch,
                                                                        capsys: pytest.CaptureFixture[str],
                                                                        root_logging: None) -> None:
    """Ctrl-C while the sweep writes its tables or plots left a summary.md not marked partial
    beside an empty plots/: now only the summary stays, marked partial, and the same command
    run again writes everything complete from the kept cells."""
    from cold_maps.evaluation import sweep as sweep_module
    from cold_maps.evaluation import sweep_report

    out = tmp_path / "sweep"
    args = ["sweep", "--map", STRAIGHT, "--gaps", "30", "--interpolation", "paper", "--frames", "2", "--routes", "1",
            "--workers", "1", "-q", "--out", str(out)]
    if interrupt_at == "tables written":
        write_tables = sweep_module.write_tables

        def interrupted_tables(*a: object) -> None:
            write_tables(*a)
            raise KeyboardInterrupt

        monkeypatch.setattr(sweep_module, "write_tables", interrupted_tables)
    else:
        save, saved = sweep_report._save, []

        def interrupted_save(figure: object, path: Path) -> Path:
            if len(saved) == ("first plot", "second plot").index(interrupt_at):
                raise KeyboardInterrupt
            saved.append(save(figure, path))
            return saved[-1]

        monkeypatch.setattr(sweep_report, "_save", interrupted_save)
    assert evaluate.main(args) == 130
    err = capsys.readouterr().err
    assert "interrupted while writing the tables" in err and "summary.md marked partial" in err
    assert sorted(p.name for p in out.iterdir()) == ["cells", "summary.md"]
    assert sweep_report.INTERRUPTED_WRITING in (out / "summary.md").read_text()
    assert len(list((out / "cells").glob("*.json"))) == 1
    monkeypatch.undo()
    assert evaluate.main(args) == 0
    assert "PARTIAL" not in (out / "summary.md").read_text()
    assert sorted(p.name for p in (out / "plots").iterdir()) == ["safe_gap.png", "sweep_straight.png"]
    assert (out / "results.csv").is_file() and (out / "results.parquet").is_file()
