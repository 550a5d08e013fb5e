"""`blurset stats`: the statistics of a build, as figures, numbers and a report (DESIGN §7).

The numbers come from blurset-core (`rust/core/src/stats.rs`, where every quantity is
defined): it reads each complete setting's meta.json in parallel and returns one
document. This module writes that document as `stats.json` and CSV, draws the
histograms with matplotlib (Agg, no display needed) and writes `report.md`. Every file
in `--out` is written to a temporary sibling and renamed, so a reader never sees half
a file; `stats.json` is written last.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import math
import re
import sys
import time
from collections import Counter
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from blurset import __version__, _core, layout
from blurset.exceptions import InputError
from blurset.services import outputs, publish
from blurset.services.options import check_range

if TYPE_CHECKING:
    pass

BAR = "#3b6ea8"  # histogram bars (tests look for this colour in the PNGs)
MEDIAN = "#c8553d"

# name -> (title, x label with unit, y label)
FIGURES = {
    "scene_range": (
        "Scene range (far / near)",
        "scene range f / n  (ratio of far to near depth, unitless)",
        "views",
    ),
    "scene_dimension": (
        "Scene dimension",
        "cbrt(dx·dy·dz) of the bounding box  (object units, largest side = 1)",
        "settings",
    ),
    "blur_weight": (
        "Blur weight w_l per level",
        "w_l  (multiplier of trajectory δ, unitless)",
        "views",
    ),
    "factors": ("Scene-dependent factors of w_u", None, "views"),
    "latent_frames": ("Latent frames per blurry image", "latent frames m  (frames)", "views"),
    "motion_px": (
        "Blur extent per level",
        "largest bounding-box corner motion  (px at build resolution)",
        "views",
    ),
    # Each other kind's statistic, as the kind declares its histogram in the core.
    **{stat: (title, xlabel, "views") for _, stat, title, xlabel in _core.kind_figures()},
    "render_psnr": (
        "Render PSNR per image",
        "estimated render PSNR on the object's pixels  (dB)",
        "rendered images",
    ),
    "image_samples": (
        "Samples per image",
        "Cycles samples, every latent frame and both halves  (samples)",
        "rendered images",
    ),
}
FACTORS = [  # (quantity, panel title, x label with unit)
    ("flatness", "Flatness F", "F = (f − n) / max(d)  (ratio)"),
    ("depth_range", "Depth range R", "R = f / n  (ratio)"),
    ("orientation", "Orientation O", "O = max(d) / min(d)  (ratio)"),
    ("w_u", "Scene weight w_u", "w_u = (F·R·O)^(1/3)  (unitless)"),
]
COUNTS = [
    ("objects", "distinct object uids among complete settings"),
    ("settings", "complete settings (`.complete` marker, not `*.partial`)"),
    ("views", "views of complete settings"),
    (layout.IMAGES, "image files: views × level directories (sharp + each blur level)"),
    (
        "sharp_copy_views",
        "held-out views whose blur levels hold the sharp image (Deblur-NeRF's convention): "
        "left out of blur weight, latent frames and blur extent",
    ),
    ("test_settings", "complete settings listed as `test` in splits.json"),
    (
        "test_views",
        "held-out target views of the test settings, Σ |splits.test_views[s]| "
        "(the paper's '52 settings → 156 test images' counts these)",
    ),
    ("test_images", "image files of those views at every level: Σ |test_views[s]| × levels(s)"),
    ("unsplit_settings", "complete settings not yet in splits.json (written when a build ends)"),
    (
        "failures",
        "objects failing now: the latest failures.jsonl record per object (or per setting, "
        "for render QA) whose work is still not complete",
    ),
    ("settings_failed", "settings failing render QA now (records that name a setting)"),
    ("failure_lines_skipped", "failures.jsonl lines that do not parse (torn by a kill)"),
    (
        "licence_skipped",
        "objects `--licenses` leaves out (failures.jsonl stage `license`): skipped by "
        "request, not counted in failures",
    ),
    ("incomplete_settings", "setting directories skipped: `*.partial` or no `.complete` marker"),
    (
        "damaged_settings",
        "complete settings a rerun would redo (a file missing or damaged): counted from "
        "their meta.json, named under `damaged`",
    ),
]


STATS = outputs.OutputKind.STATS


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("build", type=Path, metavar="BUILD", help="a build directory (may be running)")
    p.add_argument(
        "--out",
        type=Path,
        metavar="DIR",
        help="where figures, stats.json, CSV and report.md go (default: BUILD/stats)",
    )
    p.add_argument("--bins", type=int, default=40, help="most histogram bins per panel")
    p.add_argument("--quiet", action="store_true", help="print only where the report is")


def build_stats(build: Path) -> _core.BuildStats:
    """The statistics of a build (blurset-core); InputError names a bad file."""
    return _core.build_stats(Path(build))


def load_stats(build: Path) -> dict[str, Any]:
    """The stats document of a build as a dict."""
    return dict(build_stats(build).to_dict())


def _write_text(path: Path, text: str | Iterable[str]) -> None:
    layout.write_text_atomic(path, text if isinstance(text, str) else "".join(text))


# -- figures ---------------------------------------------------------------------------


def _median(stats: dict, quantity: str) -> float | None:
    return next((s["median"] for s in stats["summary"] if s["quantity"] == quantity), None)


def constant(values: list) -> float | None:
    """The one value all (non-null) values share, or None (also for no values)."""
    v = {x for x in values if x is not None}
    return next(iter(v)) if len(v) == 1 else None


def _number(ax, value: float, what: str) -> None:
    """A panel whose values are all one number: the number, not a one-bar histogram."""
    ax.set_axis_off()
    ax.text(0.5, 0.58, f"{value:.6g}", ha="center", va="center", fontsize=40,
            color=BAR, transform=ax.transAxes)  # fmt: skip
    ax.text(0.5, 0.25, what, ha="center", va="center", fontsize=10, transform=ax.transAxes)


def _hist(ax, values: list[float], max_bins: int, median: float | None) -> None:
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    if v.size and constant(values) is not None:
        _number(ax, float(v[0]), f"all {v.size} values")
        return
    _integer_counts(ax)
    if v.size == 0:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        return
    nbins = int(np.clip(math.isqrt(v.size), 5, max(5, max_bins)))
    lo, hi = float(v.min()), float(v.max())
    if lo > 0 and hi / lo > 100:  # heavy tail (e.g. near at the floor): log bins
        ax.hist(v, bins=np.geomspace(lo, hi, nbins + 1), color=BAR)
        ax.set_xscale("log")
    else:
        ax.hist(v, bins=nbins, color=BAR)
    if median is not None:
        ax.axvline(median, color=MEDIAN, ls="--", lw=1.5, label=f"median {median:.3g}")
        ax.legend(fontsize=8, loc="best", framealpha=0.9)


def _integer_counts(ax) -> None:
    from matplotlib.ticker import MaxNLocator

    ax.yaxis.set_major_locator(MaxNLocator(integer=True))


def _bars(ax, values: list[int]) -> None:
    c = Counter(x for x in values if x is not None)
    if len(c) == 1:
        ((value, n),) = c.items()
        _number(ax, value, f"all {n} values")
        return
    _integer_counts(ax)
    if not c:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
        return
    keys = sorted(c)
    ax.bar([str(k) for k in keys], [c[k] for k in keys], color=BAR)


def _figure(panels: int):
    from matplotlib.figure import Figure  # no pyplot: no global state, Agg canvas

    ncols = 1 if panels <= 1 else 2 if panels <= 4 else 4
    nrows = max(1, math.ceil(panels / ncols))
    width = 6.4 if ncols == 1 else 5.0 * ncols
    fig = Figure(figsize=(width, 3.8 * nrows + 0.4), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[panels:]:
        ax.set_visible(False)
    return fig, axes[:panels]


def _save(fig, path: Path) -> Path:
    layout.write_figure(path, lambda f: fig.savefig(f, format="png", dpi=110))
    return path


def write_figures(stats: dict, out_dir: Path, *, max_bins: int = 40) -> list[Path]:
    """The PNG histograms; returns their paths in report order."""
    c = stats["counts"]
    n_set, n_views = c["settings"], c["views"]
    written = [
        _single_figure(stats, "scene_range", f"{n_views} views, {n_set} settings", out_dir, max_bins),
        _single_figure(stats, "scene_dimension", f"{n_set} settings, {c['objects']} objects",
                       out_dir, max_bins),
    ]  # fmt: skip
    blurry = f"{n_set} settings"
    if c.get("sharp_copy_views"):
        blurry += f"; {c['sharp_copy_views']} held-out sharp copies left out"
    for name in PER_LEVEL:
        by_level = stats.get(name) or {}
        # motion and the per-image figures exist only in builds that record them.
        if name not in ("blur_weight", "latent_frames") and not by_level:
            continue
        written.append(_per_level_figure(stats, name, blurry, out_dir, max_bins))
    # The factors figure follows the blur weights in the report.
    written.insert(
        3, _factors_figure(stats, f"{n_views} views, {n_set} settings", out_dir, max_bins)
    )
    return written


# Each degradation kind's statistic beside motion blur (the core's registry of kinds), to
# the prefix of its level folders: from builds with that kind only.
KINDS = {stat: kind for kind, stat, _, _ in _core.kind_figures()}
# The per-level figures, in report order; latent_frames as bars of counts, the rest as
# histograms. render_psnr and image_samples from --target-psnr builds only: what each
# image cost and reached, per level directory (sharp, blur_1, and each kind's).
PER_LEVEL = (
    "blur_weight", "latent_frames", "motion_px", *KINDS, "render_psnr", "image_samples",
)  # fmt: skip
PER_IMAGE = ("render_psnr", "image_samples")


def level_order(level: str) -> tuple[str, int]:
    """Levels in reading order: a blur level's number, or a level directory (the sharp
    image first, then each kind's prefix and level)."""
    if level.isdigit():
        return "", int(level)
    prefix, _, n = level.rpartition("_")
    return prefix, int(n) if n.isdigit() else -1


def _single_figure(stats: dict, name: str, n_label: str, out_dir: Path, max_bins: int) -> Path:
    title, xlabel, ylabel = FIGURES[name]
    fig, (ax,) = _figure(1)
    _hist(ax, stats[name], max_bins, _median(stats, name))
    ax.set(title=f"{title} — {n_label}", xlabel=xlabel, ylabel=ylabel)
    return _save(fig, out_dir / f"{name}.png")


def _factors_figure(stats: dict, n_label: str, out_dir: Path, max_bins: int) -> Path:
    fig, axes = _figure(len(FACTORS))
    for ax, (q, title, xlabel) in zip(axes, FACTORS, strict=True):
        _hist(ax, stats[q], max_bins, _median(stats, q))
        ax.set(title=title, xlabel=xlabel, ylabel="views")
    fig.suptitle(f"{FIGURES['factors'][0]} — {n_label}")
    return _save(fig, out_dir / "factors.png")


def _per_level_figure(stats: dict, name: str, blurry: str, out_dir: Path, max_bins: int) -> Path:
    """One panel per level, or one number for all when every level has the same."""
    by_level = stats.get(name) or {}
    title, xlabel, ylabel = FIGURES[name]
    levels = sorted(by_level, key=level_order) or ["-"]
    one = constant([x for lvl in by_level for x in by_level[lvl]]) if by_level else None
    if one is not None:
        # One number at every level (a fixed --latents): one panel says it.
        n = sum(x is not None for lvl in by_level for x in by_level[lvl])
        fig, (ax,) = _figure(1)
        _number(ax, one, f"every blurry image at levels {', '.join(levels)} ({n} images)")
        ax.set(title=f"{title} — {blurry}")
        return _save(fig, out_dir / f"{name}.png")
    fig, axes = _figure(len(levels))
    for ax, lvl in zip(axes, levels, strict=True):
        values = by_level.get(lvl, [])
        n = sum(x is not None for x in values)
        if name == "latent_frames":
            _bars(ax, values)
        else:
            _hist(ax, values, max_bins, _median(stats, f"{name}_{lvl}"))
        per_image = name in PER_IMAGE
        what = f"{n} images" if per_image else f"{n} blurry views"
        label = lvl if per_image else f"level {lvl}"
        if name in KINDS:
            what, label = f"{n} views", f"{KINDS[name]}_{lvl}"
        panel = f"{label} ({what})" if by_level else "no blur levels (sharp only)"
        ax.set(title=panel, xlabel=xlabel, ylabel=ylabel)
    fig.suptitle(f"{title} — {blurry}")
    return _save(fig, out_dir / f"{name}.png")


# -- CSV -------------------------------------------------------------------------------


def _cells(column: list[Any]) -> list[str]:
    """CSV cells of one column: repr of numbers (exact round trip), "" for None,
    strings quoted only when they need it."""
    if column and isinstance(column[0], str):
        if not any(map(_NEEDS_QUOTE.search, set(column))):
            return column
        return [_quote(x) for x in column]
    if None in column:
        return ["" if x is None else repr(x) for x in column]
    return list(map(repr, column))


_NEEDS_QUOTE = re.compile(r'[,"\r\n]')


def _quote(x: str) -> str:
    if _NEEDS_QUOTE.search(x):
        buf = io.StringIO()
        csv.writer(buf, lineterminator="").writerow([x])
        return buf.getvalue()
    return x


def _csv(header: list[str], columns: list[list[Any]], chunk: int = 20_000) -> Iterator[str]:
    """A CSV table, built column by column and yielded `chunk` rows at a time (memory
    stays small at 340,000 views × 20 columns)."""
    n = len(columns[0])
    if any(len(c) != n for c in columns) or len(header) != len(columns):
        raise ValueError("CSV columns of unequal length")
    yield ",".join(header) + "\n"
    for a in range(0, n, chunk):
        cells = [_cells(c[a : a + chunk]) for c in columns]
        yield "\n".join(map(",".join, zip(*cells, strict=True))) + "\n"


def write_csvs(stats: dict, out_dir: Path) -> list[Path]:
    """views.csv (one row per view), settings.csv, summary.csv, counts.csv."""
    per_level = [
        (f"{name}_{lvl}", stats[name][lvl])
        for name in ("blur_weight", "latent_frames", "motion_px", "render_psnr", "image_samples")
        for lvl in sorted(stats.get(name) or {}, key=level_order)
    ]
    view_cols = ["scene_range", "flatness", "depth_range", "orientation", "w_u"]
    settings = stats["settings"]
    names = [s["name"] for s in settings]
    uids = [s["uid"] for s in settings]
    files = {
        "views.csv": _csv(
            ["setting", "uid", "view", *view_cols, *(n for n, _ in per_level)],
            [
                [names[i] for i in stats["view_setting"]],
                [uids[i] for i in stats["view_setting"]],
                stats["view_index"],
                *(stats[c] for c in view_cols),
                *(v for _, v in per_level),
            ],
        ),
        "settings.csv": _csv(
            [
                "setting",
                "uid",
                "theta0_deg",
                "views",
                layout.IMAGES,
                "bbox_dx",
                "bbox_dy",
                "bbox_dz",
                "scene_dimension",
            ],
            [
                names,
                uids,
                *([s[k] for s in settings] for k in ("theta0_deg", "views", layout.IMAGES)),
                *([s["bbox_dims"][j] for s in settings] for j in range(3)),
                stats["scene_dimension"],
            ],
        ),  # fmt: skip
    }
    keys = ["quantity", "unit", "n", "min", "median", "max", "mean"]
    files["summary.csv"] = _csv(keys, [[s[k] for s in stats["summary"]] for k in keys])
    files["counts.csv"] = _csv(
        ["count", "value"], [[k for k, _ in COUNTS], [stats["counts"][k] for k, _ in COUNTS]]
    )
    for name, text in files.items():
        _write_text(out_dir / name, text)
    return [out_dir / n for n in files]


# -- report ----------------------------------------------------------------------------


def _fmt(x: Any) -> str:
    if x is None:
        return "–"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def report_markdown(stats: dict, figures: list[Path]) -> str:
    c = stats["counts"]
    lines = [
        f"# blurset stats: `{stats['build']}`",
        "",
        f"Generated {stats['generated']} by blurset {stats['blurset_version']} from the meta.json "
        f"of {c['settings']} complete settings. Numbers: `stats.json` (and CSV); every one "
        "traces back to a meta.json field.",
        "",
        *(
            [
                "**The build is not finished**: " + "; ".join(stats["provisional"]) + ". These "
                "numbers describe the complete settings found when they were made.",
                "",
            ]
            if stats.get("provisional")
            else []
        ),
        "## Counts",
        "",
        "| count | value | definition |",
        "|---|---:|---|",
    ]
    lines += [f"| {k} | {_fmt(c[k])} | {d} |" for k, d in COUNTS]
    if c["test_settings"] is None:
        lines += ["", "No splits.json yet (it is written when a build ends): test counts are –."]
    lines += [
        "",
        "## Summary",
        "",
        "| quantity | unit | n | min | median | max | mean |",
        "|---|---|---:|---:|---:|---:|---:|",
    ]
    lines += [
        f"| {s['quantity']} | {s['unit']} | {s['n']} | {_fmt(s['min'])} | {_fmt(s['median'])} "
        f"| {_fmt(s['max'])} | {_fmt(s['mean'])} |"
        for s in stats["summary"]
    ]
    lines += ["", "Median: the middle value (mean of the two middle ones for an even n).", ""]
    lines += ["## Definitions", ""]
    lines += [f"- **{q['name']}** ({q['unit']}): {q['definition']}" for q in stats["quantities"]]
    lines += ["", "## Figures", ""]
    for f in figures:
        lines += [f"![{f.stem}]({f.name})", ""]
    lines += _damaged_lines(stats.get("damaged") or [])
    lines += _skipped_lines(stats)
    return "\n".join(lines)


def _skipped_lines(stats: dict) -> list[str]:
    """report.md's section on what the numbers leave out: incomplete settings, failed
    objects and objects skipped by --licenses (the first 50 of each named)."""
    skips = stats.get("licence_skipped") or []
    if not (stats["incomplete"] or stats["failures"] or skips):
        return []
    lines = ["## Skipped", ""]
    shown = stats["incomplete"][:50]
    if shown:
        more = len(stats["incomplete"]) - len(shown)
        lines += [
            f"- incomplete settings: {', '.join(f'`{n}`' for n in shown)}"
            + (f" and {more} more" if more else "")
        ]
    for f in stats["failures"][:50]:
        what = f"setting `{f['setting']}`" if f.get("setting") else f"object `{f['uid']}`"
        lines += [f"- failed {what} ({f.get('stage') or '?'}): {f.get('reason') or ''}"]
    if len(stats["failures"]) > 50:
        lines += [f"- and {len(stats['failures']) - 50} more failed objects (failures.jsonl)"]
    lines += [f"- skipped object `{f['uid']}` ({f.get('reason') or 'licence'})" for f in skips[:50]]
    if len(skips) > 50:
        lines += [f"- and {len(skips) - 50} more objects skipped by --licenses"]
    return [*lines, ""]


def _damaged_lines(damaged: list[dict]) -> list[str]:
    """report.md's section on the complete settings a rerun would redo (counted all the
    same): each named with what is wrong."""
    if not damaged:
        return []
    lines = [
        "## Damaged",
        "",
        "Counted from their meta.json; a rerun of the build redoes them.",
        "",
    ]
    lines += [f"- `{d['setting']}`: {d['problem']}" for d in damaged[:50]]
    if len(damaged) > 50:
        lines += [f"- and {len(damaged) - 50} more damaged settings"]
    return [*lines, ""]


def terminal_summary(stats: dict, report: Path) -> str:
    c = stats["counts"]
    test = (
        f"test: {c['test_settings']} settings, {c['test_views']} views, {c['test_images']} images"
        if c["test_settings"] is not None
        else "no splits.json yet"
    )
    lines = [
        f"blurset stats: {stats['build']}"
        + (
            " (not finished: " + "; ".join(stats["provisional"]) + ")"
            if stats.get("provisional")
            else ""
        ),
        f"  {c['settings']} settings, {c['objects']} objects, {c['views']} views, "
        f"{c['images']} images; {test}",
        f"  skipped: {c['incomplete_settings']} incomplete settings; "
        f"{c['failures']} failed objects"
        + (f"; {c['licence_skipped']} skipped by --licenses" if c.get("licence_skipped") else ""),
    ]
    for s in stats["summary"]:
        q = s["quantity"]
        if q in ("flatness", "depth_range", "orientation") or q.startswith(("latent", "motion")):
            continue
        lines.append(
            f"  {q:<16} min {_fmt(s['min']):>8}  median {_fmt(s['median']):>8}  "
            f"max {_fmt(s['max']):>8}  ({s['unit']})"
        )
    lines.append(f"  -> {report}")
    return "\n".join(lines)


# -- the command -----------------------------------------------------------------------


def write_stats(
    stats: dict, out_dir: Path, *, max_bins: int = 40, document: _core.BuildStats | None = None
) -> Path:
    """Figures, CSV, report.md, then stats.json into `out_dir`; returns the report path.

    `document` is the core's stats `stats` came from, if at hand: the core writes it
    (no re-encoding of 100 MB at 10,000 settings in Python) with two fields in front.
    """
    out_dir.mkdir(parents=True, exist_ok=True)
    # Until stats.json is written the folder is not yet a statistics folder by its
    # record: this mark lets the rerun of a stopped (or disk-full) run take it back.
    unfinished = out_dir / UNFINISHED
    if not (out_dir / layout.STATS).is_file():
        unfinished.touch()
    head = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "blurset_version": __version__}
    stats = {**head, **stats}
    figures = write_figures(stats, out_dir, max_bins=max_bins)
    write_csvs(stats, out_dir)
    report = out_dir / "report.md"
    _write_text(report, report_markdown(stats, figures) + "\n")
    if document is None:
        _write_text(out_dir / layout.STATS, json.dumps(stats, allow_nan=False) + "\n")
    else:
        document.write(out_dir / layout.STATS, head["generated"])
    unfinished.unlink(missing_ok=True)
    return report


# The mark of a statistics folder whose stats.json is not written yet.
UNFINISHED = ".stats.unfinished"


def own_files() -> set[str]:
    """The names stats writes into its folder."""
    return {f"{n}.png" for n in FIGURES} | {
        "views.csv",
        "settings.csv",
        "summary.csv",
        "counts.csv",
        "report.md",
        layout.STATS,
    }


def _claim(out_dir: Path, build: Path) -> None:
    """The output owner's claim, and also a folder a stopped stats run left: its mark
    and nothing but files stats writes (a user's file there is still refused)."""
    try:
        outputs.claim(out_dir, STATS, "--out", within=build)
    except ValueError:
        left = out_dir / UNFINISHED
        names = {p.name for p in out_dir.iterdir() if not p.name.startswith(".")}
        if not (left.is_file() and names <= own_files()):
            raise


def run(args: argparse.Namespace) -> int:
    check_range("--bins", args.bins, 1)
    build = args.build.expanduser().absolute()
    kind = outputs.kind_of(build) if build.is_dir() else None
    if kind is not None and kind is not outputs.OutputKind.BUILD:
        raise InputError(
            f"BUILD is a blurset {kind.label} ({kind.record}), not a build: stats describe "
            f"a build: {build}"
        )
    out_dir = (args.out or build / "stats").expanduser().absolute()
    outputs.refuse_inside_settings(out_dir)
    outputs.refuse_inside_output(out_dir, "--out", within=build)
    t0 = time.perf_counter()
    document = build_stats(build)  # names what is not a build, before anything is written
    # Stats may read a running build: they say what they describe.
    state = outputs.build_state(build)
    provisional = list(state.provisional)
    # The core's cheap check, run once with the statistics (it decodes EXRs).
    damaged = [(d["setting"], d["problem"]) for d in document.to_dict()["damaged"]]
    if damaged:
        # Counted from their meta.json all the same: said, not passed off as whole.
        shown = ", ".join(f"{n} ({p})" for n, p in damaged[:3])
        more = f" and {len(damaged) - 3} more" if len(damaged) > 3 else ""
        provisional.append(f"damaged settings: {shown}{more}")
    # What the figures and the summary read: the document and whether it is provisional.
    stats: dict[str, Any] = {**document.to_dict(), "provisional": provisional}
    t_read = time.perf_counter() - t0
    # Refused before the lock creates anything; only the build it describes may hold it.
    _claim(out_dir, build)
    with outputs.lock(out_dir, STATS):
        _claim(out_dir, build)
        report = write_stats(stats, out_dir, max_bins=args.bins, document=document)
        # Statistics written into a published build keep its manifest whole.
        publish.refresh_manifest(
            [p for p in out_dir.rglob("*") if p.is_file() and not p.name.startswith(".")]
        )
    if args.quiet:
        print(report)
    else:
        print(terminal_summary(stats, report))
        print(
            f"  ({stats['counts']['settings']} meta.json read in {t_read:.2f} s, "
            f"written in {time.perf_counter() - t0 - t_read:.2f} s)"
        )
    return 0


if __name__ == "__main__":
    from blurset.cli import main

    sys.exit(main(["stats", *sys.argv[1:]]))
