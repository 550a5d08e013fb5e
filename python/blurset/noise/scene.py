"""`blurset noise`: reproducible LLFF-N style noisy copies of an LLFF scene (DESIGN §5).

Per gain g, OUT/gain_<g>/ is a complete LLFF scene: images/ (processed sRGB PNG),
linear/ (float EXR of the unclipped linear noisy image, same stems),
poses_bounds.npy (hwf of the written resolution) and noise.json; OUT/noise_scene.json
says what OUT is. The gains are written into a staging folder inside OUT and each moves
into place whole; the record comes last. `--overwrite` replaces the gains and the record
of an earlier noise output, nothing else in OUT, and never a build or a foreign folder.
"""

from __future__ import annotations

import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from blurset import __version__, _core, layout, outputs
from blurset.exceptions import ConfigError, InputError
from blurset.noise.params import (
    NoiseTable,
    copy_clean,
    every_kth,
    files_record,
    gain_sigmas,
    gains_of,
    kpn_path,
    noise_json,
    noise_table,
    table_record,
)
from blurset.stop import interruptible, remove_tree

if TYPE_CHECKING:
    from blurset import _records

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}
NOISE_SCENE = outputs.OutputKind.NOISE_SCENE
STAGE = "noise"  # `.noise.tmp<pid>` in OUT: the gains before they move in
MODEL = "y' = y + sqrt(sigma_read^2 + sigma_shot^2 * y) * N(0, 1), y = white_level * decode(x) / wb"


def list_images(image_dir: Path) -> list[Path]:
    """Image files in the order LLFF loaders use: sorted by file name."""
    return sorted(
        (
            p
            for p in image_dir.iterdir()
            if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith(".")
        ),
        key=lambda p: p.name,
    )


def output_names(sources: list[Path], frames: int) -> list[str]:
    """Stems per (view, frame), view-major, whose sorted order is that order.
    Source stems are kept when that holds; otherwise index names are used."""
    stems = [p.stem for p in sources]
    if frames == 1:
        names = stems
    else:
        width = max(2, len(str(frames - 1)))
        names = [f"{s}_f{k:0{width}d}" for s in stems for k in range(frames)]
    if len(set(names)) == len(names) and sorted(names) == names:
        return names
    vw = max(3, len(str(len(sources) - 1)))
    fw = max(2, len(str(frames - 1)))
    if frames == 1:
        return [f"view{i:0{vw}d}" for i in range(len(sources))]
    return [f"view{i:0{vw}d}_f{k:0{fw}d}" for i in range(len(sources)) for k in range(frames)]


def run(scene: Path, cfg: _core.NoiseConfig) -> int:
    """The single-scene mode: SCENE is one LLFF scene."""
    assert cfg.out is not None  # a required flag
    out = Path(cfg.out)
    _refuse_build_options(scene, cfg)
    gains = gains_of(cfg)
    kpn = kpn_path(cfg)
    src = _read_scene(scene, cfg)
    levels = noise_table(kpn)
    outputs.refuse_overlap(out, [scene])
    outputs.refuse_inside_settings(out)
    if outputs.claim(out, NOISE_SCENE, "--out") == "same" and not cfg.overwrite:
        raise ConfigError(
            f"--out is a noise output already (pass --overwrite to replace it): {out}"
        )
    with outputs.lock(out, NOISE_SCENE):
        # Claimed again under the lock: another run may have written it meanwhile.
        if outputs.claim(out, NOISE_SCENE, "--out") == "same" and not cfg.overwrite:
            raise ConfigError(f"--out is a noise output already (pass --overwrite): {out}")
        # A killed run's staging tree (SIGKILL leaves it; SIGINT/SIGTERM remove their own).
        # (and an old gain a killed replace_dir had moved aside)
        layout.remove_stale_temps(out, [STAGE, *(g.name for g in out.glob("gain_*"))])
        tmp = layout.temp_path(out / STAGE)
        shutil.rmtree(tmp, ignore_errors=True)
        try:
            gain_dirs = _write_gains(tmp, src, gains, kpn, levels, cfg)
            # The previous output's own entries make way (nothing else in OUT), then each
            # gain moves in whole; the record comes last.
            outputs.remove_owned(out, NOISE_SCENE)
            for gdir in gain_dirs:
                layout.replace_dir(gdir, out / gdir.name)
            outputs.write_record(
                out / NOISE_SCENE.record,
                {
                    "kind": "blurset noise scene",
                    "blurset_version": __version__,
                    "scene": scene.resolve().name,
                    "gains": [gdir.name for gdir in gain_dirs],
                    "seed": cfg.seed,
                    "profile": cfg.profile,
                },
            )
        finally:
            remove_tree(tmp)
    print(
        f"blurset noise: wrote {len(gains)} scene(s) x {len(src.names)} images to {out} "
        f"({', '.join(layout.gain_name(g) for g in gains)})"
    )
    return 0


def _refuse_build_options(scene: Path, cfg: _core.NoiseConfig) -> None:
    """The options that choose among a build's levels and views mean nothing here."""
    if cfg.levels is not None:
        raise ConfigError(f"--levels applies to a build (no dataset.json in {scene})")
    if cfg.noisy_test_views:
        raise ConfigError(
            f"--noisy-test-views applies to a build (no dataset.json in {scene}); "
            "a scene is noised whole unless --clean-views K"
        )
    if cfg.source != "auto":
        raise ConfigError(f"--source applies to a build (no dataset.json in {scene})")


@dataclass
class _Scene:
    """An LLFF scene as the noise reads it: its images (headers checked), pose rows and
    size, and what the output names and keeps clean."""

    path: Path
    image_dir: Path
    rows: np.ndarray
    sources: list[Path]
    width: int
    height: int
    names: list[str]
    clean: list[int]
    downsample: list[int]


def _read_scene(scene: Path, cfg: _core.NoiseConfig) -> _Scene:
    """The scene's images and poses, refused whole before any pixel work: a missing
    folder or file, a count that does not match, a size that differs, a --downsample
    that does not divide it."""
    image_dir = scene / (layout.images_dir(cfg.factor) if cfg.factor else layout.IMAGES)
    if not image_dir.is_dir():
        raise InputError(f"image directory not found: {image_dir}")
    poses_path = scene / layout.POSES_BOUNDS
    if not poses_path.is_file():
        raise InputError(f"poses_bounds.npy not found: {poses_path}")
    rows = _core.read_poses_bounds(poses_path)
    sources = list_images(image_dir)
    if not sources:
        raise InputError(f"no .png/.jpg images in {image_dir}")
    if len(sources) != len(rows):
        raise InputError(
            f"{len(sources)} images in {image_dir} but {len(rows)} pose rows in {poses_path}"
        )
    if len({p.stem for p in sources}) != len(sources):
        raise InputError(f"two images share a file stem in {image_dir}")
    # Headers only: a size mismatch or an unreadable file fails before any pixel work.
    sizes = {}
    for p in sources:
        w, h, _, _ = _core.image_info(p)
        sizes[p] = (w, h)
        if (w, h) != sizes[sources[0]]:
            w0, h0 = sizes[sources[0]]
            raise InputError(f"image size {w}x{h} differs from {w0}x{h0} of {sources[0].name}: {p}")
    width, height = sizes[sources[0]]
    downsample = list(cfg.downsample or [])
    bad = next((f for f in downsample if width % f or height % f), None)
    if bad is not None:
        raise ConfigError(f"--downsample {bad}: does not divide the image size {width}x{height}")
    return _Scene(
        path=scene,
        image_dir=image_dir,
        rows=rows,
        sources=sources,
        width=width,
        height=height,
        names=output_names(sources, cfg.frames),
        clean=every_kth(len(sources), cfg.clean_views),
        downsample=downsample,
    )


def _write_gains(
    tmp: Path,
    src: _Scene,
    gains: list[float],
    kpn: Path | None,
    levels: NoiseTable,
    cfg: _core.NoiseConfig,
) -> list[Path]:
    """Every gain's noisy scene under `tmp` (images, clean copies, poses, noise.json),
    with the noise levels read from `kpn` (None: the built-in table); their folders, in
    the order of `gains`."""
    gamma = cfg.gamma or "2.2"
    sigmas = gain_sigmas(gains, levels)
    wb = _core.noise_white_balance(cfg.seed) if cfg.profile == "paper" else None
    factor = cfg.factor or 1
    variants = []
    for g in gains:
        sr, ss = sigmas[g]
        variants.append((tmp / layout.gain_name(g), sr, ss, _core.noise_key(cfg.seed, g)))
    interruptible(
        _core.noise_write_variants,
        src.sources,
        src.names,
        variants,
        frames=cfg.frames,
        gamma=gamma,
        white_balance=wb,
        white_level=cfg.white_level,
        downsample=src.downsample,
        clean_views=src.clean,
    )
    # The scene's own images_<f>/ are its clean images of that size (not with --factor).
    small = {} if cfg.factor else {f: src.path / layout.images_dir(f) for f in src.downsample}
    rows = _rows(src, cfg.frames, factor)
    for g, (gdir, sr, ss, _key) in zip(gains, variants, strict=True):
        copy_clean(gdir, src.sources, src.names, cfg.frames, src.clean, small)
        _core.write_poses_bounds(gdir / layout.POSES_BOUNDS, rows)
        doc = _noise_doc(src, g, (sr, ss), gamma, wb, kpn, levels, cfg)
        _core.write_noise_json(gdir / layout.NOISE, doc)
    return [gdir for gdir, *_ in variants]


def _rows(src: _Scene, frames: int, factor: int) -> np.ndarray:
    """The pose rows of a gain scene: every frame of a view shares its pose (a burst
    stays a valid LLFF scene: N * frames images, N * frames rows); hwf says the written
    size."""
    rows = np.repeat(np.asarray(src.rows, dtype=np.float64), frames, axis=0)
    rows[:, 4] = src.height
    rows[:, 9] = src.width
    rows[:, 14] = rows[:, 14] / factor
    return rows


def _noise_doc(
    src: _Scene,
    g: float,
    sigmas: tuple[float, float],
    gamma: str,
    wb: tuple[float, float] | None,
    kpn: Path | None,
    levels: NoiseTable,
    cfg: _core.NoiseConfig,
) -> _records.NoiseDoc:
    return noise_json(
        gain=g,
        seed=cfg.seed,
        sigmas=sigmas,
        gamma=gamma,
        white_balance=wb,
        white_level=cfg.white_level,
        frames=cfg.frames,
        profile=cfg.profile,
        model=MODEL,
        levels={**table_record(levels, kpn), "file": kpn.name if kpn else None},
        source={
            "scene": src.path.resolve().name,
            "images": src.image_dir.name,
            "factor": cfg.factor or 1,
            "resolution": [src.width, src.height],
        },
        downsample=src.downsample,
        clean_views=src.clean,
        rng="philox4x32-10, key derive_seed(seed, [fnv1a64('noise'), gain bits]), "
        "stream view<<32|frame, word = pixel*colour_channels + c; ziggurat normals",
        files=files_record([p.name for p in src.sources], src.names, cfg.frames, set(src.clean)),
    )
