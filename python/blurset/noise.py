"""`blurset noise`: reproducible LLFF-N style noisy copies of an LLFF scene (DESIGN §5).

Per gain g, OUT/gain_<g>/ is a complete LLFF scene: images/ (processed sRGB PNG),
linear/ (float EXR of the unclipped linear noisy image, same stems),
poses_bounds.npy (hwf of the written resolution) and noise.json. The whole OUT tree
is written into a temporary sibling directory and renamed at the end, so OUT either
appears complete or not at all.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path

import numpy as np

from blurset import __version__, _core
from blurset.exceptions import ConfigError, InputError

# The gain levels of the LLFF-N benchmark (NAN, Pearl et al. 2022).
LLFF_N_GAINS = (1.0, 2.0, 4.0, 8.0, 16.0, 20.0)
IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg"}
MODEL = "y' = y + sqrt(sigma_read^2 + sigma_shot^2 * y) * N(0, 1), y = white_level * decode(x) / wb"


def add_arguments(parser) -> None:
    parser.add_argument(
        "scene",
        type=Path,
        help="LLFF scene directory (images*/ + poses_bounds.npy), or a build directory "
        "(dataset.json + settings): then every chosen level of every complete setting",
    )
    parser.add_argument("--out", type=Path, required=True, help="output directory (must not exist)")
    parser.add_argument(
        "--gains",
        nargs="+",
        type=str,
        default=["1", "2", "4", "8", "16", "20"],
        help="gain levels (default: the LLFF-N levels 1 2 4 8 16 20)",
    )
    parser.add_argument(
        "--factor", type=int, default=None, help="read images_<F>/ and divide the focal length by F"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of all noise and white balance")
    parser.add_argument(
        "--profile",
        choices=("paper", "nan"),
        default="paper",
        help="paper: random white balance per scene; nan: none (parity with NAN's evaluation)",
    )
    parser.add_argument("--frames", type=int, default=1, help="independent noisy frames per view")
    parser.add_argument(
        "--kpn-levels",
        type=Path,
        default=None,
        help="KPN's synthetic test file (.npz with sig_read, sig_shot) to reproduce NAN's sigmas",
    )
    parser.add_argument(
        "--gamma",
        choices=("2.2", "srgb"),
        default=None,
        help="transfer curve (default: 2.2 as NAN for a scene; srgb, the build's own curve, "
        "for a build)",
    )
    parser.add_argument(
        "--white-level", type=float, default=1.0, help="linear value of white (1e-6..1, default 1)"
    )
    parser.add_argument(
        "--any-gain", action="store_true", help="allow gains outside the LLFF-N levels"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace OUT if it exists")
    build = parser.add_argument_group("build mode (SCENE is a build directory)")
    build.add_argument(
        "--levels", default=None, help="levels to noise, e.g. sharp,blur_4 (default: all)"
    )
    build.add_argument(
        "--source",
        choices=("auto", "linear", "png"),
        default="auto",
        help="clean image: the build's linear EXRs (--keep-linear) or its PNGs "
        "(auto: linear when every chosen level has them)",
    )
    build.add_argument("--quiet", action="store_true", help="no progress line")


def gain_name(g: float) -> str:
    """Directory name of a gain: gain_4, gain_2.5."""
    return f"gain_{int(g)}" if float(g).is_integer() else f"gain_{g:g}"


def parse_gains(values: list[str], any_gain: bool) -> list[float]:
    gains: list[float] = []
    for v in values:
        try:
            g = float(v)
        except ValueError:
            raise ConfigError(f"unknown gain {v!r} (--gains): not a number") from None
        if not (math.isfinite(g) and g > 0):
            raise ConfigError(f"unknown gain {v!r} (--gains): gains are positive numbers")
        if not any_gain and g not in LLFF_N_GAINS:
            known = " ".join(f"{k:g}" for k in LLFF_N_GAINS)
            raise ConfigError(
                f"unknown gain {v!r} (--gains): the LLFF-N levels are {known}; "
                "pass --any-gain for other values"
            )
        if g in gains:
            raise ConfigError(f"gain {v!r} given twice (--gains)")
        gains.append(g)
    return gains


def read_kpn_levels(path: Path) -> tuple[float, float, float, float]:
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


def _json_dump(path: Path, obj) -> None:
    path.write_text(json.dumps(obj, indent=2) + "\n")


def run(args) -> int:
    scene: Path = args.scene
    out: Path = args.out
    if not scene.is_dir():
        raise InputError(f"scene or build directory not found: {scene}")
    from blurset import noise_build

    if noise_build.is_build(scene):
        return noise_build.run(args)
    if args.levels is not None:
        raise ConfigError(f"--levels applies to a build (no dataset.json in {scene})")
    if args.source != "auto":
        raise ConfigError(f"--source applies to a build (no dataset.json in {scene})")
    args.gamma = args.gamma or "2.2"
    if args.factor is not None and args.factor < 1:
        raise ConfigError(f"--factor {args.factor}: must be >= 1")
    if args.frames < 1:
        raise ConfigError(f"--frames {args.frames}: must be >= 1")
    if not (1e-6 <= args.white_level <= 1.0):
        raise ConfigError(f"--white-level {args.white_level}: must be in [1e-6, 1]")
    if not (0 <= args.seed < 2**64):
        raise ConfigError(f"--seed {args.seed}: must be in [0, 2^64)")
    gains = parse_gains(args.gains, args.any_gain)

    image_dir = scene / (f"images_{args.factor}" if args.factor else "images")
    if not image_dir.is_dir():
        raise InputError(f"image directory not found: {image_dir}")
    poses_path = scene / "poses_bounds.npy"
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

    levels = read_kpn_levels(args.kpn_levels) if args.kpn_levels else _core.noise_default_levels()
    wb = _core.noise_white_balance(args.seed) if args.profile == "paper" else None
    factor = args.factor or 1
    names = output_names(sources, args.frames)

    if out.exists() and not args.overwrite:
        raise ConfigError(f"--out exists (pass --overwrite to replace it): {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.parent / f".{out.name}.tmp{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        variants = []
        for g in gains:
            sr, ss = _core.noise_sigmas(g, levels)
            variants.append((tmp / gain_name(g), sr, ss, _core.noise_key(args.seed, g)))
        _core.noise_write_variants(
            sources,
            names,
            variants,
            frames=args.frames,
            gamma=args.gamma,
            white_balance=wb,
            white_level=args.white_level,
        )
        # Every frame of a view shares its pose: the rows repeat, so a burst stays a
        # valid LLFF scene (N * frames images, N * frames rows).
        out_rows = np.repeat(np.asarray(rows, dtype=np.float64), args.frames, axis=0)
        out_rows[:, 4] = height
        out_rows[:, 9] = width
        out_rows[:, 14] = out_rows[:, 14] / factor
        files = [
            {
                "view": i,
                "frame": k,
                "source": sources[i].name,
                "image": f"images/{names[i * args.frames + k]}.png",
                "linear": f"linear/{names[i * args.frames + k]}.exr",
            }
            for i in range(len(sources))
            for k in range(args.frames)
        ]
        for g, (gdir, sr, ss, _key) in zip(gains, variants, strict=True):
            _core.write_poses_bounds(gdir / "poses_bounds.npy", out_rows)
            _json_dump(
                gdir / "noise.json",
                {
                    "gain": int(g) if g.is_integer() else g,
                    "seed": args.seed,
                    "sigma_read": sr,
                    "sigma_shot": ss,
                    "gamma": 2.2 if args.gamma == "2.2" else "srgb",
                    "white_balance": None if wb is None else {"red": wb[0], "blue": wb[1]},
                    "white_level": args.white_level,
                    "frames": args.frames,
                    "profile": args.profile,
                    "model": MODEL,
                    "levels": {
                        "source": "kpn" if args.kpn_levels else "blurset-default",
                        "file": args.kpn_levels.name if args.kpn_levels else None,
                        "log10_sigma_read_1": levels[0],
                        "read_step_per_log2_gain": levels[1],
                        "log10_sigma_shot_1": levels[2],
                        "shot_step_per_log2_gain": levels[3],
                    },
                    "source": {
                        "scene": scene.resolve().name,
                        "images": image_dir.name,
                        "factor": factor,
                        "resolution": [width, height],
                    },
                    "rng": "philox4x32-10, key derive_seed(seed, [fnv1a64('noise'), gain bits]), "
                    "stream view<<32|frame, word = pixel*colour_channels + c; ziggurat normals",
                    "blurset_version": __version__,
                    "files": files,
                },
            )
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    print(
        f"blurset noise: wrote {len(gains)} scene(s) x {len(files)} images to {out} "
        f"({', '.join(gain_name(g) for g in gains)})"
    )
    return 0
