"""The measured parts of docs/guide/noise.md, from bench/results.json (run by `make docs`
through docs/gen/bench.py).

The page holds generated blocks, each `<!-- noise NAME -->` … `<!-- /noise -->`:

- `speed`: each camera model's seconds per megapixel and its time over the paper
  model's (bench_noise's `noise_model_<model>` rows, measured side by side in one run);
- `figure`: the figure's panels, each model's gain at matched noise power and its
  residual's statistics (bench_noise's `noise_models_figure` row);
- `evidence`: variance against signal per CFA channel, row-noise power, the read
  noise's Tukey lambda, the demosaicked noise's correlation and the extremes, per model
  (bench_noise_evidence's `noise_evidence_<model>` rows).

Every number in a block is a figure marker (docs/gen/figures.py), so tests/test_docs.py
checks it against the results as it checks hand-written prose. The figure itself,
docs/images/noise_models.png, is drawn from the `noise_models_figure` row
(bench_noise.draw_figure: each crop made again at the row's gain, same seed, same
bytes; the spectra the row's), where the fern scene is at hand.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import figures  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "guide" / "noise.md"
BENCH = ROOT / "bench"
BLOCK = re.compile(r"(<!-- noise (?P<name>[a-z]+) -->\n)(?P<body>.*?)(<!-- /noise -->)", re.S)
FIGURE_ROW = "noise_models_figure"


def _order(model: str) -> tuple[int, str]:
    return (0 if model == "paper" else 1 if model == "unprocess" else 2, model)


def _rows(results: dict[str, dict], prefix: str) -> list[dict]:
    rows = [r for n, r in results.items() if n.startswith(prefix) and "model" in r]
    return sorted(rows, key=lambda r: _order(r["model"]))


def _fig(results: dict[str, dict], name: str, field: str, fmt: str) -> str:
    """A filled figure marker."""
    v = figures.value(results, name, field, fmt)
    return f"<!-- fig {name} {field} {fmt} -->{v}<!-- /fig -->"


def _missing(what: str, how: str) -> list[str]:
    return [f"Not measured yet: {what} (`{how}`, then `make docs`).", ""]


def speed_block(results: dict[str, dict]) -> list[str]:
    rows = _rows(results, "noise_model_")
    if not rows:
        return _missing("the models' speed", ".venv/bin/python bench/run.py bench_noise")
    out = [
        "| model | seconds per megapixel | over the paper's (median) | rounds' range |",
        "| --- | --- | --- | --- |",
    ]
    for r in rows:
        n = r["name"]
        out.append(
            f"| `{r['model']}` | {_fig(results, n, 's_per_megapixel', '.3f')} | "
            f"{_fig(results, n, 'over_paper', '.2f')}× | "
            f"{_fig(results, n, 'over_paper_range[0]', '.2f')}–"
            f"{_fig(results, n, 'over_paper_range[1]', '.2f')} |"
        )
    return [*out, ""]


def figure_block(results: dict[str, dict]) -> list[str]:
    if FIGURE_ROW not in results:
        return _missing("the figure", ".venv/bin/python bench/bench_noise.py --models")
    out = [
        "| panel | gain | residual std (codes) | green neighbour correlation | red-green "
        "correlation |",
        "| --- | --- | --- | --- | --- |",
    ]
    for key, v in results[FIGURE_ROW]["models"].items():

        def cell(field: str, fmt: str, key: str = key) -> str:
            return _fig(results, FIGURE_ROW, f"models.{key}.{field}", fmt)

        out.append(
            f"| `{v['model']}` | {cell('gain', '.3g')} | {cell('std', '.2f')} | "
            f"{cell('neighbour_corr', '.2f')} | {cell('red_green_corr', '.2f')} |"
        )
    return [*out, ""]


def evidence_block(results: dict[str, dict]) -> list[str]:
    rows = _rows(results, "noise_evidence_")
    if not rows:
        return _missing("the evidence", ".venv/bin/python bench/run.py bench_noise_evidence")
    out = [
        "| model | variance / model | row power / σ²_row | λ published → fitted | "
        "q(0.999) / model | green right, down | red-green | extremes: max abs linear |",
        "| --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for r in rows:
        n = r["name"]

        def fig(field: str, fmt: str, n: str = n) -> str:
            return _fig(results, n, field, fmt)

        eld = "lambda_published_top" in r
        row_power = (
            f"{fig('row_power_ratio_min', '.3f')}–{fig('row_power_ratio_max', '.3f')}"
            if eld
            else "none in the model"
        )
        lam = (
            f"{fig('lambda_published_top', '.3f')} → {fig('lambda_fit_top', '.3f')}"
            if eld
            else "Gaussian"
        )
        tail = fig("q_high_over_model_top", ".3f") if eld else "—"
        finite = "finite" if r["extremes"]["all_finite"] else "**not finite**"
        out.append(
            f"| `{r['model']}` | {fig('variance_ratio_min', '.3f')}–"
            f"{fig('variance_ratio_max', '.3f')} | {row_power} | {lam} | {tail} | "
            f"{fig('green_right_corr', '.3f')}, {fig('green_down_corr', '.3f')} | "
            f"{fig('red_green_corr', '.3f')} | {finite}, "
            f"{fig('extremes.max_abs_linear', '.3g')} |"
        )
    return [*out, ""]


BLOCKS = {"speed": speed_block, "figure": figure_block, "evidence": evidence_block}


def rewrite(text: str, results: dict[str, dict]) -> str:
    """The page with every generated block made again from the results."""

    def fill(m: re.Match) -> str:
        if m["name"] not in BLOCKS:
            raise ValueError(f"noise.md: no generator for block {m['name']!r}")
        return m.group(1) + "\n".join(BLOCKS[m["name"]](results)) + m.group(4)

    return BLOCK.sub(fill, text)


def draw_figure(results: dict[str, dict]) -> list[str]:
    """docs/images/noise_models.png from its results row, where the fern scene is at
    hand (else left as it is); returns where the row and the code disagree."""
    if FIGURE_ROW not in results:
        return []
    sys.path.insert(0, str(BENCH))
    import bench_noise

    crop = bench_noise.fern_crop()
    if crop is None:
        print("noise guide: no fern scene, the figure is left as it is", file=sys.stderr)
        return []
    stale = bench_noise.draw_figure(results[FIGURE_ROW], crop)
    return [f"docs/images/noise_models.png: {s} (rerun bench_noise)" for s in stale]


def update(results: dict[str, dict] | None = None, page: Path = PAGE) -> list[str]:
    """Rewrite the page's blocks and draw the figure; returns the problems."""
    results = figures.load() if results is None else results
    text = page.read_text()
    new = rewrite(text, results)
    if new != text:
        page.write_text(new)
        print(f"noise guide: rewrote {page.relative_to(ROOT)}", file=sys.stderr)
    return draw_figure(results)


if __name__ == "__main__":
    problems = update()
    for p in problems:
        print(p, file=sys.stderr)
    sys.exit(1 if problems else 0)
