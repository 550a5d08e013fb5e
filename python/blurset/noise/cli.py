"""`blurset noise` on the command line: one LLFF scene (`scene`) or every chosen level of
every complete setting of a build (`build`), LLFF-N style (DESIGN §5)."""

from __future__ import annotations

from pathlib import Path

from blurset.exceptions import InputError


def add_arguments(parser) -> None:
    parser.add_argument(
        "scene",
        type=Path,
        help="LLFF scene directory (images*/ + poses_bounds.npy), or a build directory "
        "(dataset.json + settings): then every chosen level of every complete setting",
    )
    parser.add_argument(
        "--out", type=Path, required=True, help="output directory (must not exist; required)"
    )
    parser.add_argument(
        "--gains",
        nargs="+",
        type=str,
        default=["1", "2", "4", "8", "16", "20"],
        help="gain levels (default: the LLFF-N levels 1 2 4 8 16 20)",
    )
    parser.add_argument(
        "--factor",
        type=int,
        default=None,
        help="read images_<F>/ and divide the focal length by F (default: images/)",
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
        help="KPN's synthetic test file (.npz with sig_read, sig_shot) to reproduce NAN's sigmas "
        "(default: none, the LLFF-N sigma table)",
    )
    parser.add_argument(
        "--gamma",
        choices=("2.2", "srgb"),
        default=None,
        help="transfer curve (default: 2.2 as NAN for a scene; srgb, the build's own curve, "
        "for a build)",
    )
    parser.add_argument(
        "--white-level", type=float, default=1.0, help="linear value of white, in [1e-6, 1]"
    )
    parser.add_argument(
        "--any-gain", action="store_true", help="allow gains outside the LLFF-N levels"
    )
    parser.add_argument(
        "--downsample",
        nargs="+",
        default=None,
        help="also images_<f>/ and linear_<f>/ per gain, noise drawn at that size on the clean "
        "image area-averaged in linear light (default: a build's own factors; a scene: none)",
    )
    parser.add_argument(
        "--clean-views",
        type=int,
        default=None,
        metavar="K",
        help="every K-th view stays clean, as a held-out target (default: a scene none; a "
        "build its test views, unless --noisy-test-views)",
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
    build.add_argument(
        "--noisy-test-views",
        action="store_true",
        help="noise the build's test views too (off: they stay clean, NAN's protocol)",
    )
    build.add_argument("--quiet", action="store_true", help="no progress line")


def run(args) -> int:
    if not args.scene.is_dir():
        raise InputError(f"scene or build directory not found: {args.scene}")
    from blurset.noise import build, scene

    if build.is_build(args.scene):
        return build.run(args)
    return scene.run(args)
