"""A command's options as the core declares them, and what is made from the declarations.

Each option is declared once, in blurset-core's table of its config (`build_options!`
in rust/core/src/plan/config.rs): name, flags, TOML keys, kind, default, range, help and
whether it shapes the outputs (`_core.OptionDecl`). From those this module makes the
command's flags (help with every default), reads a value as a flag or a TOML key gives
it (`1,2,4`, `4 8`, `auto`, a fraction or ids) and names the flag of an option in an
error. Nothing here lists an option by name: a new option is a new declaration.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Collection, Sequence
from typing import Any

from blurset import _core
from blurset.exceptions import ConfigError

Decl = _core.OptionDecl


def check_range(flag: str, value: Any, *bounds: float, **kinds: bool) -> None:
    """ConfigError `FLAG VALUE: must be …` unless `value` is in `bounds` (lo[, hi]; see
    `_core.check_range` for `lo_open`, `integer`): a command's own option, worded as
    every declared option's range, its limits exact."""
    try:
        _core.check_range(flag, value, *bounds, **kinds)
    except _core.ConfigValueError as e:
        raise ConfigError(str(e)) from None


class Options:
    """The declarations of one config (`BuildConfig.declarations()`,
    `NoiseConfig.declarations()`)."""

    def __init__(self, decls: Sequence[Decl], *, demo_flag: str = "--demo") -> None:
        self.decls = list(decls)
        self.by_name = {d.name: d for d in self.decls}
        self.by_key = {k: d.name for d in self.decls for k in d.keys}
        # An option set through another's flag (latents_auto by --latents auto).
        self.companion = {d.via: d for d in self.decls if d.via}
        self.demo_flag = demo_flag

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(d.name for d in self.decls)

    def flag(self, option: str) -> str:
        """The flag an error names for `option` (its first; a TOML-only option by its key)."""
        d = self.by_name.get(option)
        if d is None:
            return f"--{option.replace('_', '-')}"
        if d.via:
            return self.flag(d.via)
        return d.flags[0] if d.flags else d.name

    def option_of_key(self, key: str) -> str | None:
        """The option a TOML key names (dashes or underscores, or a flag's name), or None."""
        return self.by_key.get(key.replace("-", "_"))

    @property
    def shaping(self) -> frozenset[str]:
        """The options that shape the files written (a rerun must keep them)."""
        return frozenset(d.name for d in self.decls if d.shapes_outputs)

    @property
    def demo_defaults(self) -> dict[str, Any]:
        return {d.name: d.demo for d in self.decls if d.demo is not None}

    # -- help --------------------------------------------------------------------------

    def default_text(self, option: str) -> str:
        """The default of an option as help states it (and the demo's, when it has one)."""
        d = self.by_name[option]
        if d.default is None:
            other = self.companion.get(option)
            if other is not None and other.default is not None:
                return self.default_text(other.name)
            return d.unset or "none"
        text = _shown(d.default, d.kind) or "none"  # an empty list of levels
        if d.demo is not None:
            text += f"; {_shown(d.demo, d.kind)} with {self.demo_flag}"
        return text

    def help(self, d: Decl) -> str:
        text = d.help
        if d.kind != "switch" and "required" not in text:
            text = f"{text} (default: {self.default_text(d.name)})"
        return text.replace("%", "%%")

    def add_flags(self, parser: argparse.ArgumentParser, *, required: Collection[str] = ()) -> None:
        """A flag per declared option that has one, in declaration order, under its
        help section when it names one; the options in `required` must be given."""
        groups: dict[str, Any] = {}
        sections: dict[str, Any] = {}
        for d in self.decls:
            if not d.flags:
                continue
            target: Any = parser
            if d.section:
                if d.section not in sections:
                    sections[d.section] = parser.add_argument_group(d.section)
                target = sections[d.section]
            if d.group:
                if d.group not in groups:
                    groups[d.group] = target.add_mutually_exclusive_group()
                target = groups[d.group]
            kw: dict[str, Any] = {"dest": d.name, "help": self.help(d)}
            if d.name in required:
                kw["required"] = True
            if d.metavar:
                kw["metavar"] = d.metavar
            if d.kind == "switch":
                kw.update(action="store_true", default=None)
            elif d.kind == "int":
                kw["type"] = int
            elif d.kind == "float":
                kw["type"] = float
            elif d.kind == "choice":
                # Any case, as the TOML key and the core take it; help lists the names.
                kw.update(choices=d.choices, type=_any_case(d.choices))
            elif d.kind in ("words", "factors"):
                kw["nargs"] = "+"
            # text, levels, indices, count_or_auto, fraction_or_ids: the text as given
            target.add_argument(*d.flags, **kw)

    def from_args(self, args: argparse.Namespace) -> dict[str, Any]:
        """The options given as flags (those left unset are not in it), read by kind."""
        out: dict[str, Any] = {}
        for d in self.decls:
            if d.flags and getattr(args, d.name, None) is not None:
                out.update(self.read(d.name, getattr(args, d.name), self.flag(d.name)))
        return out

    # -- values ------------------------------------------------------------------------

    def read(self, option: str, value: Any, where: str) -> dict[str, Any]:
        """`option = value` as a flag or TOML key gives it → the options it sets, read by
        the option's kind (`1,2` levels, `4 8` factors, `0,2`/`all` indices, `auto`, a
        fraction or ids); other values go to the core as they are, which checks them."""
        d = self.by_name[option]
        kind = d.kind
        if kind == "levels":
            return {option: parse_levels(value, where)}
        if kind == "factors":
            return {option: parse_downsample(value, where)}
        if kind == "indices":
            return {option: parse_indices(value, where)}
        if kind == "count_or_auto":
            return self._count_or_auto(option, value, where)
        if kind == "fraction_or_ids":
            return self._fraction_or_ids(option, value, where)
        return {option: value}

    def _count_or_auto(self, option: str, value: Any, where: str) -> dict[str, Any]:
        """`auto` sets the companion (latents_auto); a count sets the option and turns
        the companion off."""
        other = self.companion[option].name
        if isinstance(value, str):
            if value.strip().lower() == "auto":
                return {other: True}
            try:
                value = int(value)
            except ValueError:
                raise ConfigError(f"{where} {value!r}: expected a number or auto") from None
        return {option: value, other: False}

    def _fraction_or_ids(self, option: str, value: Any, where: str) -> dict[str, Any]:
        """A fraction sets the companion (test_fraction); ids (`a,b` or a list) the option."""
        other = self.companion[option].name
        if isinstance(value, bool):
            raise ConfigError(f"{where} {value!r}: expected a fraction in [0, 1] or object ids")
        if isinstance(value, int | float):
            return {other: value}
        if isinstance(value, str):
            try:
                return {other: float(value)}
            except ValueError:
                value = [v.strip() for v in value.split(",") if v.strip()]
        return {option: value}


def _shown(value: Any, kind: str) -> str:
    if isinstance(value, list | tuple):
        return (",".join if kind == "levels" else " ".join)(map(str, value))
    if isinstance(value, float):
        return f"{value:g}"
    return str(value)


def parse_levels(value: Any, where: str = "--levels") -> Any:
    """`1,2,3,4` or `none`/`sharp`/`` (sharp only) → a list; other values go to the core
    as they are (it checks the list: distinct integers in 1..64)."""
    if not isinstance(value, str):
        return value
    text = value.strip().lower()
    items = [] if text in ("", "none", "sharp") else [s.strip() for s in text.split(",")]
    try:
        return [int(x) for x in items]
    except ValueError:
        raise ConfigError(f"{where}: expected levels like 1,2,3,4 or none, got {value!r}") from None


def parse_downsample(value: Any, where: str = "--downsample") -> Any:
    """`4 8` (flag words), `4,8` or `none` → a list of factors; other values go to the
    core as they are (it checks them: distinct integers in 2..64 dividing the resolution)."""
    items = value if isinstance(value, list) else [value]
    if not all(isinstance(v, str) for v in items):
        return value
    words = [w for v in items for w in v.replace(",", " ").split()]
    if [w.lower() for w in words] in ([], ["none"]):
        return []
    try:
        return [int(w) for w in words]
    except ValueError:
        raise ConfigError(f"{where}: expected factors like 4 8, or none, got {value!r}") from None


def parse_indices(value: Any, where: str = "--gpus") -> Any:
    """`0,2` → [0, 2], `all`/`` → None (every device); other values go to the core as
    they are (it checks the list: distinct integers in 0..1023)."""
    if not isinstance(value, str):
        return value
    text = value.strip().lower()
    if text in ("", "all"):
        return None
    try:
        return [int(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"{where}: expected GPU indices like 0,2 or all, got {value!r}") from None


# -- the stub's typed properties -------------------------------------------------------

STUB_BEGIN = "    # The options, generated from the core's declarations (`make stub`):\n"
STUB_END = "    # (end of the generated options)\n"


def python_type(rust: str, json: bool = False) -> str:
    """The Python type the binding gives a field of this Rust type (`Option<Vec<u32>>`
    → `list[int] | None`); `json`: as a record parsed from JSON holds it (an array is a
    list, not a tuple)."""
    rust = rust.replace(" ", "")
    if rust.startswith("Option<") and rust.endswith(">"):
        return f"{python_type(rust[7:-1], json)} | None"
    if rust.startswith("Vec<") and rust.endswith(">"):
        return f"list[{python_type(rust[4:-1], json)}]"
    if rust.startswith("[") and rust.endswith("]") and ";" in rust:
        item, n = rust[1:-1].split(";")
        if json:
            return f"list[{python_type(item, json)}]"
        return f"tuple[{', '.join([python_type(item)] * int(n))}]"
    if rust == "String":
        return "str"
    if rust == "bool":
        return "bool"
    if rust in ("f32", "f64"):
        return "float"
    if rust in ("u8", "u16", "u32", "u64", "usize", "i32", "i64"):
        return "int"
    raise ValueError(f"no Python type for the Rust type {rust!r}")


def _any_case(choices: Sequence[str]) -> Callable[[str], str]:
    """A flag's value → the choice it names in any case (else as given: argparse then
    names the flag and lists the choices)."""

    def canonical(value: str) -> str:
        return next((c for c in choices if c.lower() == value.lower()), value)

    return canonical


def property_type(d: Decl, json: bool = False) -> str:
    """The Python type of a config property (`json`: of its value in a record): a choice
    is the Literal of its names (the binding hands the value's name across), anything
    else from its Rust type."""
    if not d.choices:
        return python_type(d.rust_type, json)
    names = ", ".join(f'"{c}"' for c in d.choices)
    return f"Literal[{names}]" + (" | None" if d.optional else "")


def stub_properties(decls: Sequence[Decl]) -> str:
    """The typed properties of a config class in _core.pyi, one per declaration."""
    body = "".join(
        f"    @property\n    def {d.name}(self) -> {property_type(d)}: ...\n" for d in decls
    )
    return STUB_BEGIN + body + STUB_END


RECORD_BEGIN = "# dataset.json's config record, generated from the declarations (`make stub`):\n"
RECORD_END = "# (end of the generated record)\n"


def record_type(decls: Sequence[Decl]) -> str:
    """The TypedDict of `BuildConfig.record()` in _core.pyi: a field per declaration,
    typed as its property, a count-or-auto option also "auto" (the record writes "auto"
    for the option it sets), and the derived `effective_sharp_samples`."""
    fields = "".join(
        f"    {d.name}: {property_type(d, json=True)}"
        + (' | Literal["auto"]' if d.kind == "count_or_auto" else "")
        + "\n"
        for d in decls
    )
    return (
        RECORD_BEGIN
        + "class BuildConfigRecord(TypedDict):\n"
        + '    """dataset.json\'s `config`: every option as `BuildConfig.record()` writes it."""\n\n'
        + fields
        + "    effective_sharp_samples: int\n\n"
        + RECORD_END
    )


def write_stub(path: str, cls: str = "BuildConfig") -> bool:
    """Rewrite the generated properties of `cls` in the stub at `path`; True when it
    changed."""
    from pathlib import Path

    p = Path(path)
    text = p.read_text()
    start = text.index(f"\nclass {cls}:")
    begin = text.index(STUB_BEGIN, start)
    end = text.index(STUB_END, begin) + len(STUB_END)
    decls = getattr(_core, cls).declarations()
    new = text[:begin] + stub_properties(decls) + text[end:]
    if cls == "BuildConfig":
        rb = new.index(RECORD_BEGIN)
        re_ = new.index(RECORD_END, rb) + len(RECORD_END)
        new = new[:rb] + record_type(decls) + new[re_:]
    if new != text:
        p.write_text(new)
    return new != text
