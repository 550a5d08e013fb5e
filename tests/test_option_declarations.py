"""The build options are declared in the core (`build_options!` in plan/config.rs); every
other place that lists them is checked against that declaration here: the flags of
`blurset build`, the typed properties of the stub, the run options (those that do not
shape the files) and the help's defaults. A core option without its flag, stub
property or classification fails, and so does a flag that is no option."""

from __future__ import annotations

import argparse
import re
import types
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin

import pytest
from blurset import cli
from blurset.commands.builder.cli import default_text
from blurset.commands.builder.dataset import BEFORE_OPTION, RUN_OPTIONS
from blurset.services.config import BuildConfig

OPTIONS = BuildConfig.options()
STUB = Path(__file__).resolve().parents[1] / "python" / "blurset" / "_core.pyi"

# Options reached through another option's flag.
FLAG_VIA = {"latents_auto": "--latents", "test_fraction": "--test-objects"}
# The paper's constants of the sampling: TOML keys only, no flag.
TOML_ONLY = {
    "phi0_deg",
    "window_deg",
    "delta0",
    "radius_margin",
    "level_spread",
    "orientation_max",
    "near_floor",
    "background",
}
# Flags of `blurset build` that are not options of the config.
NOT_OPTIONS = {"help", "debug", "config", "quiet", "dry_run"}


def _build_parser() -> argparse.ArgumentParser:
    return cli.subcommands()["build"]


def test_every_option_has_a_flag_and_every_flag_is_an_option() -> None:
    dests = {a.dest for a in _build_parser()._actions}
    missing = [o for o in OPTIONS if o not in dests and o not in FLAG_VIA and o not in TOML_ONLY]
    assert not missing, f"core options without a flag of blurset build: {missing}"
    extra = sorted(dests - set(OPTIONS) - NOT_OPTIONS)
    assert not extra, f"flags of blurset build that are no core option: {extra}"
    assert not (TOML_ONLY | set(FLAG_VIA)) - set(OPTIONS)


def _stub_properties() -> dict[str, str]:
    text = STUB.read_text()
    start = text.index("\nclass BuildConfig:")
    end = text.index("\nclass ", start + 1)
    body = text[start:end]
    return dict(re.findall(r"@property\s+def (\w+)\(self\) -> ([^:]+?): \.\.\.", body))


def _conforms(value: Any, hint: Any) -> bool:
    origin = get_origin(hint)
    if origin in (Union, types.UnionType):
        return any(_conforms(value, h) for h in get_args(hint))
    if hint is None or hint is type(None):
        return value is None
    if origin is Literal:
        return value in get_args(hint)
    if origin is list:
        (item,) = get_args(hint)
        return isinstance(value, list) and all(_conforms(v, item) for v in value)
    if origin is tuple:
        items = get_args(hint)
        return (
            isinstance(value, tuple)
            and len(value) == len(items)
            and all(_conforms(v, h) for v, h in zip(value, items, strict=True))
        )
    if hint is float:
        return isinstance(value, float)
    if hint is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, hint)


def test_the_stub_types_every_option_as_the_core_gives_it() -> None:
    props = _stub_properties()
    missing = [o for o in OPTIONS if o not in props]
    assert not missing, f"_core.pyi has no BuildConfig property for {missing}"
    demo = BuildConfig(
        demo=True,
        out="o",
        objects=["a.glb"],
        samples_total=64,
        sharp_samples=8,
        gpus_per_task=0.5,
        executor="ray",
        ray_address="auto",
        shard="0/2",
        objaverse_dir="d",
        objaverse_count=3,
        blender="blender",
        test_objects=["a"],
        licenses="cc0-1.0",
    )
    local = BuildConfig(gpus=[0, 1], workers=2)
    wrong = []
    for o in OPTIONS:
        hint = eval(props[o], {"list": list, "tuple": tuple, "Literal": Literal})  # noqa: S307 - our own stub
        for cfg in (BuildConfig(), demo, local):
            if not _conforms(getattr(cfg, o), hint):
                wrong.append(f"{o}: {getattr(cfg, o)!r} is not {props[o]}")
    assert not wrong, wrong


def test_the_config_record_is_what_its_stub_type_says() -> None:
    """BuildConfigRecord (generated into _core.pyi) names every key of
    `BuildConfig.record()` and types each value as it comes, under latents auto too."""
    text = STUB.read_text()
    start = text.index("class BuildConfigRecord(TypedDict):")
    body = text[start : text.index("# (end of the generated record)", start)]
    fields = dict(re.findall(r"^    (\w+): (.+)$", body, re.M))
    env = {"list": list, "tuple": tuple, "Literal": Literal}
    for cfg in (BuildConfig(), BuildConfig(latents_auto=True, background=[0.5, 0.5, 0.5])):
        record = cfg.record()
        assert sorted(record) == sorted(fields)
        wrong = [
            f"{k}: {v!r} is not {fields[k]}"
            for k, v in record.items()
            if not _conforms(v, eval(fields[k], env))  # noqa: S307 - our own stub
        ]
        assert not wrong, wrong
    assert BuildConfig(latents_auto=True).record()["latents"] == "auto"


def test_every_option_is_classified_as_shaping_the_files_or_not() -> None:
    """RUN_OPTIONS (a rerun may change them) are options; every other option shapes the
    files and is compared between runs; BEFORE_OPTION only names shaping options."""
    assert RUN_OPTIONS <= set(OPTIONS), sorted(RUN_OPTIONS - set(OPTIONS))
    assert set(BEFORE_OPTION) <= set(OPTIONS) - RUN_OPTIONS
    record = BuildConfig().record()
    assert set(OPTIONS) <= set(record), sorted(set(OPTIONS) - set(record))


def test_help_states_the_core_default_of_every_flagged_option() -> None:
    helps = {a.dest: a.help or "" for a in _build_parser()._actions}
    for o in OPTIONS:
        if o in helps and o not in ("objects", "out") and _takes_value(o):
            shown = "test_fraction" if o == "test_objects" else o  # --test-objects F|ids
            assert f"(default: {default_text(shown)})" in helps[o], (o, helps[o])


def _takes_value(option: str) -> bool:
    return not isinstance(getattr(BuildConfig(), option), bool)


def test_the_build_guides_synopsis_names_real_flags_with_the_core_defaults() -> None:
    """The build guide's `blurset build` synopsis (docs/guide/build.md): every flag it
    names is a flag of the parser, and a number it shows as the value of an option that
    has one is the core's default."""
    readme = (Path(__file__).resolve().parents[1] / "docs" / "guide" / "build.md").read_text()
    # The generated block (docs/gen/cli.py writes it between these markers).
    start = readme.index("```sh\nblurset build", readme.index("<!-- synopsis build -->"))
    synopsis = readme[start : readme.index("```", start + 5)]
    flags = {s for a in _build_parser()._actions for s in a.option_strings}
    named = re.findall(r"(--[a-z][a-z-]*)", synopsis)
    assert named and not [f for f in named if f not in flags], named
    dest = {s: a.dest for a in _build_parser()._actions for s in a.option_strings}
    core = BuildConfig()
    shown = re.findall(r"\[(--[a-z-]+) (\d+)[\]|]", synopsis)
    assert shown
    for f, value in shown:
        default = getattr(core, dest[f])
        if default is not None:  # a None default shows an example (`--gpus-per-task 1`)
            assert default == int(value), (f, value, default)


# -- issue 72: a limit reads one way in every command, its numbers exact ------------------

RANGE = re.compile(
    r"must be (an integer in -?\d+\.\.=\d+|a number in [\[(]-?\d+(\.\d+)?, -?\d+(\.\d+)?[\])]"
    r"|a finite number( [≥>] -?\d+(\.\d+)?)?)$"
)


def _value(module: Any, node: Any) -> Any:
    """A literal, or a module constant by its name."""
    import ast

    return node.value if isinstance(node, ast.Constant) else getattr(module, node.id)


def _own_range_checks() -> list[tuple[str, str, tuple, dict]]:
    """(module, flag, bounds, kinds) of every `check_range` call of the commands: the
    options no config declares."""
    import ast
    import importlib

    found = []
    for p in sorted((Path(cli.__file__).parent).rglob("*.py")):
        mod = ".".join(p.relative_to(Path(cli.__file__).parents[1]).with_suffix("").parts)
        for node in ast.walk(ast.parse(p.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "check_range":
                m = importlib.import_module(mod)
                bounds = tuple(_value(m, a) for a in node.args[2:])
                kinds = {k.arg: _value(m, k.value) for k in node.keywords}
                found.append((mod, node.args[0].value, bounds, kinds))
    return found


def test_every_declared_range_is_worded_one_way_with_exact_limits() -> None:
    from blurset.commands.noise.cli import NoiseConfig

    for config in (BuildConfig, NoiseConfig):
        for d in config.declarations():
            if d.kind in ("int", "float", "count_or_auto"):
                assert RANGE.match(d.range), (config.__name__, d.name, d.range)


def test_every_commands_own_range_is_worded_as_the_declared_ones() -> None:
    """Each command's own option (found in the sources) out of its range, below and
    above: refused in the declared options' words, its limits printed exactly."""
    from blurset.exceptions import ConfigError
    from blurset.services.options import check_range

    checks = _own_range_checks()
    flags = {flag for _, flag, _, _ in checks}
    assert {
        "--shard-size",
        "--rows",
        "--columns",
        "--tile",
        "--bins",
        "--factor",
        "--view",
    } <= flags
    for mod, flag, bounds, kinds in checks:
        lo, hi = bounds[0], bounds[1] if len(bounds) > 1 else 2**32 - 1
        for bad in (lo - 1, hi + 1):
            with pytest.raises(ConfigError) as e:
                check_range(flag, bad, *bounds, **kinds)
            said = str(e.value)
            assert said.startswith(f"{flag} {bad}"), (mod, said)
            assert RANGE.match(said.split(": ", 1)[1]), (mod, said)
            for limit in (lo, hi):
                text = str(int(limit)) if float(limit).is_integer() else str(limit)
                assert text in said, (mod, flag, limit, said)


def test_no_command_words_a_limit_by_hand() -> None:
    """A range message outside the core's words (`at least`, `at most`, `%g` rounding)
    in a command's refusal fails here."""
    hand = re.compile(r"ConfigError\([^)]*(must be at least|at most|must be in \d|>= \d|:g\})")
    for p in sorted((Path(cli.__file__).parent).rglob("*.py")):
        text = " ".join(p.read_text().split())
        assert not hand.search(text), (p, hand.search(text))


def test_a_shard_size_past_its_limit_names_it_exactly(tmp_path) -> None:
    """The issue's row: `--shard-size 1000001` was refused as 'at most 1e+06'."""
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-m", "blurset.cli", "export", str(tmp_path), "--for", "hub",
         "--shard-size", "1000001", "--out", str(tmp_path / "h")],
        capture_output=True, text=True,
    )  # fmt: skip
    assert proc.returncode == 2, proc.stderr
    assert "--shard-size 1000001.0: must be a number in (0, 1000000]" in proc.stderr, proc.stderr
