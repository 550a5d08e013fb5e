"""`blurset build` on the command line: its flags, and the config they make."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from blurset import layout
from blurset.config import (
    DEMO_DEFAULTS,
    BuildConfig,
    load_toml,
    make_config,
    out_dir,
    parse_downsample,
    parse_levels,
    split_test_objects,
)

# Defaults the core holds as none, in words (the others are the core's values).
NONE_DEFAULTS = {
    "samples_total": "--samples × the most latent frames of an image",
    "sharp_samples": "the blurry image's budget S",
    "gpus": "all",
    "gpus_per_task": "1 with a GPU device, else 0",
    "ray_address": "a local Ray",
    "shard": "every object",
    "objaverse_dir": "the objaverse package's, ~/.objaverse",
    "objaverse_count": "every object listed",
    "blender": "the bpy module",
    "licenses": "every licence",
    "test_settings": "none, --test-objects decides",
}


def default_text(option: str) -> str:
    """The default of a build option as help states it: the core's value (and the
    demo's, when it has its own)."""
    core = BuildConfig()
    value = getattr(core, option)
    if value is None:
        return NONE_DEFAULTS[option]
    if isinstance(value, list):
        text = ",".join(map(str, value)) if option == "levels" else " ".join(map(str, value))
    elif isinstance(value, float):
        text = f"{value:g}"
    else:
        text = str(value)
    if option in DEMO_DEFAULTS:
        text += f"; {DEMO_DEFAULTS[option]} with --demo"
    return text


def _state_defaults(p: argparse.ArgumentParser, first: int) -> None:
    """Append the core's default to the help of each option added since action `first`
    (flags, and options whose help says it, excepted)."""
    for action in p._actions[first:]:
        if (
            action.nargs == 0
            or "default" in (action.help or "")
            or "required" in (action.help or "")
        ):
            continue
        option = "test_fraction" if action.dest == "test_objects" else action.dest
        action.help = f"{action.help} (default: {default_text(option)})"


def add_arguments(p: argparse.ArgumentParser) -> None:
    first = len(p._actions)
    p.add_argument(
        "--config", type=Path, help="TOML file of options (flags override it; default: none)"
    )
    p.add_argument(
        "--objects",
        nargs="+",
        help="GLB files, folders of GLBs, or text files listing them (required, unless --demo)",
    )
    p.add_argument("--out", type=Path, help="output directory (required)")
    p.add_argument("--demo", action="store_true", default=None, help="built-in procedural objects")
    p.add_argument("--settings-per-object", type=int, help="azimuth settings per object")
    p.add_argument("--views", type=int, help="views per setting")
    p.add_argument("--levels", type=str, help="blur levels, e.g. 1,2,3,4 or none (sharp only)")
    p.add_argument(
        "--latents",
        type=str,
        help="latent frames averaged per blurry image, or auto: per view and level, "
        "the fewest that leave no gap over --max-ghost-px on screen",
    )
    p.add_argument("--latents-max", type=int, help="cap of --latents auto")
    p.add_argument(
        "--max-ghost-px",
        type=float,
        help="--latents auto: largest screen gap between latent frames, px",
    )
    p.add_argument(
        "--samples",
        type=int,
        help="Cycles samples per latent frame of the flat split (budget S = this × m)",
    )
    p.add_argument(
        "--samples-total",
        type=int,
        help="sample budget S of one blurry image: its m latent frames render ceil(S·m^0.4/m) "
        "samples each under --blur-budget parity, ceil(S/m) under flat",
    )
    p.add_argument(
        "--blur-method",
        choices=["average", "motion_blur"],
        help="average of latent renders (the paper) or one Cycles motion blur render",
    )
    p.add_argument("--sharp-samples", type=int, help="Cycles samples of the sharp image")
    p.add_argument(
        "--latent-sampling",
        choices=["subsets", "independent"],
        help="subsets: a blurry image's latent frames render the blocks of one sample "
        "sequence on the view's seed, which the sharp image renders too; "
        "independent: a seed per frame",
    )
    p.add_argument(
        "--blur-budget",
        choices=["parity", "flat", "need"],
        help="parity: a blurry image of m >= 2 latent frames renders the sample budget S "
        "times m^0.4, so it is no noisier than its sharp image; need: that factor bought by "
        "the image's measured motion between frames (less for small motion); flat: the "
        "budget as given, ceil(S/m) samples a frame",
    )
    p.add_argument(
        "--denoise",
        choices=["none", "oidn"],
        help="none: images as rendered; oidn: every image denoised once by Open Image "
        "Denoise, a blurry image after averaging (its frames' albedo and normal averaged the "
        "same way), the sharp image the same way",
    )
    p.add_argument(
        "--light-paths",
        choices=["auto", "fixed"],
        help="light-path bounces from the object's materials (auto) or the same for every object",
    )
    p.add_argument(
        "--device",
        choices=["auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal"],
        help="Cycles device; auto: the best backend Cycles reports "
        "(OptiX > CUDA > HIP > oneAPI > Metal > CPU)",
    )
    p.add_argument("--gpus", help="GPU indices of the backend, e.g. 0,2, or all")
    p.add_argument(
        "--gpus-per-task", type=float, help="GPUs each Ray task reserves (--executor ray)"
    )
    p.add_argument("--resolution", type=int, help="image side in pixels, square")
    p.add_argument("--seed", type=int, help="build seed")
    p.add_argument("--fov-deg", type=float, help="field of view in degrees")
    p.add_argument(
        "--latent-positions",
        choices=["random", "stratified"],
        help="latent positions on the segment: uniform random or stratified",
    )
    p.add_argument(
        "--trajectory",
        choices=["start", "centered"],
        help="where the written pose p sits on each blurry image's camera path: its start "
        "(the paper) or its middle, so sharp image, pose and exposure coincide",
    )
    p.add_argument(
        "--keep-linear",
        "--write-linear",
        dest="write_linear",
        action="store_true",
        default=None,
        help="also store the linear float image (EXR) of every view and level; "
        "`blurset noise BUILD` then starts from it",
    )
    p.add_argument(
        "--previews", action="store_true", default=None, help="write <setting>/preview.png"
    )
    p.add_argument(
        "--downsample",
        nargs="+",
        help="images_<f>/ beside images/ in every level, area-averaged in linear light "
        "(e.g. 4 8, or none)",
    )
    p.add_argument(
        "--blurry-test-views",
        action="store_true",
        default=None,
        help="render the held-out views blurry too (off: Deblur-NeRF's convention, "
        "the blur levels hold the sharp image there)",
    )
    p.add_argument(
        "--test-view-stride",
        dest="view_stride",
        type=int,
        help="every k-th view of a setting is held out (LLFF's llffhold)",
    )
    split = p.add_mutually_exclusive_group()
    split.add_argument(
        "--test-objects",
        help="test settings: a seeded fraction F of the objects, or object ids a,b",
    )
    split.add_argument(
        "--test-settings",
        type=int,
        help="test settings: N seeded random settings (the paper: 52)",
    )
    p.add_argument("--workers", type=int, help="objects rendered in parallel")
    p.add_argument("--threads", type=int, help="Cycles threads per worker (0: all cores)")
    p.add_argument("--executor", choices=["local", "ray"], help="local process pool or Ray")
    p.add_argument(
        "--ray-address", help="Ray cluster to join (ray://host:10001 or auto; --executor ray)"
    )
    p.add_argument(
        "--shard", help="i/N: this job's share of the objects (0 ≤ i < N), for job arrays"
    )
    p.add_argument("--objaverse-dir", help="the objaverse package's cache directory")
    p.add_argument(
        "--objaverse-offline",
        action="store_true",
        default=None,
        help="never download: objects missing from the cache fail",
    )
    p.add_argument(
        "--objaverse-count", type=int, help="a seeded random subset of N objaverse objects"
    )
    p.add_argument(
        "--timeout", type=float, help="seconds without a worker reply before it is killed"
    )
    p.add_argument(
        "--object-timeout", type=float, help="wall-clock budget of one object, s (0: none)"
    )
    p.add_argument("--retries", type=int, help="extra attempts after a worker crash or hang")
    p.add_argument(
        "--max-failure-rate",
        type=float,
        help="exit 1 when more than this fraction of objects failed",
    )
    p.add_argument("--max-triangles", type=int, help="pre-flight triangle budget")
    p.add_argument("--max-texture-pixels", type=int, help="pre-flight texture budget, pixels")
    p.add_argument("--blender", help="a Blender binary instead of the bpy module")
    p.add_argument(
        "--check-poses", action="store_true", default=None, help="COLMAP check per setting"
    )
    p.add_argument(
        "--allow-mixed",
        action="store_true",
        default=None,
        help="build into an OUT made with other output-shaping options (mixes settings)",
    )
    p.add_argument(
        "--licenses",
        help="only objects under these licences, e.g. cc-by-4.0,cc0-1.0 (SPDX ids; add "
        "unknown for objects that name none, other for unmapped ones); the rest are skipped "
        "before rendering and recorded in failures.jsonl (stage license)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    _state_defaults(p, first)


def config_from_args(args: argparse.Namespace) -> BuildConfig:
    file_values = load_toml(args.config) if args.config else {}
    flags = {
        k: getattr(args, k)
        for k in (
            "objects out demo settings_per_object views latents latents_max max_ghost_px "
            "samples samples_total blur_method sharp_samples latent_sampling blur_budget denoise "
            "light_paths "
            "device gpus gpus_per_task resolution seed fov_deg latent_positions trajectory "
            "write_linear workers threads executor shard timeout "
            "object_timeout retries max_failure_rate max_triangles max_texture_pixels "
            "ray_address objaverse_dir objaverse_offline objaverse_count "
            "blender check_poses previews allow_mixed view_stride test_settings "
            "blurry_test_views downsample licenses"
        ).split()
    }
    if args.levels is not None:
        flags["levels"] = parse_levels(args.levels)
    if args.downsample is not None:
        flags["downsample"] = parse_downsample(args.downsample)
    if args.test_objects is not None:
        flags.update(split_test_objects(args.test_objects, "--test-objects"))
    return make_config(file_values, flags, config_path=args.config)


def run(args: argparse.Namespace) -> int:
    from blurset.build import build

    cfg = config_from_args(args)
    summary = build(cfg, progress=not args.quiet)
    skipped = summary.get("objects_skipped", 0)
    n, bad = summary["objects"] - skipped, summary["objects_failed"]
    rate = bad / n if n else 0.0
    line = (
        f"blurset build: {summary['settings_complete']} settings complete "
        f"({summary['settings_new']} new), {bad} of {n} objects failed ({100 * rate:.0f}%)"
    )
    if skipped:
        line += f", {skipped} skipped by --licenses"
    if summary["settings_failed"]:
        line += f", {summary['settings_failed']} settings failed QA"
    print(f"{line} -> {cfg.out}", file=sys.stderr)
    for f in summary["failures"][:5]:
        where = f.get("setting") or f["uid"]
        print(f"  {where}: {f['stage']}: {f['reason']}", file=sys.stderr)
    if len(summary["failures"]) > 5:
        print(f"  … see {out_dir(cfg) / layout.FAILURES}", file=sys.stderr)
    if summary["objects"] and summary["settings_complete"] == 0:
        return 1  # nothing built (every object failed, or --licenses left none)
    if rate > cfg.max_failure_rate:
        print(
            f"blurset build: error: {100 * rate:.0f}% of objects failed, more than "
            f"--max-failure-rate {cfg.max_failure_rate:g}",
            file=sys.stderr,
        )
        return 1
    return 0
