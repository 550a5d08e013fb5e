"""Build configuration: defaults < `--demo` defaults < TOML file (`--config`) < flags.

The options, their defaults, ranges and derived numbers live in blurset-core
(`_core.BuildConfig`, the one validator). This module maps flags and TOML keys (and
their spellings: `keep-linear`, `latents = "auto"`, `levels = "1,2"`) onto option
names, and turns the core's errors into one line naming the flag or the file and key.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from blurset import _core
from blurset.exceptions import ConfigError
from blurset.services import outputs
from blurset.services.options import Options, parse_downsample, parse_indices, parse_levels

__all__ = [
    "BUILD",
    "DEMO_DEFAULTS",
    "OPTIONS",
    "BuildConfig",
    "check_downsample",
    "flag",
    "from_flags",
    "load_toml",
    "make_config",
    "out_dir",
    "parse_downsample",
    "parse_indices",
    "parse_levels",
]

BuildConfig = _core.BuildConfig

# The options of `blurset build` as the core declares them (flags, keys, kinds, help).
BUILD = Options(BuildConfig.declarations())
OPTIONS: tuple[str, ...] = BUILD.names
# Small enough for about two minutes on 2 cores, rich enough for SfM (declared per option).
DEMO_DEFAULTS: dict[str, Any] = BUILD.demo_defaults


def flag(option: str) -> str:
    return BUILD.flag(option)


def check_downsample(factors: Any, where: str = "--downsample") -> list[int]:
    """Factors of `images_<f>/` copies whose image size is not the build's (noise of a
    scene): the core's range, distinct."""
    try:
        _core.check_downsample(factors)
    except (OverflowError, TypeError):
        raise ConfigError(f"{where} {factors!r}: expected factors like 4 8, or none") from None
    except _core.ConfigValueError as e:
        raise ConfigError(f"{where} {e.detail}") from None
    return sorted(factors)


def _option(key: str, where: str) -> str:
    name = BUILD.option_of_key(key)
    if name is None:
        raise ConfigError(f"{where}: unknown option {key!r}")
    return name


def load_toml(path: Path) -> TomlValues:
    """Read a TOML config. Keys are option names (`latents`, `settings-per-object` …),
    either all at top level or all under one `[build]` table; anything else is an error."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_bytes().decode("utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"--config: no such file {str(path)!r}") from None
    except IsADirectoryError:
        raise ConfigError(f"--config: {str(path)!r} is a directory, not a TOML file") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"--config: {str(path)!r} is not UTF-8 text ({e.reason})") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"--config: {str(path)!r} is not valid TOML: {e}") from None
    except OSError as e:
        raise ConfigError(f"--config: cannot read {str(path)!r}: {e.strerror}") from None
    if "build" in data:
        if not isinstance(data["build"], dict):
            raise ConfigError(f"{path}: build must be a table ([build]), got {data['build']!r}")
        beside = [k for k in data if k != "build"]
        if beside:
            raise ConfigError(
                f"{path}: {', '.join(map(repr, beside))} beside the [build] table: put every "
                "option under [build] (or none)"
            )
        data = data["build"]
    out = TomlValues()
    for key, value in data.items():
        if isinstance(value, dict):
            raise ConfigError(f"{path}: unknown table [{key}] (only [build] is read)")
        name = _option(key, str(path))
        if name in out:
            raise ConfigError(f"{path}: {key!r} is given twice (as {name})")
        # Read by the option's kind (levels "1,2", factors, `auto`, a fraction or ids …);
        # a count or auto stays as given: make_config reads it per layer.
        if BUILD.by_name[name].kind == "count_or_auto":
            read = {name: value}
        else:
            read = BUILD.read(name, value, f"{path}: {key}")
        out.update(read)
        out.written.update(dict.fromkeys(read, key))
    return out


class TomlValues(dict):
    """The options of a TOML file by name, and `written`: each option's key as the file
    spells it (`test-view-stride` for view_stride), so an error names what the user wrote."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.written: dict[str, str] = {}


def _layer(layer: dict[str, Any], where: Any) -> dict[str, Any]:
    """One layer's values (None: not given) with a count-or-auto (`latents = auto`) and
    device indices read in it; `where(option)` names what gave the option."""
    layer = {k: v for k, v in layer.items() if v is not None}
    for name in list(layer):
        d = BUILD.by_name.get(name)
        if d is not None and d.kind in ("count_or_auto", "indices"):
            layer.update(BUILD.read(name, layer.pop(name), where(name)))
    return layer


def _via(option: str) -> str:
    """The option whose flag or key sets `option` (itself, or the one it is set via)."""
    d = BUILD.by_name.get(option)
    return d.via if d is not None and d.via else option


def _plain(value: Any) -> Any:
    return str(value) if isinstance(value, Path) else value


# What a target replaces: a demo default among these would be refused beside it.
_SAMPLE_COUNTS = ("samples", "samples_total", "sharp_samples", "blur_budget")


def _under_preset(values: dict[str, Any], given: dict[str, Any]) -> None:
    """A preset (and a target) comes under what the user gave but over the demo's smaller
    defaults: drop a demo default that the preset sets, or that a target replaces."""
    sets: dict[str, Any] = {}
    preset = given.get("preset")
    if isinstance(preset, str):
        try:
            sets = _core.preset_values(preset.strip().lower())
        except ValueError:
            return  # not a preset: the core refuses the name, naming the option
    dropped = [*sets, *(["latents"] if "latents_auto" in sets else [])]
    if "target_psnr" in sets or given.get("target_psnr") is not None:
        dropped += _SAMPLE_COUNTS
    for k in dropped:
        if k not in given:
            values.pop(k, None)


def make_config(
    file_values: dict[str, Any], flag_values: dict[str, Any], *, config_path: Path | None = None
) -> BuildConfig:
    """Combine the layers, validate in the core, and name the flag or file key of a bad value."""
    # Only true is the demo: another value (`demo = "no"`) goes to the core, which refuses it.
    demo = flag_values.get("demo") is True or (
        flag_values.get("demo") is None and file_values.get("demo") is True
    )
    origin: dict[str, str] = {}
    values: dict[str, Any] = dict(DEMO_DEFAULTS) if demo else {}
    in_file = f"{config_path}: " if config_path else "--config: "
    written = getattr(file_values, "written", {})
    given = _layer(file_values, lambda k: f"{in_file}{written.get(k, k)}")
    origin.update({k: f"{in_file}{written.get(k, written.get(_via(k), k))}" for k in given})
    flags = _layer(flag_values, flag)
    origin.update({k: flag(k) for k in flags})
    given.update(flags)
    for k in ("out", "objaverse_dir", "blender"):
        # The same check as the flags' (cli._refuse_empty_paths): an empty path, an
        # output that is a link to nothing.
        if isinstance(given.get(k), str | Path):
            problem = outputs.path_problem(given[k], output=k == "out")
            if problem is not None:
                raise ConfigError(f"{origin.get(k, flag(k))} {problem}")
    values.update(given)
    _under_preset(values, given)
    values.setdefault("demo", False)
    # Every rule between options is the core's (BuildConfig's validator).
    try:
        cfg = BuildConfig(**{k: _plain(v) for k, v in values.items()})
        cfg.require_target()
    except _core.ConfigValueError as e:
        where = origin.get(e.option, flag(e.option))
        raise ConfigError(f"{where} {e.detail}") from None
    return cfg


def out_dir(cfg: BuildConfig) -> Path:
    """The output directory of a build's config (`require_target` has checked it)."""
    if cfg.out is None:
        raise ConfigError("--out is required: an output directory")
    return Path(cfg.out)


def from_flags(names: dict[str, str] | None = None, **values: Any) -> BuildConfig:
    """A config of these options over the defaults, for commands whose flags are options
    (tradeoff); an error names the flag (`names` maps an option to another flag)."""
    try:
        return BuildConfig(**{k: _plain(v) for k, v in values.items()})
    except _core.ConfigValueError as e:
        where = (names or {}).get(e.option, flag(e.option))
        raise ConfigError(f"{where} {e.detail}") from None
