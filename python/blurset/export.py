"""`blurset export`: one flat root of LLFF scenes that the GNeRF loaders (IBRNet, NAN,
GNT, GeoNeRF) or nerfstudio take unchanged (issue 13, DESIGN §12).

Every (setting, level[, gain]) of a build (and of a `blurset noise BUILD` output) becomes
one scene folder `<setting>__<level>[__gain_<g>]` holding `images/`, `images_<f>/`,
`poses_bounds.npy` and `transforms.json` (symlinks into the build, or copies with
`--copy`); `train.txt` and `test.txt` list the scenes of the build's train and test
settings, `export.json` says what was exported and the `llffhold` to use.

The export lives beside whatever else `--out` holds (IBRNet's and NAN's `data/` keep
other datasets next to `nerf_llff_data/`): it writes and replaces only its own entries,
the ones its export.json names, and refuses to write over anything else. The scenes
are staged in a temp folder and moved into place one rename each; a rerun that would
write the same export changes nothing. The build must be finished (see
blurset.outputs.finished_build); a damaged setting is refused, never passed on.
"""

from __future__ import annotations

import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from blurset import __version__, _core, export_hub, layout, outputs
from blurset.exceptions import ConfigError, InputError, reason_of
from blurset.export_rules import (
    EXPORT,
    EXPORT_FILE,
    LISTS,
    STAGE,
    TRASH,
    prune_empty_parents,
    record_replacing,
)
from blurset.export_rules import gains as _gains
from blurset.export_rules import levels as _levels
from blurset.export_rules import refuse_foreign as _refuse_foreign
from blurset.export_rules import refuse_other_export as _refuse_other_export
from blurset.export_rules import refuse_overlap as _refuse_overlap

if TYPE_CHECKING:
    from blurset import _records

NOISE_DATASET = outputs.OutputKind.NOISE.record
# What each target reads: IBRNet's `<rootdir>/data/nerf_llff_data/<scene>` and NAN's
# `DATA_DIR/nerf_llff_data/<scene>` list every entry of that folder as a scene, so
# nothing else may lie there; nerfstudio takes any scene folder (`--data`).
SCENES_DIR = {"llff": "nerf_llff_data", "nerfstudio": ".", "geonerf": "geonerf"}
# GeoNeRF (data/llff.py) holds out every 8th image of a scene (hard-coded) and draws a
# target's sources from all the others: a test scene is its target and the 7 nearest
# train views, so the target is its only held-out view and every source is degraded.
GEONERF_IMAGES = 8
GEONERF_DIR = "images_4"  # what GeoNeRF's LLFF dataset reads


def add_arguments(p) -> None:
    p.add_argument("build", type=Path, help="a build directory (dataset.json, splits.json)")
    p.add_argument(
        "--out", type=Path, required=True, help="the export root (outside the build; required)"
    )
    p.add_argument(
        "--for",
        dest="target",
        type=str.lower,  # choices in any case, as build and noise take them
        choices=sorted([*SCENES_DIR, export_hub.TARGET]),
        default="llff",
        help="llff: OUT/nerf_llff_data/<scene>/ (IBRNet, NAN, GNT); nerfstudio: OUT/<scene>/ "
        "with transforms.json; geonerf: OUT/geonerf/train/<scene>/ (train views only) and "
        "OUT/geonerf/test/<scene>__v<view>/ (one sharp target, 7 nearest degraded sources); "
        "hub: Parquet shards OUT/data/<config>/<split>-*.parquet that `datasets` loads and "
        "the Hugging Face Hub shows (one config per level and gain)",
    )
    export_hub.add_arguments(p)
    p.add_argument("--levels", help="levels to export, e.g. blur_4,sharp (default: all)")
    p.add_argument(
        "--noise",
        type=Path,
        help="a `blurset noise BUILD` output: export its gains (default: none)",
    )
    p.add_argument("--gains", nargs="+", help="gains of --noise to export (default: all)")
    p.add_argument("--copy", action="store_true", help="copy the files instead of symlinking")
    p.add_argument(
        "--no-masks",
        action="store_true",
        help="leave the build's masks (--passes mask) out: no masks/ folders, and no "
        "mask_path in a nerfstudio scene's transforms.json, so a loader trains on every "
        "pixel (export.json lists the passes exported)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="replace an export of another build, or of another --noise (or none), in --out "
        "(a re-export of the same build and --noise replaces its own scenes without it)",
    )


def _noise_output(noise: Path, build: Path) -> dict:
    """noise_dataset.json of a finished `blurset noise BUILD` output made from `build`."""
    return outputs.noise_of_build(noise, build)


def _scene_problem(src: Path, noise: bool) -> str | None:
    """What is wrong with a scene to export on the cheap (a build's settings also get the
    rerun's own check, layout.setting_problem): its pose rows, read as the core reads
    them (bounds that are no depth interval are refused, never passed on), and a noise
    unit's images against them."""
    try:
        rows = len(_core.read_poses_bounds(src / layout.POSES_BOUNDS))
    except (OSError, ValueError) as e:
        return f"{layout.POSES_BOUNDS} does not read: {reason_of(e)}"
    if not noise:
        return None
    images = src / layout.IMAGES
    n = len([p for p in images.iterdir() if p.suffix == ".png"]) if images.is_dir() else 0
    return None if n == rows else f"{n} images for {rows} pose rows"


@dataclass
class _Inputs:
    """What an export reads: the build, the noise output, and the levels, gains, image
    factors and held-out images it will hold."""

    build: Path
    noise: Path | None
    complete: list[str]
    splits: dict
    levels: list[str]
    gains: list[str]
    factors: list[int]
    held: str
    passes: list[str]


def _inputs(args) -> _Inputs:
    """The build and the noise output read, and every option checked against them."""
    build: Path = args.build.resolve()
    state = outputs.finished_build(build)
    dataset = outputs.read_record(build / layout.DATASET)
    splits = outputs.read_record(build / layout.SPLITS)
    noise = args.noise.resolve() if args.noise else None
    if args.gains and noise is None:
        raise ConfigError("--gains needs --noise (a `blurset noise BUILD` output)")
    available = dataset.get("levels") or [layout.SHARP]
    factors = dataset["config"].get("downsample") or []
    held = splits.get("test_view_images") or "blurry"
    gains: list[str] = []
    frames = 1
    if noise:  # the levels, factors and test views of the noise output
        noised = _noise_output(noise, build)
        available = [lvl for lvl in available if lvl in noised["levels"]]
        params = noised["params"]
        factors = params.get("downsample") or []
        held = held if params.get("clean_views") == "test_views" else "noisy"
        gains = _gains(noise, noised, args.gains)
        frames = int(params.get("frames", 1))
    levels = _levels(args.levels, available)
    if args.target == "geonerf" and frames != 1:
        raise ConfigError(
            "--for geonerf: GeoNeRF reads one image per view; --noise holds several noisy "
            "frames per view (blurset noise --frames)"
        )
    if args.target == "geonerf" and 4 not in factors:
        raise ConfigError(
            "--for geonerf: GeoNeRF reads images_4/, which this build has not: build with "
            "--downsample 4"
        )
    passes = [] if args.target == "geonerf" else list(dataset["config"].get("passes") or [])
    if args.no_masks:
        # Recorded by their absence from export.json's passes: a rerun with masks differs.
        passes = [p for p in passes if p != "mask"]
    return _Inputs(build, noise, state.complete, splits, levels, gains, factors, held, passes)


def _source(inp: _Inputs, name: str, rel: str) -> Path:
    """The folder a scene is made from (a level of the build, or a gain of the noise
    output), refused by name when it is missing or damaged."""
    src = (inp.noise or inp.build) / rel
    if inp.noise and not layout.is_complete(src):
        raise InputError(f"--noise has no complete {src.name} here: {src}")
    if problem := _scene_problem(src, inp.noise is not None):
        if inp.noise:
            raise InputError(f"--noise scene {rel} is damaged ({problem}): {src}")
        raise InputError(
            f"the build's setting {name} is damaged ({problem}): {src / layout.POSES_BOUNDS}"
        )
    return src


@dataclass
class _Scenes:
    """The scenes of an export: each one's source folder and its path relative to the
    build or noise output, the views of a GeoNeRF scene, and the two lists."""

    sources: dict[str, Path] = field(default_factory=dict)
    rels: dict[str, str] = field(default_factory=dict)
    views: dict[str, list[int]] = field(default_factory=dict)
    train: list[str] = field(default_factory=list)
    test: list[str] = field(default_factory=list)

    def add(self, scene: str, src: Path, rel: str, test: bool) -> None:
        self.sources[scene] = src
        self.rels[scene] = rel
        (self.test if test else self.train).append(scene)


def _scenes(inp: _Inputs, target: str) -> _Scenes:
    """Every scene of every complete setting, level and gain."""
    out = _Scenes()
    test = set(inp.splits["test"])
    for name in inp.complete:
        setting = inp.build / name
        if problem := layout.setting_problem(setting):
            raise InputError(
                f"the build's setting {name} is damaged ({problem}): `blurset verify` lists "
                f"what is wrong, a rerun of the build redoes it: {setting}"
            )
        held_out = [int(v) for v in inp.splits["test_views"].get(name, [])]
        for level in inp.levels:
            rels = [f"{name}/{level}/{g}" for g in inp.gains] if inp.noise else [f"{name}/{level}"]
            for rel in rels:
                scene, src = rel.replace("/", "__"), _source(inp, name, rel)
                if target != "geonerf":
                    out.add(scene, src, rel, name in test)
                    continue
                # Held-out views of a degraded scene hold clean copies (unless the build
                # rendered them blurry): GeoNeRF must never draw one as a source.
                clean_held = level != layout.SHARP and inp.held in ("sharp", "clean")
                for sc, vs in _geonerf_scenes(scene, src, held_out, clean_held, name in test):
                    out.add(sc, src, rel, name in test)
                    out.views[sc] = vs
    return out


def plan(args) -> tuple[_records.ExportDoc, dict[str, Path]]:
    """What the export holds (export.json: scene name → its source, relative to the
    build or the noise output, and the lists), and each scene's source folder."""
    inp = _inputs(args)
    sc = _scenes(inp, args.target)
    if not sc.rels:
        raise InputError(f"nothing to export (no complete setting with {inp.levels}): {args.build}")
    doc: _records.ExportDoc = {
        "kind": "blurset export",
        "blurset_version": __version__,
        "for": args.target,
        # Outputs by their folder's name, sources relative to them: no builder paths.
        "build": inp.build.name,
        "noise": inp.noise.name if inp.noise else None,
        "levels": inp.levels,
        "gains": inp.gains,
        "copy": bool(args.copy),
        "llffhold": inp.splits["view_stride"],
        "factors": inp.factors,
        "test_view_images": inp.held,
        "scenes_dir": SCENES_DIR[args.target],
        "scenes": sc.rels,
        "train": sorted(sc.train),
        "test": sorted(sc.test),
    }
    if inp.passes:
        doc["passes"] = inp.passes
    if sc.views:
        # Which views each GeoNeRF scene holds, in its order; a test scene's first is its
        # target, whose image is the sharp level's (the clean ground truth).
        doc["views"] = sc.views
        doc["target_images"] = layout.SHARP
    return doc, sc.sources


def _geonerf_scenes(
    scene: str, src: Path, held_out: list[int], clean_held: bool, is_test: bool
) -> list[tuple[str, list[int]]]:
    """GeoNeRF scenes of one level: a train setting's train views (its held-out views too
    when they are degraded), or per held-out view of a test setting, that view and its 7
    nearest train views by camera centre (GeoNeRF's own `dist`)."""
    rows = np.asarray(_core.read_poses_bounds(src / layout.POSES_BOUNDS), dtype=np.float64)
    n = len(rows)
    train = [v for v in range(n) if v not in held_out]
    if not is_test:
        return [(f"train/{scene}", train if clean_held else list(range(n)))]
    centres = rows[:, [3, 8, 13]]
    out = []
    for v in held_out:
        d = np.linalg.norm(centres[train] - centres[v], axis=1)
        near = [train[i] for i in np.argsort(d, kind="stable")[: GEONERF_IMAGES - 1]]
        if len(near) < GEONERF_IMAGES - 1:
            raise InputError(
                f"--for geonerf: {scene} has {len(train)} train views, a test scene needs "
                f"{GEONERF_IMAGES - 1}: {src}"
            )
        out.append((f"test/{scene}__v{v:03d}", [v, *near]))
    return out


def _link(s: Path, dst: Path, final: Path, copy: bool) -> None:
    """`dst` (staged) links to or copies `s`; `final` is where `dst` will end up."""
    if copy:
        try:
            (shutil.copytree if s.is_dir() else shutil.copyfile)(s, dst)
        except shutil.Error as e:
            # copytree gathers every file's error into one list of (src, dst, why)
            # tuples: say the first reason, how many, and where, in one line.
            errors = e.args[0] if e.args and isinstance(e.args[0], list) else []
            why = str(errors[0][2]) if errors else str(e)
            why = why.split("] ", 1)[-1].split(":", 1)[0] if why.startswith("[Errno") else why
            raise OSError(
                f"--copy: {why} ({len(errors) or 'some'} files not copied; nothing of the "
                f"new export was put in place): {final}"
            ) from None
    else:
        # Relative to where the link will live: the export and the build may move
        # together.
        os.symlink(os.path.relpath(s, final.parent), dst)


def _write_geonerf_scene(
    d: Path, final: Path, src: Path, doc: _records.ExportDoc, scene: str, build: Path
) -> None:
    """A GeoNeRF scene: its views' images_4/ files (renamed 000.png … in its order) and
    their poses_bounds.npy rows; a test scene's target image is the sharp level's."""
    views = doc.get("views")
    assert views is not None  # a GeoNeRF export's plan lists every scene's views
    vs = views[scene]
    rows = np.asarray(_core.read_poses_bounds(src / layout.POSES_BOUNDS), dtype=np.float64)
    images = sorted(p for p in (src / GEONERF_DIR).iterdir() if p.suffix == ".png")
    if len(images) != len(rows):
        raise InputError(f"{len(images)} images for {len(rows)} pose rows: {src / GEONERF_DIR}")
    setting = doc["scenes"][scene].split("/", 1)[0]
    sharp = build / setting / layout.SHARP / GEONERF_DIR
    (d / GEONERF_DIR).mkdir(parents=True)
    for k, v in enumerate(vs):
        test_target = k == 0 and scene.startswith("test/")
        image = sharp / layout.image_name(v, len(rows)) if test_target else images[v]
        name = f"{k:03d}.png"
        _link(image, d / GEONERF_DIR / name, final / GEONERF_DIR / name, doc["copy"])
    _core.write_poses_bounds(d / layout.POSES_BOUNDS, rows[vs])


def _write_scene(d: Path, final: Path, src: Path, doc: _records.ExportDoc) -> None:
    d.mkdir(parents=True)
    parts = [layout.IMAGES, *(layout.images_dir(f) for f in doc["factors"])]
    parts += [layout.POSES_BOUNDS]
    # A nerfstudio scene with passes gets a transforms.json of its own (_write_passes).
    parts += [] if _own_transforms(doc) else [layout.TRANSFORMS]
    for part in parts:
        s = src / part
        if not s.exists():
            if part == layout.TRANSFORMS and doc["for"] == "llff":
                continue  # a build from before per-level transforms.json
            raise InputError(f"missing {part} in the scene to export: {src}")
        _link(s, d / part, final / part, doc["copy"])


def _write_passes(
    d: Path, final: Path, src: Path, setting: Path, level: str, doc: _records.ExportDoc
) -> None:
    """The build's `--passes` beside a scene's images: the folders (depth/, normals/,
    masks/ and their _<f> sizes; LLFF loaders ignore them) of the sharp level, but a blur
    level's own masks (`layout.pass_level`), and for nerfstudio its own: depth as 16-bit
    millimetre PNGs in depths/ (its default unit) and a
    transforms.json whose frames name them (`depth_file_path`) and the masks
    (`mask_path`), which its parser looks up in depths_<f>/ and masks_<f>/ when it
    downscales."""
    own = layout.level_masks(layout.read_json(setting / layout.META, layout.META))
    for kind in doc.get("passes") or []:
        for f in [1, *doc["factors"]]:
            sub, holder = layout.pass_dir(kind, f), setting / layout.pass_level(kind, level, own)
            if not (holder / sub).is_dir():
                raise InputError(f"missing {sub} in the build's {holder.name} level: {holder}")
            _link(holder / sub, d / sub, final / sub, doc["copy"])
    if not _own_transforms(doc):
        return
    tf = layout.read_json(src / layout.TRANSFORMS, layout.TRANSFORMS)
    for frame in tf["frames"]:
        name = Path(frame["file_path"]).name
        if "depth" in doc["passes"]:
            frame["depth_file_path"] = f"{layout.nerfstudio_depth_dir(1)}/{name}"
        if "mask" in doc["passes"]:
            frame["mask_path"] = f"{layout.pass_dir('mask', 1)}/{name}"
    if "depth" in doc["passes"]:
        for f in [1, *doc["factors"]]:
            sub = layout.nerfstudio_depth_dir(f)
            (d / sub).mkdir()
            for frame in tf["frames"]:
                name = Path(frame["file_path"]).name
                exr = (
                    setting
                    / layout.pass_level("depth", level, own)
                    / layout.pass_dir("depth", f)
                    / layout.pass_file("depth", name)
                )
                _core.write_depth_millimetres(exr, d / sub / name)
    layout.write_json(d / layout.TRANSFORMS, tf)


def _own_transforms(doc: _records.ExportDoc) -> bool:
    """Whether each scene's transforms.json is written by the export (nerfstudio, with
    depth or masks to name) instead of linked from the build."""
    return doc["for"] == "nerfstudio" and bool({"depth", "mask"} & set(doc.get("passes") or []))


def _entry(doc: _records.ExportDoc, scene: str) -> str:
    return scene if doc["scenes_dir"] == "." else f"{doc['scenes_dir']}/{scene}"


def run(args) -> int:
    if args.target == export_hub.TARGET:
        return export_hub.run(args)
    if args.shard_size is not None:
        raise ConfigError(f"--shard-size: only --for hub writes shards (not --for {args.target})")
    out: Path = args.out
    doc, sources = plan(args)
    inputs = [args.build] + ([args.noise] if args.noise else [])
    _refuse_overlap(out, doc, inputs)
    outputs.refuse_inside_settings(out)
    outputs.claim(out, EXPORT, "--out")  # refused before the lock creates anything
    with outputs.lock(out, EXPORT):
        # Claimed again under the lock: another export may have finished meanwhile.
        how = outputs.claim(out, EXPORT, "--out")
        return _replace(out, doc, sources, how, args.build.resolve(), overwrite=args.overwrite)


def _replace(
    out: Path,
    doc: _records.ExportDoc,
    sources: dict[str, Path],
    how: str,
    build_root: Path,
    overwrite: bool,
) -> int:
    """Put the export's entries in place, replacing only what the previous export here
    wrote; everything else in OUT stays as it is."""
    _sweep_stale(out, doc)
    old = outputs.read_record(out / EXPORT_FILE) if how == "same" else None
    if old == doc:
        _say(doc, out, "up to date")
        return 0
    if old is not None:
        _refuse_other_export(old, doc, out, overwrite)
    owned = set(outputs.owned_entries(out, EXPORT)) if old is not None else set()
    new = [_entry(doc, s) for s in doc["scenes"]] + list(LISTS)
    _refuse_foreign(out, doc, owned, new)
    _put_in_place(out, doc, sources, build_root, owned, new)
    _say(doc, out, "written")
    return 0


def _sweep_stale(out: Path, doc: _records.ExportDoc) -> None:
    """A killed export's staged scenes and the old ones it moved aside (GBs with --copy)
    go first, also when the export is otherwise up to date; and an old scene a killed
    replace_dir had moved aside, beside the new one."""
    layout.remove_stale_temps(out, [STAGE, TRASH, *LISTS])
    for parent in {(out / _entry(doc, s)).parent for s in doc["scenes"]}:
        layout.remove_stale_temps(parent, list(doc["scenes"]))


def _put_in_place(
    out: Path,
    doc: _records.ExportDoc,
    sources: dict[str, Path],
    build_root: Path,
    owned: set[str],
    new: list[str],
) -> None:
    """Every scene staged, then the old entries out and the new ones in (replace_dir),
    the lists and the record last."""
    stage, trash = layout.temp_path(out / STAGE), layout.temp_path(out / TRASH)
    for t in (stage, trash):
        shutil.rmtree(t, ignore_errors=True)
    try:
        for scene, src in sources.items():
            final = out / _entry(doc, scene)
            if doc["for"] == "geonerf":
                _write_geonerf_scene(stage / scene, final, src, doc, scene, build_root)
            else:
                setting, level = doc["scenes"][scene].split("/")[:2]
                _write_scene(stage / scene, final, src, doc)
                _write_passes(stage / scene, final, src, build_root / setting, level, doc)
        record_replacing(out, doc, owned | set(new))
        trash.mkdir()
        # Old scenes (and a scene folder of another target) make way, one rename each.
        for k, rel in enumerate(sorted(owned - set(new))):
            os.replace(out / rel, trash / str(k))
            # (A hub export's shards leave their empty data/<config>/ folders.)
            prune_empty_parents(out, rel)
        for scene in doc["scenes"]:
            dst = out / _entry(doc, scene)
            dst.parent.mkdir(parents=True, exist_ok=True)
            layout.replace_dir(stage / scene, dst)
        for split in ("train", "test"):
            layout.write_text_atomic(out / f"{split}.txt", "".join(f"{n}\n" for n in doc[split]))
        outputs.write_record(out / EXPORT_FILE, doc)
    finally:
        for t in (stage, trash):
            shutil.rmtree(t, ignore_errors=True)


def _say(doc: _records.ExportDoc, out: Path, what: str) -> None:
    root = out / doc["scenes_dir"] if doc["scenes_dir"] != "." else out
    factors = ", ".join(f"{layout.images_dir(f)}/" for f in doc["factors"]) or "images/ only"
    # nerfstudio reads the split from each scene's transforms.json; LLFF loaders need llffhold.
    hint = {
        "nerfstudio": "splits in each transforms.json",
        "geonerf": f"GeoNeRF: --llff_path {root / 'train'} --llff_test_path {root / 'test'}, "
        "--nb_views 6 at most",
    }.get(doc["for"], f"use llffhold {doc['llffhold']}")
    print(
        f"blurset export: {len(doc['scenes'])} scenes ({len(doc['train'])} train, "
        f"{len(doc['test'])} test) {what} -> {root}; {hint} "
        f"({factors}; test views hold {doc['test_view_images']} images)",
        file=sys.stdout,
    )
