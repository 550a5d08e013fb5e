"""What the command writes: tradeoff.csv, tradeoff.json and tradeoff.png."""

from __future__ import annotations

import csv
import io
import json
from pathlib import Path
from typing import Any

from blurset import layout
from blurset.services import outputs

COLUMNS = (
    "role",
    "method",
    "sampling",
    "latents",
    "samples_per_frame",
    "samples_total",
    "budget",
    "seconds",
    "psnr",
    "psnr_linear",
    "render_psnr",
    "sharp_render_psnr",
    "denoise",
    "detail_ratio",
    "sharp_detail_ratio",
    "render_reference_factor",
    "cpu_seconds",
    "max_gap_px",
    "pareto",
    "label",
)


def write_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO(newline="")
    wr = csv.DictWriter(buf, fieldnames=list(COLUMNS))
    wr.writeheader()
    for r in rows:
        wr.writerow({k: r[k] for k in COLUMNS})
    layout.write_text_atomic(path, buf.getvalue())


def write_record(path: Path, setup: dict, rows: list[dict], rec: dict) -> None:
    layout.write_text_atomic(
        path,
        json.dumps(
            {"kind": outputs.TRADEOFF_KIND, "setup": setup, "rows": rows, "recommendation": rec},
            indent=1,
        )
        + "\n",
    )


def plot(path: Path, rows: list[dict], setup: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cands = [r for r in rows if r["role"] == "candidate"]
    style = {
        ("average", "random"): ("tab:red", "o", "average, random positions"),
        ("average", "stratified"): ("tab:blue", "s", "average, stratified positions"),
        ("average", "auto-stratified"): ("tab:green", "D", "average, --latents auto (stratified)"),
        ("motion_blur", "continuous"): ("black", "*", "Cycles motion blur"),
    }
    fig, ax = plt.subplots(figsize=(9, 6), dpi=130)
    for key, (color, marker, name) in style.items():
        pts = [r for r in cands if (r["method"], r["sampling"]) == key]
        if pts:
            _scatter(ax, key, pts, color, marker, name)
    front = sorted((r for r in cands if r["pareto"]), key=lambda r: r["seconds"])
    if front:
        ax.plot(
            [r["seconds"] for r in front],
            [r["psnr"] for r in front],
            "--",
            color="grey",
            lw=1,
            label="Pareto front",
            zorder=2,
        )
    ax.set_xscale("log")
    ax.set_xlabel("seconds per blurry image (render + accumulate, log scale)", fontsize=11)
    ax.set_ylabel("PSNR against the reference (dB, sRGB)", fontsize=11)
    ref = setup["reference"]
    ax.set_title(
        f"{setup['uid']}: view {setup['view']}, blur level {setup['level']}, "
        f"{setup['motion_px']:.1f} px of motion at {setup['resolution']} px\n"
        f"reference: {ref['latents']} stratified frames x {ref['samples_per_frame']} samples; "
        "labels: frames x samples per frame",
        fontsize=10,
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=9, loc="lower right")
    fig.tight_layout()
    layout.write_figure(path, lambda f: fig.savefig(f, format="png"))
    plt.close(fig)


def _scatter(
    ax: Any, key: tuple[str, str], pts: list[dict], color: str, marker: str, name: str
) -> None:
    """One method's points, each labelled frames x samples (or S= for motion blur)."""
    ax.scatter(
        [r["seconds"] for r in pts],
        [r["psnr"] for r in pts],
        c=color,
        marker=marker,
        s=90 if marker == "*" else 45,
        label=name,
        zorder=3,
    )
    for r in pts:
        if key[0] == "motion_blur":
            text = f"S={r['samples_total']}"
        else:
            text = f"{r['latents']}x{r['samples_per_frame']}"
        ax.annotate(
            text,
            (r["seconds"], r["psnr"]),
            textcoords="offset points",
            xytext=(5, 4),
            fontsize=8,
            color=color,
        )
