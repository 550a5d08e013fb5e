"""`blurset tradeoff`: the command (options, the --out folder it may write, the run)."""

from __future__ import annotations

import argparse
from pathlib import Path

from blurset import layout
from blurset.commands.tradeoff.grid import preset_from_args
from blurset.commands.tradeoff.measure import measure
from blurset.commands.tradeoff.recommend import summary_lines
from blurset.exceptions import ConfigError
from blurset.services import outputs
from blurset.services.config import BUILD


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--object", required=True, type=Path, help="a GLB file (required)")
    p.add_argument("--out", required=True, type=Path, help="output directory (required)")
    p.add_argument(
        "--quick", action="store_true", help="small grid, 96 px: a few minutes on 2 cores"
    )
    p.add_argument("--level", type=int, help="blur level of the measured image (default: 4)")
    p.add_argument("--view", type=int, default=0, help="view index in the setting")
    p.add_argument(
        "--resolution", type=int, help="image side, px (default: 96 with --quick, else 256)"
    )
    p.add_argument(
        "--budgets", type=str, help="samples per blurry image, e.g. 16,64 (default: the preset's)"
    )
    p.add_argument("--latents", type=str, help="latent counts, e.g. 2,8,32 (default: the preset's)")
    p.add_argument(
        "--reference",
        type=str,
        help="reference M,S: M stratified frames of S samples each (default: the preset's)",
    )
    p.add_argument("--max-ghost-px", type=float, default=1.0, help="for the auto rows")
    p.add_argument(
        "--latent-sampling",
        type=str.lower,  # choices in any case, as build takes them (its declaration's)
        choices=BUILD.by_name["latent_sampling"].choices,
        default="subsets",
        help="how the candidates' latent frames share samples",
    )
    p.add_argument("--seed", type=int, default=0, help="setting seed")
    p.add_argument("--theta0-deg", type=float, default=0.0, help="base azimuth, degrees")
    p.add_argument("--threads", type=int, default=0, help="Cycles threads (0: all cores)")
    p.add_argument(
        "--blender", help="a Blender binary instead of the bpy module (default: the bpy module)"
    )
    p.add_argument(
        "--denoise",
        type=str.lower,  # choices in any case, as build and noise take them
        choices=["none", "oidn"],
        default="none",
        help="oidn: every candidate is also measured denoised (Open Image Denoise on the "
        "mean of its frames and of their albedo/normal guides, the sharp image the same "
        "way) against references at 32x its samples",
    )
    p.add_argument("--timeout", type=float, default=1800.0, help="worker reply timeout, s")
    p.add_argument("--quiet", action="store_true", help="no per-candidate lines")


def run_tradeoff(args: argparse.Namespace) -> dict:
    pre = preset_from_args(args)
    glb = Path(args.object)
    if not glb.is_file():
        raise ConfigError(f"--object: no such file {str(glb)!r}")
    out = Path(args.out)
    outputs.refuse_overlap(out, [glb])
    outputs.refuse_inside_settings(out)
    claim(out)  # refused before anything is created
    out.mkdir(parents=True, exist_ok=True)

    def busy(holder: str) -> None:
        raise ConfigError(
            f"--out is being written by another blurset tradeoff ({holder}): wait for it "
            f"to end, or give another --out: {out}"
        )

    with outputs.flock_file(out / outputs.TRADEOFF_LOCK, busy):
        claim(out)  # again under the lock
        if not outputs.is_tradeoff(out):
            # The record first: a stopped run's folder is still this command's own.
            layout.write_json(out / outputs.TRADEOFF_RECORD, {"kind": outputs.TRADEOFF_KIND})
        return measure(args, pre, glb, out)


def claim(out: Path) -> None:
    """May tradeoff write into `out`? A new or empty folder, or an earlier tradeoff's
    (its tradeoff.json says so): it replaces only its own files there. Anything else (a
    build, any other output, a folder of other files, a folder inside an output) is
    refused by name: ConfigError."""
    outputs.refuse_inside_output(out, "--out")
    if (problem := outputs.path_problem(out, output=True)) is not None:
        raise ConfigError(f"--out {problem}")
    if not out.exists():
        return
    if not out.is_dir():
        raise ConfigError(f"--out exists and is not a directory: {out}")
    kind = outputs.kind_of(out)
    if kind is not None:
        raise ConfigError(
            f"--out is a blurset {kind.label} ({kind.record}), not a tradeoff folder: give a "
            f"new or empty folder (nothing was written): {out}"
        )
    if outputs.is_tradeoff(out):
        return
    if any(not p.name.startswith(".") for p in out.iterdir()):
        raise ConfigError(
            f"--out is a folder with other files, not an earlier blurset tradeoff's (no "
            f"{outputs.TRADEOFF_RECORD} of its own): give a new or empty folder (nothing "
            f"was written): {out}"
        )


def run(args: argparse.Namespace) -> int:
    res = run_tradeoff(args)
    for line in summary_lines(res):
        print(line)
    print(f"  wrote {Path(args.out) / 'tradeoff.csv'} and tradeoff.png")
    return 0
