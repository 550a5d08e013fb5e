"""`blurset export`: one flat root of LLFF scenes that the GNeRF loaders (IBRNet, NAN,
GNT, GeoNeRF) or nerfstudio take unchanged (issue 13, DESIGN §12).

Every (setting, level[, gain]) of a build (and of a `blurset noise BUILD` output) becomes
one scene folder `<setting>__<level>[__gain_<g>]` holding `images/`, `images_<f>/`,
`poses_bounds.npy` and `transforms.json` (symlinks into the build, or copies with
`--copy`); `train.txt` and `test.txt` list the scenes of the build's train and test
settings, `export.json` says what was exported and the `llffhold` to use.

Each target (`--for`) is a module of blurset.commands.export.targets, whose `Target` declares what sets
it apart: where its scenes lie, what its loader needs of the build, how a folder splits
into scenes, how a scene is written. This module is the flow every scene-folder target
shares, and names none; a target of its own kind (Parquet shards) runs its own.

The export lives beside whatever else `--out` holds (IBRNet's and NAN's `data/` keep
other datasets next to `nerf_llff_data/`): it writes and replaces only its own entries,
the ones its export.json names, and refuses to write over anything else. The scenes
are staged in a temp folder and moved into place one rename each; a rerun that would
write the same export changes nothing. The build must be finished (see
blurset.services.outputs.finished_build); a damaged setting is refused, never passed on.
"""

from __future__ import annotations

import os
import shutil
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from blurset import __version__, _core, layout
from blurset.commands.export import targets as exports
from blurset.commands.export.rules import (
    EXPORT,
    EXPORT_FILE,
    LISTS,
    STAGE,
    TRASH,
    OwnOutput,
    SceneFolders,
    SceneSource,
    StagedScene,
    Target,
    prune_empty_parents,
    record_replacing,
)
from blurset.commands.export.rules import gains as _gains
from blurset.commands.export.rules import levels as _levels
from blurset.commands.export.rules import refuse_foreign as _refuse_foreign
from blurset.commands.export.rules import refuse_other_export as _refuse_other_export
from blurset.commands.export.rules import refuse_overlap as _refuse_overlap
from blurset.exceptions import ConfigError, InputError, reason_of
from blurset.services import outputs

if TYPE_CHECKING:
    from blurset import _records

NOISE_DATASET = outputs.OutputKind.NOISE.record


def add_arguments(p) -> None:
    targets = exports.targets()
    p.add_argument("build", type=Path, help="a build directory (dataset.json, splits.json)")
    p.add_argument(
        "--out", type=Path, required=True, help="the export root (outside the build; required)"
    )
    p.add_argument(
        "--for",
        dest="target",
        type=str.lower,  # choices in any case, as build and noise take them
        choices=sorted(targets),
        default=exports.DEFAULT,
        help="; ".join(f"{t.name}: {t.help}" for t in targets.values())
        + f" (default: {exports.DEFAULT})",
    )
    for t in targets.values():
        if isinstance(t.output, OwnOutput):
            t.output.add_arguments(p)
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
        "mask_path in a scene's own transforms.json, so a loader trains on every "
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


def _inputs(args, target: Target, folders: SceneFolders) -> _Inputs:
    """The build and the noise output read, and every option checked against them and
    against what the target's loader needs."""
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
    if folders.one_frame and frames != 1:
        raise ConfigError(
            f"--for {target.name}: {folders.reader} reads one image per view; --noise holds "
            "several noisy frames per view (blurset noise --frames)"
        )
    if folders.factor is not None and folders.factor not in factors:
        raise ConfigError(
            f"--for {target.name}: {folders.reader} reads {layout.images_dir(folders.factor)}/, "
            f"which this build has not: build with --downsample {folders.factor}"
        )
    passes = list(dataset["config"].get("passes") or []) if folders.passes else []
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
    build or noise output, the views of a scene that holds only some, and the lists."""

    sources: dict[str, Path] = field(default_factory=dict)
    rels: dict[str, str] = field(default_factory=dict)
    views: dict[str, list[int]] = field(default_factory=dict)
    train: list[str] = field(default_factory=list)
    test: list[str] = field(default_factory=list)

    def add(self, scene: str, src: Path, rel: str, test: bool) -> None:
        self.sources[scene] = src
        self.rels[scene] = rel
        (self.test if test else self.train).append(scene)


def _scenes(inp: _Inputs, folders: SceneFolders) -> _Scenes:
    """Every scene of every complete setting, level and gain, as the target splits them."""
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
                # Held-out views of a degraded scene hold clean copies: the sharp image of
                # a blur level (unless the build rendered them blurry), the noise-free one
                # of every noisy scene, sharp level too (unless noise drew them): a loader
                # that draws sources must skip them.
                sharp_held = level != layout.SHARP and inp.held == "sharp"
                clean_held = inp.held != "noisy" if inp.noise else sharp_held
                source = SceneSource(scene, src, held_out, clean_held, name in test)
                for sc, vs in folders.split(source):
                    out.add(sc, src, rel, name in test)
                    if vs is not None:
                        out.views[sc] = vs
    return out


def plan(args, target: Target, folders: SceneFolders) -> tuple[_records.ExportDoc, dict[str, Path]]:
    """What the export holds (export.json: scene name → its source, relative to the
    build or the noise output, and the lists), and each scene's source folder."""
    inp = _inputs(args, target, folders)
    sc = _scenes(inp, folders)
    if not sc.rels:
        raise InputError(f"nothing to export (no complete setting with {inp.levels}): {args.build}")
    doc: _records.ExportDoc = {
        "kind": "blurset export",
        "blurset_version": __version__,
        "for": target.name,
        # Outputs by their folder's name, sources relative to them: no builder paths.
        "build": inp.build.name,
        "noise": inp.noise.name if inp.noise else None,
        "levels": inp.levels,
        "gains": inp.gains,
        "copy": bool(args.copy),
        "llffhold": inp.splits["view_stride"],
        "factors": inp.factors,
        "test_view_images": inp.held,
        "scenes_dir": folders.folder,
        "scenes": sc.rels,
        "train": sorted(sc.train),
        "test": sorted(sc.test),
    }
    if inp.passes:
        doc["passes"] = inp.passes
    if sc.views:
        # Which views each scene holds, in its order (GeoNeRF's); a test scene's first is
        # its target, whose image is the sharp level's (the clean ground truth).
        doc["views"] = sc.views
        doc["target_images"] = layout.SHARP
    return doc, sc.sources


def _entry(doc: _records.ExportDoc, scene: str) -> str:
    return scene if doc["scenes_dir"] == "." else f"{doc['scenes_dir']}/{scene}"


def _refuse_others_options(args, target: Target) -> None:
    """An option only another target reads is refused, never ignored."""
    for other in exports.targets().values():
        if other is target or not isinstance(other.output, OwnOutput):
            continue
        for dest in other.output.options:
            if getattr(args, dest, None) is not None:
                raise ConfigError(
                    f"--{dest.replace('_', '-')}: only --for {other.name} "
                    f"{other.output.does} (not --for {target.name})"
                )


def run(args) -> int:
    target = exports.get(args.target)
    _refuse_others_options(args, target)
    if isinstance(target.output, OwnOutput):
        return target.output.run(args)
    folders = target.output
    out: Path = args.out
    doc, sources = plan(args, target, folders)
    inputs = [args.build] + ([args.noise] if args.noise else [])
    _refuse_overlap(out, doc, inputs)
    outputs.refuse_inside_settings(out)
    outputs.claim(out, EXPORT, "--out")  # refused before the lock creates anything
    with outputs.lock(out, EXPORT):
        # Claimed again under the lock: another export may have finished meanwhile.
        how = outputs.claim(out, EXPORT, "--out")
        build_root = args.build.resolve()
        return _replace(out, folders, doc, sources, how, build_root, overwrite=args.overwrite)


def _replace(
    out: Path,
    folders: SceneFolders,
    doc: _records.ExportDoc,
    sources: dict[str, Path],
    how: str,
    build_root: Path,
    overwrite: bool,
) -> int:
    """Put the export's entries in place, replacing only what the previous export here
    wrote; everything else in OUT stays as it is."""
    new = [_entry(doc, s) for s in doc["scenes"]] + list(LISTS)
    outputs.refuse_links(out, new, "export")  # before the sweep lists their folders
    _sweep_stale(out, doc)
    old = outputs.read_record(out / EXPORT_FILE) if how == "same" else None
    if old == doc:
        _say(folders, doc, out, "up to date")
        return 0
    if old is not None:
        _refuse_other_export(old, doc, out, overwrite)
    owned = set(outputs.owned_entries(out, EXPORT)) if old is not None else set()
    _refuse_foreign(out, doc, owned, new)
    _put_in_place(out, folders, doc, sources, build_root, owned, new)
    if isinstance(old, dict):
        _leave_replaced(old, out)
    _say(folders, doc, out, "written")
    return 0


def _leave_replaced(old: dict, out: Path) -> None:
    """What the export this one replaced wrote beside its entries goes with it."""
    prev = exports.targets().get(str(old.get("for")))
    if prev is not None and isinstance(prev.output, OwnOutput) and prev.output.replaced:
        prev.output.replaced(out)


def _sweep_stale(out: Path, doc: _records.ExportDoc) -> None:
    """A killed export's staged scenes and the old ones it moved aside (GBs with --copy)
    go first, also when the export is otherwise up to date; and an old scene a killed
    replace_dir had moved aside, beside the new one."""
    layout.remove_stale_temps(out, [STAGE, TRASH, *LISTS])
    for parent in {(out / _entry(doc, s)).parent for s in doc["scenes"]}:
        layout.remove_stale_temps(parent, list(doc["scenes"]))


def _put_in_place(
    out: Path,
    folders: SceneFolders,
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
            folders.write(StagedScene(stage / scene, final, src, scene, build_root, doc))
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
            names = "".join(f"{n}\n" for n in listed(doc, split))
            layout.write_text_atomic(out / f"{split}.txt", names)
        outputs.write_record(out / EXPORT_FILE, doc)
    finally:
        for t in (stage, trash):
            shutil.rmtree(t, ignore_errors=True)


def listed(doc: _records.ExportDoc, split: str) -> list[str]:
    """train.txt / test.txt, the paper's protocol (docs/training/index.md): train on the
    train settings' degraded scenes, evaluate on the test settings'. A clean `__sharp`
    scene (the pairs' truth, in the root beside them) is listed only in an export of
    nothing else: listed, a client would train on clean images and average clean scenes
    into its evaluation."""
    clean = {s for s, rel in doc["scenes"].items() if not doc["noise"] and rel.endswith("/sharp")}
    names = doc[split]  # type: ignore[literal-required]
    return names if clean >= set(doc["scenes"]) else [n for n in names if n not in clean]


def _say(folders: SceneFolders, doc: _records.ExportDoc, out: Path, what: str) -> None:
    root = out / doc["scenes_dir"] if doc["scenes_dir"] != "." else out
    factors = ", ".join(f"{layout.images_dir(f)}/" for f in doc["factors"]) or "images/ only"
    hint = folders.hint(doc, root)
    train, test = listed(doc, "train"), listed(doc, "test")
    print(
        f"blurset export: {len(doc['scenes'])} scenes ({len(train)} in train.txt, {len(test)} "
        f"in test.txt) {what} -> {root}; {hint} "
        f"({factors}; test views hold {doc['test_view_images']} images)",
        file=sys.stdout,
    )
    if not doc["copy"]:
        print(
            "  its scenes are links into the build, relative: a copy of the root made with "
            "`cp -a` dangles; copy it with `cp -rL`, or export with --copy",
            file=sys.stdout,
        )
    if not test:
        print(
            "blurset export: warning: test.txt is empty: the build holds out no setting "
            "(--test-objects holds out whole objects, none of one); rebuild with "
            "--test-settings N (the paper's 52) to evaluate on held-out settings",
            file=sys.stderr,
        )
