"""Noise from linear light vs from the sRGB PNG (issue 9), on real tiny demo builds.

`blurset build --keep-linear` keeps the linear float image of every view and level;
`blurset noise BUILD --source linear` adds the noise to it (composited over the build's
background), `--source png` to the inverse of the 8-bit PNG. Both sources share the
same draws (same key, stream and value index), so every difference between their
outputs is what the PNG did to the clean image: 8-bit quantization and, with NAN's
`--gamma 2.2`, a curve that is not the sRGB curve the build encoded with.

Measured per background (the default white one, and black, which puts the object's
dark edges and shadows against true black), gamma and gain:
- PSNR between the two sources' noisy linear images (peak 1) and processed PNGs;
- PSNR of the noise itself (linear source vs its clean image), for scale;
- the noise-variance model fit against the *true* linear light y (the EXR): per
  brightness bin, residual MSE / (sigma_r^2 + sigma_s^2 y) for each source (1.0 is a
  perfect fit, bias included), and each source against its own clean reference.

`ratio` of a `linear_vs_png_*` entry: residual MSE of the PNG source / that of the linear
source, against the true light, in the brightness bin (>= MIN_COUNT values) where it is
largest (> 1: the PNG source is further from the physical model there); `darkest_bin`
holds the same numbers for the darkest populated bin. `linear_vs_png_time` is the wall
time of the PNG source / the linear source on the same build.

Set BLURSET_BENCH_BUILD=DIR to reuse a build made with --keep-linear (white only).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from blurset.noise.model import read_linear_composited
from PIL import Image

GAINS = ("1", "4", "16")
SEED = 7
EDGES = np.array([0.0, 0.002, 0.008, 0.03, 0.1, 0.3, 0.7, 1.01])
MIN_COUNT = 2000
BUILD_ARGS = (
    "--demo", "--views", "17", "--latents", "8", "--samples", "4", "--sharp-samples", "8",
    "--resolution", "96", "--seed", "5", "--quiet", "--keep-linear",
)  # fmt: skip


def cli(*args: object) -> None:
    proc = subprocess.run(
        [sys.executable, "-m", "blurset.cli", *map(str, args)], capture_output=True, text=True
    )
    if proc.returncode != 0:
        raise RuntimeError(f"blurset {' '.join(map(str, args))}: {proc.stderr.strip()}")


def make_build(root: Path, background: str) -> Path:
    out = root / f"build_{background}"
    extra = []
    if background == "black":
        cfg = root / "black.toml"
        cfg.write_text("background = [0.0, 0.0, 0.0]\n")
        extra = ["--config", str(cfg)]
    cli("build", *BUILD_ARGS, *extra, "--out", out)
    return out


def read_exr_rgb(path: Path) -> np.ndarray:
    import OpenEXR

    ch = OpenEXR.File(str(path)).channels()
    key = "RGBA" if "RGBA" in ch else "RGB"
    return np.asarray(ch[key].pixels, dtype=np.float64)[..., :3]


def srgb_decode(x: np.ndarray) -> np.ndarray:
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)


def psnr(mse: float, peak: float = 1.0) -> float:
    return float(10 * np.log10(peak**2 / mse)) if mse > 0 else float("inf")


def measure(build: Path, lin_out: Path, png_out: Path, gain: str, gamma: str) -> dict:
    """Pool every unit of one gain: PSNRs and per-bin fits, in NumPy from the files."""
    nb = len(EDGES) - 1
    acc = {k: np.zeros(nb) for k in ("n", "pred", "lin_true", "png_true", "png_own", "lin_own")}
    bias = {k: np.zeros(nb) for k in ("lin", "png")}
    se_lin = se_png8 = se_noise = 0.0
    count = 0
    for unit in sorted(lin_out.glob(f"*/*/gain_{gain}")):
        rel = unit.relative_to(lin_out)
        other = png_out / rel
        meta = json.loads((unit / "noise.json").read_text())
        sr, ss, wb = meta["sigma_read"], meta["sigma_shot"], meta["white_balance"]
        scale = np.array([1 / wb["red"], 1.0, 1 / wb["blue"]]) if wb else np.ones(3)
        bg = tuple(meta["source"]["background"])
        level_dir = build / rel.parent
        for f in meta["files"]:
            stem = Path(f["image"]).stem
            true_l = read_linear_composited(
                level_dir / "linear" / f"{stem}.exr", background=bg
            ).astype(np.float64)
            y_true = np.clip(true_l, 0, 1) * scale
            x = np.asarray(Image.open(level_dir / "images" / f"{stem}.png"), np.float64) / 255
            y_png = (srgb_decode(x) if gamma == "srgb" else x**2.2) * scale
            a = read_exr_rgb(unit / f["linear"])
            b = read_exr_rgb(other / f["linear"])
            se_lin += float(((a - b) ** 2).sum())
            se_noise += float(((a - y_true) ** 2).sum())
            pa = np.asarray(Image.open(unit / f["image"]), np.float64)
            pb = np.asarray(Image.open(other / f["image"]), np.float64)
            se_png8 += float(((pa - pb) ** 2).sum())
            count += a.size
            bins = np.clip(np.digitize(y_true.ravel(), EDGES) - 1, 0, nb - 1)
            model = sr**2 + ss**2 * y_true.ravel()
            own = sr**2 + ss**2 * y_png.ravel()

            def add(key, values, bins=bins):
                acc[key] += np.bincount(bins, values, minlength=nb)

            acc["n"] += np.bincount(bins, minlength=nb)
            add("pred", model)
            add("lin_true", (a - y_true).ravel() ** 2)
            add("png_true", (b - y_true).ravel() ** 2)
            add("lin_own", (a - y_true).ravel() ** 2 / model)
            add("png_own", (b - y_png).ravel() ** 2 / own)
            bias["lin"] += np.bincount(bins, (a - y_true).ravel() / np.sqrt(model), minlength=nb)
            bias["png"] += np.bincount(bins, (b - y_true).ravel() / np.sqrt(model), minlength=nb)
    bins_out = []
    for i in range(nb):
        n = acc["n"][i]
        if n < MIN_COUNT:
            continue
        pred = acc["pred"][i] / n
        bins_out.append(
            {
                "y_lo": float(EDGES[i]),
                "y_hi": float(EDGES[i + 1]),
                "count": int(n),
                "linear_mse_over_model": float(acc["lin_true"][i] / n / pred),
                "png_mse_over_model": float(acc["png_true"][i] / n / pred),
                "linear_own_fit": float(acc["lin_own"][i] / n),
                "png_own_fit": float(acc["png_own"][i] / n),
                "linear_bias_in_sigmas": float(bias["lin"][i] / n),
                "png_bias_in_sigmas": float(bias["png"][i] / n),
            }
        )
    return {
        "psnr_linear_between_sources_db": psnr(se_lin / count),
        "psnr_png_between_sources_db": psnr(se_png8 / count, 255.0),
        "psnr_noise_db": psnr(se_noise / count),
        "bins": bins_out,
    }


def entry(m: dict, bg: str, gamma: str, gain: str) -> dict:
    """One result: `ratio` is the largest PNG/linear residual-MSE ratio over the bins."""
    worst = max(m["bins"], key=lambda b: b["png_mse_over_model"] / b["linear_mse_over_model"])
    dark = m["bins"][0]
    span = f"y in [{worst['y_lo']}, {worst['y_hi']})"
    return {
        "name": f"linear_vs_png_{bg}_gamma{gamma}_gain{gain}",
        "ratio": worst["png_mse_over_model"] / worst["linear_mse_over_model"],
        "contender": f"linear source MSE/model {worst['linear_mse_over_model']:.3f} at {span}",
        "baseline": f"png source {worst['png_mse_over_model']:.3f}; PSNR between sources "
        f"{m['psnr_linear_between_sources_db']:.1f} dB (noise {m['psnr_noise_db']:.1f} dB)",
        "background": bg,
        "gamma": gamma,
        "gain": float(gain),
        "darkest_bin": dark,
        **m,
    }


def timed_noise(build: Path, out: Path, source: str, gamma: str) -> float:
    t0 = time.perf_counter()
    cli("noise", build, "--out", out, "--gains", *GAINS, "--seed", SEED, "--source", source,
        "--gamma", gamma, "--quiet")  # fmt: skip
    return time.perf_counter() - t0


def run() -> list[dict]:
    results = []
    with tempfile.TemporaryDirectory(prefix="blurset-bench-linear-") as tmp:
        root = Path(tmp)
        given = os.environ.get("BLURSET_BENCH_BUILD")
        builds = {"white": Path(given)} if given else {}
        for bg in ("white", "black"):
            if bg not in builds and not (given and bg == "black"):
                builds[bg] = make_build(root, bg)
        times: dict[str, list[float]] = {"linear": [], "png": []}
        for bg, build in builds.items():
            for gamma in ("srgb", "2.2"):
                outs = {}
                for source in ("linear", "png"):
                    outs[source] = root / f"noise_{bg}_{gamma}_{source}"
                    times[source].append(timed_noise(build, outs[source], source, gamma))
                for gain in GAINS:
                    m = measure(build, outs["linear"], outs["png"], gain, gamma)
                    results.append(entry(m, bg, gamma, gain))
        t_lin, t_png = sum(times["linear"]), sum(times["png"])
        results.append(
            {
                "name": "linear_vs_png_time",
                "ratio": t_png / t_lin,
                "contender": f"blurset noise --source linear {t_lin:.2f} s",
                "baseline": f"blurset noise --source png {t_png:.2f} s",
                "contender_s": t_lin,
                "baseline_s": t_png,
                "gains": list(GAINS),
            }
        )
    return results


if __name__ == "__main__":
    for r in run():
        bins = r.pop("bins", [])
        print(json.dumps(r))
        for b in bins:
            print("   ", json.dumps(b))
