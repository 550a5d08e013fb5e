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

BuildConfig = _core.BuildConfig

# Small enough for about two minutes on 2 cores, rich enough for SfM.
DEMO_DEFAULTS: dict[str, Any] = {
    "settings_per_object": 1,
    "views": 17,
    "latents": 6,
    "samples": 4,
    "resolution": 96,
}

OPTIONS: tuple[str, ...] = tuple(BuildConfig.options())
# Other spellings of option names in TOML files (the name → the option).
ALIASES = {"keep_linear": "write_linear", "test_view_stride": "view_stride"}


# Options whose flag is not their name.
FLAGS = {
    "view_stride": "--test-view-stride",
    "test_fraction": "--test-objects",
    "test_objects": "--test-objects",
}


def flag(option: str) -> str:
    return FLAGS.get(option, f"--{option.replace('_', '-')}")


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


def split_test_objects(value: Any, where: str) -> dict[str, Any]:
    """`test-objects`: a fraction of the objects (0.2) → test_fraction, or object ids
    (`a,b` or a list) → test_objects."""
    if isinstance(value, bool):
        raise ConfigError(f"{where} {value!r}: expected a fraction in [0, 1] or object ids")
    if isinstance(value, int | float):
        return {"test_fraction": value}
    if isinstance(value, str):
        try:
            return {"test_fraction": float(value)}
        except ValueError:
            value = [v.strip() for v in value.split(",") if v.strip()]
    return {"test_objects": value}


def parse_gpus(value: Any, where: str = "--gpus") -> Any:
    """`0,2` → [0, 2], `all`/`` → None (every GPU of the backend); other values go to the
    core as they are (it checks the list: distinct integers in 0..1023)."""
    if not isinstance(value, str):
        return value
    text = value.strip().lower()
    if text in ("", "all"):
        return None
    try:
        return [int(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"{where}: expected GPU indices like 0,2 or all, got {value!r}") from None


def _option(key: str, where: str) -> str:
    name = key.replace("-", "_")
    name = ALIASES.get(name, name)
    if name not in OPTIONS:
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
        if name == "test_objects":
            split = split_test_objects(value, f"{path}: {key}")
            out.update(split)
            out.written.update(dict.fromkeys(split, key))
            continue
        out.written[name] = key
        if name == "levels":
            value = parse_levels(value, f"{path}: {key}")
        elif name == "downsample":
            value = parse_downsample(value, f"{path}: {key}")
        elif name == "gpus":
            value = parse_gpus(value, f"{path}: {key}")
        out[name] = value
    return out


class TomlValues(dict):
    """The options of a TOML file by name, and `written`: each option's key as the file
    spells it (`test-view-stride` for view_stride), so an error names what the user wrote."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.written: dict[str, str] = {}


def _latents_layer(layer: dict[str, Any], where: str) -> dict[str, Any]:
    """`latents = auto` in one layer → latents_auto; a number there turns auto off."""
    layer = {k: v for k, v in layer.items() if v is not None}
    if "latents" in layer:
        value = layer.pop("latents")
        if isinstance(value, str) and value.strip().lower() == "auto":
            layer["latents_auto"] = True
        else:
            if isinstance(value, str):
                try:
                    value = int(value)
                except ValueError:
                    raise ConfigError(
                        f"{where} {value!r}: expected a number of frames or auto"
                    ) from None
            layer["latents"], layer["latents_auto"] = value, False
    return layer


def _plain(value: Any) -> Any:
    return str(value) if isinstance(value, Path) else value


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
    given = _latents_layer(file_values, f"{in_file}latents")
    written = getattr(file_values, "written", {})
    origin.update({k: f"{in_file}{written.get(k, k)}" for k in given})
    if isinstance(given.get("gpus"), str):
        given["gpus"] = parse_gpus(given["gpus"], f"{in_file}gpus")
    flags = _latents_layer(flag_values, "--latents")
    if isinstance(flags.get("gpus"), str):
        flags["gpus"] = parse_gpus(flags["gpus"])
    origin.update({k: flag(k) for k in flags})
    if "latents_auto" in flags:
        origin["latents_auto"] = "--latents"
    given.update(flags)
    values.update(given)
    values.setdefault("demo", False)
    if isinstance(values.get("device"), str):  # CUDA, Cuda … name the same backend
        values["device"] = values["device"].strip().lower()
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
