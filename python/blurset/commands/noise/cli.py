"""`blurset noise` on the command line: one LLFF scene (`scene`) or every chosen level of
every complete setting of a build (`build`), LLFF-N style (DESIGN §5).

Every flag is an option of the core's `NoiseConfig` (`noise_options!` in
rust/core/src/noise/config.rs), made by `Options` from its declaration; the core checks
the values, and the validated config (not the flags) goes to the noise modes."""

from __future__ import annotations

import argparse
from pathlib import Path

from blurset import _core
from blurset.commands.noise.params import NOISE
from blurset.exceptions import ConfigError, InputError

NoiseConfig = _core.NoiseConfig


def add_arguments(parser) -> None:
    parser.add_argument(
        "scene",
        type=Path,
        help="LLFF scene directory (images*/ + poses_bounds.npy), or a build directory "
        "(dataset.json + settings): then every chosen level of every complete setting",
    )
    NOISE.add_flags(parser, required=("out",))


def config_of(args: argparse.Namespace) -> NoiseConfig:
    """The validated config of the flags given; a bad value names its flag."""
    try:
        return NoiseConfig(**NOISE.from_args(args))
    except _core.ConfigValueError as e:
        raise ConfigError(f"{NOISE.flag(e.option)} {e.detail}") from None


def run(args) -> int:
    scene: Path = args.scene
    if not scene.is_dir():
        raise InputError(f"scene or build directory not found: {scene}")
    cfg = config_of(args)
    from blurset.commands.noise import build
    from blurset.commands.noise import scene as scene_mode

    if build.is_build(scene):
        return build.run(scene, cfg)
    return scene_mode.run(scene, cfg)
