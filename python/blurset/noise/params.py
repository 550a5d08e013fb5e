"""What every noise output shares: the gain levels, the σ table, and the one writer of
`noise.json` (DESIGN §4, §5), used by the single-scene and the build mode alike."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np

from blurset import __version__, _core, layout
from blurset.exceptions import ConfigError, InputError, reason_of

if TYPE_CHECKING:
    from blurset import _records

NoiseTable = tuple[float, float, float, float]


def kpn_path(cfg: _core.NoiseConfig) -> Path | None:
    """The `--kpn-levels` file of a config, or None."""
    return Path(cfg.kpn_levels) if cfg.kpn_levels else None


def gains_of(cfg: _core.NoiseConfig) -> list[float]:
    """The gains of a config as numbers, in the order given (the core has checked each:
    a positive number, an LLFF-N level unless --any-gain, none twice); two that would
    share a gain_<g>/ folder are refused."""
    gains: list[float] = []
    for v, g in zip(cfg.gains, cfg.gain_values, strict=True):
        same = next((h for h in gains if layout.gain_name(h) == layout.gain_name(g)), None)
        if same is not None:
            raise ConfigError(
                f"--gains {same:.17g} and {v}: both would be written to {layout.gain_name(g)}/"
            )
        gains.append(g)
    return gains


def gain_sigmas(gains: list[float], table) -> dict[float, tuple[float, float]]:
    """(σ_read, σ_shot) of every gain under `table`; a gain whose σ is out of range (a
    huge `--any-gain`) is refused naming --gains, before anything is written."""
    out = {}
    for g in gains:
        try:
            sr, ss = _core.noise_sigmas(g, table)
        except ValueError as e:
            raise ConfigError(f"--gains {g:g}: {reason_of(e)}") from None
        if not (math.isfinite(sr) and math.isfinite(ss)):
            raise ConfigError(
                f"--gains {g:g}: its noise sigma is not a finite number (read {sr}, shot {ss})"
            )
        out[g] = (sr, ss)
    return out


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


def table_record(table: NoiseTable, kpn_levels: Path | None) -> dict[str, Any]:
    """The σ table as noise.json / noise_dataset.json record it."""
    return {
        "source": "kpn" if kpn_levels else "blurset-default",
        "log10_sigma_read_1": table[0],
        "read_step_per_log2_gain": table[1],
        "log10_sigma_shot_1": table[2],
        "shot_step_per_log2_gain": table[3],
    }


def files_record(
    sources: list[str], names: list[str], frames: int, clean_views: set[int] | None = None
) -> list[dict[str, Any]]:
    """Per written image: its view, frame, the clean source it came from, its files, and
    whether it stayed clean (a held-out target). `images_<f>/` and `linear_<f>/` copies
    use the same names."""
    clean = clean_views or set()
    return [
        {
            "view": i,
            "frame": k,
            "source": sources[i],
            "image": f"images/{names[i * frames + k]}.png",
            "linear": f"linear/{names[i * frames + k]}.exr",
            "clean": i in clean,
        }
        for i in range(len(sources))
        for k in range(frames)
    ]


def every_kth(n_views: int, k: int | None) -> list[int]:
    """Views 0, K, 2K … (`--clean-views K`): the core's held-out view rule; none when K
    is None."""
    return [] if k is None else _core.test_views(n_views, k)


def copy_clean(
    out: Path,
    pngs: list[Path],
    names: list[str],
    frames: int,
    clean: list[int],
    small_dirs: dict[int, Path],
) -> None:
    """The clean views of a gain directory as the scene's own files, byte for byte: its
    PNG at images/ and, where the scene has one, its copy in `small_dirs[f]` at
    images_<f>/ (the noise kernel at σ = 0 wrote the PNG's pixels, and the area mean of
    the decoded image where the scene has no copy of that size)."""
    import shutil

    for i in clean:
        p = pngs[i]
        for k in range(frames):
            name = f"{names[i * frames + k]}.png"
            if p.suffix.lower() == ".png":
                shutil.copyfile(p, out / layout.IMAGES / name)
            for f, d in small_dirs.items():
                if (d / p.name).is_file():
                    shutil.copyfile(d / p.name, out / layout.images_dir(f) / name)


def noise_json(
    *,
    gain: float,
    seed: int,
    sigmas: tuple[float, float],
    gamma: str,
    white_balance: tuple[float, float] | None,
    white_level: float,
    frames: int,
    profile: str,
    model: str,
    levels: dict[str, Any],
    source: dict[str, Any],
    rng: str,
    files: list[dict[str, Any]],
    **extra: Any,
) -> _records.NoiseDoc:
    """The `noise.json` of one noisy scene (one gain). The core checks every field when
    it writes it (write_noise_json: unknown or missing fields are errors)."""
    wb = white_balance
    doc: dict[str, Any] = {
        "gain": int(gain) if float(gain).is_integer() else gain,
        "seed": seed,
        "sigma_read": sigmas[0],
        "sigma_shot": sigmas[1],
        "gamma": 2.2 if gamma == "2.2" else "srgb",
        "white_balance": None if wb is None else {"red": wb[0], "blue": wb[1]},
        "white_level": white_level,
        "frames": frames,
        "profile": profile,
        "model": model,
        **({"clean": extra.pop("clean")} if "clean" in extra else {}),
        "levels": levels,
        "source": source,
        **extra,
        "rng": rng,
        "blurset_version": __version__,
        "files": files,
    }
    return cast("_records.NoiseDoc", doc)
