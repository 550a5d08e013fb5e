"""The `blurset` command. Each subcommand lives in its own module with
`add_arguments(parser)` and `run(args) -> int`; this file only dispatches."""

from __future__ import annotations

import argparse
import importlib
import sys

from blurset.exceptions import BlursetError

# subcommand -> (module, one-line help)
COMMANDS = {
    "build": ("blurset.build", "render an Objaverse-Blur style dataset from GLB objects"),
    "noise": ("blurset.noise", "write reproducible noisy copies (LLFF-N style) of an LLFF scene"),
    "check-poses": ("blurset.check_poses", "cross-check a scene's poses with COLMAP"),
    "stats": ("blurset.stats", "histograms, numbers and a report of a build's statistics"),
}


def make_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="blurset", description=__doc__.split("\n")[0])
    from blurset import __version__

    parser.add_argument("--version", action="version", version=f"blurset {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for name, (module, help_) in COMMANDS.items():
        p = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module)
        importlib.import_module(module).add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = make_parser().parse_args(argv)
    try:
        return int(importlib.import_module(args._module).run(args) or 0)
    except (BlursetError, FileNotFoundError, PermissionError, ValueError) as e:
        # One clear line, naming the file or option; no traceback for bad input.
        print(f"blurset {args.command}: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"blurset {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
