"""`blurset noise` is declared once, like the build (issue 27): every flag of its parser
is one declaration of the core's `NoiseConfig` (`noise_options!`) and back, the help's
defaults are the core's, and a bad value is refused by the core with the flag named."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest
from blurset import cli
from blurset.commands.noise.cli import NOISE, NoiseConfig, config_of
from blurset.exceptions import ConfigError
from blurset.services import options

from tests.conftest import help_text

# Flags of `blurset noise` that are not options of the config.
NOT_OPTIONS = {"help", "debug", "scene"}


def _noise_parser() -> argparse.ArgumentParser:
    return cli.subcommands()["noise"]


def test_every_declared_flag_is_one_parser_flag_with_its_default_and_back() -> None:
    p = _noise_parser()
    by_dest: dict[str, list[argparse.Action]] = {}
    for a in p._actions:
        by_dest.setdefault(a.dest, []).append(a)
    for d in NOISE.decls:
        assert d.flags, d.name  # every noise option has a flag
        (action,) = by_dest[d.name]  # exactly one flag per declaration
        assert action.option_strings == d.flags, d.name
        assert action.default is None  # unset flags leave the core's default
        assert d.help.split()[0] in help_text(p, action), d.name
        if d.kind == "switch":
            assert action.nargs == 0, d.name
        elif "required" in d.help:
            assert action.required and "default" not in help_text(p, action), d.name
        else:
            assert f"(default: {NOISE.default_text(d.name)})" in help_text(p, action), d.name
        if d.kind == "choice":
            assert list(action.choices or []) == d.choices, d.name
    declared = {d.name for d in NOISE.decls}
    extra = {a.dest for a in p._actions} - declared - NOT_OPTIONS
    assert not extra, f"flags of blurset noise without a declaration: {sorted(extra)}"
    flags = [f for a in p._actions for f in a.option_strings]
    assert len(flags) == len(set(flags))
    # The build-mode options are listed under their own section of the help.
    sections = {
        a.dest: g.title for g in p._action_groups for a in g._group_actions if a.dest in declared
    }
    for d in NOISE.decls:
        assert sections[d.name] == (d.section or "options"), d.name


def test_the_help_default_is_the_core_default() -> None:
    core = NoiseConfig()
    assert NoiseConfig.options() == [d.name for d in NOISE.decls]
    for d in NOISE.decls:
        assert d.default == getattr(core, d.name), d.name
    assert core.gain_values == [1.0, 2.0, 4.0, 8.0, 16.0, 20.0]
    text = _noise_parser().format_help()
    assert "(default: 1 2 4 8 16 20)" in " ".join(text.split())


def test_flags_read_into_the_core_config(tmp_path: Path) -> None:
    p = _noise_parser()
    args = p.parse_args(
        [
            str(tmp_path),
            "--out",
            "o",
            "--gains",
            "2",
            "16",
            "--frames",
            "3",
            "--seed",
            "7",
            "--downsample",
            "4",
            "--gamma",
            "srgb",
            "--quiet",
        ]  # fmt: skip
    )
    cfg = config_of(args)
    assert (cfg.out, cfg.gains, cfg.gain_values) == ("o", ["2", "16"], [2.0, 16.0])
    assert (cfg.frames, cfg.seed, cfg.downsample, cfg.gamma) == (3, 7, [4], "srgb")
    assert cfg.quiet and not cfg.overwrite and cfg.white_level == 1.0
    assert config_of(p.parse_args([str(tmp_path), "--out", "o", "--downsample", "none"])).downsample == []  # fmt: skip


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--frames", "0"], ["--frames 0:"]),
        (["--white-level", "2"], ["--white-level 2"]),
        (["--white-level", "0"], ["--white-level 0"]),
        (["--seed", "-1"], ["--seed -1:"]),
        (["--seed", str(2**64)], ["--seed"]),
        (["--factor", "0"], ["--factor 0:"]),
        (["--clean-views", "0"], ["--clean-views 0:"]),
        (["--gains", "1", "3"], ["--gains", "unknown gain '3'", "--any-gain"]),
        (["--gains", "x"], ["--gains", "unknown gain 'x'", "not a number"]),
        (["--gains", "2", "2"], ["--gains", "given twice"]),
        (["--gains", "-1", "--any-gain"], ["--gains", "positive"]),
        (["--downsample", "1"], ["--downsample"]),
    ],
)
def test_a_bad_value_is_refused_by_the_core_naming_the_flag(
    tmp_path: Path, flags: list[str], words: list[str]
) -> None:
    args = _noise_parser().parse_args([str(tmp_path), "--out", "o", *flags])
    with pytest.raises(ConfigError) as e:
        config_of(args)
    assert all(w in str(e.value) for w in words), (str(e.value), words)
    # The core refuses it itself, naming the option.
    name = next(d.name for d in NOISE.decls if flags[0] in d.flags)
    with pytest.raises(ValueError) as raw:  # the core's ConfigValueError
        NoiseConfig(**NOISE.from_args(args))
    assert getattr(raw.value, "option", None) == name


def test_the_stubs_noise_properties_are_generated_from_the_declarations() -> None:
    stub = (Path(__file__).resolve().parents[1] / "python" / "blurset" / "_core.pyi").read_text()
    start = stub.index("\nclass NoiseConfig:")
    begin = stub.index(options.STUB_BEGIN, start)
    end = stub.index(options.STUB_END, begin) + len(options.STUB_END)
    assert stub[begin:end] == options.stub_properties(NOISE.decls), "run `make stub`"
