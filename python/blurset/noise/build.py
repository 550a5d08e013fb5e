"""`blurset noise BUILD_DIR`: blur + noise on a whole build (issue 9).

Every chosen level of every complete setting of a build becomes LLFF-N style noisy
copies, mirroring the build's layout:

    DIR/noise_dataset.json            seed, options, the seed of every (setting, level)
    DIR/splits.json                   the build's splits, unchanged (same test views)
    DIR/<setting>/<level>/gain_<g>/   a complete LLFF scene, as `blurset noise SCENE` writes:
        images/  linear/  poses_bounds.npy  noise.json  .complete

The unit of work is one gain of one level of one setting. It is written under
`gain_<g>.partial/` and renamed into place after its `.complete` marker, the last file
written: a rerun skips complete units and redoes partial ones; an error removes what
the failing call had started and leaves complete units alone.

The seed of a (setting, level) is derived in blurset-core from the one `--seed`
(`noise_scene_seed`) and plays the role of the single-scene `--seed`, so the PNG path
of a unit is byte-identical to `blurset noise <build>/<setting>/<level> --seed <that
seed> --gamma srgb`.

Source of the clean image: the build's linear EXRs (`blurset build --keep-linear`),
composited over the build's background exactly as its PNGs were, or the sRGB PNGs
inverted (`--source png`). Both share the same draws, so they differ only by what the
8-bit PNG did to the clean image.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from blurset import __version__, _core, layout, outputs, publish
from blurset.exceptions import ConfigError, InputError
from blurset.layout import gain_name
from blurset.noise.params import (
    copy_clean,
    files_record,
    gain_sigmas,
    gains_of,
    kpn_path,
    noise_json,
    noise_table,
    table_record,
)
from blurset.noise.scene import list_images, output_names
from blurset.stop import interruptible, remove_tree

if TYPE_CHECKING:
    from blurset import _records

NOISE = outputs.OutputKind.NOISE
DATASET_FILE = NOISE.record
SEED_DERIVATION = (
    "noise_scene_seed(seed, setting, level) = derive_seed(seed, [fnv1a64('build_noise'), "
    "fnv1a64(setting), fnv1a64(level)]); per gain key noise_key(scene seed, gain) and white "
    "balance noise_white_balance(scene seed), as `blurset noise SCENE --seed <scene seed>`"
)
MODEL = "y' = y + sqrt(sigma_read^2 + sigma_shot^2 * y) * N(0, 1)"
CLEAN = {
    "linear": "y = white_level * clip(composite(L, background), 0, 1) / wb, L the build's "
    "linear premultiplied RGBA (linear/*.exr)",
    "png": "y = white_level * decode(x) / wb, x the build's 8-bit sRGB PNG (images/*.png)",
}


def is_build(path: Path) -> bool:
    """A build directory (as `blurset build` writes it) rather than one LLFF scene."""
    return outputs.kind_of(path) is outputs.OutputKind.BUILD


def parse_levels(value: str | None, available: list[str]) -> list[str]:
    """`sharp,blur_1,…` → level directory names, in the build's order."""
    if value is None:
        return list(available)
    names = [s.strip() for s in value.split(",") if s.strip()]
    if not names:
        raise ConfigError(f"--levels {value!r}: give level names like sharp,blur_1")
    for n in names:
        if n not in available:
            raise ConfigError(
                f"unknown level {n!r} (--levels): the build has {', '.join(available)}"
            )
    if len(set(names)) != len(names):
        raise ConfigError(f"--levels {value!r}: a level is given twice")
    return [lvl for lvl in available if lvl in names]


@dataclass
class Unit:
    """One level of one setting and the gains still to write there."""

    setting: str
    level: str
    src: Path
    dst: Path
    seed: int
    background: tuple[float, float, float]
    sources: list[Path]
    names: list[str]
    rows: np.ndarray
    resolution: tuple[int, int]
    pending: list[float]
    pngs: list[Path]
    test_views: list[int]
    clean_views: list[int]


def _plan_unit(
    setting_dir: Path,
    level: str,
    out: Path,
    seed: int,
    gains: list[float],
    frames: int,
    kind: str,
    clean_policy: str,
    downsample: list[int],
) -> Unit:
    src = setting_dir / level
    meta = outputs.read_record(setting_dir / layout.META)
    bg = (meta.get("render") or {}).get("background") or [1.0, 1.0, 1.0]
    image_dir = src / layout.IMAGES
    if not image_dir.is_dir():
        raise InputError(f"level {level!r} has no images/ directory: {image_dir}")
    pngs = list_images(image_dir)
    if not pngs:
        raise InputError(f"no .png/.jpg images in {image_dir}")
    poses = src / layout.POSES_BOUNDS
    if not poses.is_file():
        raise InputError(f"poses_bounds.npy not found: {poses}")
    rows = np.asarray(_core.read_poses_bounds(poses), dtype=np.float64)
    if len(rows) != len(pngs):
        raise InputError(f"{len(pngs)} images in {image_dir} but {len(rows)} pose rows in {poses}")
    w0, h0, _, _ = _core.image_info(pngs[0])
    bad = next((f for f in downsample if w0 % f or h0 % f), None)
    if bad is not None:
        raise ConfigError(f"--downsample {bad}: does not divide the image size {w0}x{h0}: {src}")
    for p in pngs[1:]:
        w, h, _, _ = _core.image_info(p)
        if (w, h) != (w0, h0):
            raise InputError(f"image size {w}x{h} differs from {w0}x{h0} of {pngs[0].name}: {p}")
    if kind == "linear":
        sources = [src / layout.LINEAR / f"{p.stem}.exr" for p in pngs]
        missing = next((s for s in sources if not s.is_file()), None)
        if missing is not None:
            raise InputError(
                f"--source linear: missing linear image (build with --keep-linear): {missing}"
            )
    else:
        sources = pngs
    dst = out / setting_dir.name / level
    pending = [g for g in gains if not layout.is_complete(dst / gain_name(g))]
    test_views = [int(v) for v in meta.get("test_views", [])]
    return Unit(
        pngs=pngs,
        test_views=test_views,
        clean_views=test_views if clean_policy == "test_views" else [],
        setting=setting_dir.name,
        level=level,
        src=src,
        dst=dst,
        seed=_core.noise_scene_seed(seed, setting_dir.name, level),
        background=(float(bg[0]), float(bg[1]), float(bg[2])),
        sources=sources,
        names=output_names(pngs, frames),
        rows=rows,
        resolution=(w0, h0),
        pending=pending,
    )


def _has_linear(level_dir: Path) -> bool:
    lin = level_dir / layout.LINEAR
    images = level_dir / layout.IMAGES
    if not (lin.is_dir() and images.is_dir()):
        return False
    return all((lin / f"{p.stem}.exr").is_file() for p in list_images(images))


def _params(
    cfg: _core.NoiseConfig, kind: str, gamma: str, table, downsample: list[int], clean_policy: str
) -> dict:
    """The options a noise build is made with; a rerun into the same DIR must match them."""
    return {
        "seed": cfg.seed,
        "source": kind,
        "profile": cfg.profile,
        "gamma": gamma,
        "white_level": cfg.white_level,
        "frames": cfg.frames,
        "levels_table": table_record(table, kpn_path(cfg)),
        "downsample": downsample,
        "clean_views": clean_policy,
    }


def _prepare_out(out: Path, build: Path, params: dict, overwrite: bool) -> None:
    """Claim OUT for this noise run (call under its lock): a new or empty folder, or a
    noise output made with the same options; `--overwrite` replaces a noise output's own
    units and records, nothing else in the folder, and never a build or a foreign folder."""
    if outputs.claim(out, NOISE, "--out") == "same":
        old = outputs.read_record(out / DATASET_FILE)
        if old["build"] != build.resolve().name and not overwrite:
            raise ConfigError(
                f"--out holds the noise of the build {old['build']!r}: use another --out, or "
                f"--overwrite to replace it: {out}"
            )
        if overwrite:
            outputs.remove_owned(out, NOISE)
        else:
            for k, v in params.items():
                if old["params"].get(k) != v:
                    raise ConfigError(
                        f"--out was written with {k} = {old['params'].get(k)!r}, not {v!r}: use "
                        f"another --out, or --overwrite to replace it: {out / DATASET_FILE}"
                    )
    out.mkdir(parents=True, exist_ok=True)
    if not (out / DATASET_FILE).is_file():
        # Written first (options only) so that a run killed before its end resumes;
        # rewritten with the seeds and counts at the end.
        outputs.write_record(out / DATASET_FILE, {"build": build.resolve().name, "params": params})
    for stale in out.glob("*/*/gain_*.partial"):
        shutil.rmtree(stale, ignore_errors=True)
    # The old unit a killed publish had moved aside (replace_dir), beside the new one.
    for level in {g.parent for g in out.glob("*/*/gain_*")}:
        layout.remove_stale_temps(level, [g.name for g in level.glob("gain_*")])


def _noise_json(
    unit: Unit, g: float, sr: float, ss: float, wb, params: dict, cfg: _core.NoiseConfig, build
) -> _records.NoiseDoc:
    subdir = layout.LINEAR if params["source"] == "linear" else layout.IMAGES
    return noise_json(
        gain=g,
        seed=unit.seed,
        sigmas=(sr, ss),
        gamma=params["gamma"],
        white_balance=wb,
        white_level=cfg.white_level,
        frames=cfg.frames,
        profile=cfg.profile,
        model=MODEL,
        clean=CLEAN[params["source"]],
        levels={
            **params["levels_table"],
            "file": Path(cfg.kpn_levels).name if cfg.kpn_levels else None,
        },
        source={
            "kind": params["source"],
            # The build by its folder's name: no builder paths in outputs (issue 19).
            "build": build.resolve().name,
            "setting": unit.setting,
            "level": unit.level,
            "background": list(unit.background),
            "resolution": list(unit.resolution),
        },
        build_noise={"seed": cfg.seed, "seed_derivation": SEED_DERIVATION},
        rng="philox4x32-10, key noise_key(seed, gain), stream view<<32|frame, "
        "word = pixel*3 + c; ziggurat normals (shared by the png and linear sources)",
        downsample=params["downsample"],
        clean_views=unit.clean_views,
        files=files_record(
            [f"{unit.level}/{subdir}/{p.name}" for p in unit.sources],
            unit.names,
            cfg.frames,
            set(unit.clean_views),
        ),
    )


# Fault injection, as the worker's BLURSET_WORKER_FAULT: "kill_in:K" SIGKILLs this
# process inside the K-th unit it writes, once that unit's noisy images are on disk and
# before any of its gains is complete, so a test of the resume kills at a known point
# instead of racing the run.
FAULT = "BLURSET_NOISE_FAULT"


def _fault_unit() -> int | None:
    spec = os.environ.get(FAULT, "")
    kind, _, k = spec.partition(":")
    if kind != "kill_in" or not k.isdigit():
        if spec:
            raise ConfigError(f"{FAULT}={spec!r}: expected kill_in:K")
        return None
    return int(k)


def _write_unit(
    unit: Unit,
    gains_sigmas,
    wb,
    params: dict,
    cfg: _core.NoiseConfig,
    build: Path,
    die: bool = False,
) -> None:
    """Every pending gain of `unit` written under its partial folder, each published
    once whole; an error removes the partial folders this call started."""
    unit.dst.mkdir(parents=True, exist_ok=True)
    partials = {g: layout.partial_dir(unit.dst / gain_name(g)) for g in unit.pending}
    for p in partials.values():
        shutil.rmtree(p, ignore_errors=True)
    try:
        _write_images(unit, partials, gains_sigmas, wb, params, cfg)
        if die:
            os.kill(os.getpid(), signal.SIGKILL)
        for g in unit.pending:
            _write_scene_files(unit, partials[g], g, gains_sigmas[g], wb, params, cfg, build)
            layout.publish(partials[g], unit.dst / gain_name(g))
    except BaseException:
        for p in partials.values():
            remove_tree(p)
        raise


def _write_images(
    unit: Unit, partials: dict[float, Path], gains_sigmas, wb, params: dict, cfg: _core.NoiseConfig
) -> None:
    """The noisy images of every pending gain, one pass over the unit's sources."""
    variants = [
        (partials[g], *gains_sigmas[g], _core.noise_key(unit.seed, g)) for g in unit.pending
    ]
    # The linear EXRs are composited over the build's background, as its PNGs were.
    background = unit.background if params["source"] == "linear" else None
    interruptible(
        _core.noise_write_variants,
        unit.sources,
        unit.names,
        variants,
        background=background,
        frames=cfg.frames,
        gamma=params["gamma"],
        white_balance=wb,
        white_level=cfg.white_level,
        downsample=params["downsample"],
        clean_views=unit.clean_views,
    )


def _write_scene_files(
    unit: Unit,
    part: Path,
    g: float,
    sigmas: tuple[float, float],
    wb,
    params: dict,
    cfg: _core.NoiseConfig,
    build: Path,
) -> None:
    """What makes a gain's images an LLFF scene: the clean views' own files, the poses,
    transforms.json and noise.json."""
    # Every frame of a view shares its pose (a burst stays a valid LLFF scene); the
    # build's rows already hold the written resolution and focal length.
    rows = np.repeat(unit.rows, cfg.frames, axis=0)
    small = {f: unit.src / layout.images_dir(f) for f in params["downsample"]}
    files = [
        (v, f"images/{unit.names[v * cfg.frames + k]}.png")
        for v in range(len(unit.pngs))
        for k in range(cfg.frames)
    ]
    copy_clean(part, unit.pngs, unit.names, cfg.frames, unit.clean_views, small)
    _core.write_poses_bounds(part / layout.POSES_BOUNDS, rows)
    _core.write_scene_transforms(
        part / layout.TRANSFORMS,
        unit.src.parent / layout.TRANSFORMS,
        files,
        test_views=unit.test_views,
        level=unit.level,
        gain=g,
        test_view_images="clean" if unit.clean_views else "noisy",
    )
    _core.write_noise_json(
        part / layout.NOISE, _noise_json(unit, g, *sigmas, wb, params, cfg, build)
    )


def _finalize(out: Path, build: Path, params: dict, dataset: dict) -> dict:
    """noise_dataset.json over the complete units on disk."""
    seeds: dict[str, dict[str, int]] = {}
    gains_on_disk: dict[str, dict] = {}
    n_units = n_images = 0
    for unit in sorted(u for u in out.glob("*/*/gain_*") if layout.is_complete(u)):
        meta = outputs.read_record(unit / layout.NOISE)
        setting, level = unit.parent.parent.name, unit.parent.name
        seeds.setdefault(setting, {})[level] = meta["seed"]
        gains_on_disk[unit.name] = {
            "gain": meta["gain"],
            "sigma_read": meta["sigma_read"],
            "sigma_shot": meta["sigma_shot"],
        }
        n_units += 1
        n_images += len(meta["files"])
    order = {lvl: i for i, lvl in enumerate(dataset.get("levels", []))}
    seeds = {
        s: dict(sorted(d.items(), key=lambda kv: order.get(kv[0], 99))) for s, d in seeds.items()
    }
    doc = {
        "name": "blurset Objaverse-Blur + noise",
        "blurset_version": __version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S"),
        "build": build.resolve().name,
        "build_seed": dataset.get("seed"),
        "params": params,
        "seed_derivation": SEED_DERIVATION,
        "gains": sorted(gains_on_disk.values(), key=lambda d: d["gain"]),
        "levels": [
            lvl for lvl in dataset.get("levels", []) if any(lvl in s for s in seeds.values())
        ],
        "seeds": seeds,
        "layout": "<setting>/<level>/gain_<g>/ (images/, linear/, images_<f>/, linear_<f>/, "
        "poses_bounds.npy, transforms.json, noise.json)",
        "splits": "splits.json (copied from the build)",
        "counts": {"settings": len(seeds), "units": n_units, "images": n_images},
    }
    outputs.write_record(out / DATASET_FILE, doc)
    return doc


def _refuse_scene_options(cfg: _core.NoiseConfig) -> None:
    """The options that pick a scene's images or held-out views mean nothing here."""
    if cfg.factor is not None:
        raise ConfigError("--factor: a build has no images_<F>/ directories; omit it")
    if cfg.clean_views is not None:
        raise ConfigError(
            "--clean-views applies to a scene: a build keeps its own test views clean "
            "(splits.json), or none with --noisy-test-views"
        )


def _write_pending(
    units: list[Unit],
    gains_sigmas,
    params: dict,
    cfg: _core.NoiseConfig,
    build: Path,
    fault: int | None,
) -> int:
    """Every unit's pending gains, a unit at a time (a count on a terminal); returns the
    gain scenes written."""
    written = 0
    todo = [u for u in units if u.pending]
    show = not cfg.quiet and sys.stderr.isatty()
    for n, u in enumerate(todo, 1):
        wb = _core.noise_white_balance(u.seed) if cfg.profile == "paper" else None
        _write_unit(u, gains_sigmas, wb, params, cfg, build, die=n == fault)
        written += len(u.pending)
        if show:
            print(f"\r{n}/{len(todo)} levels noised", end="", file=sys.stderr, flush=True)
    if show and todo:
        print(file=sys.stderr)
    return written


def run(build: Path, cfg: _core.NoiseConfig) -> int:
    assert cfg.out is not None  # a required flag
    out = Path(cfg.out)
    _refuse_scene_options(cfg)
    gains = gains_of(cfg)
    # A build still being written (or stopped) would be noised half, with stale splits.
    complete = outputs.finished_build(build, "SCENE").complete
    dataset = outputs.read_record(build / layout.DATASET)
    if cfg.downsample is not None:
        downsample = list(cfg.downsample)
    else:  # the build's own images_<f>/ factors (none in a build made before them)
        downsample = list((dataset.get("config") or {}).get("downsample") or [])
    clean_policy = "none" if cfg.noisy_test_views else "test_views"
    available = dataset.get("levels") or ["sharp"]
    levels = parse_levels(cfg.levels, available)
    settings = [build / name for name in complete]
    if not settings:
        raise InputError(f"no complete setting (<setting>/{layout.MARKER}) in build: {build}")

    source = cfg.source
    with_linear = all(_has_linear(s / lvl) for s in settings for lvl in levels)
    kind = ("linear" if with_linear else "png") if source == "auto" else source
    gamma = cfg.gamma or "srgb"
    table = noise_table(kpn_path(cfg))
    gains_sigmas = gain_sigmas(gains, table)
    params = _params(cfg, kind, gamma, table, downsample, clean_policy)

    # Check every unit before writing anything: a bad build fails with nothing written.
    units = [
        _plan_unit(s, lvl, out, cfg.seed, gains, cfg.frames, kind, clean_policy, downsample)
        for s in settings
        for lvl in levels
    ]
    outputs.refuse_overlap(out, [build])
    outputs.refuse_inside_settings(out)
    fault = _fault_unit()  # a bad spec is refused before anything is written
    outputs.claim(out, NOISE, "--out")  # refused before the lock creates anything
    with outputs.lock(out, NOISE):
        _prepare_out(out, build, params, cfg.overwrite)
        # Pending gains once more: --overwrite may just have removed units.
        for u in units:
            u.pending = [g for g in gains if not layout.is_complete(u.dst / gain_name(g))]
        layout.write_text_atomic(out / layout.SPLITS, (build / layout.SPLITS).read_text())
        skipped = sum(len(gains) - len(u.pending) for u in units)
        written = _write_pending(units, gains_sigmas, params, cfg, build, fault)
        doc = _finalize(out, build, params, dataset)
        publish.write_manifest(out)
    print(
        f"blurset noise: {written} scene(s) written, {skipped} complete skipped "
        f"({len(settings)} settings x {len(levels)} levels x {len(gains)} gains, "
        f"source {kind}) -> {out} [{doc['counts']['units']} scenes in total]"
    )
    return 0
