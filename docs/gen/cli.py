"""Write docs/reference/cli.md from the real parsers (`blurset.cli.make_parser()`).

Run by `make docs`. Nothing here lists an option by hand: every subcommand, option,
choice, default and help text comes from the argparse parser the `blurset` command
itself uses, whose build and noise flags are made from the core's option declarations
(python/blurset/services/options.py), and the keys only a `--config` file sets come from those
declarations too; so the page changes when a declaration changes.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import sanitize  # noqa: E402

DOCS = Path(__file__).resolve().parents[1]
OUT = DOCS / "reference" / "cli.md"
WIDTH = 88
# Guide pages whose synopsis of a command is generated: a block
# `<!-- synopsis NAME -->` ```sh … ``` `<!-- /synopsis -->` that main() rewrites.
GUIDES = [DOCS / "guide" / "build.md"]
SYNOPSIS = re.compile(
    r"(<!-- synopsis (?P<name>[a-z-]+) -->\n```sh\n)(?P<body>.*?)(```\n<!-- /synopsis -->)", re.S
)


def _cell(text: object) -> str:
    return sanitize(" ".join(str(text).split())).replace("|", "\\|")


def _help_text(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    if not action.help or action.help == argparse.SUPPRESS:
        return ""
    formatter = parser._get_formatter()
    return formatter._expand_help(action)


def _value(parser: argparse.ArgumentParser, action: argparse.Action) -> str:
    """What the option takes: its choices, or its metavar, or nothing for a switch."""
    if action.nargs == 0:
        return ""
    if action.choices is not None and not isinstance(action, argparse._SubParsersAction):
        value = "|".join(str(c) for c in action.choices)
    else:
        formatter = parser._get_formatter()
        value = formatter._format_args(action, formatter._get_default_metavar_for_optional(action))
    return value


def _default(action: argparse.Action, help_text: str) -> str:
    d = action.default
    if d is None or d is argparse.SUPPRESS or d is False or action.nargs == 0:
        return ""
    if "default" in help_text.lower():  # the help already says it
        return ""
    if isinstance(d, (list, tuple)):
        d = " ".join(str(x) for x in d)
    return f"`{d}`"


def _options_table(parser: argparse.ArgumentParser) -> list[str]:
    exclusive = {id(a): g for g in parser._mutually_exclusive_groups for a in g._group_actions}
    lines: list[str] = []
    for group in parser._action_groups:
        actions = [
            a
            for a in group._group_actions
            if a.option_strings
            and not isinstance(a, argparse._HelpAction)
            and a.help != argparse.SUPPRESS
            and "--debug" not in a.option_strings
        ]
        if not actions:
            continue
        title = group.title or "options"
        if title in ("options", "optional arguments"):
            title = "options"
        lines.append(f"\n**{title.capitalize()}**\n")
        if group.description:
            lines.append(f"{_cell(group.description)}\n")
        rows = []
        for a in actions:
            help_text = _help_text(parser, a)
            names = ", ".join(f"`{s}`" for s in a.option_strings) or f"`{a.metavar or a.dest}`"
            value = _value(parser, a)
            value = f"`{value}`" if value else ""
            note = ""
            if id(a) in exclusive:
                others = [
                    b.option_strings[0]
                    for b in exclusive[id(a)]._group_actions
                    if b is not a and b.option_strings
                ]
                if others:
                    note = " (not with " + ", ".join(f"`{o}`" for o in others) + ")"
            if a.required and a.option_strings:
                note += " (required)"
            rows.append((names, value, _default(a, help_text), f"{_cell(help_text)}{note}"))
        if any(r[2] for r in rows):
            lines += ["| option | value | default | what it does |", "| --- | --- | --- | --- |"]
            lines += [f"| {n} | {v} | {d} | {h} |" for n, v, d, h in rows]
        else:
            lines += ["| option | value | what it does |", "| --- | --- | --- |"]
            lines += [f"| {n} | {v} | {h} |" for n, v, _, h in rows]
    return lines


def _toml_only_table() -> list[str]:
    """The options of `blurset build` a `--config` file sets but no flag does (the
    paper's constants), from the core's declarations."""
    from blurset.services.config import BUILD

    rows = [d for d in BUILD.decls if not d.flags and not d.via]
    if not rows:
        return []
    lines = [
        "\n**Keys of a `--config` file only**\n",
        "| key | default | accepted | what it sets |",
        "| --- | --- | --- | --- |",
    ]
    for d in rows:
        accepted = d.range.removeprefix("must be ")
        default = BUILD.default_text(d.name)
        lines.append(f"| `{d.name}` | `{default}` | {_cell(accepted)} | {_cell(d.help)} |")
    return lines


def _synopsis_value(parser: argparse.ArgumentParser, a: argparse.Action, decls: dict) -> str:
    """An option's value in a synopsis: its choices, else its declared default (what a
    user most often types), else its metavar."""
    if a.nargs == 0:
        return ""
    if a.choices is not None:
        return "|".join(str(c) for c in a.choices)
    d = decls.get(a.dest)
    default = getattr(d, "default", None)
    if default is not None and default is not False and default != []:
        if isinstance(default, (list, tuple)):
            sep = " " if a.nargs in ("+", "*") else ","
            return sep.join(f"{x:g}" if isinstance(x, float) else str(x) for x in default) + (
                " …" if sep == " " else ""
            )
        return f"{default:g}" if isinstance(default, float) else str(default)
    return _value(parser, a)


def synopsis(name: str) -> str:
    """`blurset NAME` and every option of its parser (the core's declarations for build),
    `[--flag VALUE]`, exclusive options as `[--a A | --b B]`, wrapped at WIDTH."""
    from blurset.cli import subcommands

    p = subcommands()[name]
    decls = {}
    if name == "build":
        from blurset.services.config import BUILD

        decls = {d.name: d for d in BUILD.decls}
    exclusive = {id(a): g for g in p._mutually_exclusive_groups for a in g._group_actions}
    parts: list[str] = []
    done: set[int] = set()
    for a in p._actions:
        if id(a) in done or isinstance(a, argparse._HelpAction) or "--debug" in a.option_strings:
            continue
        if a.help == argparse.SUPPRESS:
            continue
        group = exclusive[id(a)]._group_actions if id(a) in exclusive else [a]
        items = []
        for b in group:
            done.add(id(b))
            value = _synopsis_value(p, b, decls)
            flag = b.option_strings[0] if b.option_strings else ""
            items.append(" ".join(x for x in (flag, value) if x))
        text = " | ".join(items)
        parts.append(text if not group[0].option_strings else f"[{text}]")
    lines = [f"blurset {name}"]
    for part in parts:  # an option is never split across lines
        if len(lines[-1]) + 1 + len(part) > WIDTH:
            lines.append("  " + part)
        else:
            lines[-1] += " " + part
    return "\n".join(lines) + "\n"


def rewrite_synopses(text: str) -> str:
    return SYNOPSIS.sub(lambda m: m.group(1) + synopsis(m["name"]) + m.group(4), text)


def _help_lines(p: argparse.ArgumentParser) -> list[str]:
    return [sanitize(line) for line in p.format_help().rstrip().split("\n")]


def reference() -> str:
    os.environ["COLUMNS"] = str(WIDTH)  # argparse wraps the usage at this width
    from blurset.cli import make_parser, subcommands

    parser = make_parser()
    subs = subcommands(parser)
    out = [
        "# Command-line reference",
        "",
        "Every `blurset` command, with each option, its values, its default and its help,",
        "generated from the parsers the command itself uses (`make docs` runs",
        "`docs/gen/cli.py`). `blurset COMMAND --help` prints the same text.",
        "",
        "Every command also takes `--debug` (show the traceback of an error instead of one",
        "line). A TOML file given to `blurset build --config` takes the option names as keys",
        "(`samples-total = 256`); a flag on the command line wins over the file.",
        "",
        "| command | what it does |",
        "| --- | --- |",
    ]
    (sub_action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    helps = {c.dest: c.help for c in sub_action._choices_actions}
    for name in subs:
        out.append(f"| [`blurset {name}`](#blurset-{name}) | {_cell(helps.get(name, ''))} |")
    for name, p in subs.items():
        out += ["", f"## `blurset {name}` {{ #blurset-{name} }}", ""]
        if p.description:
            out.append(_cell(p.description) + "\n")
        usage = p.format_usage().rstrip()
        out += ["```text", usage, "```"]
        positionals = [a for a in p._actions if not a.option_strings and a.help]
        if positionals:
            out.append("")
            for a in positionals:
                out.append(f"- `{a.metavar or a.dest}`: {_cell(_help_text(p, a))}")
        out += _options_table(p)
        if name == "build":
            out += _toml_only_table()
        out += [
            "",
            f'??? note "`blurset {name} --help`"',
            "",
            "    ```text",
            *("    " + line if line else "" for line in _help_lines(p)),
            "    ```",
        ]
    return "\n".join(out) + "\n"


def main() -> int:
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(reference())
    print(f"wrote {OUT}", file=sys.stderr)
    for page in GUIDES:
        text = page.read_text()
        new = rewrite_synopses(text)
        if new != text:
            page.write_text(new)
            print(f"wrote the synopsis in {page}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
