"""The measured parts of the build guide's shake section (docs/guide/build.md), from
bench/results.json (run by `make docs` through docs/gen/bench.py).

The page holds generated blocks, each `<!-- shake NAME -->` … `<!-- /shake -->`:

- `recorded`: per shake level and for Levin et al. 2009's recorded kernels, the extent
  as a share of the image width and the shape statistics (bench_shake_recorded's
  `shake_recorded_levin09` and `shake_paths_level<l>` rows);
- `cost`: per level and ghost bound, the frames the hand shake and the harmonics before
  it take, and the estimated seconds (bench_shake_cost's `shake_cost_ghost<g>px_level<l>`
  rows).

Every number in a block is a figure marker (docs/gen/figures.py), so tests/test_docs.py
checks it against the results. The figure, docs/images/shake_paths.png, is drawn from
the rows: the example views' paths planned again by the core at the rows' seed (their
path lengths checked against the rows'), the statistics the rows'.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import figures  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "guide" / "build.md"
BENCH = ROOT / "bench"
FIGURE = ROOT / "docs" / "images" / "shake_paths.png"
BLOCK = re.compile(r"(<!-- shake (?P<name>[a-z]+) -->\n)(?P<body>.*?)(<!-- /shake -->)", re.S)
RECORDED = "shake_recorded_levin09"
LEVELS = (1, 2, 3, 4)
GHOSTS = ("1", "2")


def _fig(results: dict[str, dict], name: str, field: str, fmt: str) -> str:
    v = figures.value(results, name, field, fmt)
    return f"<!-- fig {name} {field} {fmt} -->{v}<!-- /fig -->"


def _missing(what: str, how: str) -> list[str]:
    return [f"Not measured yet: {what} (`{how}`, then `make docs`).", ""]


def _levels(results: dict[str, dict]) -> list[str]:
    return [f"shake_paths_level{lv}" for lv in LEVELS if f"shake_paths_level{lv}" in results]


def recorded_block(results: dict[str, dict]) -> list[str]:
    if RECORDED not in results or not _levels(results):
        return _missing(
            "the paths beside the recordings",
            "BLURSET_SHAKE_RECORDINGS=Levin09.mat .venv/bin/python bench/run.py "
            "bench_shake_recorded",
        )
    out = [
        "| | extent, share of the image width | length / extent | ends share | "
        "dwell share | stroke width (px) | drift share | path / extent |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]

    def rec(field: str, fmt: str) -> str:
        return _fig(results, RECORDED, f"{field}_median", fmt)

    out.append(
        f"| recorded (Levin et al. 2009, median of {_fig(results, RECORDED, 'count', 'd')}) | "
        f"{rec('extent_share_of_image', '.1%')} | {rec('length_over_extent', '.2f')} | "
        f"{rec('ends_share', '.2f')} | {rec('dwell_share', '.2f')} | "
        f"{rec('width_px', '.1f')} | not recorded | not recorded |"
    )
    for name in _levels(results):

        def cell(field: str, fmt: str, name: str = name) -> str:
            return _fig(results, name, field, fmt)

        out.append(
            f"| level {results[name]['level']} (median over "
            f"{cell('views', 'd')} views) | {cell('extent_share_of_image', '.1%')} | "
            f"{cell('length_over_extent_median', '.2f')} | {cell('ends_share_median', '.2f')} | "
            f"{cell('dwell_share_median', '.2f')} | {cell('width_px_median', '.1f')} | "
            f"{cell('drift_share_median', '.2f')} | {cell('path_over_extent_median', '.1f')} |"
        )
    return [*out, ""]


def cost_block(results: dict[str, dict]) -> list[str]:
    names = [
        (g, lv, f"shake_cost_ghost{g}px_level{lv}")
        for g in GHOSTS
        for lv in LEVELS
        if f"shake_cost_ghost{g}px_level{lv}" in results
    ]
    if not names:
        return _missing(
            "the frames at equal ghost gap", ".venv/bin/python bench/run.py bench_shake_cost"
        )
    out = [
        "| `--max-ghost-px` | level | frames, hand shake | frames, harmonics (before) | "
        "hand shake / harmonics | seconds (estimate), hand shake / harmonics |",
        "| --- | --- | --- | --- | --- | --- |",
    ]
    for g, lv, n in names:

        def cell(field: str, fmt: str, n: str = n) -> str:
            return _fig(results, n, field, fmt)

        seconds = cell("seconds_ratio", ".2f") + "×" if "seconds_ratio" in results[n] else "—"
        out.append(
            f"| {g} | {lv} | {cell('frames_new_median', 'g')} | {cell('frames_old_median', 'g')} | "
            f"{cell('ratio', '.2f')}× | {seconds} |"
        )
    return [*out, ""]


BLOCKS = {"recorded": recorded_block, "cost": cost_block}


def rewrite(text: str, results: dict[str, dict]) -> str:
    """The page with every generated block made again from the results."""

    def fill(m: re.Match) -> str:
        if m["name"] not in BLOCKS:
            raise ValueError(f"build.md: no generator for block {m['name']!r}")
        return m.group(1) + "\n".join(BLOCKS[m["name"]](results)) + m.group(4)

    return BLOCK.sub(fill, text)


def draw_figure(results: dict[str, dict], out: Path = FIGURE) -> list[str]:
    """docs/images/shake_paths.png from the rows; returns where the rows and the code
    disagree (an example path whose length is not the row's: rerun the bench)."""
    names = _levels(results)
    if RECORDED not in results or not names:
        return []
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    sys.path.insert(0, str(BENCH))
    import shake_paths as sp

    rows = [results[n] for n in names]
    rec = results[RECORDED]
    first = rows[0]
    paths = sp.model_paths(first["views"], [r["level"] for r in rows], resolution=first["resolution"],
                           ghost_px=first["ghost_px"], seed=first["seed"])  # fmt: skip
    stale = []
    colours = plt.get_cmap("viridis")(np.linspace(0.1, 0.85, len(rows)))
    with plt.style.context("default"):
        fig, axes = plt.subplots(2, 4, figsize=(13, 7.4), dpi=90)
        for ax, r in zip(axes[0], rows, strict=False):
            lv = r["level"]
            for k, ex in enumerate(r["examples"]):
                p = paths[lv][ex["view"]]
                got = p["record"]["path_px"]
                if abs(got - ex["path_px"]) > 1e-9 * max(1.0, ex["path_px"]):
                    stale.append(f"level {lv} view {ex['view']}: path {got:.6g} px, "
                                 f"the results say {ex['path_px']:.6g}")  # fmt: skip
                # A 2 × 2 grid of places: the recordings' circle, then the examples.
                cx, cy = np.array([(k + 1) % 2, -((k + 1) // 2)]) * 1.4 * r["extent_px"]
                xy = p["path"] - (p["path"].min(axis=0) + p["path"].max(axis=0)) / 2
                ax.plot(xy[:, 0] + cx, cy - xy[:, 1], lw=0.8)
                ax.plot(xy[0, 0] + cx, cy - xy[0, 1], "k.", ms=4)
            d = rec["extent_share_of_image_median"] * r["resolution"]
            ax.add_patch(plt.Circle((0, 0), d / 2, fill=False, ls="--", color="0.3"))
            ax.set_aspect("equal")
            ax.set_title(f"level {lv}: extent {r['extent_px']:g} px at {r['resolution']} px",
                         fontsize=9)  # fmt: skip
            ax.tick_params(labelsize=7)
        axes[0][0].set_ylabel("image centre (px)", fontsize=8)
        # Extent as a share of the image width.
        ax = axes[1][0]
        shares = [k["extent_share_of_image"] for k in rec["kernels"]]
        ax.plot(np.zeros(len(shares)), shares, "ko", ms=4, label="recorded")
        for c, r in zip(colours, rows, strict=True):
            ax.plot([1], [r["extent_share_of_image"]], "s", color=c, label=f"level {r['level']}")
        ax.set_yscale("log")
        ax.set_xticks([0, 1], ["Levin et al.\n2009", "shake\nlevels"], fontsize=8)
        ax.set_xlim(-0.6, 1.6)
        ax.set_title("extent / image width", fontsize=9)
        ax.legend(fontsize=7)
        stats = (
            ("length_over_extent", "length along the stroke / extent"),
            ("dwell_share", "mass in the brightest fifth"),
            ("width_px", f"stroke width (px, at {rec['extent_px_median']:.1f} px extent)"),
        )
        for ax, (key, title) in zip(axes[1][1:], stats, strict=True):
            vals = [k[key] for k in rec["kernels"]]
            ax.plot(np.zeros(len(vals)), vals, "ko", ms=4)
            for i, (c, r) in enumerate(zip(colours, rows, strict=True)):
                x = 1 + 0.15 * (i - (len(rows) - 1) / 2)
                lo, mid, hi = r[f"{key}_q1"], r[f"{key}_median"], r[f"{key}_q3"]
                ax.errorbar([x], [mid], yerr=[[mid - lo], [hi - mid]], fmt="s", color=c, ms=4,
                            capsize=2)  # fmt: skip
            ax.set_xticks([0, 1], ["recorded", "model\n(median, quartiles)"], fontsize=8)
            ax.set_xlim(-0.6, 1.6)
            ax.set_title(title, fontsize=9)
            ax.tick_params(labelsize=7)
        fig.suptitle(
            "Top: the core's shake paths (3 views; dot: the start; dashed circle: the recorded "
            "kernels' median extent at the same share of the width). Bottom: the same "
            "statistics of both",
            fontsize=9,
        )
        fig.tight_layout()
        fig.savefig(out, dpi=90, metadata={"Software": None})
        plt.close(fig)
    return stale


def update(results: dict[str, dict] | None = None, page: Path = PAGE) -> list[str]:
    """Rewrite the page's blocks and draw the figure; returns the problems."""
    results = figures.load() if results is None else results
    text = page.read_text()
    new = rewrite(text, results)
    if new != text:
        page.write_text(new)
        print(f"shake guide: rewrote {page.relative_to(ROOT)}", file=sys.stderr)
    return [f"docs/images/shake_paths.png: {s} (rerun bench_shake_recorded)" for s in
            draw_figure(results)]  # fmt: skip


if __name__ == "__main__":
    problems = update()
    for p in problems:
        print(p, file=sys.stderr)
    sys.exit(1 if problems else 0)
