"""The global options, declared once (app/cli_options.py): each command that uses one takes it
before or after its name, with the same default and help; parsed in-process, nothing runs."""

from __future__ import annotations

import argparse

import pytest

from app import cli
from app.cli_options import ALL, GLOBAL_OPTIONS

# Each command that takes global options after its name, with the arguments it needs.
COMMANDS = {
    "move": (["move", "step", "--target", "5"], ALL),
    "controller": (["controller"], ALL),
    "serve": (["serve"], ALL),
    "emulate": (["emulate"], ("machine", "seed")),
    "fk": (["fk", "1000", "0", "0", "0", "0", "0"], ("machine",)),
    "ik": (["ik", "1200", "-440", "1187", "0", "0", "0"], ("machine",)),
    "runs": (["runs", "list"], ("data_dir",)),
}
# A value other than the default for each option, as typed and as parsed.
GIVEN = {"machine": (["--machine", "rig"], "rig"),
         "backend": (["--backend", "serial"], "serial"),
         "port": (["--port", "/dev/ttyACM0"], "/dev/ttyACM0"),
         "data_dir": (["--data-dir", "runs"], "runs"),
         "seed": (["--seed", "7"], 7),
         "timing": (["--timing", "thesis"], "thesis"),
         "interrupt_ms": (["--interrupt-ms", "6"], 6.0),
         "slip": (["--slip", "windup"], ["windup"])}
CASES = [(command, name) for command, (_, names) in COMMANDS.items() for name in names]


def test_every_global_option_has_a_value_to_try() -> None:
    assert set(GIVEN) == set(GLOBAL_OPTIONS)
    assert all(GIVEN[name][0][0] in GLOBAL_OPTIONS[name].flags for name in GIVEN)


@pytest.fixture(scope="module")
def whole() -> argparse.ArgumentParser:
    """The whole parser, built once: parsing a line leaves it as it was."""
    return cli.build_parser()


@pytest.mark.parametrize(("command", "name"), CASES)
def test_a_global_option_works_before_or_after_the_command(
        command: str, name: str, whole: argparse.ArgumentParser) -> None:
    argv, _ = COMMANDS[command]
    typed, value = GIVEN[name]
    parse = whole.parse_args
    assert getattr(parse(argv), name) == GLOBAL_OPTIONS[name].default  # not given
    assert getattr(parse([*typed, *argv]), name) == value  # before the command
    assert getattr(parse([*argv, *typed]), name) == value  # after it
    # the default before, the option after: the one given counts
    assert getattr(parse([*typed, *argv, *typed[:1], typed[1]]), name) == value


def test_data_is_data_dir_for_every_command() -> None:
    parse = cli.build_parser().parse_args
    assert parse(["--data", "a"]).data_dir == "a"
    assert parse(["runs", "list", "--data", "b"]).data_dir == "b"
    assert parse(["move", "goto", "--targets", "1", "--data", "c"]).data_dir == "c"


def test_a_command_refuses_a_global_option_it_has_no_use_for(
        capsys: pytest.CaptureFixture[str]) -> None:
    """fk solves a model: it takes --machine, never a backend it would silently ignore."""
    with pytest.raises(SystemExit) as refused:
        cli.build_parser().parse_args(["fk", *COMMANDS["fk"][0][1:], "--backend", "serial"])
    assert refused.value.code == 2
    assert "unrecognized arguments: --backend serial" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["", *COMMANDS])
def test_each_help_shows_the_global_options_it_takes_with_their_help(
        command: str, capsys: pytest.CaptureFixture[str]) -> None:
    argv = COMMANDS[command][0][:2 if command in ("move", "runs") else 1] if command else []
    names = COMMANDS[command][1] if command else ALL
    with pytest.raises(SystemExit):
        cli.build_parser().parse_args([*argv, "--help"])
    shown = " ".join(capsys.readouterr().out.split())  # argparse wraps the help to the width
    for name in names:
        option = GLOBAL_OPTIONS[name]
        assert option.flags[0] in shown and " ".join(option.help.split()) in shown, name


@pytest.mark.parametrize("command", list(COMMANDS))
def test_a_command_line_reads_the_same_with_its_commands_parser_alone(
        command: str, whole: argparse.ArgumentParser) -> None:
    """``parse_for_command`` (the named command's module alone, for a quicker start) reads
    every line the whole parser reads, the same, each global option the command takes before
    or after it."""
    argv, names = COMMANDS[command]
    for name in names:
        typed, _ = GIVEN[name]
        for line in (argv, [*typed, *argv], [*argv, *typed]):
            alone = cli.parse_for_command(line)
            assert alone is not None, line
            assert vars(alone) == vars(whole.parse_args(line)), line


@pytest.mark.parametrize("line", [
    [], ["--machine", "rig"],  # no command: the TUI's
    ["--help", "move"], ["-h", "runs", "list"],  # help asked before the command: the whole one's
    ["move", "step"],  # a usage error (--target is required): the whole parser says so
    ["fk", *COMMANDS["fk"][0][1:], "--backend", "serial"],
])
def test_a_line_the_commands_parser_cannot_read_is_left_to_the_whole_one(
        line: list[str]) -> None:
    assert cli.parse_for_command(line) is None


def test_a_commands_parser_alone_has_its_modules_commands_only() -> None:
    """What ``parse_for_command`` builds for ``runs`` adds cli_runs' commands and no other
    module's (whose imports, cli_move's planners or cli_emulate's serial port, it spares)."""
    [commands] = [action for action in cli.build_parser("runs")._actions
                  if isinstance(action, argparse._SubParsersAction)]
    assert set(commands.choices) == {"runs"}
    [kinematics] = [action for action in cli.build_parser("ik")._actions
                    if isinstance(action, argparse._SubParsersAction)]
    assert set(kinematics.choices) == {"fk", "ik"}
