"""The help of every subcommand: each option states its default (or that it is required),
nothing speaks of the project's history, and no option is taken from an abbreviation."""

from __future__ import annotations

import argparse
import re

import pytest
from blurset import cli

HISTORY = re.compile(r"\bissue\b|builds? before|this round", re.IGNORECASE)


SUBPARSERS = cli.subcommands()


def _help_of(p: argparse.ArgumentParser, action: argparse.Action) -> str:
    return p._get_formatter()._expand_help(action) if action.help else ""


def test_top_level_help_opens_with_a_user_sentence() -> None:
    text = cli.make_parser().format_help()
    assert " ".join(cli.DESCRIPTION.split()) in " ".join(text.split())
    assert "module" not in cli.DESCRIPTION and "subcommand" not in cli.DESCRIPTION
    assert not HISTORY.search(text)


def test_top_level_help_starts_the_researcher_on_a_path_that_parses() -> None:
    """Four lines to start from, as written, each a command line the parser takes."""
    text = cli.make_parser().format_help()
    shown = text.split("Start here:\n", 1)[1].splitlines()[: len(cli.START)]
    assert [ln.strip() for ln in shown] == list(cli.START) and len(cli.START) == 4
    for line in cli.START:
        argv = line.split("#")[0].split()[1:]
        assert cli.make_parser(argv[0]).parse_args(argv).command == argv[0], line


def test_every_parser_refuses_abbreviations() -> None:
    parser = cli.make_parser()
    assert parser.allow_abbrev is False
    for name, p in SUBPARSERS.items():
        assert p.allow_abbrev is False, name


@pytest.mark.parametrize("command", sorted(SUBPARSERS))
def test_help_states_every_default_and_no_history(command: str) -> None:
    p = SUBPARSERS[command]
    text = p.format_help()
    assert not HISTORY.search(text), HISTORY.search(text)
    missing = []
    for action in p._actions:
        if not action.option_strings or action.nargs == 0:
            continue  # positionals, and flags (off unless given)
        helped = _help_of(p, action)
        if action.required or "required" in helped:
            continue
        # "(default: )": an empty list of levels is stated, not left blank.
        if "default" not in helped or re.search(r"default: ?\)", helped):
            missing.append(action.option_strings[0])
    assert not missing, f"blurset {command}: help states no default of {missing}"


def _required_args(p: argparse.ArgumentParser) -> list[str]:
    out: list[str] = []
    for action in p._actions:
        if not action.option_strings:
            out.append("x")
        elif action.required:
            out += [action.option_strings[0], "x"]
    return out


@pytest.mark.parametrize("command", sorted(SUBPARSERS))
def test_an_abbreviated_option_is_not_taken(command: str) -> None:
    """`--resol 5` is not `--resolution 5`: every long option's shortest unique prefix is
    left unrecognised."""
    p = SUBPARSERS[command]
    longs = [s for a in p._actions for s in a.option_strings if s.startswith("--")]
    tried = 0
    for opt in longs:
        for n in range(3, len(opt)):
            prefix = opt[:n]
            if sum(o.startswith(prefix) for o in longs) == 1:
                break
        else:
            continue  # no proper prefix names it alone (`--latents` of `--latents-max`)
        tried += 1
        _, extra = cli.make_parser().parse_known_args([command, *_required_args(p), prefix, "5"])
        assert prefix in extra, f"blurset {command} {prefix} was taken as {opt}"
    assert tried


def test_build_resol_is_refused_on_the_command_line(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as e:
        cli.make_parser().parse_args(["build", "--demo", "--out", "o", "--resol", "-5"])
    assert e.value.code == 2
    assert "--resol" in capsys.readouterr().err


def test_build_help_defaults_come_from_the_core() -> None:
    from blurset.commands.builder.cli import default_text
    from blurset.services.config import BuildConfig

    core = BuildConfig()
    assert default_text("views").startswith(f"{core.views};")
    assert default_text("resolution") == f"{core.resolution}; 96 with --demo"
    assert default_text("levels") == ",".join(map(str, core.levels))
    assert default_text("blur_budget") == core.blur_budget
    text = " ".join(SUBPARSERS["build"].format_help().split())
    assert "m^0.4" in text  # --samples-total and --blur-budget describe the parity budget


def test_stats_input_and_out_have_distinct_metavars() -> None:
    usage = SUBPARSERS["stats"].format_usage()
    assert "BUILD" in usage and "--out DIR" in usage
