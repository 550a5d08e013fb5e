"""The `blurset` command. Each subcommand lives in its own module with
`add_arguments(parser)` and `run(args) -> int`; this file only dispatches."""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_early(signum: int, frame: object) -> None:
    # Ctrl-C while the command starts (its modules import numpy, matplotlib …): nothing
    # was written yet, so it ends at once, quietly; main() installs the real stop.
    sys.stderr.write("blurset: interrupted\n")
    os._exit(128 + signum)


if __name__ == "__main__" or sys.argv[0].endswith("blurset"):
    signal.signal(signal.SIGINT, _interrupted_early)

import argparse  # noqa: E402
import importlib  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

from blurset.exceptions import BlursetError  # noqa: E402

# What an interrupted command keeps, and how to go on (commands that resume).
RESUME = {
    "build": "; complete settings are kept: rerun the same command to resume",
    "noise": "; complete scenes are kept: rerun the same command to resume",
}

# subcommand -> (module, one-line help)
COMMANDS = {
    "build": (
        "blurset.commands.builder.cli",
        "render an Objaverse-Blur style dataset from GLB objects",
    ),
    "noise": (
        "blurset.commands.noise.cli",
        "write reproducible noisy copies (LLFF-N style) of an LLFF scene or of a whole build",
    ),
    "check-poses": ("blurset.commands.check_poses", "cross-check a scene's poses with COLMAP"),
    "preview": (
        "blurset.commands.preview",
        "figure of a setting at every level, or a build's contact sheet",
    ),
    "tradeoff": (
        "blurset.commands.tradeoff",
        "measure render time against PSNR for latent counts, samples and blur methods",
    ),
    "stats": ("blurset.commands.stats", "histograms, numbers and a report of a build's statistics"),
    "export": (
        "blurset.commands.export.cli",
        "one root of LLFF scenes (IBRNet/NAN/GNT/GeoNeRF) or nerfstudio scenes of a build",
    ),
    "card": (
        "blurset.commands.card",
        "write a Hugging Face dataset card (README.md) for a build: licences, construction, "
        "counts, attribution",
    ),
    "verify": (
        "blurset.commands.verify",
        "check that a build (or a noise output) is whole: every file, every image decoded, "
        "counts, MANIFEST.sha256",
    ),
}


# What `blurset --help` opens with.
DESCRIPTION = (
    "Make multi-view datasets with realistic degradations for generalizable NeRF research:\n"
    "motion blur rendered with Blender from GLB objects (Objaverse-Blur style), sensor\n"
    "noise (LLFF-N style), and the tools to check, export and describe them."
)
# The researcher's path, first thing `blurset --help` shows (tests/test_cli_help.py
# parses every line).
START = (
    "blurset build --objects models/ --out OUT --test-settings 52 --dry-run  # plan, cost",
    "blurset build --objects models/ --out OUT --test-settings 52  # sharp + blur_1..4",
    "blurset noise OUT --out NOISY --gains 4 8 16                  # noisy copies",
    "blurset export OUT --out ROOT/data                            # a training root",
)


class HelpFormatter(argparse.HelpFormatter):
    """Help that states the default of every option with a value: argparse's own default
    is appended as `(default: X)` unless the text already says it (an option whose default
    argparse does not hold, such as a build option taken from the core, says it in its
    help). Flags (on or off) and positionals have none to state."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        if (
            not action.option_strings
            or action.nargs == 0
            or action.default in (None, argparse.SUPPRESS)
            or "default" in text
        ):
            return text
        d = action.default
        shown = " ".join(map(str, d)) if isinstance(d, list | tuple) else str(d)
        return f"{text} (default: {shown.replace('%', '%%')})"


class _TopFormatter(argparse.RawDescriptionHelpFormatter, HelpFormatter):
    """`blurset --help`: its description's lines (the path to start on) kept as written."""


def make_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The whole CLI's parser; with `command`, only that subcommand's module is imported
    and given its options (the others keep their names and help): a run of `blurset
    verify` does not import the builder, numpy and all."""
    start = "\n".join(f"  {line}" for line in START)
    parser = argparse.ArgumentParser(
        prog="blurset",
        description=f"{DESCRIPTION}\n\nStart here:\n{start}",
        allow_abbrev=False,
        formatter_class=_TopFormatter,
    )
    from blurset import __version__

    parser.add_argument("--version", action="version", version=f"blurset {__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show the traceback of an error, not one line"
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(
            name,
            help=help_,
            description=help_,
            allow_abbrev=False,
            formatter_class=HelpFormatter,
        )
        p.set_defaults(_module=module)
        # Also after the subcommand; SUPPRESS keeps it from resetting the top-level flag.
        p.add_argument("--debug", action="store_true", default=argparse.SUPPRESS, help="traceback")
        if command in (None, name):
            importlib.import_module(module).add_arguments(p)
            _refuse_empty_paths(p)
    return parser


class EmptyPathError(BlursetError):
    """An empty value of a path option, or an --out that is a link to nothing (argparse
    does not catch it: one line, in main)."""


def _nonempty(option: str, convert: Any, output: bool = False) -> Any:
    def check(text: str) -> Any:
        from blurset.services.outputs import path_problem

        # The same check as a config file's path (config.make_config).
        if (problem := path_problem(text, output=output)) is not None:
            raise EmptyPathError(f"{option} {problem}")
        return convert(text)

    check.__name__ = getattr(convert, "__name__", "path")  # argparse names it in errors
    return check


def _refuse_empty_paths(p: argparse.ArgumentParser) -> None:
    """Every option that names a file or folder (`type=Path`, and build's and noise's
    `--out`) refuses an empty value by name, before anything runs; an `--out` that is a
    link to nothing too."""
    for action in p._actions:
        if action.type is Path or (action.dest == "out" and action.type in (None, str)):
            name = action.option_strings[-1] if action.option_strings else action.dest.upper()
            action.type = _nonempty(name, action.type or str, output=action.dest == "out")


def subcommands(
    parser: argparse.ArgumentParser | None = None,
) -> dict[str, argparse.ArgumentParser]:
    """The parser of each subcommand of `parser` (default: `make_parser()`'s), by name:
    what the CLI reference and the help tests read."""
    parser = parser or make_parser()
    (sub,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


# Put before a value that starts with '-' of an option taking several values, so that
# argparse takes it as a value; main() removes it after parsing.
_DASH_MARK = " "


def _dash_values(parser: argparse.ArgumentParser, argv: list[str]) -> tuple[list[str], set[str]]:
    """`--shard -1/2` → `--shard=-1/2`: a value that starts with '-' after an option that
    takes one reaches the option's own check (argparse would call it a missing value, as
    it does for anything but a plain negative number); after an option that takes
    several (`--gains -1e-3 2`), each such word up to the next option is marked as a
    value. A word that is an option of the command is left alone. Returns the words and
    the dests whose values main() must unmark."""
    command = next((i for i, a in enumerate(argv) if a in COMMANDS), None)
    if command is None:
        return argv, set()
    known = subcommands(parser)[argv[command]]._option_string_actions

    def is_option(word: str) -> bool:
        return word == "--" or word.split("=", 1)[0] in known

    out, dashed = argv[: command + 1], set()
    i = command + 1
    while i < len(argv):
        word = argv[i]
        out.append(word)
        i += 1
        if word == "--":
            out += argv[i:]
            break
        action = known.get(word)
        if action is None or action.nargs == 0:
            continue
        if action.nargs is None:
            if i < len(argv) and argv[i].startswith("-") and not is_option(argv[i]):
                out[-1] = f"{word}={argv[i]}"
                i += 1
            continue
        # Several values: argparse takes every word up to the next option.
        while i < len(argv) and not is_option(argv[i]):
            value = argv[i]
            if value.startswith("-"):
                value = _DASH_MARK + value
                dashed.add(action.dest)
            out.append(value)
            i += 1
    return out, dashed


def main(argv: list[str] | None = None) -> int:
    try:
        # Building the parser imports the command (numpy, matplotlib …): a Ctrl-C in
        # that first second is a stop like any other, not a traceback.
        given = sys.argv[1:] if argv is None else list(argv)
        # The command is the first word that names one: the top-level options take no value.
        parser = make_parser(next((a for a in given if a in COMMANDS), ""))
        given, dashed = _dash_values(parser, given)
        args = parser.parse_args(given)
        for dest in dashed:  # the values kept from argparse's option matching
            setattr(
                args,
                dest,
                [
                    v[len(_DASH_MARK) :] if v.startswith(_DASH_MARK) else v
                    for v in getattr(args, dest)
                ],
            )
    except EmptyPathError as e:
        command = next((a for a in (sys.argv[1:] if argv is None else argv) if a in COMMANDS), "")
        print(f"blurset {command}: error: {e}".replace("  ", " "), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("blurset: interrupted", file=sys.stderr)
        return 130
    from blurset.services import stop

    stop.install()
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except (BlursetError, OSError, ValueError) as e:
        # One clear line, naming the file or option; no traceback for bad input.
        if args.debug:
            raise
        print(f"blurset {args.command}: error: {_one_line(e)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as e:
        code = stop.exit_code(e)
        why = f" ({e.args[0]})" if code != 130 else ""
        print(
            f"blurset {args.command}: interrupted{why}{RESUME.get(args.command, '')}",
            file=sys.stderr,
        )
        if stop.must_exit_now():
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(code)
        return code
    except Exception as e:  # a bug: still one line, with the way to see more
        if args.debug:
            raise
        print(
            f"blurset {args.command}: internal error: {type(e).__name__}: {_one_line(e)} "
            "(rerun with --debug for the traceback)",
            file=sys.stderr,
        )
        return 70


def _one_line(e: BaseException) -> str:
    return " ".join(str(e).split()) or type(e).__name__


if __name__ == "__main__":
    sys.exit(main())
