"""Write the benchmark pages (docs/benchmarks/) from bench/results.json, with plots.

Run by `make docs`. Every number and figure on these pages comes from the results file
that `make bench` writes; nothing is kept by hand. Results are grouped by their names
(`settings_per_hour_<preset>`, `render_parity_<preset>_level<l>_<budget>`, …); a preset
or benchmark added later lands in its group's plots, and a result no group knows is
listed on the index page, so nothing measured goes missing.
"""

from __future__ import annotations

import ast
import json
import math
import re
import shutil
import sys
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import matplotlib.ticker  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
import figures  # noqa: E402
import noise_guide  # noqa: E402
import shake_guide  # noqa: E402
from common import sanitize  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results.json"
# `make bench-gpu` (bench/run.py --device gpu): the same benchmarks on a GPU node.
RESULTS_GPU = ROOT / "bench" / "results_gpu.json"
OUT = ROOT / "docs" / "benchmarks"
PNG_FLOOR_DB = 58.9  # PSNR of 8-bit quantization alone: 1 / (255² · 12) in MSE

PRESETS = re.compile(r"^settings_per_hour_(?:(?P<res>\d+)px_)?(?P<preset>[a-z][a-z0-9_]*)$")
PARITY = re.compile(
    r"^render_parity_(?P<preset>[a-z0-9]+)_level(?P<level>\d)_(?P<budget>x\d+|\w+)$"
)
NOISE = re.compile(
    r"^render_noise_(?P<preset>[a-z0-9]+)_(?P<motion>moving|zero_trajectory)_(?P<scheme>\w+)$"
)
COST = re.compile(
    r"^(blur_cost_vs_sharp\w*|motion_blur_cost_vs_sharp|render_region_saving|exr_crop_saving)$"
)
LIGHT = re.compile(r"^light_paths_(?P<glb>.+)$")
GAIN = re.compile(r"^denoise_gain_(?P<glb>.+)_(?P<res>\d+)px$")
TARGET = re.compile(
    r"^target_(?P<res>\d+)px_(?P<db>[\d.]+)db(?:_(?P<method>motion_blur|average|auto))?_(?P<model>.+)$"
)
SPEED = re.compile(r"^target_speed_(?P<res>\d+)px_(?P<model>.+)$")
KINDS = re.compile(
    r"^target_kinds_(?P<res>\d+)px_(?P<db>[\d.]+)db_(?P<kind>sharp|[a-z]+)_(?P<model>.+)$"
)
DETAIL = re.compile(r"^target_detail_(?P<res>\d+)px_(?P<model>.+)$")
HALF_NOISE = re.compile(r"^half_noise_(?P<model>.+)_(?P<estimator>plain|about_merged)$")
DEVICE_COSTS = re.compile(r"^device_costs_(?:(?P<cpu>cpu)_)?(?P<res>\d+)px$")
ONE_SETTING = re.compile(r"^one_setting_(?P<res>\d+)px_(?P<preset>\w+)$")
NOT_PRESETS = {"settings_per_hour_2_vs_1_workers"}

plt.rcParams.update({"figure.dpi": 110, "font.size": 9, "axes.grid": True, "grid.alpha": 0.3})


def _cell(text: object) -> str:
    return sanitize(" ".join(str(text).split())).replace("|", "\\|")


def _match(pattern: re.Pattern[str], name: str) -> re.Match[str]:
    """A result name's fields: main() sorts every result into its section by these
    patterns, so each name a section reads matches its pattern."""
    m = pattern.match(name)
    assert m is not None, name
    return m


def _machine(results: list[dict]) -> str:
    """What the results were measured on, from their `device` fields."""
    seen = []
    for r in results:
        d = r.get("device")
        if isinstance(d, dict):
            text = f"{d.get('backend', '?')}: {', '.join(d.get('devices', []))}"
            if d.get("kernel"):
                text += f" (Cycles kernel {d['kernel']})"
        elif isinstance(d, str):
            text = d
        else:
            continue
        if text not in seen:
            seen.append(text)
    # A bare backend name ("CPU") says less than an entry that names the device too.
    seen = [t for t in seen if not any(o != t and o.startswith(f"{t}:") for o in seen)]
    return "; ".join(seen) or "not recorded"


def _save(fig, name: str) -> str:
    fig.tight_layout()
    fig.savefig(OUT / name)
    plt.close(fig)
    return f"![{name}]({name})"


def _flags(contender: str) -> str:
    """`fast preset {'blur_method': 'motion_blur', …}: …` as the build flags it used."""
    m = re.search(r"\{.*\}", contender)
    if not m:
        return (
            "`blurset build …` (the defaults)"
            if contender.startswith("paper")
            else _cell(contender)
        )
    try:
        options = ast.literal_eval(m.group(0))
    except (ValueError, SyntaxError):
        return _cell(contender)
    flags = []
    for k, v in options.items():
        if k == "latents_auto" and v is True:
            flags.append("--latents auto")
        elif v is True:
            flags.append(f"--{k.replace('_', '-')}")
        else:
            flags.append(f"--{k.replace('_', '-')} {v}")
    return f"`blurset build … {' '.join(flags)}`"


def _collapsed(title: str, lines: list[str]) -> list[str]:
    """A table folded under a title (pymdownx.details), so the plot leads the page."""
    return [f'??? info "{title}"', ""] + [f"    {line}" if line else "" for line in lines] + [""]


def _fmt(x: object, digits: int = 2) -> str:
    if isinstance(x, float):
        return f"{x:.{digits}f}"
    return "" if x is None else str(x)


def _count(x: object) -> str:
    """A count recorded as a mean (samples, calls per view): whole, with thousands marked."""
    return f"{round(x):,}" if isinstance(x, int | float) else ""


def _calls_share(t: dict, build: dict) -> float | None:
    """The fitted share of a build's seconds per view that its render calls cost."""
    a, b = t.get("s_per_call"), t.get("s_per_ksample")
    calls, samples = build.get("calls_per_view"), build.get("samples_per_view")
    if a is None or b is None or calls is None or samples is None:
        return None
    call_s, sample_s = float(a) * calls, float(b) * samples / 1000.0
    return call_s / (call_s + sample_s) if call_s + sample_s > 0 else None


# ----------------------------------------------------------------------------- presets


def presets_page(rs: list[dict]) -> list[str]:
    """The 128 px run (the default size), then one section per other size measured: a
    size's ratios are to the paper preset of its own run."""
    by_res: dict[str, list[dict]] = defaultdict(list)
    for r in rs:
        by_res[_match(PRESETS, r["name"])["res"] or ""].append(r)
    out = _presets_section(by_res.pop("", []))
    for res in sorted(by_res, key=int):
        out += _presets_section(by_res[res], res)
    return out


def _paper_of(r: dict) -> float:
    """The settings per hour of the paper preset a result was measured against (its run's):
    a result re-measured later keeps its own run's ratio."""
    sph, ratio = r.get("settings_per_hour"), r.get("ratio")
    return round(sph / ratio, 6) if sph and ratio else 0.0


def _presets_section(rs: list[dict], res: str = "") -> list[str]:
    rows = {_match(PRESETS, r["name"])["preset"]: r for r in rs}
    if res:
        # The newest run at this size: the results measured against its paper preset
        # (an earlier run's results are history, which git keeps).
        newest = _paper_of(rows["paper"]) if "paper" in rows else None
        group = [r for r in rs if _paper_of(r) == newest] if newest is not None else rs
        g_rows = {_match(PRESETS, r["name"])["preset"]: r for r in group}
        objects = sorted({o for r in group for o in r.get("objects", [])})
        ref = group[0].get("reference", "not recorded")
        denoised = any("'denoise': 'oidn'" in r.get("contender", "") for r in group)
        corrected = any("reference_noise_psnr_blur_db" in r for r in group)
        if denoised and not corrected:
            ref += (
                "; a denoised image was scored as measured, its reference's own noise "
                "counted against it: its render PSNR reads low"
            )
        return [
            "",
            f"## At {res} px",
            "",
            f"One run at {res} px: each ratio is to that run's paper preset. An empty render "
            "PSNR was not measured (the paper preset's render reference costs as much as its "
            "build); the bar then takes the paper preset to be above the floor.",
            "",
            f"The run ({', '.join(f'`{o}`' for o in objects)}; "
            f"{_fmt(group[0].get('views_measured'))} view, "
            f"{_fmt(group[0].get('repeats'))} repeat; references: {ref}).",
            "",
            *_presets_table(g_rows, f"presets_{res}.png", f"{res} px"),
        ]
    out = [
        "# Presets: settings per hour and accuracy",
        "",
        "Each preset builds the same setting of each measured object side by side in one run",
        "of `bench/bench_settings_per_hour.py`; settings per hour are extrapolated from the",
        "views measured, and PSNR is measured over every blurry and sharp image against",
        "converged references (the guide [Speed or accuracy](../guide/speed.md) says what each",
        "preset is for). The dotted line is the 8-bit floor: a PNG's own rounding alone is",
        f"{PNG_FLOOR_DB} dB, so an image well above the line differs from its reference by",
        "less than the PNG format itself does.",
        "",
    ]
    if not rows:
        return out + ["No `settings_per_hour_<preset>` result in bench/results.json yet."]
    return out + _presets_table(rows, "presets.png", "")


def _log_x(ax) -> None:
    """A log x-axis labelled at 1, 2 and 5 of each decade in plain numbers, no minor
    labels: matplotlib's default labels every minor tick of a short range in scientific
    notation, and they print over each other."""
    ax.set_xscale("log")
    ax.xaxis.set_major_locator(matplotlib.ticker.LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.xaxis.set_minor_locator(matplotlib.ticker.LogLocator(base=10, subs=tuple(range(2, 10))))
    ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())


# Short column headers, so the table fits a page without scrolling sideways; the line
# under the table says what they mean.
# Two tables of few columns each: one table of all of them scrolls sideways at 1280 px
# (the page's content column is about 600 px wide beside the navigation).
PRESET_COLUMNS = [
    ("psnr_blur_db", "blur dB"),
    ("psnr_sharp_db", "sharp dB"),
]
PRESET_QUALITY_COLUMNS = [
    ("render_psnr_blur_db", "blur render dB"),
    ("render_psnr_sharp_db", "sharp render dB"),
    ("detail_ratio_blur", "blur detail"),
    ("detail_ratio_sharp", "sharp detail"),
]


def _presets_figure(rows: dict, names: list[str], png: str) -> str:
    """Settings per hour per preset, and each preset's accuracy against its speed."""
    sph = [rows[p].get("settings_per_hour", rows[p].get("ratio")) for p in names]
    fig, axes = plt.subplots(1, 2, figsize=(9.5, 3.6))
    ax = axes[0]
    ax.barh(names[::-1], sph[::-1], color="#3f51b5")
    _log_x(ax)
    ax.set_xlabel("settings per hour (log)")
    for y, v in enumerate(sph[::-1]):
        ax.text(v, y, f" {v:.2f}", va="center", fontsize=8)
    ax.set_xlim(right=max(sph) * 4)
    ax = axes[1]
    placed: list[tuple[float, float]] = []  # label anchors (log10 x, dB) already drawn
    for i, p in enumerate(names):
        r = rows[p]
        x, yb, ys = r.get("settings_per_hour"), r.get("psnr_blur_db"), r.get("psnr_sharp_db")
        if x is None:
            continue
        color = f"C{i % 10}"
        ys_ = [y for y in (yb, ys) if y is not None]
        if len(ys_) == 2:
            ax.plot([x, x], ys_, color=color, lw=1, alpha=0.5)
        if yb is not None:
            ax.scatter([x], [yb], marker="o", color=color)
        if ys is not None:
            ax.scatter([x], [ys], marker="s", color=color)
        if ys_:
            # Presets close on both axes would print their names over each other: each
            # next one goes on the left of its marker, then a line lower.
            here = (math.log10(x), max(ys_))
            n = sum(abs(here[0] - a) < 0.15 and abs(here[1] - b) < 1.5 for a, b in placed)
            placed.append(here)
            left = n % 2 == 1
            ax.annotate(
                p, (x, max(ys_)), fontsize=8, textcoords="offset points",
                xytext=(-6 if left else 4, 4 - 10 * (n // 2)), ha="right" if left else "left",
            )  # fmt: skip
    ax.scatter([], [], marker="o", color="grey", label="blurry images")
    ax.scatter([], [], marker="s", color="grey", label="sharp images")
    ax.axhline(PNG_FLOOR_DB, ls=":", color="grey", label="8-bit floor")
    _log_x(ax)
    ax.set_xlabel("settings per hour (log)")
    ax.set_ylabel("PSNR against the reference, dB")
    ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.2), ncol=3)
    return _save(fig, png)


def _presets_table(rows: dict, png: str, res: str, explain: bool = True) -> list[str]:
    out: list[str] = []
    names = sorted(rows, key=lambda p: (p != "paper", -rows[p].get("settings_per_hour", 0)))
    out += [_presets_figure(rows, names, png), ""]
    cols = [c for c in PRESET_COLUMNS if any(c[0] in rows[p] for p in names)]
    sizes = sorted({rows[p]["resolution"] for p in names if "resolution" in rows[p]})
    paper = any(rows[p].get("ratio") for p in names)
    head = ["preset", "settings/h"] + (["× paper"] if paper else []) + [t for _, t in cols]
    if len(sizes) > 1:
        head.append("px")
    out += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for p in names:
        r = rows[p]
        cells = [f"`{p}`", _fmt(r.get("settings_per_hour"))]
        if paper:
            # Each result's own ratio: to the paper preset of the run that measured it.
            cells.append(f"{r['ratio']:.1f}×" if r.get("ratio") else "")
        cells += [_fmt(r.get(k), 1 if "db" in k else 2) for k, _ in cols]
        if len(sizes) > 1:
            cells.append(_fmt(r.get("resolution")))
        out.append("| " + " | ".join(cells) + " |")
    quality = [c for c in PRESET_QUALITY_COLUMNS if any(c[0] in rows[p] for p in names)]
    if quality:
        head = ["preset"] + [t for _, t in quality]
        out += ["", "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
        for p in names:
            cells = [f"`{p}`"] + [_fmt(rows[p].get(k), 1 if "db" in k else 2) for k, _ in quality]
            out.append("| " + " | ".join(cells) + " |")
    size = f" Every preset at {sizes[0]} px." if len(sizes) == 1 else ""
    out += [
        "",
        "blur / sharp: the blurry / sharp images; dB: their PSNR against the reference;"
        " render dB: the render PSNR; detail: the detail ratio." + size,
    ]
    out += ["", "What each preset ran:", ""]
    for p in names:
        out.append(f"- `{p}`: {_flags(rows[p].get('contender', ''))}")
    out += _verdicts(rows, names, res, explain) + _pairs(rows, names, res)
    return out


VERDICT_CHECKS = {
    "sharp_accurate": "sharp render PSNR ≥ min(paper's, 8-bit floor)",
    "blur_accurate": "blurry render PSNR ≥ min(paper's, 8-bit floor)",
    "blur_vs_continuous": "blurry PSNR against the continuous blur ≥ paper's",
    "parity": "blurry and sharp render PSNR within 0.5 dB, or both ≥ the floor",
    "detail": "detail ratios within [0.95, 1.05]",
    "speed_10x": "≥ 10× the paper preset's settings per hour",
}


def _verdicts(rows: dict, names: list[str], res: str = "", explain: bool = True) -> list[str]:
    """Issue 28's bar, as the bench judged each preset against the paper preset (`explain`:
    spell the checks out; not again for a size's earlier runs)."""
    judged = [p for p in names if isinstance(rows[p].get("verdict"), dict)]
    if not judged:
        return []
    out = ["", f"{'###' if res else '##'} Against the bar{f' at {res}' if res else ''}", ""]
    if explain:
        out += [
            "A preset is a cheaper way to make the paper's pairs when every check holds",
            "(means over the images of all objects; the bench's `verdict`):",
            "",
            *[f"- **{k.replace('_', ' ')}**: {t}" for k, t in VERDICT_CHECKS.items()],
        ]
    # Spaces, not the keys' underscores: a header can wrap, and the table fits the page.
    head = ["preset", *(k.replace("_", " ") for k in VERDICT_CHECKS), "all"]
    out += ["", "| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for p in judged:
        v = rows[p]["verdict"]
        marks = ["✓" if v.get(k) else "✗" for k in [*VERDICT_CHECKS, "all"]]
        out.append("| " + " | ".join([f"`{p}`", *marks]) + " |")
    return out


def _pairs(rows: dict, names: list[str], res: str = "") -> list[str]:
    """Render PSNR of blurry and sharp per object: parity is a property of each pair, and
    a mean over objects can hide a pair that is not one."""
    have = [
        p
        for p in names
        if any(
            o.get("render_psnr_blur_db") is not None
            for o in (rows[p].get("per_object") or {}).values()
        )
    ]
    if not have:
        return []
    objects = sorted({u for p in have for u in rows[p]["per_object"]})
    lines = ["| preset | " + " | ".join(f"`{u}`" for u in objects) + " |"]
    lines.append("|" + " --- |" * (len(objects) + 1))
    for p in have:
        cells = []
        for u in objects:
            o = rows[p]["per_object"].get(u)
            if o is None:
                cells.append("")
                continue
            b, s = o.get("render_psnr_blur_db"), o.get("render_psnr_sharp_db")
            gap = "" if b is None or s is None else f" ({b - s:+.1f})"
            cells.append(f"{_fmt(b, 1)} / {_fmt(s, 1)}{gap}")
        lines.append("| " + " | ".join([f"`{p}`", *cells]) + " |")
    return [
        "",
        f"{'###' if res else '##'} Per object{f' at {res}' if res else ''}",
        "",
        "Render PSNR of the blurry / sharp images of each object, dB (blurry minus sharp in",
        "brackets: a pair at parity is within ±0.5).",
        "",
        *lines,
    ]


def denoise_gain_lines(rs: list[dict]) -> list[str]:
    """What the denoiser buys a sharp image, per object and size (bench_denoise_gain)."""
    if not rs:
        return []
    out = [
        "",
        "## What the denoiser buys, by size",
        "",
        "`bench/bench_denoise_gain.py`: one sharp view of each object rendered with its guide",
        "passes at several sample counts, scored undenoised and denoised (`--denoise oidn`)",
        "against a converged render; the samples each needs to reach the 8-bit floor are read",
        "off its curve. Render time is close to proportional to samples, so their ratio is",
        "the render time the denoiser saves, before its own time.",
        "",
        "| object | px | undenoised: samples for the floor | OIDN: samples | ratio "
        "| OIDN detail ratio | denoise s |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rs, key=lambda r: (r.get("resolution", 0), r["name"])):
        m = _match(GAIN, r["name"])
        samples = r.get("samples", [])
        detail = r.get("oidn_detail", [])
        det = f"{min(detail):.3f}–{max(detail):.3f}" if detail else ""
        den = r.get("denoise_s", [])
        ratio = r.get("ratio")
        ratio = f"{ratio:.2f}" if isinstance(ratio, float) and math.isfinite(ratio) else "–"
        raw_n, oidn_n = r.get("raw_samples_at_floor"), r.get("oidn_samples_at_floor")
        above = f"> {max(samples)}" if samples else "–"
        out.append(
            f"| `{m['glb']}` | {m['res']} | {above if raw_n is None else f'{raw_n:.0f}'} | "
            f"{above if oidn_n is None else f'{oidn_n:.0f}'} | {ratio} | {det} | "
            f"{_fmt(max(den) if den else None)} |"
        )
    return out


# -------------------------------------------------------------------------- render noise


def _budget_factor(b: str) -> float | None:
    return float(b[1:]) if b.startswith("x") and b[1:].isdigit() else None


def render_noise_page(parity: list[dict], noise: list[dict]) -> list[str]:
    out = [
        "# Render noise of a blurry/sharp pair",
        "",
        "A blurry image should differ from its sharp truth by the blur, not by Monte Carlo",
        "noise. These benchmarks render one view of a demo object as a build renders it and",
        "measure the render-noise MSE of the blurry image over the sharp image's, against",
        "references rendered with many times the samples on other seeds: 1× is a pair at",
        "parity, and 1.12× is 0.5 dB. The guide [Speed or accuracy](../guide/speed.md)",
        "explains the sample budget these numbers chose.",
        "",
    ]
    if parity:
        out += _parity_section(parity)
    if noise:
        out += _subsets_section(noise)
    if not parity and not noise:
        out.append("No `render_parity_*` or `render_noise_*` result in bench/results.json yet.")
    return out


def _parity_section(parity: list[dict]) -> list[str]:
    out = [
        "## The parity budget",
        "",
        "Blurry over sharp render-noise MSE with the budget split flat at F times the",
        "preset's samples (`--samples-total F·S --blur-budget flat`, lines), and with the",
        "default parity budget (markers at the right).",
        "",
    ]
    by_preset: dict[str, dict] = defaultdict(lambda: defaultdict(dict))
    for r in parity:
        m = _match(PARITY, r["name"])
        by_preset[m["preset"]][int(m["level"])][m["budget"]] = r
    presets = sorted(by_preset, key=lambda p: (p != "paper", p))
    fig, axes = plt.subplots(1, len(presets), figsize=(4.6 * len(presets), 3.4), sharey=True)
    axes = [axes] if len(presets) == 1 else list(axes)
    for ax, preset in zip(axes, presets, strict=True):
        _parity_axes(ax, preset, by_preset[preset])
    axes[0].set_ylabel("blurry / sharp render-noise MSE")
    out += [_save(fig, "parity.png"), ""]
    table = ["| result | blurry / sharp MSE | motion, px | what was rendered |"]
    table += ["| --- | --- | --- | --- |"]
    for r in parity:
        table.append(
            f"| `{r['name']}` | {r['ratio']:.2f}× | {_fmt(r.get('motion_px'), 1)} | "
            f"{_cell(r.get('contender', ''))} |"
        )
    out += _collapsed("Every result of the plot", table)
    return out


def _parity_axes(ax, preset: str, levels: dict[int, dict[str, dict]]) -> None:
    """One preset's panel: a line per level over the flat budgets, a marker for each other."""
    xmax = max((_budget_factor(b) or 1 for lv in levels.values() for b in lv), default=1)
    for level in sorted(levels):
        flat = sorted(
            (_budget_factor(b), r["ratio"]) for b, r in levels[level].items() if _budget_factor(b)
        )
        line = None
        if flat:
            (line,) = ax.plot(
                [f for f, _ in flat], [v for _, v in flat], "o-", label=f"level {level}"
            )
        other = [(b, r) for b, r in levels[level].items() if not _budget_factor(b)]
        for b, r in other:
            ax.plot(
                [xmax * 1.6],
                [r["ratio"]],
                "D",
                color=line.get_color() if line else None,
                label=f"level {level}, {b}" if not line else None,
            )
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.axhline(1.12, color="grey", lw=0.8, ls=":")
    ax.set_xscale("log", base=2)
    ax.set_yscale("log")
    ticks = [2**k for k in range(int(xmax).bit_length())] + [xmax * 1.6]
    ax.set_xticks(ticks, [f"{t:g}" for t in ticks[:-1]] + ["parity"])
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
    ax.set_yticks([0.25, 0.5, 1, 2, 4, 8])
    ax.set_title(f"{preset} preset")
    ax.set_xlabel("F: the budget split flat at F times the preset's")
    ax.legend(fontsize=7)


def _subsets_section(noise: list[dict]) -> list[str]:
    out = [
        "## Sample subsets or a seed per frame",
        "",
        "The same ratio with the preset's budget split flat: the latent frames as sample",
        "subsets of one sequence (`--latent-sampling subsets`, the default) or on a seed",
        "each (`independent`); at zero motion and along a moving level-4 trajectory.",
        "`adaptive` is Cycles' adaptive sampling (noise threshold 0.01), which blurset",
        "leaves off: it stops the sharp image's pixels early and breaks the pair.",
        "",
    ]
    groups: dict[tuple[str, str], dict[str, float]] = defaultdict(dict)
    for r in noise:
        m = _match(NOISE, r["name"])
        groups[(m["preset"], m["motion"].replace("_trajectory", ""))][m["scheme"]] = r["ratio"]
    schemes = sorted({s for g in groups.values() for s in g})
    keys = sorted(groups, key=lambda k: (k[0] != "paper", k))
    fig, ax = plt.subplots(figsize=(9, 3.4))
    width = 0.8 / max(1, len(schemes))
    for i, s in enumerate(schemes):
        xs = [j + i * width for j in range(len(keys))]
        ax.bar(xs, [groups[k].get(s, float("nan")) for k in keys], width, label=s)
    ax.set_xticks([j + width * (len(schemes) - 1) / 2 for j in range(len(keys))])
    ax.set_xticklabels([f"{p}\n{m}" for p, m in keys])
    ax.axhline(1.0, color="grey", lw=0.8)
    ax.set_yscale("log")
    ax.yaxis.set_major_formatter(matplotlib.ticker.FormatStrFormatter("%g"))
    ax.set_ylabel("blurry / sharp render-noise MSE")
    ax.legend(fontsize=7)
    out += [_save(fig, "render_noise.png"), ""]
    table = ["| result | blurry / sharp MSE | what was rendered |", "| --- | --- | --- |"]
    for r in noise:
        table.append(f"| `{r['name']}` | {r['ratio']:.2f}× | {_cell(r.get('contender', ''))} |")
    out += _collapsed("Every result of the plot", table)
    return out


# --------------------------------------------------------------------------- render cost


def render_cost_page(cost: list[dict], light: list[dict]) -> list[str]:
    out = [
        "# Render cost",
        "",
        "What a blurry image costs against its sharp image at equal total samples (the",
        "design's limit is 1.0), what render regions and cropped EXRs save, and what the",
        "light-path choice costs. Ratios are of CPU time (Blender worker and blurset's own",
        "process) where the benchmark measured it, since wall time swings on a shared",
        "machine.",
        "",
    ]
    if cost:
        out += _cost_section(cost)
    if light:
        out += _light_section(light)
    return out


def _cost_section(cost: list[dict]) -> list[str]:
    out: list[str] = []
    cost = sorted(cost, key=lambda r: (r["name"].endswith("_saving"), r["name"]))
    kinds = [
        (
            [r for r in cost if not r["name"].endswith("_saving")],
            "blurry / sharp cost (CPU time where measured)",
            "#009688",
        ),
        (
            [r for r in cost if r["name"].endswith("_saving")],
            "saving: baseline / contender CPU time",
            "#607d8b",
        ),
    ]
    kinds = [k for k in kinds if k[0]]
    n = sum(len(k[0]) for k in kinds)
    fig, axes = plt.subplots(
        len(kinds),
        1,
        figsize=(8, 0.42 * n + 1.2 * len(kinds)),
        gridspec_kw={"height_ratios": [len(k[0]) for k in kinds]},
    )
    axes = [axes] if len(kinds) == 1 else list(axes)
    for ax, (rs, label, color) in zip(axes, kinds, strict=True):
        vals = [r.get("cpu_ratio", r["ratio"]) for r in rs]
        ax.barh([r["name"] for r in rs][::-1], vals[::-1], color=color)
        ax.axvline(1.0, color="grey", lw=0.8)
        for y, v in enumerate(vals[::-1]):
            ax.text(v, y, f" {v:.2f}×", va="center", fontsize=8)
        ax.set_xlim(0, max(vals) * 1.2)
        ax.set_xlabel(label)
    out += ["## Blurry against sharp, regions, crops", "", _save(fig, "render_cost.png"), ""]
    out += _collapsed("Every result of the plot", _cost_table(cost))
    extra = [
        (r["name"], k, r[k])
        for r in cost
        for k in ("traced_px_ratio", "cpu_ratio_per_traced_px", "exr_mb_ratio")
        if k in r
    ]
    if extra:
        out += ["", "Where the time goes:", ""]
        out += [f"- `{n}`: {k.replace('_', ' ')} {v:.2f}×" for n, k, v in extra]
    out.append("")
    return out


def _cost_table(cost: list[dict]) -> list[str]:
    table = [
        "| result | ratio | ratio is | contender | baseline |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in cost:
        ratio = f"{r['ratio']:.2f}×"
        if "cpu_ratio" in r:
            ratio += f" (CPU {r['cpu_ratio']:.2f}×)"
        table.append(
            f"| `{r['name']}` | {ratio} | {_cell(r.get('ratio_is', ''))} | "
            f"{_cell(r.get('contender', ''))} | {_cell(r.get('baseline', ''))} |"
        )
    return table


def _light_section(light: list[dict]) -> list[str]:
    out = [
        "## Light paths",
        "",
        "`--light-paths auto` takes Cycles' bounces from the object's materials;",
        "`fixed` uses the same bounces for every object. Auto over fixed time per GLB, and",
        "whether the pixels came out identical:",
        "",
    ]
    names = [_match(LIGHT, r["name"])["glb"] for r in light]
    fig, ax = plt.subplots(figsize=(8, 0.4 * len(light) + 1))
    cpu = [r.get("cpu_ratio", r["ratio"]) for r in light]
    ax.barh(names[::-1], cpu[::-1], color="#795548")
    ax.axvline(1.0, color="grey", lw=0.8)
    ax.set_xlabel("auto / fixed CPU time")
    out += [_save(fig, "light_paths.png"), ""]
    out += [
        "| GLB | CPU ratio | identical pixels | bounces (auto) |",
        "| --- | --- | --- | --- |",
    ]
    for glb, r in zip(names, light, strict=True):
        out.append(
            f"| {glb} | {r.get('cpu_ratio', r['ratio']):.2f}× | "
            f"{'yes' if r.get('identical_pixels') else 'no'} | "
            f"{_cell(r.get('contender', '').split(':')[0])} |"
        )
    return out


# ------------------------------------------------------------------------ render targets

TARGET_COLUMNS = [
    ("images", "images", "d"),
    ("at_target_share", "at target − 0.5 dB", ".0%"),
    ("estimate_within_1db_share", "estimate within 1 dB", ".0%"),
    ("bound_holds_share", "bound holds", ".0%"),
    ("measured_worst_db", "worst, dB", ".1f"),
    ("measured_p5_db", "5th pct, dB", ".1f"),
    ("measured_mean_db", "mean, dB", ".1f"),
    ("coverage_mean", "coverage", ".0%"),
    ("spent_over_least", "samples spent / least", ".2f"),
    ("fixed_over_target", "one fixed count / target", ".2f"),
]


def targets_page(rs: list[dict]) -> list[str]:
    """Builds with `--target-psnr`, judged image by image against converged references
    on models no number was chosen from (bench/bench_target.py)."""
    out = [
        "# Render targets",
        "",
        "A build with `--target-psnr T` renders every image until its own estimate of its",
        "render noise, on the object's pixels, reaches T. `bench/bench_target.py` builds one",
        "setting of each held-out model (models no preset, threshold or sample count was",
        "chosen from) with a target, renders each image's own frames again at many times",
        "its samples as two halves on other seeds (the reference, its own noise taken out),",
        "and measures every image against it on the object's pixels. Per model: the share",
        "of images measuring at least T − 0.5 dB, the share whose estimate (meta.json's",
        "`render_psnr_db`) is within 1 dB of the measurement, the worst image, the 5th",
        "percentile and the mean; the mean coverage (the object's share of the frame); the",
        "samples spent over the least that reaches T (each image's measured noise",
        "extrapolated along the fall measured between it and a probe, the same image at half",
        "its samples, summed over the images); and what one fixed count per image kind",
        "(sharp, blur_l) that reaches T on every image of every model of the same run (the",
        "row's `baseline` names it) would cost, over what the target spent. The rounds stop",
        "on a bound of the estimate",
        "(`render_psnr_bound_db`: the estimate plus 2.809 standard deviations, the one-sided",
        "Vysochanskij-Petunin quantile of one image in twenty for any unimodal tail, of the",
        "real error's scatter about it, √(4 / (3 n_eff)) over the object's pixels) where",
        'results record one: "bound holds" is the share of images measuring at or above',
        "their bound (within 0.25 dB). The guide",
        "[Speed or accuracy](../guide/speed.md) says what a target promises.",
        "",
    ]
    specular = [r for r in rs if _match(TARGET, r["name"])["model"].startswith("specular_")]
    rs = [r for r in rs if r not in specular]
    per_model = [r for r in rs if _match(TARGET, r["name"])["model"] != "estimate"]
    overall = {r["name"]: r for r in rs if _match(TARGET, r["name"])["model"] == "estimate"}
    if not per_model:
        return out + ["No `target_*` result in bench/results.json yet."]
    runs: dict[tuple[str, str, str], list[dict]] = defaultdict(list)
    for r in per_model:
        m = _match(TARGET, r["name"])
        runs[(m["res"], m["db"], m["method"] or "")].append(r)
    for (res, db, method), group in sorted(
        runs.items(), key=lambda kv: (int(kv[0][0]), kv[0][1], kv[0][2])
    ):
        tag = f"_{method}" if method else ""
        out += _target_run(res, db, group, overall.get(f"target_{res}px_{db}db{tag}_estimate"),
                           method)  # fmt: skip
    return out + _specular_section(specular)


def kinds_lines(rs: list[dict]) -> list[str]:
    """Every kind under a target (bench/bench_target_kinds.py): per resolution, a row per
    kind and model, the kind over every model first."""
    if not rs:
        return []
    out = [
        "## Every kind of image",
        "",
        "`bench/bench_target_kinds.py` builds each model (the held-out models, and where a",
        "run names it the glossy `WaterBottle_blender_reexport`, from which no number of the",
        "target rule was chosen either) with defocus and shake levels beside the blur levels,",
        "under `--preset balanced` and the target, and judges each image against its own",
        "references as above. Per kind (the sharp images, blur, defocus and shake levels) and",
        "model:",
        "",
    ]
    runs: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rs:
        m = _match(KINDS, r["name"])
        runs[(m["res"], m["db"])].append(r)
    head = (
        "| kind | model | images | at T − 0.5 dB | bound holds | estimate within 1 dB "
        "| estimate − measured (dB) | spent / least |"
    )
    for (res, db), group in sorted(runs.items(), key=lambda kv: int(kv[0][0])):
        levels = group[0].get("levels") or {}
        named = ", ".join(f"{k} {','.join(map(str, v))}" for k, v in sorted(levels.items()))
        out += [
            f"### {res} px, {db} dB ({_views(group[0].get('views_measured'))} a model, "
            f"references at {_fmt(group[0].get('reference_factor'))}× the samples; "
            f"levels {named}; {ESTIMATORS[group[0].get('estimator', 'plain')]})",
            "",
            head,
            "| --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        first = {"all": 0, "held_out": 1}  # then each model, by name
        order = sorted(group, key=lambda r: (r["kind"], first.get(r["model"], 2), r["model"]))
        for r in order:
            lo, hi = r.get("estimate_over_measured_db_range") or [math.nan, math.nan]
            model = model_label(r["model"])
            out.append(
                f"| {r['kind']} | {model} | {r['images']} | {r['at_target_share']:.0%} | "
                f"{r['bound_holds_share']:.0%} | {r['estimate_within_1db_share']:.0%} | "
                f"{lo:+.2f} … {hi:+.2f} | {r['spent_over_least']:.2f}× |"
            )
        out.append("")
    return out


# The half-noise estimates a target build has recorded and stopped on (rows without the
# field were measured with the plain one).
ESTIMATORS = {
    "plain": "estimate: the halves' plain difference",
    "about_merged": "estimate: the halves about the merged image",
}


def half_noise_lines(rs: list[dict]) -> list[str]:
    """The two half-noise estimates on replicated renders (bench/check_half_noise.py): at
    fixed sample counts, and where the target rule stops on each."""
    if not rs:
        return []
    first = rs[0]
    counts = ("4", "16", "64", "256")
    out = [
        "## The estimate where sRGB bends",
        "",
        "`bench/check_half_noise.py` renders a sharp view of a glossy model as two halves on",
        "independent seeds at each of a grid of sample counts, on several independent seed",
        f"pairs, at {_fmt(first.get('resolution'))} px against a reference of",
        f"{_fmt(first.get('reference_samples_per_half'))} samples a half, and replays the",
        f"target rule ({_fmt(first.get('target_db'))} dB) on the grid once per estimate: the",
        "halves' plain difference, MSE(h₁, h₂)/4, and each half's sRGB distance from the",
        "image their mean writes (what builds record and stop on). Where the noise spans",
        "sRGB's bend the plain difference misses part of the written image's error.",
        "",
        "| model | estimate | images | mean estimate / measured at "
        + ", ".join(counts)
        + " samples a half | stopped: estimate − measured, median (dB) | within 1 dB "
        "| bound holds | at T − 0.5 dB | samples a half, median |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rs, key=lambda r: (r["model"] != "all", r["model"], r["estimator"] != "plain")):
        ratios = r.get("mean_estimate_over_measured_by_samples") or {}
        model = "**every model**" if r["model"] == "all" else f"`{r['model']}`"
        out.append(
            f"| {model} | {ESTIMATORS[r['estimator']].split(': ')[1]} | {r['images']} | "
            + ", ".join(_fmt(ratios.get(c)) for c in counts)
            + f" | {r['stopped_estimate_over_measured_db_median']:+.2f} | "
            f"{r['stopped_estimate_within_1db_share']:.0%} | "
            f"{r['stopped_bound_holds_share']:.0%} | {r['stopped_at_target_share']:.0%} | "
            f"{_fmt(r['stopped_samples_per_half_median'])} |"
        )
    return [*out, ""]


def _specular_section(rs: list[dict]) -> list[str]:
    """The bound on specular PBR models of our own (bench/specular_models.py), where a few
    fireflies carry the render noise and one round's estimate scatters by decibels."""
    every = next((r for r in rs if r["name"].endswith("_specular_bound")), None)
    models = sorted((r for r in rs if r is not every), key=lambda r: r["name"])
    if every is None or not models:
        return []
    lo, hi = every.get("estimate_over_measured_db_range") or [math.nan, math.nan]
    out = [
        f"## Specular models: the bound ({_fmt(every.get('target_db'))} dB at "
        f"{_fmt(every.get('resolution'))} px)",
        "",
        "Two procedural metal/roughness models of our own with normal and emissive maps",
        "(`bench/specular_models.py`: polished metal, roughness 0.04–0.6), made for this",
        "check and never used to choose a number. Their noise is heavy-tailed: a few",
        "fireflies on glossy metal carry much of it, so one round's estimate scatters. Over",
        f"their {every.get('images')} images the estimate erred by {lo:+.2f} to {hi:+.2f} dB",
        f"(estimate − measured; {every.get('estimate_within_1db_share', 0):.0%} within 1 dB);",
        f"the bound the rounds stop on held on {every.get('ratio', 0):.0%} of them, and",
        f"{every.get('at_target_share', 0):.0%} measured at least "
        f"{float(every.get('target_db', 0)) - 0.5:g} dB (`{every['name']}`).",
        "",
    ]
    head = ["model", *[t for _, t, _ in TARGET_COLUMNS[:7]], "largest bound excess, dB"]
    out += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in models:
        cells = [f"`{_match(TARGET, r['name'])['model']}`"]
        for k, _, fmt in TARGET_COLUMNS[:7]:
            v = r.get(k)
            cells.append(format(v, fmt) if isinstance(v, (int, float)) else "")
        cells.append(_fmt(r.get("bound_over_measured_db_max")))
        out.append("| " + " | ".join(cells) + " |")
    return [*out, ""]


def _target_run(
    res: str, db: str, group: list[dict], est: dict | None, method: str = ""
) -> list[str]:
    """One target, size and blur method: the per-model table, the misses and plot, more
    per model."""
    first = group[0]
    out = [
        f"## {db} dB at {res} px" + (f", {method.replace('_', ' ')}" if method else ""),
        "",
        f"{_fmt(first.get('views_measured'))} views a model, references at "
        f"{_fmt(first.get('reference_factor'))}× the samples"
        + (
            f"; every blurry image rendered by `--blur-method {method}` (what the accuracy "
            "presets choose on a GPU, rendered here on the CPU)."
            if method == "motion_blur"
            else "."
        ),
        "",
    ]
    if est:
        out += [
            f"Over all {est.get('images')} images of the {len(group)} models: "
            f"{est.get('at_target_share', 0):.0%} measure at least {float(db) - 0.5:g} dB, "
            f"and {est.get('ratio', 0):.0%} of the estimates are within 1 dB of the "
            f"measurement (`{est['name']}`).",
            "",
        ]
    head = ["model", *[t for _, t, _ in TARGET_COLUMNS]]
    out += ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    for r in sorted(group, key=lambda r: r["name"]):
        cells = [f"`{_match(TARGET, r['name'])['model']}`"]
        for k, _, fmt in TARGET_COLUMNS:
            v = r.get(k)
            cells.append(format(v, fmt) if isinstance(v, (int, float)) else "")
        out.append("| " + " | ".join(cells) + " |")
    out.append("")
    if est and isinstance(est.get("per_image"), dict):
        out += _target_misses(est["per_image"])
        png = f"targets_{res}_{db}{'_' + method if method else ''}.png"
        out += _target_plot(est["per_image"], float(db), png)
    more = [
        ("spent_over_least_median_image", "samples over the least, median image"),
        ("spent_over_least_max_image", "samples over the least, worst image"),
        ("estimate_error_db_max", "largest estimate error, dB"),
        ("render_s_per_view", "render time per view, s (the machine may be busy)"),
    ]
    table = ["| model | " + " | ".join(t for _, t in more) + " |"]
    table.append("|" + " --- |" * (len(more) + 1))
    for r in sorted(group, key=lambda r: r["name"]):
        table.append(
            f"| `{_match(TARGET, r['name'])['model']}` | "
            + " | ".join(_fmt(r.get(k)) for k, _ in more)
            + " |"
        )
    out += _collapsed("More per model", table)
    return out


# The builds a speed row holds, by key, and their label.
SPEED_BUILDS = (
    ("paper", "paper"),
    ("at_paper_worst", "T = worst"),
    ("at_paper_median", "T = median"),
    ("at_floor", "floor"),
    ("at_paper_continuous", "continuous, per kind"),
)


def _at(r: dict) -> str:
    """A speed row's size beside its model where it is not the default 128 px."""
    res = r.get("resolution")
    return f" at {res} px" if res and res != 128 else ""


def speed_lines(rs: list[dict]) -> list[str]:
    """Settings per hour at equal accuracy (bench/bench_target_speed.py): per model, the
    paper preset against target builds at its worst and median measured image, and the
    floor preset; each build's accuracy against the continuous blur; where the time goes."""
    if not rs:
        return []
    out = [
        "## Speed at equal accuracy",
        "",
        "`bench/bench_target_speed.py` builds each held-out model with the paper preset,",
        "measures the render PSNR of each of its images on the object's pixels (a second",
        "render on other seeds), then builds it with `--preset balanced --target-psnr T` at T",
        "= the paper images' worst (every image at least as accurate as the paper's worst)",
        "and at their median, and with `--preset floor` (every image to the 8-bit floor),",
        "side by side in one run; and, per image kind (sharp, each blur level), one target",
        "build of that kind alone at the paper images' worst PSNR against the continuous",
        "blur (its blurry kinds by motion blur, which has no ghosts), timed as their sum:",
        "equal accuracy against the continuous blur. Settings per hour are extrapolated to a",
        "setting's 34 views from the views built (worker start and object load included).",
        "",
        "| result | model | views | paper: worst / median dB | paper settings/h | "
        + " | ".join(f"{label}: settings/h (×)" for _, label in SPEED_BUILDS[1:])
        + " |",
        "| --- " * (5 + len(SPEED_BUILDS) - 1) + "|",
    ]
    for r in sorted(rs, key=lambda r: r["name"]):
        p = r.get("paper_measured") or {}
        cells = [
            f"`{r['name']}`",
            f"`{r.get('model')}`",
            _fmt(r.get("views_measured")),
            f"{_fmt(p.get('worst_db'))} / {_fmt(p.get('median_db'))}",
            _fmt(r.get("paper_settings_per_hour")),
        ]
        for key, _ in SPEED_BUILDS[1:]:
            b = r.get(key)
            cells.append(
                f"{_fmt(b.get('settings_per_hour'))} ({_fmt(b.get('ratio'))}×)" if b else "not run"
            )
        out.append("| " + " | ".join(cells) + " |")
    out.append("")
    quality = [r for r in rs if isinstance(r.get("paper"), dict)]
    if not quality:
        return out
    return out + _continuous_table(quality) + _per_kind_table(quality) + _time_split_table(quality)


def _per_kind_table(quality: list[dict]) -> list[str]:
    """The continuous rule's builds, one per image kind: what the paper preset's worst image
    of the kind measured against the continuous blur, what the kind's own build reached."""
    rows = [r for r in quality if isinstance(r.get("at_paper_continuous"), dict)]
    if not rows:
        return []
    out = [
        "",
        "Equal accuracy against the continuous blur, per image kind: the paper preset's worst",
        "image of the kind against the continuous blur (the kind's target), the worst its own",
        "build reached (object pixels, the reference's own render noise taken out; † left in),",
        "that build's work per view and wall time, and how its blurry images were rendered.",
        "",
        "| model | kind | paper worst dB | reached worst dB | samples / view | calls / view "
        "| build s | method |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rows, key=lambda r: r["name"]):
        for kind, k in sorted(r["at_paper_continuous"].get("kinds", {}).items()):
            method = ", ".join(k.get("methods") or [])
            out.append(
                f"| `{r.get('model')}`{_at(r)}{'†' if _noise_left_in(r) else ''} | {kind} | "
                f"{_fmt(k.get('paper_worst_db'))} | "
                f"{_fmt(k.get('worst_db'))} | {_count(k.get('samples_per_view'))} | "
                f"{_count(k.get('calls_per_view'))} | {_fmt(k.get('build_s'))} | {method} |"
            )
    return out


def _noise_left_in(r: dict) -> bool:
    """A row scored before the reference's own render noise was taken out of its PSNR."""
    return (r.get("continuous") or {}).get("reference_noise") != "taken out"


def _continuous_table(quality: list[dict]) -> list[str]:
    """Each build against the continuous blur, and its work per view."""
    older = any(not r.get("continuous") for r in quality)
    noisy = {r["name"] for r in quality if _noise_left_in(r)}
    out = [
        "Each build against the continuous blur (stratified frames at most 0.5 px apart on",
        "screen sharing 1,024 samples"
        + (
            ", in rows marked *; in the others, measured before, 64 stratified frames × 16 samples"
            if older
            else ""
        )
        + "; the sharp image at 1,024 samples, rendered twice on independent seeds), on",
        "object pixels: the blurry images' mean and worst PSNR against the two renders' mean,",
        "that mean's own render noise taken out (MSE(r₁, r₂) / 4"
        + (
            "; rows marked † were scored with it left in, which reads low where an image is as"
            " noisy as the reference"
            if noisy
            else ""
        )
        + "), the sharp images' mean, and the detail ratio (high-frequency energy over the",
        "reference's, blurry / sharp: under 1 is texture smoothed away, over 1 noise on top);",
        "the texture kept (core `detail_kept`, blurry / sharp: the share of the reference's",
        "Laplacian the image keeps, from two independent reference renders, so that noise",
        "counts on neither side; rows measured before it have none);",
        "then the work per view: samples, render calls (a target image renders each frame",
        "once per half and round) and the paper preset's samples over the build's.",
        "",
        "| model | build | blurry mean / worst dB | sharp dB | detail blurry / sharp "
        "| texture kept blurry / sharp | samples / view | calls / view | paper samples / these |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(quality, key=lambda r: r["name"]):
        for key, label in SPEED_BUILDS:
            b = r.get(key)
            if not b or "kinds" in b:
                # (a run that left this build out: a 512 px run on 2 cores; the per-kind
                # builds have their own table)
                continue
            out.append(
                f"| `{r.get('model')}`{_at(r)}{'*' if older and r.get('continuous') else ''}"
                f"{'†' if r['name'] in noisy else ''} | "
                f"{label} | "
                f"{_fmt(b.get('blur_vs_continuous_mean_db'))} / "
                f"{_fmt(b.get('blur_vs_continuous_worst_db'))} | "
                f"{_fmt(b.get('sharp_vs_continuous_mean_db'))} | "
                f"{_fmt(b.get('detail_ratio_blur'))} / {_fmt(b.get('detail_ratio_sharp'))} | "
                f"{_kept(b)} | {_count(b.get('samples_per_view'))} | {_count(b.get('calls_per_view'))} | "
                f"{_fmt(b.get('sample_ratio', 1.0 if key == 'paper' else None))} |"
            )
    return out


def _kept(b: dict) -> str:
    """Texture kept, blurry / sharp, where the run measured it."""
    if "detail_kept_blur" not in b:
        return ""
    return f"{_fmt(b.get('detail_kept_blur'), 3)} / {_fmt(b.get('detail_kept_sharp'), 3)}"


def _time_split_table(quality: list[dict]) -> list[str]:
    """Seconds per render call and per sample, fitted per model."""
    out = [
        "",
        "Where the time goes: seconds per view fitted, per model, as a × render calls +",
        "b × samples over its four builds (least squares), and the share of a view's",
        "fitted time its render calls take in the paper build and in the T = worst build",
        "(a target renders every frame once per half and round).",
        "",
        "| model | s per render call | s per 1,000 samples | calls' share: paper | calls' share: T = worst |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in sorted(quality, key=lambda r: r["name"]):
        t = r.get("time_split")
        if not t:
            continue  # (fewer builds than the fit's two unknowns need)
        shares = [_calls_share(t, r.get(k) or {}) for k in ("paper", "at_paper_worst")]
        out.append(
            f"| `{r.get('model')}`{_at(r)} | {_fmt(t.get('s_per_call'), 3)} | {_fmt(t.get('s_per_ksample'))} | "
            + " | ".join("" if x is None else f"{x:.0%}" for x in shares)
            + " |"
        )
    return [*out, ""]


def detail_lines(rs: list[dict]) -> list[str]:
    """Does a target build keep the texture (bench/bench_target_detail.py): the share of
    a continuous reference's texture its images keep, from two renders of the reference."""
    if not rs:
        return []
    out = [
        "## Texture kept",
        "",
        "`bench/bench_target_detail.py` rebuilds the T = worst build above and renders the",
        "continuous blur twice, on independent seeds. *Kept* is the share of the reference's",
        "texture an image keeps (core `detail_kept`: the image's luma Laplacian against each",
        "render's, over the two renders' against each other; render noise on neither side",
        "counts): 1 kept, under 1 smoothed away. *Energy* is the image's high-frequency energy",
        "over the reference's noise-free part, 2 E(mean of the two) - (E(r1) + E(r2)) / 2:",
        "over 1 where render noise sits on top of the image. PSNR is against the mean of the two,",
        "its own render noise taken out; rows marked † were measured before that and before",
        "object pixels left out Cycles' rounding of a background's alpha (about 10⁻⁸), so their",
        "PSNR may read high or low.",
        "",
        "| result | size | views | T dB | kept blurry: mean (lowest, highest) | kept sharp "
        "| energy blurry / sharp | blurry vs continuous: mean / worst dB | largest gap px |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rs, key=lambda r: r["name"]):
        lo, hi = r.get("detail_kept_blur_range") or (None, None)
        out.append(
            f"| `{r['name']}`{'†' if _noise_left_in(r) else ''} | {_fmt(r.get('resolution'))} px | "
            f"{_fmt(r.get('views_measured'))} | {_fmt(r.get('target_db'))} | "
            f"{_fmt(r.get('detail_kept_blur'))} ({_fmt(lo)}, {_fmt(hi)}) | "
            f"{_fmt(r.get('detail_kept_sharp'))} | "
            f"{_fmt(r.get('detail_ratio_blur'))} / {_fmt(r.get('detail_ratio_sharp'))} | "
            f"{_fmt(r.get('blur_vs_continuous_mean_db'))} / "
            f"{_fmt(r.get('blur_vs_continuous_worst_db'))} | {_fmt(r.get('max_gap_px'))} |"
        )
    return [*out, ""]


def _target_misses(per_image: dict) -> list[str]:
    """Which way the estimates that miss by more than 1 dB err: under the measurement is
    the safe side (the image is better than its record says)."""
    errors = [
        r["estimate_db"] - r["measured_db"]
        for rows in per_image.values()
        for r in rows
        if isinstance(r.get("estimate_db"), (int, float))
        and isinstance(r.get("measured_db"), (int, float))
    ]
    misses = [e for e in errors if abs(e) > 1.0]
    if not errors:
        return []
    under = sum(e < 0 for e in misses)
    if not misses:
        return [
            f"No estimate is more than 1 dB off: the estimate errs by {min(errors):+.2f} to",
            f"{max(errors):+.2f} dB (estimate − measured).",
            "",
        ]
    return [
        f"Of the {len(misses)} estimates more than 1 dB off, {under} are under the measurement",
        f"(the image is better than its record says) and {len(misses) - under} over it; the",
        f"estimate errs by {min(errors):+.2f} to {max(errors):+.2f} dB (estimate − measured).",
        "",
    ]


def _target_plot(per_image: dict, target: float, png: str) -> list[str]:
    """Each image's estimate against its measurement, per model."""
    fig, ax = plt.subplots(figsize=(5.6, 4.2))
    lo, hi = math.inf, -math.inf
    for i, (model, rows) in enumerate(sorted(per_image.items())):
        xs = [r["measured_db"] for r in rows]
        ys = [r["estimate_db"] for r in rows]
        if not xs:
            continue
        lo, hi = min(lo, *xs, *ys), max(hi, *xs, *ys)
        ax.scatter(xs, ys, s=14, color=f"C{i % 10}", label=model)
    if not math.isfinite(lo):
        plt.close(fig)
        return []
    ax.plot([lo, hi], [lo, hi], color="grey", lw=0.8)
    ax.fill_between([lo, hi], [lo - 1, hi - 1], [lo + 1, hi + 1], color="grey", alpha=0.15)
    ax.axvline(target - 0.5, ls=":", color="grey")
    ax.set_xlabel("measured render PSNR on the object's pixels, dB")
    ax.set_ylabel("estimate (meta.json), dB")
    ax.legend(fontsize=7)
    return [
        "Every image: its estimate against its measurement (the band is ± 1 dB, the dotted",
        "line the target − 0.5 dB).",
        "",
        _save(fig, png),
        "",
    ]


# ---------------------------------------------------------------------------------- device


def device_costs_lines(rs: list[dict]) -> list[str]:
    """The unit costs that price a plan on a device (bench/bench_device_costs.py)."""
    if not rs:
        return []
    out = [
        "## What a render call and a sample cost",
        "",
        "`bench/bench_device_costs.py` renders jobs of frames at 1 to 128 samples through the",
        "build's path (worker, EXR, accumulator) and fits seconds per frame = a + b × samples",
        "(medians of interleaved repeats): a is the fixed cost of a render call, b the cost of",
        "a sample; the share is a's part of a 32-sample latent frame (the paper preset's).",
        "",
        "| result | device | s per call | ms per sample | fixed share of a 32-sample frame |",
        "| --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rs, key=lambda r: r["name"]):
        call_s, sample_s, share = r.get("call_s"), r.get("sample_s"), r.get("ratio")
        out.append(
            f"| `{r['name']}` | {_cell(_machine([r]))} | {_fmt(call_s, 4)} | "
            f"{_fmt(None if sample_s is None else sample_s * 1000, 3)} | "
            f"{'' if share is None else format(share, '.0%')} |"
        )
    return [*out, ""]


def one_setting_lines(rs: list[dict]) -> list[str]:
    """Whole settings as a user builds them (bench/bench_one_setting.py)."""
    if not rs:
        return []
    out = [
        "## One whole setting",
        "",
        "`bench/bench_one_setting.py` builds one setting of a held-out model end to end (worker",
        "start, object load and the device's first render included).",
        "",
        "| result | model | views | s | budget s | worst render PSNR dB | blurry images by |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in sorted(rs, key=lambda r: r["name"]):
        method = ", ".join(f"{m} {n}" for m, n in sorted((r.get("blur_choice") or {}).items()))
        budget = r.get("baseline", "").removesuffix(" s")
        out.append(
            f"| `{r['name']}` | `{r.get('model')}` | {_fmt(r.get('views'))} | "
            f"{_fmt(r.get('build_s'), 1)} | {_cell(budget)} | "
            f"{_fmt(r.get('worst_render_psnr_db'))} | {method} |"
        )
    return [*out, ""]


def device_page(results: list[dict] | None) -> list[str]:
    """The GPU node's page, from bench/results_gpu.json where `make bench-gpu` wrote one."""
    out = [
        "# On a GPU",
        "",
        "`make bench-gpu` (`bench/run.py --device gpu`) runs on the best GPU backend Cycles",
        "reports: the unit costs of a render call and of a sample (and of the same node's",
        "CPU beside them), speed at equal accuracy on two held-out models at 512 px, and one",
        "whole 34-view setting of the balanced preset; it writes `bench/results_gpu.json`, from",
        "which `make docs` generates this page.",
        "",
    ]
    if not results:
        return out + [
            "No GPU results yet: the development machines have no GPU, and no",
            "`bench/results_gpu.json` has been measured. Every figure in the other pages was",
            "measured on a CPU.",
        ]
    kinds = defaultdict(list)
    for r in results:
        kind = next(
            (k for k, rx in (("costs", DEVICE_COSTS), ("speed", SPEED), ("one", ONE_SETTING))
             if rx.match(r["name"])),
            "other",
        )  # fmt: skip
        kinds[kind].append(r)
    out += [f"Measured on: {_machine(results)}.", ""]
    out += device_costs_lines(kinds["costs"])
    out += speed_lines(kinds["speed"])
    out += one_setting_lines(kinds["one"])
    if kinds["other"]:
        out += ["## Other measurements", "", "| result | ratio | ratio is |", "| --- | --- | --- |"]
        out += [
            f"| `{r['name']}` | {_fmt(r.get('ratio'), 3)} | {_cell(r.get('ratio_is', ''))} |"
            for r in sorted(kinds["other"], key=lambda r: r["name"])
        ]
    return out


# ---------------------------------------------------------------------------------- index


def index_page(
    results: list[dict], other: list[dict], pages: list[tuple[str, str, int]]
) -> list[str]:
    out = [
        "# Benchmarks",
        "",
        "`make bench` runs every `bench/bench_*.py` and writes `bench/results.json`; these",
        "pages are generated from that file by `make docs` (`docs/gen/bench.py`). Each",
        "benchmark measures its ratios side by side in one run, from medians of repeats,",
        "so a ratio holds on a busy machine where absolute times do not. Tests never assert",
        "timings.",
        "",
        f"Measured on: {_machine(results)}. The development machines have 2 CPU cores,",
        "shared with other jobs, and no GPU; each result records its own device (and, in",
        "results measured since December 2026, its `machine`). `make bench-gpu` runs the rendering",
        "benchmarks on a GPU into `bench/results_gpu.json`.",
        "",
        "| page | results |",
        "| --- | --- |",
    ]
    out += [f"| [{title}]({page}) | {n} |" for page, title, n in pages]
    out += [
        "",
        "Run one benchmark again with `.venv/bin/python bench/run.py bench_noise` (it replaces",
        "its own entries in results.json only), then `make docs`.",
        "",
    ]
    if other:
        out += [
            "## Other measurements",
            "",
            "| result | ratio | ratio is | contender | baseline |",
            "| --- | --- | --- | --- | --- |",
        ]
        for r in sorted(other, key=lambda r: r["name"]):
            ratio = r.get("ratio")
            ratio = f"{ratio:.3g}" if isinstance(ratio, (int, float)) else _cell(ratio)
            out.append(
                f"| `{r['name']}` | {ratio} | {_cell(r.get('ratio_is', ''))} | "
                f"{_cell(r.get('contender', ''))} | {_cell(r.get('baseline', ''))} |"
            )
    return out


def _by_page(results: list[dict]) -> dict[str, list[dict]]:
    """Each result under the first kind whose name pattern it matches, else "other"."""
    kinds: list[tuple[str, Callable[[str], object]]] = [
        ("presets", lambda n: PRESETS.match(n) and n not in NOT_PRESETS),
        ("parity", PARITY.match),
        ("noise", NOISE.match),
        ("cost", COST.match),
        ("light", LIGHT.match),
        ("gain", GAIN.match),
        ("target", TARGET.match),
        ("speed", SPEED.match),
        ("kinds", KINDS.match),
        ("detail", DETAIL.match),
        ("half_noise", HALF_NOISE.match),
    ]
    out: dict[str, list[dict]] = {k: [] for k, _ in [*kinds, ("other", None)]}
    for r in results:
        out[next((k for k, match in kinds if match(r["name"])), "other")].append(r)
    return out


def model_label(model: str) -> str:
    """A kinds row's model as its table names it: a model, or one of the aggregates."""
    return {"all": "**every model**", "held_out": "**the held-out models**"}.get(
        model, f"`{model}`"
    )


def _views(n: object) -> str:
    """`n views`, `1 view`."""
    return f"{_fmt(n)} view{'' if n == 1 else 's'}"


def main(figures_too: bool = True) -> int:
    """The benchmark pages, then (`figures_too`) the figures quoted in README.md and the
    guides rewritten from the same results (docs/gen/figures.py), the noise guide's
    tables and figure among them (docs/gen/noise_guide.py), and the build guide's shake
    tables and figure (docs/gen/shake_guide.py)."""
    results = json.loads(RESULTS.read_text())
    if OUT.exists():
        shutil.rmtree(OUT)
    OUT.mkdir(parents=True)
    kind = _by_page(results)
    pages = [
        (
            "presets.md",
            "Presets",
            presets_page(kind["presets"]) + denoise_gain_lines(kind["gain"]),
            len(kind["presets"]) + len(kind["gain"]),
        ),
        (
            "render-noise.md",
            "Render noise of a pair",
            render_noise_page(kind["parity"], kind["noise"]),
            len(kind["parity"]) + len(kind["noise"]),
        ),
        (
            "render-cost.md",
            "Render cost",
            render_cost_page(kind["cost"], kind["light"]),
            len(kind["cost"]) + len(kind["light"]),
        ),
        (
            "targets.md",
            "Render targets",
            targets_page(kind["target"])
            + kinds_lines(kind["kinds"])
            + half_noise_lines(kind["half_noise"])
            + speed_lines(kind["speed"])
            + detail_lines(kind["detail"]),
            len(kind["target"])
            + len(kind["kinds"])
            + len(kind["half_noise"])
            + len(kind["speed"])
            + len(kind["detail"]),
        ),
    ]
    gpu = json.loads(RESULTS_GPU.read_text()) if RESULTS_GPU.exists() else None
    pages.append(("gpu.md", "On a GPU", device_page(gpu), len(gpu or [])))
    for name, _, lines, _ in pages:
        (OUT / name).write_text("\n".join(lines).rstrip() + "\n")
    index = index_page(results, kind["other"], [(p, t, n) for p, t, _, n in pages])
    (OUT / "index.md").write_text("\n".join(index).rstrip() + "\n")
    print(f"wrote {len(pages) + 1} benchmark pages in {OUT}", file=sys.stderr)
    if not figures_too:
        return 0
    by_name = {r["name"]: r for r in results}
    # The noise guide's generated blocks (their values are figure markers) and figure.
    bad = noise_guide.update(results=by_name)
    bad += shake_guide.update(results=by_name)
    bad += figures.update(results=by_name)
    bad += figures.problems(results=by_name)
    for b in bad:
        print(f"figures: {b}", file=sys.stderr)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
