"""What both noise modes share on the Python side: the σ table (KPN's file is read with
NumPy), the flags of the noise options, and the one way a plan's refusal names its flag.
The plan itself, its gains and every noise.json are the core's (dataset/noise_plan.rs)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from blurset import _core
from blurset.exceptions import ConfigError, InputError
from blurset.services.options import Options

NoiseTable = tuple[float, float, float, float]
NOISE = Options(_core.NoiseConfig.declarations())
T = TypeVar("T")


def planned(plan: Callable[..., T], *args: Any) -> T:
    """A core noise plan; an option it refuses (gains, levels, downsample) is named by
    its flag, as a refused flag value is."""
    try:
        return plan(*args)
    except _core.ConfigValueError as e:
        raise ConfigError(f"{NOISE.flag(e.option)} {e.detail}") from None


def kpn_path(cfg: _core.NoiseConfig) -> Path | None:
    """The `--kpn-levels` file of a config, or None."""
    return Path(cfg.kpn_levels) if cfg.kpn_levels else None


def read_kpn_levels(path: Path) -> NoiseTable:
    """NAN's mapping from KPN's synthetic test file."""
    if not path.is_file():
        raise InputError(f"--kpn-levels file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {
                k: np.asarray(data[k], dtype=np.float64).ravel() for k in ("sig_read", "sig_shot")
            }
    except KeyError as e:
        raise InputError(f"--kpn-levels file has no array {e.args[0]!r}: {path}") from None
    except (OSError, ValueError) as e:
        raise InputError(f"--kpn-levels file is not a readable .npz ({e}): {path}") from None
    try:
        return _core.noise_levels_from_kpn(arrays["sig_read"], arrays["sig_shot"])
    except ValueError as e:
        raise InputError(f"--kpn-levels {e}: {path}") from None


def noise_table(kpn_levels: Path | None) -> NoiseTable:
    """The σ(gain) table: NAN's from KPN's file when given, else blurset's default."""
    return read_kpn_levels(kpn_levels) if kpn_levels else _core.noise_default_levels()
