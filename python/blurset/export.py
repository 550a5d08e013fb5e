"""`blurset export`: one flat root of LLFF scenes that the GNeRF loaders (IBRNet, NAN,
GNT, GeoNeRF) or nerfstudio take unchanged (issue 13, DESIGN §12).

Every (setting, level[, gain]) of a build (and of a `blurset noise BUILD` output) becomes
one scene folder `<setting>__<level>[__gain_<g>]` holding `images/`, `images_<f>/`,
`poses_bounds.npy` and `transforms.json` (symlinks into the build, or copies with
`--copy`); `train.txt` and `test.txt` list the scenes of the build's train and test
settings, `export.json` says what was exported and the `llffhold` to use. The export
is written whole into a temp folder and renamed into place; a rerun that would write
the same export changes nothing.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

from blurset import __version__, layout
from blurset.exceptions import ConfigError, InputError

EXPORT_FILE = "export.json"
# What each target reads: IBRNet's `<rootdir>/data/nerf_llff_data/<scene>` and NAN's
# `DATA_DIR/nerf_llff_data/<scene>` list every entry of that folder as a scene, so
# nothing else may lie there; nerfstudio takes any scene folder (`--data`).
SCENES_DIR = {"llff": "nerf_llff_data", "nerfstudio": "."}


def add_arguments(p) -> None:
    p.add_argument("build", type=Path, help="a build directory (dataset.json, splits.json)")
    p.add_argument(
        "--out", type=Path, required=True, help="the export root (outside the build; required)"
    )
    p.add_argument(
        "--for",
        dest="target",
        choices=sorted(SCENES_DIR),
        default="llff",
        help="llff: OUT/nerf_llff_data/<scene>/ (IBRNet, NAN, GNT, GeoNeRF); "
        "nerfstudio: OUT/<scene>/ with transforms.json",
    )
    p.add_argument("--levels", help="levels to export, e.g. blur_4,sharp (default: all)")
    p.add_argument(
        "--noise",
        type=Path,
        help="a `blurset noise BUILD` output: export its gains (default: none)",
    )
    p.add_argument("--gains", nargs="+", help="gains of --noise to export (default: all)")
    p.add_argument("--copy", action="store_true", help="copy the files instead of symlinking")


def _levels(value: str | None, available: list[str]) -> list[str]:
    if value is None:
        return available
    names = [s.strip() for s in value.split(",") if s.strip()]
    for n in names:
        if n not in available:
            raise ConfigError(f"--levels: the build has no level {n!r} ({', '.join(available)})")
    return [lvl for lvl in available if lvl in names]


def _gains(noise: Path, value: list[str] | None) -> list[str]:
    doc = layout.read_json(noise / "noise_dataset.json", "noise_dataset.json")
    have = [layout.gain_name(g["gain"]) for g in doc.get("gains", [])]
    if value is None:
        return have
    names = []
    for v in value:
        try:
            name = layout.gain_name(float(v))
        except ValueError:
            raise ConfigError(f"--gains {v!r}: not a number") from None
        if name not in have:
            raise ConfigError(f"--gains {v}: {noise} has no {name} ({', '.join(have)})")
        names.append(name)
    return names


def plan(args) -> dict:
    """What the export holds: scene name → its source folder, and the lists."""
    build: Path = args.build.resolve()
    if not (build / "dataset.json").is_file():
        raise InputError(f"not a build (no dataset.json): {args.build}")
    dataset = layout.read_json(build / "dataset.json", "dataset.json")
    splits = layout.read_json(build / "splits.json", "splits.json")
    config = dataset.get("config") or {}
    noise = args.noise.resolve() if args.noise else None
    if args.gains and noise is None:
        raise ConfigError("--gains needs --noise (a `blurset noise BUILD` output)")
    available = dataset.get("levels") or [layout.SHARP]
    factors = config.get("downsample", [])
    held = splits.get("test_view_images", "blurry")
    if noise:  # the levels, factors and test views of the noise output
        noised = layout.read_json(noise / "noise_dataset.json", "noise_dataset.json")
        available = [lvl for lvl in available if lvl in noised.get("levels", [])]
        params = noised.get("params", {})
        factors = params.get("downsample", [])
        held = held if params.get("clean_views") == "test_views" else "noisy"
    levels = _levels(args.levels, available)
    gains = _gains(noise, args.gains) if noise else []
    test = set(splits.get("test", []))
    scenes: dict[str, str] = {}
    train_list: list[str] = []
    test_list: list[str] = []
    for setting in layout.complete_settings(build):
        for level in levels:
            srcs = (
                [(f"{setting.name}__{level}__{g}", noise / setting.name / level / g) for g in gains]
                if noise
                else [(f"{setting.name}__{level}", setting / level)]
            )
            for name, src in srcs:
                if not layout.is_complete(src) and src.parent != setting:
                    raise InputError(f"--noise has no complete {src.name} here: {src}")
                scenes[name] = str(src)
                (test_list if setting.name in test else train_list).append(name)
    if not scenes:
        raise InputError(f"nothing to export (no complete setting with {levels}): {args.build}")
    return {
        "kind": "blurset export",
        "blurset_version": __version__,
        "for": args.target,
        "build": str(build),
        "noise": str(noise) if noise else None,
        "levels": levels,
        "gains": gains,
        "copy": bool(args.copy),
        "llffhold": splits.get("view_stride", 16),
        "factors": factors,
        "test_view_images": held,
        "scenes_dir": SCENES_DIR[args.target],
        "scenes": scenes,
        "train": sorted(train_list),
        "test": sorted(test_list),
    }


def _write(tmp: Path, doc: dict) -> None:
    scenes_dir = tmp / doc["scenes_dir"]
    scenes_dir.mkdir(parents=True, exist_ok=True)
    for name, src in doc["scenes"].items():
        d = scenes_dir / name
        d.mkdir()
        src = Path(src)
        parts = ["images", *(f"images_{f}" for f in doc["factors"])]
        parts += ["poses_bounds.npy", "transforms.json"]
        for part in parts:
            s = src / part
            if not s.exists():
                if part == "transforms.json" and doc["for"] == "llff":
                    continue  # a build from before per-level transforms.json
                raise InputError(f"missing {part} in the scene to export: {src}")
            if doc["copy"]:
                (shutil.copytree if s.is_dir() else shutil.copyfile)(s, d / part)
            else:
                # Relative links: the export and the build may move together.
                os.symlink(os.path.relpath(s, d), d / part)
    for split in ("train", "test"):
        (tmp / f"{split}.txt").write_text("".join(f"{n}\n" for n in doc[split]))
    (tmp / EXPORT_FILE).write_text(json.dumps(doc, indent=1) + "\n")


def run(args) -> int:
    out: Path = args.out
    doc = plan(args)
    inputs = [Path(doc["build"])] + ([Path(doc["noise"])] if doc["noise"] else [])
    layout.refuse_overlap(out, inputs)
    layout.refuse_inside_settings(out)
    if layout.is_build_dir(out) or (out / "noise_dataset.json").is_file():
        raise ConfigError(f"--out is a build or a noise output, not an export: {out}")
    old = out / EXPORT_FILE
    if out.exists():
        if not out.is_dir():
            raise ConfigError(f"--out exists and is not a directory: {out}")
        if old.is_file():
            if layout.read_json(old, EXPORT_FILE) == doc:
                _say(doc, out, "up to date")
                return 0
        elif any(out.iterdir()):
            raise ConfigError(f"--out is a folder with other files, not an export: {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    layout.remove_stale_temps(out.parent, [out.name, f"{out.name}.old"])
    tmp = layout.temp_path(out)
    shutil.rmtree(tmp, ignore_errors=True)
    try:
        _write(tmp, doc)
        if out.exists():
            # The old export (ours: export.json, or an empty folder) makes way in one
            # rename each; a reader sees the old or the new export, never a mix.
            gone = layout.temp_path(out.with_name(f"{out.name}.old"))
            os.replace(out, gone)
            os.replace(tmp, out)
            shutil.rmtree(gone, ignore_errors=True)
        else:
            os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    _say(doc, out, "written")
    return 0


def _say(doc: dict, out: Path, what: str) -> None:
    root = out / doc["scenes_dir"] if doc["scenes_dir"] != "." else out
    factors = ", ".join(f"images_{f}/" for f in doc["factors"]) or "images/ only"
    # nerfstudio reads the split from each scene's transforms.json; LLFF loaders need llffhold.
    hint = (
        "splits in each transforms.json"
        if doc["for"] == "nerfstudio"
        else f"use llffhold {doc['llffhold']}"
    )
    print(
        f"blurset export: {len(doc['scenes'])} scenes ({len(doc['train'])} train, "
        f"{len(doc['test'])} test) {what} -> {root}; {hint} "
        f"({factors}; test views hold {doc['test_view_images']} images)",
        file=sys.stdout,
    )
