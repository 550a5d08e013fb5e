"""`blurset verify BUILD` (issue 14 D6, issue 19): is a build, or a noise output, whole?

For a build, every complete setting must hold every file its meta.json promises: per
level one image per view (in images/ and, at 1/f of the size, in each images_<f>/)
and a poses_bounds.npy with one row per view, linear/ EXRs
when the build kept them, transforms.json naming those images; every image must decode
whole at the setting's resolution (decoded in blurset-core, in parallel); dataset.json's
counts and settings must be what is on disk; splits.json must name only settings that
are there; and when MANIFEST.sha256 is present every file it lists must match it.

For a noise output (`blurset noise BUILD --out DIR`): every complete unit holds the
images and linear EXRs its noise.json lists (and their images_<f>/, linear_<f>/
copies), decoding at their resolution, and a
poses_bounds.npy with one row per image; noise_dataset.json's counts match; and the
manifest, as above. An output whose run has not finished (its record still the start's,
or a unit half written: killed, or running) is one problem: nothing vouches for it. For
`blurset noise SCENE --out DIR`: the same of every gain noise_scene.json names, in the
folders of the factor read.

One line per problem, naming the file; exit 1 on damage, 0 when whole. Settings still
being built (`*.partial`, no marker) and files added after the manifest are notes,
not damage.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from blurset import _core, layout
from blurset.exceptions import InputError, reason_of
from blurset.services import outputs, publish

NOISE_DATASET = layout.NOISE_DATASET
# The files of a noise.json entry and the folder of each at a factor.
KINDS = {"image": layout.images_dir, "linear": layout.linear_dir}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "path",
        type=Path,
        help="a build directory, a `blurset noise` output (of a build or a scene), or a "
        "`blurset export --for hub` output",
    )
    p.add_argument(
        "--no-decode",
        action="store_true",
        help="check files, sizes from headers and counts, without decoding every image",
    )
    p.add_argument("--quiet", action="store_true", help="print problems and the verdict only")


@dataclass
class Report:
    """What verify found. `problems` are damage, `notes` are not."""

    root: Path
    problems: list[tuple[str, str]] = field(default_factory=list)
    notes: list[tuple[str, str]] = field(default_factory=list)
    settings: int = 0
    # "settings" of a build, "units" (gains of a level of a setting) of a noise output.
    unit: str = "settings"
    images: int = 0
    manifest_files: int | None = None
    # Files that should not be there at all, and where in `problems` that is said: their
    # one problem (_one_per_file).
    strays: dict[str, int] = field(default_factory=dict)

    def bad(self, rel: str | Path, what: str) -> None:
        self.problems.append((str(rel), what))

    def stray(self, rel: str | Path, what: str) -> None:
        self.strays[str(rel)] = len(self.problems)
        self.bad(rel, what)

    def note(self, rel: str | Path, what: str) -> None:
        self.notes.append((str(rel), what))


def _read_json(root: Path, rel: str, report: Report) -> Any:
    """A record read through the core's shapes (blurset.services.outputs.read_record), or None
    with the problem reported; transforms.json has no record shape and is read as JSON."""
    p = root / rel
    if not p.is_file():
        report.bad(rel, "missing")
        return None
    try:
        if p.name == layout.TRANSFORMS:
            return json.loads(p.read_text())
        return outputs.read_record(p)
    except (OSError, ValueError, InputError) as e:
        report.bad(rel, reason_of(e)[:200])
    return None


def _rows(path: Path) -> int | str:
    """The number of pose rows of a poses_bounds.npy, or what is wrong with it."""
    try:
        return len(_core.read_poses_bounds(path))
    except FileNotFoundError:
        return "missing"
    except (OSError, ValueError) as e:
        return f"does not parse ({reason_of(e)})"


def _expect_files(
    root: Path, folder: Path, names: list[str], report: Report, what: str
) -> list[Path]:
    """The expected files of a folder that are there; one line for a missing folder,
    one per missing or unexpected file."""
    rel = folder.relative_to(root)
    if not folder.is_dir():
        report.bad(rel, f"{what} folder missing")
        return []
    present = {p.name for p in folder.iterdir() if not p.name.startswith(".")}
    for n in names:
        if n not in present:
            report.bad(rel / n, "missing")
    for n in sorted(present - set(names)):
        report.stray(rel / n, f"not a file of this {what} folder")
    return [folder / n for n in names if n in present]


# -- one setting --------------------------------------------------------------------------


def setting_problems(
    setting: Path, *, root: Path | None = None
) -> tuple[list[tuple[str, str]], list[tuple[Path, int, int]]]:
    """The problems of one complete setting's files (no pixels decoded) and the images
    (path, width, height) to decode. The cheap check is the rerun's own
    (blurset.layout.setting_problems, from the core); on top, verify names each missing
    or unexpected file, counts pose rows and checks transforms.json's file paths."""
    root = root or setting.parent
    rep = Report(root)
    name = setting.relative_to(root)
    cheap = layout.setting_problems(setting)
    for rel, kind, what in cheap:
        # A wrong count of images is named file by file below.
        if kind != "count":
            rep.bad(name / rel, what)
    flagged = {rel for rel, _, _ in cheap}
    if layout.META in flagged:
        return rep.problems, []
    meta = _read_json(root, f"{name}/meta.json", rep)
    try:
        views = meta["views"]
        levels = list(meta["levels"])
        w, h = (int(x) for x in meta["resolution"])
        indices = [int(v["index"]) for v in views]
    except (KeyError, TypeError, ValueError):
        rep.bad(f"{name}/meta.json", "lacks views, levels or resolution")
        return rep.problems, []
    n = len(indices)
    render = meta.get("render") if isinstance(meta.get("render"), dict) else {}
    factors = meta.get("downsample") or []
    images = [layout.image_name(i, n) for i in indices]
    exrs = [layout.linear_name(i) for i in images]
    to_decode: list[tuple[Path, int, int]] = []
    for level in levels:
        if level in flagged:  # the level folder is missing
            continue
        # images/ at full size, images_<f>/ at 1/f (the core checked f divides the size).
        subs = [(layout.IMAGES, images, w, h)] + [
            (layout.images_dir(f), images, w // int(f), h // int(f)) for f in factors
        ]
        if render.get("linear"):
            subs.append((layout.LINEAR, exrs, w, h))
        # --passes: depth/, normals/, masks/ and their _<f> sizes, named as the images, in
        # the sharp level; a blur level's own masks in it (layout.pass_level).
        for kind in render.get("passes") or []:
            if layout.pass_level(kind, level, layout.level_masks(meta)) != level:
                continue
            names = [layout.pass_file(kind, i) for i in images]
            for f in [1, *factors]:
                subs.append((layout.pass_dir(kind, int(f)), names, w // int(f), h // int(f)))
        to_decode += _level_problems(root, setting / level, subs, n, flagged, rep)
    if layout.TRANSFORMS in flagged:
        return _one_per_file(rep), to_decode
    _transforms_problems(
        root, name, rep, n, [f"{lvl}/images/{i}" for lvl in levels for i in images]
    )
    return _one_per_file(rep), to_decode


def _level_problems(
    root: Path, d: Path, subs: list, n: int, flagged: set[str], rep: Report
) -> list[tuple[Path, int, int]]:
    """A level's image folders (`subs`: folder, file names, width, height) file by file
    and its pose rows; the images to decode."""
    level = d.name
    to_decode: list[tuple[Path, int, int]] = []
    for sub, names, sw, sh in subs:
        for p in _expect_files(root, d / sub, names, rep, sub):
            if f"{level}/{sub}/{p.name}" not in flagged:
                to_decode.append((p, sw, sh))
    if f"{level}/poses_bounds.npy" not in flagged:
        rows = _rows(d / layout.POSES_BOUNDS)
        if isinstance(rows, str):
            rep.bad((d / layout.POSES_BOUNDS).relative_to(root), rows)
        elif rows != n:
            rep.bad((d / layout.POSES_BOUNDS).relative_to(root), f"{rows} rows, expected {n}")
    return to_decode


def _transforms_problems(root: Path, name: Path, rep: Report, n: int, want: list[str]) -> None:
    """transforms.json has one frame per view, naming this setting's images."""
    tf = _read_json(root, f"{name}/transforms.json", rep)
    if tf is None:
        return
    frames = tf.get("frames") if isinstance(tf, dict) else None
    if not isinstance(frames, list) or len(frames) != n:
        got = len(frames) if isinstance(frames, list) else "no"
        rep.bad(f"{name}/transforms.json", f"{got} frames, expected {n}")
        return
    named = {p for f in frames if isinstance(f, dict) for p in (f.get("file_paths") or {}).values()}
    if named != set(want):
        rep.bad(f"{name}/transforms.json", "its file_paths are not this setting's images")


def _one_per_file(rep: Report) -> list[tuple[str, str]]:
    """One problem per file: a file that should not be there at all says so, instead of
    what the cheap check found wrong with it."""
    return [
        (rel, what) for i, (rel, what) in enumerate(rep.problems) if rep.strays.get(rel, i) == i
    ]


def _decode(items: list[tuple[Path, int, int]], root: Path, report: Report, decode: bool) -> None:
    if decode:
        results = _core.check_images([(str(p), w, h) for p, w, h in items])
    else:
        results = [_header(p, w, h) for p, w, h in items]
    for (p, _, _), problem in zip(items, results, strict=True):
        if problem:
            report.bad(p.relative_to(root), problem)
    report.images += len(items)


def _header(p: Path, w: int, h: int) -> str | None:
    """Without decoding: a PNG's signature and end chunk (the cheap check's rule,
    blurset.layout.png_problem) and the size its header states; an EXR is not empty."""
    if p.suffix.lower() == ".exr":
        return None if p.stat().st_size > 0 else "empty"
    if p.suffix.lower() == ".png" and (problem := layout.png_problem(p)):
        return problem
    try:
        iw, ih, _, _ = _core.image_info(p)
    except (OSError, ValueError) as e:
        return f"does not decode ({reason_of(e)})"
    return None if (iw, ih) == (w, h) else f"is {iw}x{ih}, expected {w}x{h}"


# -- a build ----------------------------------------------------------------------------


def verify_build(root: Path, *, decode: bool = True) -> Report:
    rep = Report(root)
    dataset = _read_json(root, layout.DATASET, rep)
    dataset = dataset if isinstance(dataset, dict) else {}
    complete = layout.complete_settings(root)
    for d in sorted(root.iterdir()):
        if d.is_dir() and not d.name.startswith(".") and d not in complete:
            if (d / layout.META).exists() or d.name.endswith(layout.PARTIAL_SUFFIX):
                rep.note(d.name, "incomplete setting (a rerun of the build finishes it)")
    n_images = 0
    uids: set[str] = set()
    todo: list[tuple[Path, int, int]] = []
    # One source file, one set of settings: two ids made from one file is a build that
    # kept a setting its source file no longer has.
    made_from: dict[str, set[str]] = {}
    for s in complete:
        problems, images = setting_problems(s, root=root)
        rep.problems.extend(problems)
        todo.extend(images)
        try:
            meta = outputs.read_record(s / layout.META)
        except (OSError, InputError):
            continue  # named by setting_problems
        n_images += len(meta["views"]) * len(meta["levels"])
        uids.add(str(meta["uid"]))
        source = (meta.get("object") or {}).get("path")
        if source:
            made_from.setdefault(source, set()).add(str(meta["uid"]))
    _one_source_one_id(rep, made_from)
    rep.settings = len(complete)
    _decode(todo, root, rep, decode)
    _check_dataset(rep, dataset, complete, n_images, uids)
    _check_splits(root, rep, complete)
    finished = not outputs.build_state(root).provisional
    _check_manifest(root, rep, finished=finished)
    return rep


def _one_source_one_id(rep: Report, made_from: dict[str, set[str]]) -> None:
    """One source file, one set of settings: two ids made from one file is a build that
    kept a setting its source file no longer has."""
    for source, ids in sorted(made_from.items()):
        if len(ids) > 1:
            rep.bad(
                source,
                f"one source file made the settings of {len(ids)} ids ({', '.join(sorted(ids))}): "
                "a rerun of the build removes the stale ones",
            )


def _check_dataset(
    rep: Report, dataset: dict, complete: list[Path], n_images: int, uids: set[str]
) -> None:
    """dataset.json's counts and settings against what is on disk (not for a build that
    has not finished)."""
    if dataset.get("provisional"):
        rep.note(layout.DATASET, "provisional: the build has not finished (counts not compared)")
        return
    if not dataset:
        return
    counts = dataset.get("counts")
    if not isinstance(counts, dict):
        counts = {}
    on_disk = {"settings": len(complete), "images": n_images, "objects": len(uids)}
    for key, have in on_disk.items():
        if counts.get(key) != have:
            rep.bad(layout.DATASET, f"counts.{key} is {counts.get(key)}, {have} on disk")
    listed = dataset.get("settings")
    names = [s.name for s in complete]
    if isinstance(listed, list) and sorted(map(str, listed)) != names:
        gone = sorted(set(map(str, listed)) - set(names))
        new = sorted(set(names) - set(map(str, listed)))
        what = "; ".join(
            x
            for x in (
                f"lists {', '.join(gone[:5])} not on disk" if gone else "",
                f"does not list {', '.join(new[:5])}" if new else "",
            )
            if x
        )
        rep.bad(layout.DATASET, f"settings: {what}")


def _check_splits(root: Path, rep: Report, complete: list[Path]) -> None:
    """splits.json names only settings that are on disk."""
    splits = _read_json(root, layout.SPLITS, rep)
    if isinstance(splits, dict):
        settings_on_disk = {s.name for s in complete}
        for part in ("train", "test"):
            missing = [s for s in splits.get(part) or [] if s not in settings_on_disk]
            if missing:
                rep.bad(
                    layout.SPLITS, f"{part} names settings not on disk: {', '.join(missing[:5])}"
                )


# -- a noise output ---------------------------------------------------------------------


def verify_noise(root: Path, *, decode: bool = True) -> Report:
    rep = Report(root, unit="units")
    doc = _read_json(root, NOISE_DATASET, rep)
    doc = doc if isinstance(doc, dict) else {}
    units = sorted(u for u in root.glob("*/*/gain_*") if u.is_dir())
    complete = [u for u in units if layout.is_complete(u)]
    for u in units:
        if u not in complete:
            rep.note(
                u.relative_to(root), "incomplete unit (a rerun of the noise build finishes it)"
            )
    todo: list[tuple[Path, int, int]] = []
    n_images = 0
    settings: set[str] = set()
    for u in complete:
        n = _noise_unit(root, u, rep, todo)
        if n is not None:
            settings.add(u.relative_to(root).parts[0])
            n_images += n
    rep.settings = len(complete)
    _decode(todo, root, rep, decode)
    counts = doc.get("counts") if isinstance(doc.get("counts"), dict) else None
    if counts is not None:
        on_disk = {"units": len(complete), "images": n_images, "settings": len(settings)}
        for key, have in on_disk.items():
            if counts.get(key) != have:
                rep.bad(NOISE_DATASET, f"counts.{key} is {counts.get(key)}, {have} on disk")
    finished = counts is not None and not any(u.name.endswith(".partial") for u in units)
    if not finished and doc:
        # Its record is still the start's, or a unit is half written: a run was killed
        # (or is running), and nothing says which units it was yet to write.
        rep.bad(NOISE_DATASET, "the run has not finished: rerun the noise command, then verify")
    _check_manifest(root, rep, finished=finished)
    return rep


def _noise_unit(root: Path, u: Path, rep: Report, todo: list[tuple[Path, int, int]]) -> int | None:
    """One gain folder of a noise output: the images and linear EXRs its noise.json lists,
    in the folders of its factor and downsample, queued to decode at their size, and a
    pose row per image; the number of images, None when noise.json cannot say."""
    rel = u.relative_to(root)
    meta = _read_json(root, f"{rel}/{layout.NOISE}", rep)
    try:
        files = meta["files"]
        w, h = (int(x) for x in meta["source"]["resolution"])
        factor = int(meta["source"].get("factor", 1))
        names = [[str(f[k]).rsplit("/", 1)[-1] for f in files if f.get(k)] for k in KINDS]
    except (KeyError, TypeError, ValueError, AttributeError):
        if meta is not None:
            rep.bad(f"{rel}/{layout.NOISE}", "lacks files or source.resolution")
        return None
    for f in [1, *map(int, meta.get("downsample") or [])]:
        for folder, base in zip(KINDS.values(), names, strict=True):
            sub = folder(factor * f)
            for p in _expect_files(root, u / sub, base, rep, sub) if base else []:
                todo.append((p, w // f, h // f))
    rows = _rows(u / layout.POSES_BOUNDS)
    if isinstance(rows, str):
        rep.bad(rel / layout.POSES_BOUNDS, rows)
    elif rows != len(files):
        rep.bad(rel / layout.POSES_BOUNDS, f"{rows} rows, expected {len(files)}")
    return len(files)


def verify_noise_scene(root: Path, *, decode: bool = True) -> Report:
    """A `blurset noise SCENE` output: every gain its noise_scene.json names, checked as a
    build's noise unit (it has no manifest: each gain moves in whole, the record last)."""
    rep = Report(root, unit="gains")
    todo: list[tuple[Path, int, int]] = []
    for g in map(str, (_read_json(root, layout.NOISE_SCENE, rep) or {}).get("gains") or []):
        if not (root / g).is_dir():
            rep.bad(g, "gain folder missing")
        elif _noise_unit(root, root / g, rep, todo) is not None:
            rep.settings += 1
    _decode(todo, root, rep, decode)
    return rep


def _check_manifest(root: Path, rep: Report, *, finished: bool) -> None:
    if not (root / publish.MANIFEST).is_file():
        if finished:
            # A finished run always writes it last: without it nothing vouches for the
            # bytes (two images swapped would pass every other check).
            rep.bad(publish.MANIFEST, "missing (every finished run writes it)")
        else:
            rep.note(publish.MANIFEST, "absent: the run has not finished")
        return
    try:
        found = publish.check_manifest(root)
    except (OSError, ValueError) as e:
        rep.bad(publish.MANIFEST, reason_of(e))
        return
    rep.manifest_files = len(publish.manifest_files(root))
    for rel, kind, what in found:
        if kind == "unlisted":
            rep.note(rel, f"{what} (added after it was written)")
        else:
            rep.bad(rel, f"{what} (MANIFEST.sha256)")


# -- a hub export (`blurset export --for hub`) ----------------------------------------------


def _image_problem(cell: Any, w: int, h: int, decode: bool) -> str | None:
    """What is wrong with an image cell ({bytes, path}) of a shard: no bytes, not a PNG,
    a size other than the row's, or (with `decode`) pixels that do not decode."""
    import io

    from PIL import Image, UnidentifiedImageError

    data = (cell or {}).get("bytes") if isinstance(cell, dict) else None
    if not data:
        return "no image bytes"
    try:
        with Image.open(io.BytesIO(data)) as im:
            if im.size != (w, h):
                return f"is {im.size[0]}x{im.size[1]}, expected {w}x{h}"
            if decode:
                im.load()
    except (OSError, UnidentifiedImageError, ValueError, SyntaxError) as e:
        return f"does not decode ({reason_of(e)})"
    return None


def verify_hub(root: Path, *, decode: bool = True) -> Report:
    """A `blurset export --for hub` output: every shard export.json lists is there with
    its size and sha256, holds its rows and settings (a setting's rows one row group, one
    per view), every image of every row decodes at the row's size (`image_<f>` at 1/f),
    no other file lies under data/, every config holds the same settings and views, and
    the counts match the build's dataset.json when the build lies beside the export."""
    from blurset.services import hub_format

    rep = Report(root, unit="shards")
    doc = hub_format.hub_doc(root) or {}
    record = outputs.OutputKind.EXPORT.record
    if doc.get("shards") is None:
        rep.bad(record, "the export has not finished (a run was stopped): rerun it")
        return rep
    _, pq = hub_format.pyarrow()
    listed = {f"{hub_format.DATA_DIR}/{n}" for n in doc["shards"]}
    data = root / hub_format.DATA_DIR
    for p in sorted(data.rglob("*")) if data.is_dir() else []:
        rel = p.relative_to(root).as_posix()
        if p.is_file() and rel not in listed and not p.name.startswith("."):
            rep.stray(rel, f"not a shard {record} lists")
    # Per config: setting -> views.
    views: dict[str, dict[str, int]] = {}
    for name, rec in sorted(doc["shards"].items()):
        rel = f"{hub_format.DATA_DIR}/{name}"
        p = root / rel
        if not p.is_file():
            rep.bad(rel, "missing")
            continue
        if p.stat().st_size != rec["bytes"]:
            rep.bad(rel, f"{p.stat().st_size} bytes, {record} says {rec['bytes']}")
            continue
        if _core.sha256_file(p) != rec["sha256"]:
            rep.bad(rel, f"sha256 differs from {record}'s")
            continue
        try:
            pf = pq.ParquetFile(p)
        except (OSError, ValueError) as e:
            rep.bad(rel, f"does not read as Parquet ({reason_of(e)})")
            continue
        rep.settings += 1
        if pf.metadata.num_rows != rec["rows"]:
            rep.bad(rel, f"{pf.metadata.num_rows} rows, {record} says {rec['rows']}")
        kinds = _hub_kinds(pf.schema_arrow)
        settings = []
        for g in range(pf.num_row_groups):
            cells = pf.read_row_group(g).to_pylist()
            names = sorted({str(r["setting"]) for r in cells})
            settings += names
            if len(names) != 1 or [r["view"] for r in cells] != list(range(len(cells))):
                rep.bad(rel, f"row group {g} is not one setting's views in order")
                continue
            views.setdefault(rec["config"], {})[names[0]] = len(cells)
            _hub_cells(rel, cells, kinds, decode, rep)
        if settings != rec["settings"]:
            rep.bad(rel, f"holds the settings {', '.join(settings[:3])}…, {record} lists others")
    _hub_counts(root, doc, views, rep)
    return rep


def _hub_kinds(schema: Any) -> dict[str, str]:
    """How each column of a shard is read: `image` (an Image cell, PNG bytes), `exr`
    (a pass's EXR bytes), `json` (meta.json's and noise.json's records), `value`."""
    import pyarrow as pa

    kinds = {}
    for f in schema:
        if pa.types.is_struct(f.type):
            kinds[f.name] = "image"
        elif pa.types.is_binary(f.type):
            kinds[f.name] = "exr"
        elif f.name in ("meta", "noise"):
            kinds[f.name] = "json"
        else:
            kinds[f.name] = "value"
    return kinds


def _hub_cells(
    rel: str, rows: list[dict], kinds: dict[str, str], decode: bool, rep: Report
) -> None:
    """Every cell of one setting's rows, read as a loader reads it: an image decodes at
    the row's size (1/f of it for `_<f>` columns), an EXR pass decodes (in blurset-core,
    at its size), a record parses as JSON, and every number is finite."""
    import tempfile

    from blurset.services import hub_format

    with tempfile.TemporaryDirectory(prefix="blurset-verify-") as tmp:
        exrs: list[tuple[str, Path, int, int]] = []
        for r in rows:
            where = f"{rel}: {r['setting']} view {r['view']}"
            for c, kind in kinds.items():
                x = r[c]
                f = hub_format.column_factor(c)
                w, h = r["width"] // f, r["height"] // f
                problem = None
                if kind == "image":
                    problem = _image_problem(x, w, h, decode)
                    rep.images += 1
                elif kind == "exr" and not x:
                    problem = "no EXR bytes"
                elif kind == "exr":
                    p = Path(tmp) / f"{len(exrs)}.exr"
                    p.write_bytes(x)
                    exrs.append((f"{where} {c}", p, w, h))
                elif kind == "json":
                    problem = _json_problem(x)
                elif _not_finite(x):
                    problem = f"not a finite number ({x})"
                if problem:
                    rep.bad(f"{where} {c}", problem)
        found = _core.check_images([(str(p), w, h) for _, p, w, h in exrs]) if decode else []
        for (name, *_), problem in zip(exrs, found, strict=False):
            if problem:
                rep.bad(name, problem)
        rep.images += len(exrs)


def _json_problem(text: Any) -> str | None:
    """What is wrong with a record cell: not a JSON object, or a number not finite."""

    def refuse(word: str) -> Any:
        raise ValueError(f"{word} is not a number JSON allows")

    if not isinstance(text, str):
        return "no record"
    try:
        value = json.loads(text, parse_constant=refuse)
    except ValueError as e:
        return f"does not parse as JSON ({reason_of(e)})"
    if not isinstance(value, dict):
        return "is not a JSON object"
    return "holds a number that is not finite" if _not_finite(value) else None


def _not_finite(x: Any) -> bool:
    """Whether a cell's value (a number, a list of them, a parsed record) holds a NaN or
    an infinity."""
    import math

    if isinstance(x, float):
        return not math.isfinite(x)
    if isinstance(x, list):
        return any(_not_finite(v) for v in x)
    if isinstance(x, dict):
        return any(_not_finite(v) for v in x.values())
    return False


def _hub_counts(root: Path, doc: dict, views: dict[str, dict[str, int]], rep: Report) -> None:
    """Every config holds the same settings and views; with the build beside the export,
    its dataset.json counts (settings, and images per level) are what the shards hold."""
    record = outputs.OutputKind.EXPORT.record
    configs = sorted(views)
    for c in configs[1:]:
        if views[c] != views[configs[0]]:
            rep.bad(record, f"the configs {configs[0]} and {c} hold other settings or views")
    build = root.parent / str(doc.get("build"))
    if not configs or outputs.kind_of(build) is not outputs.OutputKind.BUILD:
        rep.note(record, "the build is not beside the export: counts not compared")
        return
    counts = (outputs.read_record(build / layout.DATASET).get("counts")) or {}
    dataset = outputs.read_record(build / layout.DATASET)
    levels = dataset.get("levels") or [layout.SHARP]
    per_level = views[configs[0]]
    if counts.get("settings") != len(per_level):
        rep.bad(
            record,
            f"{len(per_level)} settings, the build's dataset.json counts {counts.get('settings')}",
        )
    rows = sum(per_level.values())
    if counts.get("images") != rows * len(levels):
        rep.bad(
            record,
            f"{rows} images per level, the build's dataset.json counts {counts.get('images')} "
            f"in {len(levels)} levels",
        )


def verify(path: Path, *, decode: bool = True) -> Report:
    """Verify a build, a noise output or a hub export (by what it holds)."""
    root = Path(path)
    if not root.is_dir():
        raise InputError(f"no such build or noise output: {path}")
    kind = outputs.kind_of(root)
    if kind is outputs.OutputKind.NOISE:
        return verify_noise(root, decode=decode)
    if kind is outputs.OutputKind.NOISE_SCENE:
        return verify_noise_scene(root, decode=decode)
    if kind is outputs.OutputKind.BUILD:
        return verify_build(root, decode=decode)
    if kind is outputs.OutputKind.EXPORT:
        from blurset.services import hub_format

        if hub_format.hub_doc(root) is not None:
            return verify_hub(root, decode=decode)
        record = root / outputs.OutputKind.EXPORT.record
        if (outputs.read_record(record) or {}).get("state") == "replacing":
            raise InputError(
                f"an export that has not finished (a run was stopped while writing it): "
                f"rerun it, then verify: {path}"
            )
    raise InputError(
        f"not a blurset build (dataset.json), noise output ({NOISE_DATASET}) or "
        f"`export --for hub` output: {path}"
    )


def run(args: argparse.Namespace) -> int:
    rep = verify(args.path, decode=not args.no_decode)
    shown = str(args.path).rstrip("/")
    for rel, what in sorted(rep.problems):
        print(f"{shown}/{rel}: {what}")
    if not args.quiet:
        for rel, what in rep.notes:
            print(f"note: {shown}/{rel}: {what}", file=sys.stderr)
    checked = "checked from headers" if args.no_decode else "decoded"
    manifest = (
        f", {rep.manifest_files} files match MANIFEST.sha256"
        if rep.manifest_files is not None
        and not any(w.endswith("(MANIFEST.sha256)") for _, w in rep.problems)
        else ""
    )
    if rep.problems:
        print(
            f"blurset verify: {len(rep.problems)} problem(s) in {shown} "
            f"({rep.settings} complete {rep.unit}, {rep.images} images {checked})",
            file=sys.stderr,
        )
        return 1
    print(
        f"blurset verify: {shown} is whole: {rep.settings} complete {rep.unit}, "
        f"{rep.images} images {checked}{manifest}",
        file=sys.stderr,
    )
    return 0
