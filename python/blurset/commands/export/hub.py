"""`blurset export BUILD --for hub --out DIR` (issue 50): a build as Parquet shards that
`datasets.load_dataset` and the Hugging Face Hub's viewer read.

    DIR/export.json                                   what was exported (shards, rows, sha256)
    DIR/data/<config>/<split>-00000-of-00003.parquet  the shards

One config per level (`sharp`, `blur_1` …, `defocus_1` …) and, with `--noise`, per
noisy level and gain (`blur_4_gain_4`); splits `train` and `test` are the build's
settings splits (splits.json). One row per image: its PNG's bytes unchanged in the
`image` column (the `datasets` Image layout, struct {bytes, path}; `image_<f>` for each
`images_<f>/` size), the setting, the view, whether it is a held-out view, its camera
(the poses_bounds.npy row as written, the OpenGL camera-to-world, focal, near, far,
the mean latent pose where meta.json records one), meta.json's per-image record
(`meta`, as JSON, and its numbers as columns), and the build's passes (`depth`,
`normal` as EXR bytes, `mask` as an image).

A shard holds whole settings (one Parquet row group each), cut at `--shard-size` MB, so
a scene streams whole. Shards are planned from the files' sizes before any is written,
written one at a time through a temp name and a rename, with fixed compression and no
timestamps: the same build gives the same bytes. A shard's schema metadata carries the
key of what it was made from (the MANIFEST.sha256 lines of the folders its files lie in,
each file's size and time where the manifest is older, the options), and export.json
its size and sha256, recorded as each shard is finished (in its `replacing` state while
the run goes on). A rerun keeps a shard whose key is its plan's and whose bytes are the
ones recorded, and writes the rest, so its shards are those of an uninterrupted export;
it never hashes a shard it did not write into the record. The plan stats every file
once and holds no line per file; writing holds one setting's rows at a time, never a
whole shard. `blurset verify DIR` checks each shard against export.json (size, sha256,
rows, settings) and reads every cell (images and passes decoded, records parsed,
numbers finite).
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import shutil
import signal
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from blurset import __version__, _core, layout
from blurset.commands.export import rules as export_rules
from blurset.exceptions import ConfigError, InputError
from blurset.services import hub_format, outputs, publish, stop
from blurset.services.options import check_range

DEFAULT_SHARD_MB = 500.0
# Fixed write options: same rows, same bytes (PNG bytes do not compress: none there).
COMPRESSION = "zstd"
COMPRESSION_LEVEL = 3


def add_arguments(p) -> None:
    """`--shard-size`: only `--for hub` reads it."""
    p.add_argument(
        "--shard-size",
        type=float,
        metavar="MB",
        help=f"--for hub: the size a Parquet shard is cut at, in MB (default: "
        f"{DEFAULT_SHARD_MB:g}; a shard holds whole settings: one setting larger than this is "
        "a shard of its own)",
    )


# -- what is exported -------------------------------------------------------------------


@dataclass
class _Config:
    """One config: a level of the build, or a gain of a level of the noise output."""

    name: str
    level: str
    gain: str | None  # the gain folder (`gain_4`), or None
    root: Path  # the build or the noise output


@dataclass
class _Shard:
    """One planned shard: its name under data/, its config and split, its settings and
    the input files' sizes (the plan's estimate of its bytes)."""

    name: str
    config: _Config
    split: str
    settings: list[str]
    size: int = 0


@dataclass
class HubPlan:
    build: Path
    noise: Path | None
    dataset: dict
    splits: dict
    configs: list[_Config]
    factors: list[int]
    passes: list[str]
    held: str
    shards: list[_Shard] = field(default_factory=list)
    doc: dict = field(default_factory=dict)
    # (config, setting) -> the digest of the files its rows are made from.
    digests: dict[tuple[str, str], str] = field(default_factory=dict)


# A shard holds whole settings: past a terabyte a larger cut changes nothing but
# export.json's number, which must fit its record (u64 bytes).
MAX_SHARD_MB = 1e6


def _shard_bytes(args) -> int:
    mb = DEFAULT_SHARD_MB if args.shard_size is None else args.shard_size
    check_range("--shard-size", mb, 0, MAX_SHARD_MB, lo_open=True, integer=False)
    return max(1, int(mb * 1e6))


def _inputs(args) -> HubPlan:
    if args.copy:
        raise ConfigError("--copy: --for hub writes the images' bytes into its shards")
    build: Path = args.build.resolve()
    state = outputs.finished_build(build)
    dataset = outputs.read_record(build / layout.DATASET)
    splits = outputs.read_record(build / layout.SPLITS)
    if args.gains and args.noise is None:
        raise ConfigError("--gains needs --noise (a `blurset noise BUILD` output)")
    available = dataset.get("levels") or [layout.SHARP]
    levels = export_rules.levels(args.levels, available)
    configs = [_Config(hub_format.config_name(lvl), lvl, None, build) for lvl in levels]
    noise = args.noise.resolve() if args.noise else None
    if noise is not None:
        doc = outputs.noise_of_build(noise, build)
        if int((doc.get("params") or {}).get("frames", 1)) != 1:
            raise ConfigError(
                "--for hub: one row per view image; --noise holds several noisy frames per "
                "view (blurset noise --frames)"
            )
        gains = export_rules.gains(noise, doc, args.gains)
        for lvl in [lvl for lvl in levels if lvl in doc["levels"]]:
            configs += [_Config(hub_format.config_name(lvl, g), lvl, g, noise) for g in gains]
    passes = list(dataset["config"].get("passes") or [])
    if args.no_masks:
        passes = [p for p in passes if p != "mask"]
    hp = HubPlan(
        build=build,
        noise=noise,
        dataset=dataset,
        splits=splits,
        configs=configs,
        factors=[int(f) for f in dataset["config"].get("downsample") or []],
        passes=passes,
        held=splits.get("test_view_images") or "blurry",
    )
    hp.doc = {"complete": state.complete}
    return hp


@dataclass
class _RowSource:
    """The files one row is made from (paths as strings: a build has ~10^5 of them)."""

    view: int
    image: str
    sized: dict[int, str]
    passes: dict[str, str]  # by column (hub_format.pass_column)

    def files(self) -> list[str]:
        return [self.image, *self.sized.values(), *self.passes.values()]


def _row_sources(
    hp: HubPlan, cfg: _Config, setting: str, meta: dict | None = None
) -> list[_RowSource]:
    """The files of each row of a setting in `cfg` (`meta`: its meta.json, read here when
    the passes need it and it is not given)."""
    sdir = hp.build / setting
    n = len(_core.read_poses_bounds(sdir / cfg.level / layout.POSES_BOUNDS))
    names = [layout.image_name(i, n) for i in range(n)]
    src = _src(hp, cfg, setting)
    if cfg.gain is not None:
        if not layout.is_complete(src):
            raise InputError(f"--noise has no complete {cfg.gain} here: {src}")
        noise = layout.read_json(src / layout.NOISE, layout.NOISE)
        by_view = {f["view"]: Path(f["image"]).name for f in noise["files"] if f["frame"] == 0}
        try:
            names = [by_view[i] for i in range(n)]
        except KeyError:
            raise InputError(f"{len(by_view)} noisy images for {n} views: {src}") from None
    holders: dict[tuple[str, int], str] = {}
    if hp.passes:
        meta = meta if meta is not None else layout.read_json(sdir / layout.META, layout.META)
        own = layout.level_masks(meta)
        for kind in hp.passes:
            for f in [1, *hp.factors]:
                holder = sdir / layout.pass_level(kind, cfg.level, own) / layout.pass_dir(kind, f)
                holders[kind, f] = str(holder)
    dirs = {
        f: str(src / (layout.IMAGES if f == 1 else layout.images_dir(f))) for f in [1, *hp.factors]
    }
    rows = []
    for i, name in enumerate(names):
        passes = {}
        for kind in hp.passes:
            base = layout.pass_file(kind, layout.image_name(i, n))
            for f in [1, *hp.factors]:
                passes[hub_format.pass_column(kind, f)] = os.path.join(holders[kind, f], base)
        rows.append(
            _RowSource(
                view=i,
                image=os.path.join(dirs[1], name),
                sized={f: os.path.join(dirs[f], name) for f in hp.factors},
                passes=passes,
            )
        )
    return rows


def _setting_digest(
    hp: HubPlan, cfg: _Config, setting: str, manifests: dict[Path, _Manifest]
) -> tuple[int, str]:
    """The bytes of a setting's files in `cfg` (the plan's estimate of its rows) and the
    digest of what its rows are made from: the manifest's digest of each folder they lie
    in (the same build gives the same digest, wherever it lies), and each file's size
    and time where the manifest does not cover it or is older than it. Stats each file
    once; a missing one is named."""
    h = hashlib.sha256()
    size = 0
    src = _src(hp, cfg, setting)
    extra = [str(hp.build / setting / layout.META), str(src / layout.POSES_BOUNDS)]
    files = [p for r in _row_sources(hp, cfg, setting) for p in r.files()]
    folders: set[tuple[Path, str]] = set()
    for k, p in enumerate([*extra, *files]):
        root = cfg.root if p.startswith(str(cfg.root) + os.sep) else hp.build
        depth = 3 if root != hp.build else 2
        if root not in manifests:
            manifests[root] = _manifest(root, depth)
        try:
            st = os.stat(p)
        except FileNotFoundError:
            raise InputError(f"missing file of the scene to export: {p}") from None
        if k >= len(extra):
            size += st.st_size
        rel = p[len(str(root)) + 1 :].replace(os.sep, "/")
        m = manifests[root]
        bucket = m.bucket(rel, depth)
        if bucket is None or st.st_mtime_ns > m.written_ns:
            h.update(f"{rel}\0{st.st_size}:{st.st_mtime_ns}\n".encode())
        if bucket is not None:
            folders.add((root, "/".join(rel.split("/")[:depth])))
    for root, folder in sorted(folders):
        h.update(f"{folder}\0{manifests[root].buckets[folder]}\n".encode())
    return size, h.hexdigest()


def plan(args) -> HubPlan:
    """The shards of the export, each with its settings, and export.json without the
    shards' sizes and hashes (known once written)."""
    target = _shard_bytes(args)
    hp = _inputs(args)
    complete: list[str] = hp.doc.pop("complete")
    test = set(hp.splits["test"])
    # (finished_build refused a damaged setting: the rerun's own cheap check.)
    manifests: dict[Path, _Manifest] = {}
    by_split = {
        "train": [s for s in complete if s not in test],
        "test": [s for s in complete if s in test],
    }
    for cfg in hp.configs:
        for split, settings in by_split.items():
            cut: list[list[str]] = []
            sizes: list[int] = []
            for s in settings:
                size, hp.digests[cfg.name, s] = _setting_digest(hp, cfg, s, manifests)
                if cut and sizes[-1] + size <= target:
                    cut[-1].append(s)
                    sizes[-1] += size
                else:
                    cut.append([s])
                    sizes.append(size)
            for k, (ss, size) in enumerate(zip(cut, sizes, strict=True)):
                name = f"{cfg.name}/{split}-{k:05d}-of-{len(cut):05d}.parquet"
                hp.shards.append(_Shard(name, cfg, split, ss, size))
    if not hp.shards:
        raise InputError(f"nothing to export (no complete setting): {args.build}")
    hp.doc = {
        "kind": "blurset export",
        "blurset_version": __version__,
        "for": hub_format.TARGET,
        "build": hp.build.name,
        "noise": hp.noise.name if hp.noise else None,
        "levels": sorted({c.level for c in hp.configs}, key=[c.level for c in hp.configs].index),
        "gains": sorted({c.gain for c in hp.configs if c.gain}),
        "copy": False,
        "llffhold": hp.splits["view_stride"],
        "factors": hp.factors,
        "test_view_images": hp.held,
        "scenes_dir": hub_format.DATA_DIR,
        # Every shard the export writes, by its config: the entries it owns.
        "scenes": {s.name: s.config.name for s in hp.shards},
        "train": [s.name for s in hp.shards if s.split == "train"],
        "test": [s.name for s in hp.shards if s.split == "test"],
        "shard_bytes": target,
    }
    if hp.passes:
        hp.doc["passes"] = hp.passes
    return hp


# -- rows --------------------------------------------------------------------------------


def _float_or_none(x: Any) -> float | None:
    return float(x) if isinstance(x, int | float) and not isinstance(x, bool) else None


def _int_or_none(x: Any) -> int | None:
    return int(x) if isinstance(x, int | float) and not isinstance(x, bool) else None


def _c2w_opengl(row: np.ndarray) -> list[list[float]]:
    """An LLFF pose row's camera-to-world in OpenGL axes (blurset.data._cameras)."""
    m = row[:15].reshape(3, 5)
    down, right, back, t = m[:, 0], m[:, 1], m[:, 2], m[:, 3]
    gl = np.eye(4)
    gl[:3, 0], gl[:3, 1], gl[:3, 2], gl[:3, 3] = right, -down, back, t
    return gl.tolist()


def _view_record(meta: dict, view: int, level: str) -> dict:
    """meta.json's records of one view at one level: the level's (`views[].levels[l]`),
    its rendered image's (`views[].images[level]`) and another kind's (a defocus level's
    lens: `views[].defocus[l]`), under the key of its kind (`level` for a blur level)."""
    v = meta["views"][view]
    rec: dict[str, Any] = {}
    if (at := layout.level_record(level)) is not None:
        kind, key = at
        rec["level" if kind == "levels" else kind] = (v.get(kind) or {}).get(key)
    if isinstance(im := (v.get("images") or {}).get(level), dict):
        rec["image"] = im
    return {k: x for k, x in rec.items() if x is not None}


def _kind_fields(meta: dict, view: int, level: str, rec: dict) -> dict[str, Any]:
    """The columns another kind's record gives a row (`rec`: _view_record's): a moving
    camera's latent frames (None under motion blur: one render along keys), its image's
    samples (each render's, times its renders), amplitude and path; and whether the level
    is a camera moving about its written pose (its mean pose, for a held-out view that
    holds the sharp image too)."""
    krec: dict[str, Any] = next((x for k, x in rec.items() if k not in ("level", "image")), {})
    renders = len(krec.get("seeds") or [])
    spf = _int_or_none(krec.get("samples_per_frame"))
    mine = _view_record(meta, view, level)
    own: dict[str, Any] = next((x for k, x in mine.items() if k != "image"), {})
    samples = spf * renders if spf is not None and renders else None
    if krec and spf is None:
        # A render without samples of its own takes the sharp image's (plan/renders.rs
        # with_samples): a defocus image is one render, a rolling shutter image's bands
        # tile it, so each of its pixels has the sharp image's samples.
        samples = _int_or_none((meta.get("render") or {}).get("sharp_samples"))
    return {
        "latents": renders if krec.get("method") == "average" else None,
        "samples": samples,
        "amplitude_px": _float_or_none(krec.get("amplitude_px")),
        "path_px": _float_or_none(krec.get("path_px")),
        "about_written": bool(own.get("poses")) and layout.written_pose(level),
    }


def _samples(im: dict, lv: dict, kind: dict, sharp_render: dict) -> int | None:
    """An image's samples: its record's (a targeted render), its blur level's (per frame
    times its latent frames), another kind's (_kind_fields), or the sharp render's
    (`sharp_render`: meta.json's `render`, empty for a degraded image of its own)."""
    if im.get("samples") is not None:
        return im["samples"]
    if lv:
        spf = _int_or_none(lv.get("samples_per_frame"))
        return spf * int(lv.get("latents", 1)) if spf is not None else None
    if kind["samples"] is not None:
        return kind["samples"]
    return _int_or_none(sharp_render.get("sharp_samples"))


def _view_cells(
    rec: dict, lv: dict, im: dict, kind: dict, row: np.ndarray, mean: Any, samples: int | None
) -> dict[str, Any]:
    """The columns of a view's row that its pose row and its record give (`rec`, `lv`,
    `im`, `kind`: as _setting_rows reads them for the view)."""
    coc = (rec.get("defocus") or {}).get("coc_px")
    return {
        "focal": float(row[14]),
        "near": float(row[15]),
        "far": float(row[16]),
        "poses_bounds": row.tolist(),
        "c2w": _c2w_opengl(row),
        "mean_c2w": mean,
        "w_l": _float_or_none(lv.get("w_l")),
        "motion_px": _float_or_none(lv.get("motion_px")),
        "latents": _int_or_none(lv.get("latents")) if lv else kind["latents"],
        "samples": samples,
        "amplitude_px": kind["amplitude_px"],
        "path_px": kind["path_px"],
        "render_psnr_db": _float_or_none(im.get("render_psnr_db")),
        "coc_px": [float(c) for c in coc] if isinstance(coc, list) else None,
        "meta": json.dumps(rec, sort_keys=True),
    }


def _setting_rows(hp: HubPlan, cfg: _Config, setting: str, split: str) -> dict[str, list]:
    """The columns of one setting's rows of one config."""
    sdir = hp.build / setting
    meta = layout.read_json(sdir / layout.META, layout.META)
    src = _src(hp, cfg, setting)
    rows = np.asarray(_core.read_poses_bounds(src / layout.POSES_BOUNDS), np.float64)
    sources = _row_sources(hp, cfg, setting, meta)
    if len(rows) != len(sources):
        raise InputError(f"{len(rows)} pose rows for {len(sources)} views: {src}")
    noise = layout.read_json(src / layout.NOISE, layout.NOISE) if cfg.gain else None
    held = {int(v) for v in (hp.splits.get("test_views") or {}).get(setting, [])}
    render = meta.get("render") or {}
    w, h = (int(x) for x in meta["resolution"])
    # The mean latent poses as open_scene(pose="mean") reads them (held-out views that
    # hold the sharp copy keep its pose); None before meta.json recorded them.
    means = None if layout.written_pose(cfg.level) else layout.mean_poses(sdir, cfg.level)
    degraded = cfg.level != layout.SHARP
    # Held-out views of a degraded level hold the sharp image (unless the build rendered
    # them blurry): their records are the sharp image's.
    clean_held = degraded and hp.held in ("sharp", "clean")
    cols: dict[str, list] = {
        n: [] for n, _ in hub_format.columns(hp.factors, hp.passes, bool(cfg.gain))
    }

    roots = [str(cfg.root) + os.sep, str(hp.build) + os.sep]

    def image(p: str) -> dict:
        # The path relative to the output holding the file (a noisy image's to the noise
        # output, a pass's to the build).
        root = roots[0] if p.startswith(roots[0]) else roots[1]
        with open(p, "rb") as f:
            data = f.read()
        return {"bytes": data, "path": p[len(root) :].replace(os.sep, "/")}

    for r in sources:
        v = r.view
        is_held = v in held
        own = not (clean_held and is_held)
        rec = _view_record(meta, v, cfg.level if own else layout.SHARP)
        lv = rec.get("level") or {}
        im = rec.get("image") or {}
        mean = means[v] if means is not None else None
        kind = _kind_fields(meta, v, cfg.level, rec)
        if kind["about_written"]:
            mean = _c2w_opengl(rows[v])
        samples = _samples(im, lv, kind, render if not degraded or not own else {})
        cols["image"].append(image(r.image))
        for f, p in r.sized.items():
            cols[f"image_{f}"].append(image(p))
        cols["setting"].append(setting)
        cols["uid"].append(str(meta.get("uid", setting)))
        cols["theta0_deg"].append(_float_or_none(meta.get("theta0_deg")))
        cols["level"].append(cfg.level)
        cols["gain"].append(float(noise["gain"]) if noise else None)
        cols["view"].append(v)
        cols["split"].append(split)
        cols["held_out"].append(is_held)
        cols["width"].append(w)
        cols["height"].append(h)
        for name, value in _view_cells(rec, lv, im, kind, rows[v], mean, samples).items():
            cols[name].append(value)
        if noise is not None:
            cols["sigma_read"].append(_float_or_none(noise.get("sigma_read")))
            cols["sigma_shot"].append(_float_or_none(noise.get("sigma_shot")))
            cols["noise"].append(json.dumps(noise, sort_keys=True))
        for col, p in r.passes.items():
            cols[col].append(image(p) if col.startswith("mask") else Path(p).read_bytes())
    return cols


# -- the shard's key and its writing ------------------------------------------------------


@dataclass
class _Manifest:
    """An output's MANIFEST.sha256, folded into one digest per folder of `depth` path
    components (`<setting>/<level>` of a build, `<setting>/<level>/<gain>` of a noise
    output; a file at that depth, meta.json, is its own): the key of a setting's rows
    without holding a line per file (a build lists ~10^5), and when it was written: a
    file changed since then is keyed by its size and time as well."""

    buckets: dict[str, str]
    written_ns: int

    def bucket(self, rel: str, depth: int) -> str | None:
        return self.buckets.get("/".join(rel.split("/")[:depth]))


def _manifest(root: Path, depth: int) -> _Manifest:
    p = root / publish.MANIFEST
    hashes: dict[str, Any] = {}
    if p.is_file():
        with open(p, encoding="utf-8") as f:
            for line in f:
                digest, _, rel = line.rstrip("\n").partition("  ")
                if rel:
                    key = "/".join(rel.split("/")[:depth])
                    if key not in hashes:
                        hashes[key] = hashlib.sha256()
                    hashes[key].update(f"{rel}\0{digest}\n".encode())
    return _Manifest(
        {k: h.hexdigest() for k, h in hashes.items()}, p.stat().st_mtime_ns if p.is_file() else 0
    )


def shard_key(hp: HubPlan, shard: _Shard) -> str:
    """What a shard is made from: its name, the options that shape its rows, and the
    digest of each setting's files (_setting_digest)."""
    head = {
        "layout": hub_format.LAYOUT,
        "blurset": __version__,
        "shard": shard.name,
        "split": shard.split,
        "settings": shard.settings,
        "factors": hp.factors,
        "passes": hp.passes,
        "held": hp.held,
        "test_views": {s: (hp.splits.get("test_views") or {}).get(s) for s in shard.settings},
        "files": [hp.digests[shard.config.name, s] for s in shard.settings],
    }
    return hashlib.sha256(json.dumps(head, sort_keys=True).encode()).hexdigest()


def _src(hp: HubPlan, cfg: _Config, setting: str) -> Path:
    if cfg.gain is None:
        return hp.build / setting / cfg.level
    return cfg.root / setting / cfg.level / cfg.gain


class _HashingFile(io.RawIOBase):
    """A file that hashes what is written to it (the shard's sha256 without reading it
    back)."""

    def __init__(self, path: Path) -> None:
        self._f = open(path, "wb")  # noqa: SIM115 - closed in close()
        self.sha = hashlib.sha256()
        self.size = 0

    def writable(self) -> bool:
        return True

    def write(self, b) -> int:
        mv = memoryview(b)
        self.sha.update(mv)
        self._f.write(mv)
        self.size += len(mv)
        return len(mv)

    def tell(self) -> int:
        return self.size

    def flush(self) -> None:
        if not self._f.closed:
            self._f.flush()

    def close(self) -> None:
        if not self._f.closed:
            self._f.flush()
            os.fsync(self._f.fileno())
            self._f.close()
        super().close()


# Fault injection for the tests: `kill_in:K` kills this process (SIGKILL) inside the K-th
# shard it writes (from 0), once its first setting is in the temp file, so a test of the
# resume kills at a known point instead of racing the run.
FAULT = "BLURSET_HUB_FAULT"


def write_shard(
    hp: HubPlan, shard: _Shard, path: Path, key: str, kill: bool = False
) -> tuple[int, str, int]:
    """Write one shard to `path` (a temp name): one row group per setting, built and
    written one setting at a time. Returns (rows, sha256, bytes). `kill`: the fault
    injection's (FAULT) SIGKILL after the first setting."""
    pa, pq = hub_format.pyarrow()
    sch = hub_format.schema(hp.factors, hp.passes, shard.config.gain is not None, key)
    sink = _HashingFile(path)
    strings = [
        f.name for f in sch if pa.types.is_string(f.type) and f.name not in ("meta", "noise")
    ]
    # PNG and EXR bytes do not compress: stored as they are; the rest zstd.
    raw = {f.name for f in sch if pa.types.is_struct(f.type) or pa.types.is_binary(f.type)}
    codecs = {c: ("NONE" if c.split(".")[0] in raw else COMPRESSION) for c in _leaf_columns(sch)}
    n = 0
    with pq.ParquetWriter(
        sink,
        sch,
        compression=codecs,
        compression_level={c: COMPRESSION_LEVEL for c, k in codecs.items() if k != "NONE"},
        use_dictionary=strings,
        write_statistics=False,
        store_schema=True,
    ) as w:
        for s in shard.settings:
            cols = _setting_rows(hp, shard.config, s, shard.split)
            table = pa.table(
                {name: pa.array(cols[name], type=sch.field(name).type) for name in sch.names},
                schema=sch,
            )
            w.write_table(table, row_group_size=max(1, table.num_rows))
            if kill:
                sink.flush()
                os.kill(os.getpid(), signal.SIGKILL)
            n += table.num_rows
            del table, cols
    sink.close()
    return n, sink.sha.hexdigest(), sink.size


def _leaf_columns(sch) -> list[str]:
    """The Parquet column paths of a schema (`image.bytes`, `c2w.list.element.list.element`)."""
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    pq.write_table(sch.empty_table(), buf)
    meta = pq.ParquetFile(io.BytesIO(buf.getvalue())).metadata.schema
    return [meta.column(i).path for i in range(len(meta))]


def _sha256(path: Path) -> str:
    return _core.sha256_file(path)


# -- the run -----------------------------------------------------------------------------


def drop_card(out: Path) -> None:
    """An export of another target replacing this one takes the card with the shards it
    described (only as blurset wrote it: an edited one is the user's)."""
    from blurset.commands import card

    card.drop_hub_card(out)


def run(args) -> int:
    out: Path = args.out
    hp = plan(args)
    doc = hp.doc
    inputs = [args.build] + ([args.noise] if args.noise else [])
    export_rules.refuse_overlap(out, doc, inputs)  # type: ignore[arg-type]
    outputs.refuse_inside_settings(out)
    outputs.claim(out, export_rules.EXPORT, "--out")
    with outputs.lock(out, export_rules.EXPORT):
        how = outputs.claim(out, export_rules.EXPORT, "--out")
        changed = _write(out, hp, how, overwrite=args.overwrite)
        # The card's configs make the export load by level as it is (blurset card's).
        from blurset.commands import card

        card.write_hub_card(hp.build, out, args.noise, refresh=changed)
        return 0


def _write(out: Path, hp: HubPlan, how: str, overwrite: bool) -> bool:
    """Write the plan's shards and export.json; whether anything changed (False: up to
    date)."""
    doc = hp.doc
    top = [export_rules.EXPORT_FILE]
    new = [f"{hub_format.DATA_DIR}/{s.name}" for s in hp.shards] + top
    outputs.refuse_links(out, new, "export")  # a link at data/ would take every shard
    layout.remove_stale_temps(out, [export_rules.STAGE, export_rules.TRASH, *top])
    for d in {(out / hub_format.DATA_DIR / s.name).parent for s in hp.shards}:
        layout.remove_stale_temps(d, [Path(s.name).name for s in hp.shards])
    old = outputs.read_record(out / export_rules.EXPORT_FILE) if how == "same" else None
    if old is not None:
        export_rules.refuse_other_export(old, doc, out, overwrite)  # type: ignore[arg-type]
    owned = set(outputs.owned_entries(out, export_rules.EXPORT)) if old is not None else set()
    export_rules.refuse_foreign(out, doc, owned, new)  # type: ignore[arg-type]
    keys = {s.name: shard_key(hp, s) for s in hp.shards}
    done_doc = old if isinstance(old, dict) and old.get("state") != "replacing" else None
    vouched = _kept_shards(out, hp, keys, _trusted_records(old))
    stale = sorted(owned - set(new))
    if len(vouched) == len(hp.shards) and not stale and done_doc is not None:
        want = dict(doc)
        want["shards"] = {s.name: vouched[s.name] for s in hp.shards}
        if want == done_doc:
            _say(want, out, hp, "up to date", 0)
            return False
    owns = owned | set(new)
    export_rules.record_replacing(out, doc, owns, vouched)  # type: ignore[arg-type]
    for rel in stale:
        p = out / rel
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink(missing_ok=True)
        export_rules.prune_empty_parents(out, rel)
    written = 0
    fault = stop.fault_index(FAULT)
    for s in hp.shards:
        if s.name in vouched:
            continue
        vouched[s.name] = _write_one(hp, s, out, keys[s.name], written == fault)
        written += 1
        # A kill from here on keeps this shard: the rerun checks it against this line.
        export_rules.record_replacing(out, doc, owns, vouched)  # type: ignore[arg-type]
    doc["shards"] = {s.name: vouched[s.name] for s in hp.shards}
    outputs.write_record(out / export_rules.EXPORT_FILE, doc)
    _say(doc, out, hp, "written", written)
    return True


def _trusted_records(old: Any) -> dict[str, dict]:
    """The shard records a rerun checks the shards on disk against: a finished export's,
    or those a stopped run carried in its `replacing` state (each a shard it wrote, or
    checked before keeping it). An older stopped run carried none: its shards are
    written again, never hashed into a record."""
    return dict(old.get("shards") or {}) if isinstance(old, dict) else {}


def _kept_shards(
    out: Path, hp: HubPlan, keys: dict[str, str], trusted: dict[str, dict]
) -> dict[str, dict]:
    """The shards of this plan on disk that are kept, with their records: made from the
    plan's files (the key in their footer) and holding the very bytes a trusted record
    lists (size, then sha256). Any other is written again, and a damaged one named on
    stderr, as a build's rerun redoes a setting that differs from its manifest: a record
    certifies only bytes this run wrote or checked."""
    kept: dict[str, dict] = {}
    for s in hp.shards:
        path = out / hub_format.DATA_DIR / s.name
        if not path.is_file() or hub_format.read_key(path) != keys[s.name]:
            continue  # not written yet, or made from other files: nothing to say
        problem = _shard_problem(s, path, trusted.get(s.name))
        if problem is None:
            rec = trusted[s.name]
            kept[s.name] = _record(s, rec["rows"], rec["bytes"], rec["sha256"])
        else:
            print(f"redoing {hub_format.DATA_DIR}/{s.name}: {problem}", file=sys.stderr)
    return kept


def _shard_problem(s: _Shard, path: Path, rec: dict | None) -> str | None:
    """Why a finished shard is not the one its record lists, or None."""
    record = export_rules.EXPORT_FILE
    if rec is None:
        return f"no line of {record} vouches for it (a run was stopped)"
    if (rec.get("config"), rec.get("split"), rec.get("settings")) != (
        s.config.name,
        s.split,
        s.settings,
    ):
        return f"{record} lists other rows for it"
    size = path.stat().st_size
    if size != rec.get("bytes"):
        return f"{size} bytes, {record} says {rec.get('bytes')}"
    if _sha256(path) != rec.get("sha256"):
        return f"sha256 differs from {record}'s"
    return None


def _record(s: _Shard, rows: int, size: int, sha256: str) -> dict:
    return {
        "config": s.config.name,
        "split": s.split,
        "settings": s.settings,
        "rows": int(rows),
        "bytes": int(size),
        "sha256": sha256,
    }


def _write_one(hp: HubPlan, s: _Shard, out: Path, key: str, kill: bool) -> dict:
    """Write one shard through a temp name; its record. A failed write (a full disk)
    names the shard: the sink's own errors carry no file name."""
    dst = out / hub_format.DATA_DIR / s.name
    dst.parent.mkdir(parents=True, exist_ok=True)
    tmp = layout.temp_path(dst)
    try:
        rows, sha, size = write_shard(hp, s, tmp, key, kill)
        os.replace(tmp, dst)
    except OSError as e:
        if e.filename is not None:
            raise
        if e.errno is None:
            raise OSError(f"cannot write {dst}: {e}") from None
        raise OSError(e.errno, e.strerror, str(dst)) from None
    finally:
        tmp.unlink(missing_ok=True)
    return _record(s, rows, size, sha)


def _say(doc: dict, out: Path, hp: HubPlan, what: str, written: int) -> None:
    shards = doc.get("shards") or {}
    rows = sum(int(s["rows"]) for s in shards.values())
    configs = sorted({c.name for c in hp.configs}, key=[c.name for c in hp.configs].index)
    print(
        f"blurset export: {len(shards)} shards ({written} written), {rows} rows in "
        f"{len(configs)} configs ({', '.join(configs)}) {what} -> {out / hub_format.DATA_DIR}; "
        f"its card, one config each: {out / 'README.md'}",
        file=sys.stdout,
    )
