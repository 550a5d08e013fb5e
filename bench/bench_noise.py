"""Noise benchmark (DESIGN §9): LLFF-N noise on fern images_8 (20 views) x 6 gains.

Baseline: the same formulas in NumPy float32 (x^2.2, inverse white balance, read + shot
noise from NumPy's Generator, forward white balance, x^(1/2.2), 8-bit rounding), the
way NAN's data loader computes them. Contender: `blurset.noise.model.noise_image` (Rust,
rayon, counter-based Philox + ziggurat). Both start from decoded uint8 arrays and
produce the linear float32 image and the processed uint8 image, so only the noise
computation is timed; the end-to-end `blurset noise` run (decode, noise, PNG + EXR
writes) is reported beside it.

Camera models (`--model`): the same views as linear light (sRGB-decoded float32), one
frame per view at gain 20, under the paper's model (`noise_image` on linear light) and
under every camera model (`noise_image_model`: the raw pipeline, mosaic, noise per
photosite, demosaic), round after round in turn; a row per model (`noise_model_<model>`,
the paper's included) with its seconds per megapixel and its time over the paper's,
the median of the rounds' ratios (the issue's goal: a model at most 3x the paper's).

The noise guide's figure: one crop of fern under several models at matched noise power
(`noise_models_figure`: each model's gain, its residual's statistics and power
spectrum); docs/gen/noise_guide.py draws docs/images/noise_models.png from that row.
`python bench/bench_noise.py --models` measures the camera models' rows and the figure's
alone and merges them into bench/results.json; `--figure` draws the figure from it.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from blurset.noise.model import (
    noise_default_levels,
    noise_image,
    noise_image_model,
    noise_key,
    noise_sigmas,
    noise_white_balance,
)
from harness import RESULTS, interleaved_times, median_times, merge_into_results
from PIL import Image

FERN = Path(__file__).resolve().parents[2] / "shared" / "data" / "llff" / "fern"
GAINS = (1.0, 2.0, 4.0, 8.0, 16.0, 20.0)
SEED = 11
REPEATS = 5
CAMERAS = ("SonyA7S2", "NikonD850", "CanonEOS70D", "CanonEOS700D", "CanonEOS5D4")
MODELS = ("unprocess", *(f"eld:{c}" for c in CAMERAS))
MODEL_GAIN = 20.0
MODEL_REPEATS = int(os.environ.get("BLURSET_BENCH_NOISE_REPEATS", "7"))


def params():
    levels = noise_default_levels()
    wb = noise_white_balance(SEED)
    return [(g, *noise_sigmas(g, levels)) for g in GAINS], wb


def baseline(images, gains, wb, rng):
    scale = np.array([1 / wb[0], 1.0, 1 / wb[1]], np.float32)
    out = None
    for _, sr, ss in gains:
        for im in images:
            y = (im.astype(np.float32) / 255) ** 2.2 * scale
            std = np.sqrt(np.float32(sr * sr) + np.float32(ss * ss) * y)
            lin = y + std * rng.standard_normal(y.shape, dtype=np.float32)
            proc = np.clip(lin / scale, 0, 1) ** np.float32(1 / 2.2)
            out = (lin, np.round(proc * 255).astype(np.uint8))
    return out


def contender(images, gains, wb):
    out = None
    for g, sr, ss in gains:
        key = noise_key(SEED, g)
        for i, im in enumerate(images):
            out = noise_image(im, sigma_read=sr, sigma_shot=ss, key=key, view=i, white_balance=wb)
    return out


def _srgb_to_linear(im: np.ndarray) -> np.ndarray:
    x = im.astype(np.float64) / 255
    return np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4).astype(np.float32)


def models_vs_paper(images, repeats: int = MODEL_REPEATS) -> list[dict]:
    """Every model's seconds per megapixel on the same linear views, the paper's model
    among them, interleaved round by round; a row per model with its time over the
    paper's (the median of the rounds' ratios, and the ratio of the medians)."""
    lin = [_srgb_to_linear(im) for im in images]
    sr, ss = noise_sigmas(MODEL_GAIN, noise_default_levels())
    wb = noise_white_balance(SEED)
    key = noise_key(SEED, MODEL_GAIN)

    def paper():
        for i, im in enumerate(lin):
            noise_image(
                im, sigma_read=sr, sigma_shot=ss, key=key, view=i, gamma="srgb", white_balance=wb
            )

    def model(m: str):
        def one():
            for i, im in enumerate(lin):
                noise_image_model(
                    im, model=m, gain=MODEL_GAIN, seed=SEED, key=key, view=i, gamma="srgb",
                    white_balance=wb,
                )  # fmt: skip

        return one

    thunks = {"paper": paper, **{m: model(m) for m in MODELS}}
    for fn in thunks.values():  # warm up
        fn()
    times = interleaved_times(thunks, repeats)
    return model_rows(times, sum(im.shape[0] * im.shape[1] for im in lin) / 1e6, len(lin))


def model_rows(times: dict[str, list[float]], megapixels: float, images: int) -> list[dict]:
    """The rows of `models_vs_paper` from each model's seconds per round ("paper" one of
    them): seconds per megapixel (medians) and the time over the paper's."""
    paper = times["paper"]
    t_paper = statistics.median(paper)
    rows = []
    for m, ts in times.items():
        t = statistics.median(ts)
        per_round = [a / b for a, b in zip(ts, paper, strict=True)]
        rows.append(
            {
                "name": f"noise_model_{m.replace(':', '_')}",
                "ratio": statistics.median(per_round),
                "ratio_is": "seconds of this model over the paper model's on the same views, "
                "median of interleaved rounds (the goal: at most 3)",
                "contender": f"{m} {t / megapixels:.3f} s/MP",
                "baseline": f"paper {t_paper / megapixels:.3f} s/MP",
                "model": m,
                "s_per_megapixel": t / megapixels,
                "paper_s_per_megapixel": t_paper / megapixels,
                "over_paper": statistics.median(per_round),
                "over_paper_of_medians": t / t_paper,
                "over_paper_range": [min(per_round), max(per_round)],
                "megapixels": megapixels,
                "images": images,
                "gain": MODEL_GAIN,
                "repeats": len(ts),
                "threads": int(os.environ.get("RAYON_NUM_THREADS") or os.cpu_count() or 1),
                "loadavg_1min": os.getloadavg()[0],
            }
        )
    return rows


def end_to_end() -> float:
    with tempfile.TemporaryDirectory(prefix="blurset-bench-noise-") as tmp:
        t0 = time.perf_counter()
        subprocess.run(
            [sys.executable, "-m", "blurset.cli", "noise", str(FERN), "--factor", "8",
             "--seed", str(SEED), "--out", str(Path(tmp) / "out")],
            check=True, capture_output=True,
        )  # fmt: skip
        return time.perf_counter() - t0


def run() -> list[dict]:
    if not (FERN / "images_8").is_dir():
        print(f"bench_noise: {FERN} is absent, skipped")
        return []
    images = [np.asarray(Image.open(p)) for p in sorted((FERN / "images_8").glob("*.png"))]
    gains, wb = params()
    rng = np.random.default_rng(0)
    # Warm up and check both sides compute the same model on the brightest gain.
    lin_b, proc_b = baseline(images, gains, wb, rng)
    lin_c, proc_c = contender(images, gains, wb)
    scale = np.array([1 / wb[0], 1.0, 1 / wb[1]], np.float32)
    y = (images[-1].astype(np.float32) / 255) ** 2.2 * scale
    std_ratio = float(np.std(lin_c - y) / np.std(lin_b - y))
    cpu: dict = {}
    t_base, t_rust = median_times(
        lambda: baseline(images, gains, wb, rng),
        lambda: contender(images, gains, wb),
        REPEATS,
        cpu=cpu,
    )
    t_cli = end_to_end()
    crop = fern_crop()
    assert crop is not None
    n_values = sum(im.size for im in images) * len(gains)
    return [
        {
            "name": "noise_vs_numpy",
            "ratio": t_base / t_rust,
            "contender": f"blurset noise_image {t_rust:.3f} s",
            "baseline": f"NumPy float32 {t_base:.3f} s",
            "contender_s": t_rust,
            "baseline_s": t_base,
            "contender_ns_per_value": t_rust / n_values * 1e9,
            "images": len(images),
            "gains": list(GAINS),
            "repeats": REPEATS,
            "cli_end_to_end_s": t_cli,
            "residual_std_ratio_gain20_last_view": std_ratio,
            "contender_cpu_s": cpu["b"],
            "baseline_cpu_s": cpu["a"],
            "cpu_ratio": cpu["a"] / cpu["b"],
            "loadavg_1min": os.getloadavg()[0],
        },
        *models_vs_paper(images),
        figure_row(crop),
    ]


# --- the noise guide's figure: one crop under each model at matched noise power --------

FIGURE = Path(__file__).resolve().parents[1] / "docs" / "images" / "noise_models.png"
FIGURE_MODELS = ("paper", "unprocess", "eld:SonyA7S2", "eld:NikonD850")
# The noise power every model is matched to: the Sony A7S2's at the top of ELD's
# calibrated range (K = Kmax = 64 Kmin).
REFERENCE = ("eld:SonyA7S2", 64.0)
CROP = 96  # px: the centre of fern's first images_8 view


def fern_crop() -> np.ndarray | None:
    """The figure's 8-bit crop (CROP x CROP, RGB), or None without the fern scene."""
    views = sorted((FERN / "images_8").glob("*.png"))
    if not views:
        return None
    src = np.asarray(Image.open(views[0]))[..., :3]
    h, w = src.shape[:2]
    c = CROP // 2
    return np.ascontiguousarray(src[h // 2 - c : h // 2 + c, w // 2 - c : w // 2 + c])


def _noisy_crop(model: str, gain: float, lin: np.ndarray) -> np.ndarray:
    """The processed 8-bit crop under `model` at `gain` (gamma 2.2, the scene default)."""
    key, wb = noise_key(SEED, gain), noise_white_balance(SEED)
    if model == "paper":
        sr, ss = noise_sigmas(gain, noise_default_levels())
        _, png = noise_image(lin, sigma_read=sr, sigma_shot=ss, key=key, gamma="2.2",
                             white_balance=wb)  # fmt: skip
    else:
        _, png, _ = noise_image_model(lin, model=model, gain=gain, seed=SEED, key=key,
                                      gamma="2.2", white_balance=wb)  # fmt: skip
    return png.astype(np.float64)


def _linear(crop: np.ndarray) -> np.ndarray:
    return ((crop.astype(np.float64) / 255) ** 2.2).astype(np.float32)


def _matched_gain(model: str, lin: np.ndarray, clean: np.ndarray, target: float) -> float:
    """The gain at which `model`'s residual standard deviation (codes) is `target`:
    bisection in log gain (the residual grows with the gain)."""
    lo, hi = -8.0, 14.0
    for _ in range(40):
        mid = (lo + hi) / 2
        std = float(np.std(_noisy_crop(model, 2.0**mid, lin) - clean))
        lo, hi = (mid, hi) if std < target else (lo, mid)
    return 2.0 ** ((lo + hi) / 2)


def radial_power(res: np.ndarray, bins: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """The residual's power spectrum (mean over channels, normalised so that white noise
    of variance v reads v in every ring), averaged over rings of spatial frequency
    (cycles per pixel, up to 0.5): (ring centres, power)."""
    p = np.mean([np.abs(np.fft.fft2(res[..., c] - res[..., c].mean())) ** 2 for c in range(3)], 0)
    fy, fx = np.meshgrid(np.fft.fftfreq(res.shape[0]), np.fft.fftfreq(res.shape[1]), indexing="ij")
    r = np.hypot(fy, fx).ravel()
    edges = np.linspace(0, 0.5, bins + 1)
    idx = np.digitize(r, edges)
    f = (edges[:-1] + edges[1:]) / 2
    power = np.array([p.ravel()[idx == i + 1].mean() for i in range(len(f))])
    return f, power / (res.shape[0] * res.shape[1])


def residual_stats(res: np.ndarray) -> dict:
    """Neighbour correlation (green, horizontal), red-green correlation and standard
    deviation of a residual."""
    g = res[..., 1]
    space = float(np.corrcoef(g[:, :-1].ravel(), g[:, 1:].ravel())[0, 1])
    across = float(np.corrcoef(res[..., 0].ravel(), g.ravel())[0, 1])
    return {"neighbour_corr": space, "red_green_corr": across, "std": float(res.std())}


def figure_row(crop: np.ndarray) -> dict:
    """What the guide's figure shows, as a results row: each model's gain at the noise
    power of REFERENCE (its residual's standard deviation in 8-bit codes), the
    residual's statistics and its radially averaged power spectrum. The crops are
    drawn again from these gains (same seed, same bytes) by `draw_figure`."""
    lin, clean = _linear(crop), crop.astype(np.float64)
    target = float(np.std(_noisy_crop(*REFERENCE, lin) - clean))
    models: dict = {}
    freq: list[float] = []
    for m in FIGURE_MODELS:
        g = REFERENCE[1] if m == REFERENCE[0] else _matched_gain(m, lin, clean, target)
        res = _noisy_crop(m, g, lin) - clean
        f, power = radial_power(res)
        freq = f.tolist()
        # Keyed by a name a figure marker can spell (models.eld_SonyA7S2.gain).
        models[m.replace(":", "_")] = {"model": m, "gain": g, **residual_stats(res),
                                       "power": power.tolist()}  # fmt: skip
    stds = [v["std"] for v in models.values()]
    return {
        "name": "noise_models_figure",
        "ratio": max(stds) / min(stds),
        "ratio_is": "largest over smallest residual standard deviation of the figure's "
        "panels (matched noise power: 1)",
        "contender": ", ".join(f"{v['model']} at gain {v['gain']:.3g}" for v in models.values()),
        "baseline": f"{REFERENCE[0]} at gain {REFERENCE[1]:g}: {target:.2f} codes",
        "target_std_codes": target,
        "reference": {"model": REFERENCE[0], "gain": REFERENCE[1]},
        "crop": {"scene": "fern images_8, first view, centre", "size": CROP},
        "seed": SEED,
        "gamma": "2.2",
        "frequencies": freq,
        "models": models,
    }


def draw_figure(row: dict, crop: np.ndarray, out: Path = FIGURE) -> list[str]:
    """The figure from its results row: each model's crop drawn again at the row's gain
    beside the row's power spectra. Returns what disagrees with the row (a crop whose
    residual is not the row's: the results are stale, rerun the bench)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lin, clean = _linear(crop), crop.astype(np.float64)
    models = row["models"]
    stale = []
    # Matplotlib's defaults, whoever calls (docs/gen/bench.py sets its own for its plots).
    with plt.style.context("default"):
        fig, axes = plt.subplots(1, len(models) + 1, figsize=(3.2 * (len(models) + 1), 3.4), dpi=90)
        for ax, v in zip(axes[:-1], models.values(), strict=True):
            m = v["model"]
            noisy = _noisy_crop(m, v["gain"], lin)
            std = float((noisy - clean).std())
            if abs(std - v["std"]) > 1e-9 * max(1.0, v["std"]):
                stale.append(
                    f"{m} at gain {v['gain']:.6g}: std {std:.6g}, the results say {v['std']:.6g}"
                )
            ax.imshow(noisy.astype(np.uint8), interpolation="nearest")
            ax.set_title(f"{m}\ngain {v['gain']:.3g}, std {v['std']:.1f}", fontsize=9)
            ax.axis("off")
            axes[-1].semilogy(row["frequencies"][1:], v["power"][1:], label=m)
        axes[-1].set_xlabel("cycles / pixel")
        axes[-1].set_ylabel("power (codes²)")
        axes[-1].set_title("noise power spectrum", fontsize=9)
        axes[-1].legend(fontsize=7)
        fig.tight_layout()
        fig.savefig(out, dpi=90, metadata={"Software": None})
        plt.close(fig)
    return stale


def models_part() -> list[dict]:
    """The camera models' rows alone: their time against the paper's and the figure's."""
    images = [np.asarray(Image.open(p)) for p in sorted((FERN / "images_8").glob("*.png"))]
    crop = fern_crop()
    assert crop is not None
    return [*models_vs_paper(images), figure_row(crop)]


if __name__ == "__main__":
    # `--models`: the camera models' rows only, merged into bench/results.json (as
    # `bench/run.py bench_noise` does for all of its rows), then the figure from them;
    # `--figure`: the figure drawn again from results.json's row.
    if sys.argv[1:] in (["--models"], ["--figure"]):
        if sys.argv[1] == "--models":
            print(merge_into_results(models_part()))
        row = {r["name"]: r for r in json.loads(RESULTS.read_text())}["noise_models_figure"]
        crop = fern_crop()
        assert crop is not None, f"{FERN} is absent"
        for problem in draw_figure(row, crop):
            print(f"stale: {problem}")
        print(FIGURE)
    else:
        for r in run():
            print(r)
