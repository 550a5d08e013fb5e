"""`blurset card BUILD`: a Hugging Face dataset card (README.md) for a build (issue 19).

The YAML header carries what the Hub reads (licence, task categories, size category,
pretty name, tags); the body explains the dataset from the build's own files: the
paper's parameters as this build used them (dataset.json, meta.json), the counts and
splits, the noise gains when a `blurset noise BUILD` output is given or found beside
the build, how to load it and check it, the paper's citation, and the attribution of
every object (title, author, licence, link). Nothing in it names a builder path.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from collections import Counter
from pathlib import Path
from typing import Any

from blurset import __version__, _core, layout
from blurset.exceptions import ConfigError, InputError
from blurset.services import attribution, outputs, publish

PAPER = (
    "Towards Degradation-Robust Reconstruction in Generalizable NeRF "
    "(Chi Ho Park, Ka Leong Cheng, Zhicheng Wang, Qifeng Chen)"
)
BIBTEX = """@article{park2024degradation,
  title   = {Towards Degradation-Robust Reconstruction in Generalizable NeRF},
  author  = {Park, Chi Ho and Cheng, Ka Leong and Wang, Zhicheng and Chen, Qifeng},
  journal = {arXiv preprint},
  year    = {2024}
}"""
TASKS = ("image-to-3d", "image-to-image")
TAGS = (
    "nerf",
    "generalizable-nerf",
    "novel-view-synthesis",
    "motion-blur",
    "deblurring",
    "multi-view",
    "llff",
    "synthetic",
    "blender",
)
# The paper's values (DESIGN §2) beside which the build's own are shown.
PAPER_VALUES = {
    "settings_per_object": 4,
    "views": 34,
    "phi0_deg": 60.0,
    "window_deg": 7.5,
    "delta0": 2.5,
    "levels": [1, 2, 3, 4],
    "level_spread": 0.1,
    "latents": 34,
    "latent_positions": "random",
    "view_stride": 16,
}
MAX_PREVIEWS = 12


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("build", type=Path, help="a build directory (dataset.json)")
    p.add_argument("--out", type=Path, help="the card to write (default: BUILD/README.md)")
    p.add_argument(
        "--noise",
        type=Path,
        action="append",
        help="a `blurset noise BUILD` output to describe (default: any found beside BUILD)",
    )
    p.add_argument(
        "--previews",
        action="store_true",
        help="show the build's pictures (contact_sheet.png, <setting>/preview.png) when present",
    )
    p.add_argument("--pretty-name", help="the card's title (default: from the build's name)")
    p.add_argument(
        "--hub",
        type=Path,
        help="a `blurset export BUILD --for hub` output: the card gets its `configs:` and "
        "`dataset_info` (what `datasets.load_dataset` and the Hub's viewer read) and is "
        "written to HUB/README.md unless --out says otherwise (default: none, a card of "
        "the build's folders)",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="replace a card that was edited, or a README blurset did not write (the old "
        "one is kept beside it as README.md.bak)",
    )


# -- reading the build ------------------------------------------------------------------


def _objects(build: Path, settings: list[Path]) -> tuple[dict[str, dict], list[dict]]:
    """Per object uid its meta.json `object` record, and every setting's meta.json."""
    objects: dict[str, dict] = {}
    metas = []
    for s in settings:
        meta = outputs.read_record(s / layout.META)
        metas.append(meta)
        rec = meta.get("object") if isinstance(meta.get("object"), dict) else {}
        objects.setdefault(str(meta.get("uid", s.name)), rec)
    return objects, metas


def _noise_outputs(build: Path, given: list[Path] | None) -> list[tuple[Path, dict]]:
    """The noise outputs to describe: those given (each must be a finished noise output
    of this build), or the folders beside the build whose noise_dataset.json names it."""
    if given:
        return [(p, outputs.noise_of_build(p, build)) for p in given]
    found = []
    for d in sorted(build.resolve().parent.iterdir()):
        try:
            if outputs.kind_of(d) is not outputs.OutputKind.NOISE:
                continue
            doc = outputs.read_record(d / layout.NOISE_DATASET)
        except (OSError, ValueError, InputError):
            continue  # a damaged folder beside the build is not described
        if doc.get("counts") is not None and outputs.noise_mismatch(doc, d, build) is None:
            found.append((d, doc))
    return found


# -- pieces of the card -----------------------------------------------------------------


def size_category(n: int) -> str:
    """The Hub's size category of n examples (images here)."""
    bounds = [
        (1_000, "n<1K"),
        (10_000, "1K<n<10K"),
        (100_000, "10K<n<100K"),
        (1_000_000, "100K<n<1M"),
        (10_000_000, "1M<n<10M"),
    ]
    for b, name in bounds:
        if n < b:
            return name
    return "n>10M" if n >= 10_000_000 else "other"


def _q(s: Any) -> str:
    """A YAML scalar: JSON's double-quoted string is valid YAML."""
    return json.dumps(str(s), ensure_ascii=False)


def _yaml(value: Any, indent: int = 0) -> list[str]:
    """Block YAML of nested dicts and lists (scalars quoted as JSON, numbers and booleans
    as they are)."""
    pad = " " * indent
    out: list[str] = []

    def scalar(v: Any) -> str:
        if isinstance(v, bool):
            return "true" if v else "false"
        if isinstance(v, int | float):
            return json.dumps(v)
        return _q(v)

    if isinstance(value, dict):
        for k, v in value.items():
            if isinstance(v, dict | list) and v:
                out.append(f"{pad}{k}:")
                out += _yaml(v, indent + 2)
            else:
                out.append(f"{pad}{k}: {scalar(v) if not isinstance(v, dict | list) else '[]'}")
    else:
        for v in value:
            if isinstance(v, dict | list) and v:
                inner = _yaml(v, indent + 2)
                out.append(f"{pad}- {inner[0].lstrip()}")
                out += inner[1:]
            else:
                out.append(f"{pad}- {scalar(v)}")
    return out


def yaml_header(meta: dict[str, Any]) -> str:
    lines = ["---"]
    for key, value in meta.items():
        if isinstance(value, list) and value and isinstance(value[0], dict):
            lines.append(f"{key}:")
            lines += _yaml(value)
        elif isinstance(value, list):
            lines.append(f"{key}:")
            lines.extend(f"- {_q(v)}" for v in value)
        else:
            lines.append(f"{key}: {_q(value)}")
    lines.append("---")
    return "\n".join(lines) + "\n"


def _feature_yaml(name: str, feature: dict) -> dict[str, Any]:
    """A `datasets` feature as the card's `dataset_info.features` writes it."""

    def inner(f: dict) -> Any:
        if f["_type"] == "Image":
            return "image"
        if f["_type"] == "Sequence":
            return {"list": inner(f["feature"])}
        return f["dtype"]

    v = inner(feature)
    return {"name": name, **(v if isinstance(v, dict) else {"dtype": v})}


def _hub_configs(doc: dict) -> list[str]:
    """A hub export's configs in its order (levels, then gains)."""
    return list(dict.fromkeys(doc["scenes"][s] for s in [*doc["train"], *doc["test"]]))


def hub_header(hub: Path, doc: dict) -> dict[str, Any]:
    """`configs:` and `dataset_info` of a `blurset export --for hub` output: one config
    per level and gain, its splits' shards, features and counts."""
    from blurset.services import hub_format

    by_config: dict[str, dict[str, list[dict]]] = {}
    for _, rec in sorted((doc.get("shards") or {}).items()):
        by_config.setdefault(rec["config"], {}).setdefault(rec["split"], []).append(rec)
    order = _hub_configs(doc)
    default = next((c for c in order if c != layout.SHARP), order[0])
    configs, infos = [], []
    for c in order:
        splits = by_config.get(c, {})
        entry: dict[str, Any] = {
            "config_name": c,
            "data_files": [
                {"split": sp, "path": f"{hub_format.DATA_DIR}/{c}/{sp}-*.parquet"}
                for sp in ("train", "test")
                if sp in splits
            ],
        }
        if c == default:
            entry["default"] = True
        configs.append(entry)
        feats = hub_format.features(
            list(doc.get("factors") or []), list(doc.get("passes") or []), c not in doc["levels"]
        )
        infos.append(
            {
                "config_name": c,
                "features": [_feature_yaml(n, f) for n, f in feats.items()],
                "splits": [
                    {
                        "name": sp,
                        "num_bytes": sum(int(r["bytes"]) for r in recs),
                        "num_examples": sum(int(r["rows"]) for r in recs),
                    }
                    for sp, recs in splits.items()
                ],
                "download_size": sum(int(r["bytes"]) for recs in splits.values() for r in recs),
                "dataset_size": sum(int(r["bytes"]) for recs in splits.values() for r in recs),
            }
        )
    return {"configs": configs, "dataset_info": infos}


def _cell(s: Any) -> str:
    """Text safe in a Markdown table cell."""
    text = " ".join(str(s).split())
    return text.replace("\\", "\\\\").replace("|", "\\|") or "-"


def _link(text: str, url: Any) -> str:
    if isinstance(url, str) and url.startswith(("http://", "https://")):
        return f"[{_cell(text)}]({url.replace(')', '%29').replace(' ', '%20')})"
    return _cell(text)


def _denoiser(render: dict, cfg: dict) -> str:
    """The card's denoiser cell: none (as the paper), or OIDN with its version and device
    (issue 28)."""
    kind = render.get("denoise", cfg.get("denoise", "none")) or "none"
    if kind == "none":
        return "none"
    d = render.get("denoiser") or {}
    what = " ".join(str(d[k]) for k in ("library", "version") if d.get(k)) or kind
    on = f" on {d['device']}" if d.get("device") else ""
    return f"{what}{on}, once per image after averaging (albedo + normal guides)"


def _fmt(x: Any) -> str:
    if isinstance(x, float):
        return f"{x:g}"
    if isinstance(x, list):
        return ", ".join(_fmt(v) for v in x) or "none"
    return "-" if x is None else str(x)


def licence_header(licences: Counter) -> dict[str, Any]:
    """`license` of the header: the one licence, or `other` with the list when mixed."""
    ids = sorted(licences)
    if len(ids) == 1:
        return {"license": attribution.hf_license(ids[0])}
    listed = ", ".join(
        f"{attribution.hf_license(k)} ({licences[k]} object{'s' if licences[k] > 1 else ''})"
        for k in ids
    )
    return {
        "license": "other",
        "license_name": "per-object",
        "license_details": f"Each object keeps its own licence: {listed}; "
        "see the attribution table.",
    }


def _level_table(metas: list[dict], levels: list[str]) -> list[str]:
    rows = ["| level | w_l (median) | motion on screen, px (median) | latent frames (median) |"]
    rows.append("|---|---|---|---|")
    for lvl in levels:
        if lvl == layout.SHARP:
            rows.append("| sharp | 0 | 0 | 1 (ground truth) |")
            continue
        kind, key = layout.level_record(lvl) or ("", "")
        if kind != "levels":
            continue  # not a motion (a lens: _defocus_table)
        w, px, m = [], [], []
        for meta in metas:
            for v in meta.get("views", []):
                lp = (v.get("levels") or {}).get(key)
                if isinstance(lp, dict):
                    w.append(lp.get("w_l"))
                    px.append(lp.get("motion_px"))
                    m.append(lp.get("latents"))

        def med(xs: list) -> str:
            xs = [x for x in xs if isinstance(x, int | float)]
            return f"{statistics.median(xs):.3g}" if xs else "-"

        rows.append(f"| {lvl} | {med(w)} | {med(px)} | {med(m)} |")
    return rows


def _kinds_meant(levels: list[str]) -> list[tuple[str, str]]:
    """Each kind among `levels` once, in level order: (`blur_l`, what its levels are)."""
    return list(dict.fromkeys(m for lvl in levels if (m := layout.level_means(lvl))))


def _defocus_table(metas: list[dict], levels: list[str]) -> list[str]:
    """The defocus levels: the largest circle of confusion on the object and the lens."""
    defocus = [lvl for lvl in levels if layout.level_kind(lvl) == "defocus"]
    if not defocus:
        return []
    rows = [
        "Defocus levels (`defocus_l`): one Cycles depth-of-field render per view, focused at "
        "a distance drawn inside the object's depth range, the aperture set so the largest "
        "circle of confusion on the object is the one below (meta.json `views[].defocus`).",
        "",
        "| level | largest circle of confusion, px | f-number (median) |",
        "|---|---|---|",
    ]
    for lvl in defocus:
        key = lvl.partition("_")[2]
        ds = [
            v["defocus"][key]
            for meta in metas
            for v in meta.get("views", [])
            if isinstance(v.get("defocus"), dict) and key in v["defocus"]
        ]
        coc = statistics.median(d["coc_px"][1] for d in ds) if ds else None
        fn = statistics.median(d["f_number"] for d in ds) if ds else None
        rows.append(f"| {lvl} | {_fmt(coc)} | {'-' if fn is None else format(fn, '.3g')} |")
    return [*rows, ""]


def make_card(
    build: Path,
    *,
    noise: list[Path] | None = None,
    previews: bool = False,
    pretty_name: str | None = None,
    card_dir: Path | None = None,
    hub: Path | None = None,
) -> str:
    """The card's text. `card_dir` is where it will be written (picture links are
    relative to it); `hub`, a `blurset export --for hub` output of the build, adds its
    configs, features and counts and how to load them."""
    build = Path(build)
    # A card describes a finished build: a provisional one would publish wrong counts.
    state = outputs.finished_build(build)
    dataset = outputs.read_record(build / layout.DATASET)
    splits = outputs.read_record(build / layout.SPLITS)
    settings = [build / n for n in state.complete]
    if not settings:
        raise InputError(f"no complete setting in build: {build}")
    objects, metas = _objects(build, settings)
    cfg = dataset.get("config") or {}
    counts = dataset.get("counts") or {}
    levels = list(dataset.get("levels") or metas[0].get("levels") or [])
    licences = Counter(str(o.get("license", attribution.UNKNOWN)) for o in objects.values())
    name = pretty_name or f"blurset Objaverse-Blur: {build.resolve().name}"
    hub_doc = _hub_doc(hub, build) if hub is not None else None
    noise_docs = _noise_outputs(build, noise)
    if hub_doc is not None:
        # The card of an upload describes what the upload holds: its own noise, if any.
        noise_docs = [(p, d) for p, d in noise_docs if p.name == hub_doc.get("noise")]
    header = _card_header(name, licences, int(counts.get("images", 0)), bool(noise_docs))
    if hub_doc is not None:
        header.update(hub_header(hub, hub_doc))  # type: ignore[arg-type]
    m0 = metas[0]
    res = m0.get("resolution") or [cfg.get("resolution")] * 2
    out: list[str] = [yaml_header(header), f"# {name}", ""]
    out += _contents(name, dataset, splits, m0, levels, res)
    if hub_doc is not None:
        out += _hub_shards()
    out += _per_view_outputs(settings, m0)
    out += _construction(cfg, m0, metas, levels)
    out += _defocus_table(metas, levels)
    for path, doc in noise_docs:
        out += _noise_section(path, doc)
    if hub_doc is not None:
        out += _hub_loading(hub_doc)
    out += _loading(levels, splits.get("view_stride") or cfg.get("view_stride") or 16)
    if previews:
        out += _previews(build, settings, card_dir or build)
    out += _attribution(objects, licences)
    out += ["## Citation", "", "```bibtex", BIBTEX, "```", ""]
    return "\n".join(out)


def _card_header(name: str, licences: Counter, n_images: int, denoising: bool) -> dict:
    """The card's YAML header before a hub export's configs: what the Hub indexes."""
    return {
        "pretty_name": name,
        **licence_header(licences),
        "task_categories": list(TASKS),
        "size_categories": [size_category(n_images)],
        "tags": list(TAGS) + (["denoising"] if denoising else []),
    }


def _hub_shards() -> list[str]:
    """The card of a hub export describes its shards; the folders are the build's."""
    return [
        "This repository holds the build as Parquet shards (`blurset export --for hub`):",
        "",
        "```",
        "export.json                                  every shard: its config, split, "
        "settings, rows and sha256",
        "data/<config>/<split>-00000-of-00004.parquet  one config per level (and gain), "
        "whole settings per shard",
        "```",
        "",
        "The layout above is the build's, which the shards were made from; "
        "`blurset verify .` checks every shard and decodes every image.",
        "",
    ]


def _per_view_outputs(settings: list[Path], m0: dict) -> list[str]:
    """What a view holds beside its images (`linear/`, `build --passes`), as the first
    setting has it."""
    out: list[str] = []
    if any((s / layout.SHARP / layout.LINEAR).is_dir() for s in settings[:1]):
        out += [
            "Each level also holds `linear/<view>.exr`: the linear premultiplied RGBA "
            "image before compositing and sRGB.",
            "",
        ]
    passes = (m0.get("render") or {}).get("passes_are") or {}
    if passes:
        out += ["Per view, beside the sharp images (`build --passes`):", ""]
        out += [f"- **{k}**: {what}" for k, what in passes.items()]
        out += [""]
    return out


def _contents(
    name: str, dataset: dict, splits: dict, m0: dict, levels: list[str], res: list
) -> list[str]:
    """What the dataset is, what it holds, its splits and its layout."""
    counts = dataset.get("counts") or {}
    views = len(m0.get("views", []))
    out: list[str] = []
    out += [
        "Multi-view images of 3D objects with realistic camera motion blur at several "
        "levels, with sharp ground truth and LLFF poses, for training and evaluating "
        "degradation-robust generalizable NeRFs (IBRNet, NAN, GeoNeRF, GNT). It re-creates "
        f"the Objaverse Blur dataset of *{PAPER}* and was built with "
        f"blurset {dataset.get('blurset_version', __version__)}"
        f" on {str(dataset.get('created', '?'))[:10]}.",
        "",
        "## Contents",
        "",
        "| objects | settings | views per setting | levels | images | objects failed |",
        "|---|---|---|---|---|---|",
        f"| {counts.get('objects')} | {counts.get('settings')} | {views} | {len(levels)} "
        f"| {counts.get('images')} | {counts.get('objects_failed', 0)} |",
        "",
        f"Images are {res[0]} x {res[1]} px sRGB PNG. Levels: {', '.join(levels)} "
        "(`sharp` is the ground truth of every view"
        + "".join(f"; `{p}` {means}" for p, means in _kinds_meant(levels))
        + ").",
        "",
        "### Splits",
        "",
        f"`splits.json`: {len(splits.get('train', []))} training and "
        f"{len(splits.get('test', []))} test settings (whole objects are held out: "
        f"{', '.join(splits.get('test_objects', []) or []) or 'none'}); in every setting "
        f"views {', '.join(map(str, m0.get('test_views', [])))} (every "
        f"{splits.get('view_stride')}th) are test views.",
        "",
        "### Layout",
        "",
        "```",
        "dataset.json  splits.json  failures.jsonl  MANIFEST.sha256",
        "<object>_<theta0>/            one setting (an object seen around one azimuth)",
        "  meta.json                   every sampled number: views, trajectories, w_u, w_l, "
        "seeds; the object's attribution",
        "  transforms.json             OpenGL camera-to-world, intrinsics, per-level paths",
        "  sharp/images/000.png …      sharp/poses_bounds.npy",
        "  blur_1/images/000.png …     blur_1/poses_bounds.npy   (… every level)",
        "```",
        "",
    ]
    return out


def _image_records(metas: list[dict], level: str) -> list[dict]:
    """Under --target-psnr: what each image of `level` rendered (meta.json
    `views[].images`)."""
    return [
        im
        for meta in metas
        for v in meta.get("views", [])
        if isinstance(im := (v.get("images") or {}).get(level), dict)
    ]


def _rendered_samples(metas: list[dict], level: str) -> str | None:
    """The samples the images of `level` rendered under a target, as the records state
    them (fewest–most, median): each image renders its own, so no one count is true."""
    n = [int(r["samples"]) for r in _image_records(metas, level)]
    if not n:
        return None
    spread = f"{min(n)}" if min(n) == max(n) else f"{min(n)}–{max(n)}"
    return f"{spread} (median {statistics.median(n):g}), each image to the target"


def _blur_method(metas: list[dict], method: Any) -> Any:
    """`auto` (issue 47) with what it chose, over every setting: how many blurry images
    took each method, on which devices (meta.json's `render.blur_choice`)."""
    choices = [c for m in metas if (c := (m.get("render") or {}).get("blur_choice"))]
    if method != "auto" or not choices:
        return method
    images: dict[str, int] = {}
    for c in choices:
        for k, n in (c.get("images") or {}).items():
            images[k] = images.get(k, 0) + int(n)
    devices = ", ".join(sorted({str(c.get("device")) for c in choices}))
    chose = ", ".join(f"{n} {k}" for k, n in sorted(images.items()))
    return f"auto, priced on {devices}: {chose} blurry images"


def _render_table(metas: list[dict], levels: list[str], target: Any) -> list[str]:
    """Under --target-psnr: per level, what the images cost and reached (the worst
    image and the 5th percentile beside the median: a mean would hide the worst)."""
    from blurset import _core

    rows = [
        f"Every image was rendered until its render PSNR on the object's pixels, estimated "
        f"from two independent halves of its samples, reached {_fmt(target)} dB; the rounds "
        "stop on a bound of that estimate that holds where a few bright pixels carry the "
        "noise (`render_psnr_bound_db`).",
        "",
        "| level | images | samples (median, max) | render PSNR dB (worst, 5th pct, median) "
        "| at least, worst | reached |",
        "|---|---|---|---|---|---|",
    ]
    for lvl in levels:
        recs = _image_records(metas, lvl)
        if not recs:
            continue
        n = [r["samples"] for r in recs]
        db = [r["render_psnr_db"] for r in recs]
        sp = _core.spread(db)
        reached = sum(bool(r.get("reached")) for r in recs)
        bounds = [r["render_psnr_bound_db"] for r in recs if "render_psnr_bound_db" in r]
        bound = f"{min(bounds):.1f}" if bounds else "–"  # builds before the bound
        rows.append(
            f"| {lvl} | {len(recs)} | {statistics.median(n):.0f}, {max(n)} | "
            f"{sp['worst']:.1f}, {sp['p5']:.1f}, {statistics.median(db):.1f} | {bound} | "
            f"{reached} of {len(recs)} |"
        )
    return [*rows, ""]


def _parameter_table(cfg: dict, m0: dict, metas: list[dict]) -> list[str]:
    """The sampled parameters beside the paper's, then those only this build states."""
    sampling = m0.get("sampling") or {}
    render = m0.get("render") or {}

    def used(key: str) -> Any:
        return cfg.get(key, sampling.get(key))

    rows = [
        ("settings per object (base azimuths θ0)", "settings_per_object"),
        ("views n per setting", "views"),
        ("polar angle φ0 (°, from +Z)", "phi0_deg"),
        ("view window ± (°)", "window_deg"),
        ("trajectory δ0 (Δr %, Δφ °, Δθ °)", "delta0"),
        ("blur levels l", "levels"),
        ("w_l spread (w_l ~ U[(1-s)·w_u·l, (1+s)·w_u·l])", "level_spread"),
        ("latent frames m per blurry image", "latents"),
        ("latent positions on the trajectory", "latent_positions"),
        ("test view stride", "view_stride"),
    ]
    table = ["| parameter | paper | this build |", "|---|---|---|"]
    for label, key in rows:
        table.append(f"| {label} | {_fmt(PAPER_VALUES.get(key))} | {_fmt(used(key))} |")
    # Under a render target no count is fixed: the sharp images' row states what they
    # rendered, and the fixed-count rows (a budget, per-frame samples) do not apply.
    targeted = render.get("target_psnr_db") is not None
    extra = [
        ("resolution (px)", cfg.get("resolution")),
        ("field of view (°)", cfg.get("fov_deg", sampling.get("fov_deg"))),
        ("blur method", _blur_method(metas, render.get("blur_method", cfg.get("blur_method")))),
        ("Cycles samples per latent frame", None if targeted else render.get("samples_per_latent")),
        ("blurry sample budget", None if targeted else render.get("blur_budget")),
        (
            "Cycles samples of a sharp image",
            _rendered_samples(metas, "sharp") if targeted else render.get("sharp_samples"),
        ),
        ("preset", render.get("preset", cfg.get("preset"))),
        ("render PSNR target per image (dB, object pixels)", render.get("target_psnr_db")),
        ("denoiser", _denoiser(render, cfg)),
        ("background", _fmt(render.get("background", cfg.get("background")))),
        ("seed", cfg.get("seed")),
    ]
    for label, value in extra:
        table.append(f"| {label} | - | {_fmt(value)} |")
    return table


def _construction(cfg: dict, m0: dict, metas: list[dict], levels: list[str]) -> list[str]:
    render = m0.get("render") or {}
    table = _parameter_table(cfg, m0, metas)
    return [
        "## Construction",
        "",
        "Each object is centred and scaled so its largest side is 1 and rendered with "
        "Blender (Cycles). Per setting, n camera positions are drawn around "
        "(φ0, θ0); each view gets a trajectory δ = (Δr, Δφ, Δθ), components ~ "
        "U[δ0/2, δ0] with random signs, and a scene-dependent weight "
        "w_u = (F·R·O)^(1/3) from the object's depth range and shape. A blurry image at "
        "level l is the mean **in linear light** of m renders at random positions on the "
        "segment p → p + w_l·δ, w_l ~ U[0.9·w_u·l, 1.1·w_u·l]; the pose written for every "
        "level is the sharp view's p. Every sampled number is in each setting's "
        "meta.json.",
        "",
        *table,
        "",
        *_level_table(metas, levels),
        "",
        *(
            _render_table(metas, levels, render["target_psnr_db"])
            if render.get("target_psnr_db") is not None
            else []
        ),
    ]


def _noise_section(path: Path, doc: dict) -> list[str]:
    params = doc.get("params") or {}
    gains = doc.get("gains") or []
    rows = ["| gain | σ_read | σ_shot |", "|---|---|---|"]
    rows += [
        f"| {_fmt(g.get('gain'))} | {g.get('sigma_read', 0):.4g} | {g.get('sigma_shot', 0):.4g} |"
        for g in gains
    ]
    counts = doc.get("counts") or {}
    model = params.get("model", "paper")
    what = (
        "LLFF-N style sensor noise on levels {levels}: "
        "y' = y + sqrt(σ_read² + σ_shot²·y)·N(0, 1) in linear light, after inverse gamma "
        if model == "paper"
        else f"Camera sensor noise (`--model {model}`) on levels {{levels}}: a raw pipeline "
        "(inverse colour matrix and white balance, Bayer mosaic, noise per photosite, "
        "bilinear demosaic; σ below are the equivalent read and shot σ in raw units, every "
        "parameter and its source in each `noise.json`'s `raw_model`), transfer "
    )
    return [
        f"## Noise variants (`{path.name}/`)",
        "",
        what.format(levels=", ".join(doc.get("levels", [])))
        + f"({params.get('gamma')}) and "
        + (
            "a random white balance per scene"
            if params.get("profile") == "paper"
            else "no white balance"
        )
        + f"; clean source: the build's {params.get('source')} images, seed "
        f"{params.get('seed')}. {counts.get('units')} noisy scenes, {counts.get('images')} "
        "images; each `<setting>/<level>/gain_<g>/` is an LLFF scene with `noise.json`.",
        "",
        *rows,
        "",
    ]


def _loading(levels: list[str], llffhold: int) -> list[str]:
    """How to load the build; `llffhold` is the build's test-view stride."""
    blur = next((lvl for lvl in levels if lvl != layout.SHARP), layout.SHARP)
    return [
        "## Loading",
        "",
        "Every level directory is an LLFF scene as IBRNet, NAN and Deblur-NeRF read it: "
        "`images/` (sorted file order is view order) and `poses_bounds.npy` (N x 17: the "
        "3 x 5 camera-to-world [down, right, backwards | t | h w f] row-major, then near, "
        f"far). With IBRNet/NAN use `--llffhold {llffhold}`; nerfstudio reads `transforms.json` "
        "(use `--center-method focus`). Training pairs a degraded level with `sharp/` of "
        "the same setting.",
        "",
        "```python",
        "import json",
        "from pathlib import Path",
        "",
        "import numpy as np",
        "from PIL import Image",
        "",
        'root = Path(".")  # e.g. huggingface_hub.snapshot_download(repo_id, repo_type="dataset")',
        'splits = json.loads((root / "splits.json").read_text())',
        'for setting in splits["train"]:',
        f'    level = root / setting / "{blur}"',
        '    pb = np.load(level / "poses_bounds.npy")  # (N, 17)',
        "    poses = pb[:, :15].reshape(-1, 3, 5)  # camera-to-world [down, right, back | t]",
        "    c2w, (h, w, focal) = poses[:, :, :4], poses[0, :, 4]",
        "    near, far = pb[:, 15], pb[:, 16]",
        '    images = [np.asarray(Image.open(p)) for p in sorted((level / "images").glob("*.png"))]',
        '    sharp = sorted((root / setting / "sharp" / "images").glob("*.png"))  # ground truth',
        "```",
        "",
        "### Checking a download",
        "",
        "`MANIFEST.sha256` lists the sha256 of every file: `sha256sum -c MANIFEST.sha256` "
        "inside the dataset passes when it arrived whole; `blurset verify .` also decodes "
        "every image and checks every setting against its meta.json.",
        "",
    ]


def _hub_doc(hub: Path, build: Path) -> dict:
    """export.json of a finished `blurset export --for hub` output of `build`."""
    from blurset.services import hub_format

    doc = hub_format.hub_doc(hub)
    if doc is None:
        raise InputError(f"--hub is not a `blurset export --for hub` output (export.json): {hub}")
    if doc.get("shards") is None:
        raise InputError(f"--hub is an export that has not finished (rerun it): {hub}")
    if doc.get("build") != build.resolve().name:
        raise InputError(f"--hub is an export of the build {doc.get('build')!r}, not of {build}")
    return doc


def _hub_loading(doc: dict) -> list[str]:
    """How to load the Parquet shards: `datasets`, a stream, the rows' columns."""
    configs = _hub_configs(doc)
    blur = next((c for c in configs if c != layout.SHARP), configs[0])
    return [
        "## Loading with `datasets`",
        "",
        f"The images are Parquet shards under `data/<config>/`: one config per level "
        f"({', '.join(f'`{c}`' for c in configs)}), splits `train` and `test` (the settings "
        "of the held-out objects). One row per image: `image` holds the build's PNG bytes "
        "unchanged"
        + ("" if not doc.get("factors") else ", `image_<f>` its `images_<f>/` copy")
        + "; `setting`, `view`, `held_out` (a held-out view of a degraded level holds the "
        f"{doc.get('test_view_images')} image), the camera (`poses_bounds`: the LLFF row; "
        "`c2w`: OpenGL camera-to-world; `focal`, `near`, `far`; `mean_c2w`: the mean latent "
        "pose of a blurry image) and meta.json's record of the image (`meta`, `w_l`, "
        "`motion_px`, `samples`, …). A shard holds whole settings, so a scene streams whole.",
        "",
        "```python",
        "from datasets import load_dataset",
        "",
        f'ds = load_dataset("REPO_ID", "{blur}", split="train")  # or a local folder',
        'row = ds[0]  # row["image"] is a PIL image; row["c2w"] a 4 x 4 list',
        "",
        "# A scene as NumPy arrays, streamed (pip install blurset):",
        "from blurset.data import open_scene",
        "",
        f'rows = load_dataset("REPO_ID", "{blur}", split="train", streaming=True)',
        'sharp = load_dataset("REPO_ID", "sharp", split="train", streaming=True)',
        'scene = open_scene(rows, ds[0]["setting"], "' + blur + '", sharp_rows=sharp)',
        "```",
        "",
    ]


def _previews(build: Path, settings: list[Path], card_dir: Path) -> list[str]:
    pics = []
    sheet = build / "contact_sheet.png"
    if sheet.is_file():
        pics.append(("contact sheet", sheet))
    pics += [(s.name, s / "preview.png") for s in settings if (s / "preview.png").is_file()]
    if not pics:
        return []
    out = ["## Previews", ""]
    for label, p in pics[: MAX_PREVIEWS + 1]:
        try:
            rel = p.resolve().relative_to(card_dir.resolve()).as_posix()
        except ValueError:
            continue  # a card written elsewhere does not link into the build
        out += [f"![{_cell(label)}]({rel})", ""]
    if len(pics) > MAX_PREVIEWS + 1:
        out += [f"… and {len(pics) - MAX_PREVIEWS - 1} more `<setting>/preview.png`.", ""]
    return out


def _attribution(objects: dict[str, dict], licences: Counter) -> list[str]:
    summary = ", ".join(f"{k}: {licences[k]}" for k in sorted(licences))
    rows = [
        "## Licensing and attribution",
        "",
        "The images are renders of 3D models made by others; each object keeps the "
        "licence its author gave it, and using the images means following those licences "
        "(attribution for CC-BY, no commercial use for CC-BY-NC, …). Licences of the "
        f"{len(objects)} objects: {summary}. `unknown` means the model file names no "
        "licence: check its origin before publishing it. The same records are in each "
        "setting's meta.json `object` (with the sha256 of the model file).",
        "",
        "| object | title | author | licence | source |",
        "|---|---|---|---|---|",
    ]
    for uid in sorted(objects):
        o = objects[uid]
        rows.append(
            f"| {_cell(uid)} | {_cell(o.get('title', attribution.UNKNOWN))} "
            f"| {_link(str(o.get('author', attribution.UNKNOWN)), o.get('author_url'))} "
            f"| {_cell(o.get('license', attribution.UNKNOWN))} "
            f"| {_link(str(o.get('source_url', attribution.UNKNOWN)), o.get('source_url'))} |"
        )
    rows.append("")
    return rows


def write_hub_card(
    build: Path, hub: Path, noise: Path | None = None, *, refresh: bool = True
) -> None:
    """HUB/README.md as `blurset card BUILD --hub HUB` writes it, written by `blurset
    export --for hub` itself: without its `configs:`, `load_dataset(HUB)` reads one
    `default` config mixing every level's rows. A card already current is not touched,
    nor, without `refresh` (an export rerun that changed nothing), one blurset wrote with
    other options (`blurset card --pretty-name`); a README someone edited, or that
    blurset did not write, is theirs: kept, and the line says how to replace it."""
    out = Path(hub) / "README.md"
    owner = _core.text_owner(out, "card")
    if owner in ("edited", "foreign"):
        what = "edited since blurset wrote it" if owner == "edited" else "not blurset's"
        print(
            f"blurset export: kept {out} ({what}); `blurset card {build} --hub {hub} --force` "
            "replaces it with the export's card",
            file=sys.stderr,
        )
        return
    if owner == "ours" and not refresh:
        return
    text = make_card(build, noise=[noise] if noise else None, card_dir=Path(hub).resolve(), hub=hub)
    if owner == "absent" or out.read_text(encoding="utf-8") != _core.mark_text(text, "card"):
        outputs.write_marked_text(out, text, command="card")


def drop_hub_card(out: Path) -> None:
    """An export of another target replacing a hub export in `out` takes the hub card
    with the shards it described (README.md, only as blurset wrote it: an edited one is
    the user's)."""
    card = Path(out) / "README.md"
    if _core.text_owner(card, "card") == "ours":
        card.unlink()


def run(args: argparse.Namespace) -> int:
    build: Path = args.build
    if outputs.kind_of(build) is not outputs.OutputKind.BUILD:
        raise InputError(f"not a blurset build (no dataset.json): {build}")
    hub: Path | None = getattr(args, "hub", None)
    if hub is not None:
        _hub_doc(hub, build)  # refused before anything is written
    out: Path = args.out or (hub or build) / "README.md"
    if hub is None and args.out is not None:
        from blurset.services import hub_format

        if hub_format.hub_doc(out.parent) is not None:
            # A card written into a hub export is that export's: its configs and counts.
            hub = out.parent
            _hub_doc(hub, build)
    if out.suffix.lower() != ".md":
        raise ConfigError(f"--out {out}: a dataset card is a Markdown file (.md)")
    outputs.refuse_inside_settings(out)
    # The card of A never lands in B (B's manifest would list it, its README describe A);
    # a hub export of the build takes its card at its top.
    within = hub if hub is not None and out.resolve().parent == hub.resolve() else build
    outputs.refuse_inside_output(out, "--out", within=within)
    if out.is_dir():
        raise ConfigError(f"--out is a folder, not a card file: {out}")
    text = make_card(
        build,
        noise=args.noise,
        previews=args.previews,
        pretty_name=args.pretty_name,
        card_dir=out.resolve().parent,
        hub=hub,
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    # A README that blurset did not write, or that someone edited, is theirs.
    backup = outputs.write_marked_text(out, text, command="card", force=args.force)
    publish.refresh_manifest([out] + ([backup] if backup else []))
    if backup is not None:
        print(f"blurset card: kept the previous {out.name} as {backup}", file=sys.stderr)
    print(f"blurset card: {out}", file=sys.stderr)
    return 0
