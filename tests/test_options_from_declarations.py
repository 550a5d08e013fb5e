"""Adding an option is one declaration (issue 27): the flags of `blurset build`, their
help and defaults, the TOML keys, the options that shape the outputs and the CLI
reference are all made from the core's declarations (`BuildConfig.declarations()`,
python/blurset/services/options.py). Checked both ways on the real table, and shown on a toy
option that exists only as a declaration."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest
from blurset import cli
from blurset.commands.builder.dataset import BEFORE_OPTION, RUN_OPTIONS, check_same_options
from blurset.exceptions import ConfigError
from blurset.services import options
from blurset.services.config import BUILD, BuildConfig, load_toml, make_config
from blurset.services.options import Options

from tests.conftest import help_text

# Flags of `blurset build` that are not options of the config.
NOT_OPTIONS = {"help", "debug", "config", "quiet", "dry_run"}


def _build_parser() -> argparse.ArgumentParser:
    return cli.subcommands()["build"]


def test_every_declared_flag_is_one_parser_flag_with_its_default_and_back() -> None:
    p = _build_parser()
    by_dest: dict[str, list[argparse.Action]] = {}
    for a in p._actions:
        by_dest.setdefault(a.dest, []).append(a)
    for d in BUILD.decls:
        if not d.flags:
            assert d.name not in by_dest, d.name  # TOML-only or set through another flag
            assert d.via or d.keys == [d.name], d.name
            continue
        (action,) = by_dest[d.name]  # exactly one flag per declaration
        assert action.option_strings == d.flags, d.name
        assert action.default is None  # unset flags leave the core's default
        assert d.help.split()[0] in help_text(p, action), d.name
        if d.kind == "switch":
            assert action.nargs == 0, d.name  # off unless given
        elif "required" in d.help:
            assert "default" not in help_text(p, action), d.name
        else:
            assert f"(default: {BUILD.default_text(d.name)})" in help_text(p, action), d.name
        if d.kind == "choice":
            assert list(action.choices or []) == d.choices, d.name
    declared = {d.name for d in BUILD.decls}
    extra = {a.dest for a in p._actions} - declared - NOT_OPTIONS
    assert not extra, f"flags of blurset build without a declaration: {sorted(extra)}"
    flags = [f for a in p._actions for f in a.option_strings]
    assert len(flags) == len(set(flags))
    assert p.allow_abbrev is False


def test_the_help_default_is_the_core_default() -> None:
    core = BuildConfig()
    for d in BUILD.decls:
        assert d.default == getattr(core, d.name) or (
            d.kind == "rgb" and list(getattr(core, d.name)) == d.default
        ), d.name
    demo = make_config({}, {"demo": True, "out": "o"})
    declared = {d.name: d.demo for d in BUILD.decls if d.demo is not None}
    assert declared and all(getattr(demo, k) == v for k, v in declared.items()), declared


def test_shapes_outputs_is_what_a_rerun_must_keep(tmp_path: Path) -> None:
    """For every option: a rerun whose recorded value differs is refused exactly when
    the declaration says the option shapes the outputs (and the run options and the
    values of a record before the option are the declarations')."""
    assert frozenset(d.name for d in BUILD.decls if not d.shapes_outputs) == RUN_OPTIONS
    assert BEFORE_OPTION == {d.name: d.before for d in BUILD.decls if d.before != d.default}
    assert RUN_OPTIONS and BEFORE_OPTION and set(BUILD.names) - RUN_OPTIONS
    cfg = BuildConfig(out=str(tmp_path), demo=True)
    now = cfg.record()
    refused = set()
    for d in BUILD.decls:
        was = dict(now)
        was[d.name] = "a value this build was not made with"
        (tmp_path / "dataset.json").write_text(json.dumps({"config": was}))
        try:
            check_same_options(tmp_path, cfg)
        except ConfigError as e:
            assert BUILD.flag(d.name) in str(e), (d.name, str(e))
            refused.add(d.name)
    assert refused == {d.name for d in BUILD.decls if d.shapes_outputs}


def test_every_declared_key_reads_from_a_config_file(tmp_path: Path) -> None:
    read = 0
    for d in BUILD.decls:
        if d.kind in ("count_or_auto", "fraction_or_ids") or d.via or d.default is None:
            continue  # read through their companion's key, or None: no TOML value
        for key in d.keys:
            f = tmp_path / f"{key}.toml"
            f.write_text(f"{key.replace('_', '-')} = {json.dumps(d.default)}\n")
            assert load_toml(f) == {d.name: d.default}, key
            read += 1
    assert read > len(BUILD.decls) // 2
    f = tmp_path / "unknown.toml"
    f.write_text("toy_width = 3\n")
    with pytest.raises(ConfigError, match="unknown option 'toy_width'"):
        load_toml(f)


def _toy(**kw: Any) -> SimpleNamespace:
    """A declaration as the core's OptionInfo gives it."""
    base = dict(
        flags=[],
        via=None,
        keys=[],
        optional=False,
        choices=[],
        range="",
        unset=None,
        demo=None,
        group=None,
        metavar=None,
        section=None,
        rust_type="u32",
    )
    base.update(kw)
    base.setdefault("before", base["default"])
    base["keys"] = base["keys"] or [base["name"]]
    return SimpleNamespace(**base)


def test_a_toy_option_is_one_declaration() -> None:
    """A declaration added to the real ones gets its flag (default in its help), is read
    from flags and TOML keys, counts as shaping the outputs and appears in the CLI
    reference's table; nothing else names it."""
    toy = _toy(
        name="toy_width",
        flags=["--toy-width"],
        keys=["toy_width"],
        kind="int",
        default=3,
        demo=2,
        help="toy width of every image",
        shapes_outputs=True,
    )
    toml_only = _toy(
        name="toy_gain", kind="float", default=0.5, help="toy gain", shapes_outputs=False
    )
    opts = Options([*BUILD.decls, toy, toml_only])  # type: ignore[list-item]
    p = argparse.ArgumentParser(allow_abbrev=False)
    opts.add_flags(p)
    (action,) = [a for a in p._actions if a.dest == "toy_width"]
    assert action.option_strings == ["--toy-width"] and action.type is int
    assert "toy width of every image (default: 3; 2 with --demo)" == action.help
    assert not [a for a in p._actions if a.dest == "toy_gain"]
    args = p.parse_args(["--toy-width", "7", "--views", "5"])
    assert opts.from_args(args) == {"toy_width": 7, "views": 5}
    assert "toy_width" in opts.shaping and "toy_gain" not in opts.shaping
    assert opts.option_of_key("toy-width") == "toy_width"
    assert opts.option_of_key("toy_gain") == "toy_gain"
    assert opts.flag("toy_gain") == "toy_gain" and opts.flag("toy_width") == "--toy-width"
    assert opts.demo_defaults["toy_width"] == 2
    # Without the declaration there is no such flag.
    with pytest.raises(SystemExit):
        _build_parser().parse_args(["--toy-width", "7"])


def test_the_cli_reference_lists_every_declaration(monkeypatch: pytest.MonkeyPatch) -> None:
    import importlib.util

    monkeypatch.setenv("COLUMNS", "88")
    monkeypatch.setattr("sys.path", list(__import__("sys").path))

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("gen_cli", root / "docs" / "gen" / "cli.py")
    assert spec and spec.loader
    gen = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(gen)
    page = gen.reference()
    for d in BUILD.decls:
        if d.flags:
            assert f"`{d.flags[0]}`" in page, d.name
        elif not d.via:
            assert f"| `{d.name}` |" in page, d.name


def test_the_stubs_typed_properties_are_generated_from_the_declarations() -> None:
    """_core.pyi's BuildConfig properties are exactly `make stub`'s output: a property
    per declaration, typed as the binding converts the declared Rust type."""
    stub = (Path(__file__).resolve().parents[1] / "python" / "blurset" / "_core.pyi").read_text()
    start = stub.index("\nclass BuildConfig:")
    begin = stub.index(options.STUB_BEGIN, start)
    end = stub.index(options.STUB_END, begin) + len(options.STUB_END)
    assert stub[begin:end] == options.stub_properties(BUILD.decls), "run `make stub`"
    rb = stub.index(options.RECORD_BEGIN)
    re_ = stub.index(options.RECORD_END, rb) + len(options.RECORD_END)
    assert stub[rb:re_] == options.record_type(BUILD.decls), "run `make stub`"
    assert options.python_type("Option<Vec<u32>>") == "list[int] | None"
    assert options.python_type("[f64; 3]") == "tuple[float, float, float]"
    # A toy declaration gets its typed property.
    toy = _toy(name="toy_width", kind="int", default=3, help="toy", shapes_outputs=True)
    assert "    def toy_width(self) -> int: ...\n" in options.stub_properties([toy])  # type: ignore[list-item]


def test_a_choice_flag_takes_any_case_as_its_toml_key_does() -> None:
    p = _build_parser()
    for d in BUILD.decls:
        if d.kind == "choice" and d.flags:
            c = d.choices[-1]
            got = p.parse_args([d.flags[0], c.upper()])
            assert getattr(got, d.name) == c, d.name
            assert BUILD.from_args(got) == BUILD.from_args(p.parse_args([d.flags[0], c]))
    with pytest.raises(SystemExit):
        p.parse_args(["--blur-budget", "needy"])
