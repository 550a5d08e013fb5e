"""Evidence for the camera noise models (`blurset noise --model`), measured through the
binding (`blurset.noise.model.noise_image_model`) at small size: one row per model.

Each camera model runs the raw pipeline: linear RGB -> camera RGB (cam_from_rgb) ->
inverse white balance -> RGGB mosaic -> noise per photosite -> bilinear demosaic ->
white balance -> colour matrix -> linear. The bilinear demosaic keeps each photosite's
own value, so the raw noise of a photosite is recovered exactly from the linear output:
(cam_from_rgb . (noisy - clean)) / white_balance_gains at the pixel's own CFA channel,
the clean frame being the same call with `clean=True`; for ELD, times (white - black)
in DN (the noisy raw is whole DN, which the recovery checks). From that:

- variance against signal per CFA channel (flat frames at several levels and gains)
  over the model's: K x + s^2 Var_Tukey(lambda) + sigma_row^2 + 1/12 in DN^2 for ELD
  (Poisson shot, Tukey-lambda read, row, rounding), shot x + read for unprocess, and
  sigma_r^2 + sigma_s^2 y per RGB channel for the paper's;
- row-noise power (ELD, dark frames): the variance of the row means less the read
  noise's share, over the calibrated sigma_row^2;
- the read noise's shape (ELD, dark frames less each row's mean): the Tukey lambda that
  fits its quantiles best (probability-plot correlation, as ELD calibrates lambda)
  beside the published lambda, and its 0.1 % and 99.9 % quantiles over the model's;
- the demosaicked noise's correlation (flat grey at gain 20): green with its right and
  lower neighbour, red with green; the paper's model beside them (0 by construction);
- black, saturated and far-overexposed frames at gains 1, 64 and 1e4: every value
  finite, the largest |linear| (bounded by the raw clip for ELD) and the PNG codes.

`bench/run.py bench_noise_evidence` writes the rows into bench/results.json (seconds
on 2 cores); the noise guide's evidence table is generated from them (`make docs`).
"""

from __future__ import annotations

import json
import math
import os
import sys

import numpy as np
import numpy.typing as npt
from bench_noise import CAMERAS
from blurset.noise.model import (
    noise_default_levels,
    noise_image,
    noise_image_model,
    noise_key,
    noise_sigmas,
    noise_white_balance,
)

MODELS = ("paper", "unprocess", *(f"eld:{c}" for c in CAMERAS))
SEED = 5
# Flat frames: linear levels, gains and side (px) of the variance check.
LEVELS = (0.0, 0.02, 0.2, 0.6)
VARIANCE_GAINS = (1.0, 20.0)
VARIANCE_SIZE = int(os.environ.get("BLURSET_BENCH_EVIDENCE_SIZE", "384"))
# Dark frames for the row noise and the read noise's shape: ELD's calibrated range
# (K = Kmin .. Kmax = 64 Kmin) at its middle and its top.
# Row-noise power is estimated from the rows' means: its sampling error is about
# sqrt(2 / rows), so the frames are tall and several views are pooled.
DARK_GAINS = (8.0, 64.0)
DARK_SHAPE = (2048, 512)
DARK_VIEWS = int(os.environ.get("BLURSET_BENCH_EVIDENCE_DARK_VIEWS", "4"))
CORR_GAIN, CORR_LEVEL, CORR_SIZE = 20.0, 0.2, 256
EXTREME_GAINS = (1.0, 64.0, 1.0e4)
EXTREME_LEVELS = (0.0, 1.0, 4.0)
TAIL = (0.001, 0.999)

Array = npt.NDArray[np.float64]


# --- the Tukey-lambda distribution --------------------------------------------------------


def tukey_quantile(p: Array, lam: float) -> Array:
    """Q(p) = (p^lambda - (1 - p)^lambda) / lambda (the logistic's log(p / (1 - p)) at 0)."""
    p = np.asarray(p, dtype=np.float64)
    if abs(lam) < 1e-9:
        return np.log(p / (1 - p))
    return (p**lam - (1 - p) ** lam) / lam


def tukey_variance(lam: float) -> float:
    """The variance of the standard Tukey-lambda distribution (lambda > -1/2)."""
    if abs(lam) < 1e-9:
        return math.pi**2 / 3
    g = math.lgamma(lam + 1) * 2 - math.lgamma(2 * lam + 2)
    return 2 / lam**2 * (1 / (1 + 2 * lam) - math.exp(g))


# Probability points of the shape fit: even in logit, so the tails weigh as the middle.
_P = 1 / (1 + np.exp(-np.linspace(-7.0, 7.0, 561)))


def fit_lambda(samples: Array, grid: Array | None = None) -> tuple[float, float]:
    """(lambda, r): the Tukey lambda whose quantiles correlate best with the samples'
    (probability-plot correlation), and that correlation."""
    q = np.quantile(samples, _P)
    grid = np.linspace(-0.5, 0.5, 1001) if grid is None else grid
    best = (0.0, -2.0)
    for lam in grid:
        r = float(np.corrcoef(q, tukey_quantile(_P, float(lam)))[0, 1])
        if r > best[1]:
            best = (float(lam), r)
    return best


# --- frames and the raw noise they carry -------------------------------------------------


def _call(
    model: str, img: npt.NDArray[np.float32], gain: float, clean: bool = False, view: int = 0
):
    return noise_image_model(
        img, model=model, gain=gain, seed=SEED, key=noise_key(SEED, gain), view=view,
        gamma="srgb", white_balance=noise_white_balance(SEED), clean=clean,
    )  # fmt: skip


def cfa_channel(h: int, w: int) -> npt.NDArray[np.intp]:
    """The RGGB channel of each photosite: 0 red, 1 green, 2 blue."""
    y, x = np.mgrid[0:h, 0:w]
    return (x & 1) + (y & 1)


def raw_noise(
    model: str, img: npt.NDArray[np.float32], gain: float, view: int = 0
) -> tuple[Array, Array, dict]:
    """(clean raw, raw noise) per photosite, each (H, W) at the photosite's own CFA
    channel, in the model's noise units (DN above black for ELD, normalised raw for
    unprocess), and the model's record."""
    noisy, _, record = _call(model, img, gain, view=view)
    clean, _, _ = _call(model, img, gain, clean=True, view=view)
    rec = json.loads(record)
    to_raw = np.asarray(rec["cam_from_rgb"]).T / np.asarray(rec["white_balance_gains"])
    unit = rec["white_level_dn"] - rec["black_level_dn"] if "white_level_dn" in rec else 1.0
    own = cfa_channel(*img.shape[:2])[..., None]

    def pick(lin: npt.NDArray[np.float32]) -> Array:
        raw = lin.astype(np.float64) @ to_raw * unit
        return np.take_along_axis(raw, own, axis=2)[..., 0]

    x, n = pick(clean), pick(noisy) - pick(clean)
    if "white_level_dn" in rec:
        # The noisy raw is whole DN above the (whole) black level: the recovery is exact.
        frac = np.abs((x + n) - np.round(x + n))
        assert float(frac.max()) < 1e-2, f"{model}: raw not recovered ({frac.max():.3g} DN)"
    return x, n, rec


def model_variance(rec: dict, x: float) -> float:
    """The variance the record's model gives at clean raw `x` (its noise units)."""
    if "system_gain_k" in rec:
        lam = rec["read_noise"]["lambda"]
        read = rec["read_noise"]["scale_dn"] ** 2 * tukey_variance(lam)
        return rec["system_gain_k"] * x + read + rec["row_noise"]["sigma_dn"] ** 2 + 1 / 12
    return rec["shot_noise"] * x + rec["read_noise"]


def flat(size: int, level: float) -> npt.NDArray[np.float32]:
    return np.full((size, size, 3), level, np.float32)


# --- the measurements -----------------------------------------------------------------


def variance_per_channel(model: str, size: int = VARIANCE_SIZE) -> list[dict]:
    """Per gain, level and channel: clean signal, measured and model variance."""
    out = []
    for gain in VARIANCE_GAINS:
        for level in LEVELS:
            if model == "paper":
                sr, ss = noise_sigmas(gain, noise_default_levels())
                lin, _ = noise_image(
                    flat(size, level), sigma_read=sr, sigma_shot=ss, key=noise_key(SEED, gain),
                    gamma="srgb", white_balance=None,
                )  # fmt: skip
                res = lin.astype(np.float64) - level
                per = [(level, res[..., c].ravel()) for c in range(3)]
                want = [sr * sr + ss * ss * level] * 3
            else:
                x, n, rec = raw_noise(model, flat(size, level), gain)
                cfa = cfa_channel(size, size)
                per = [(float(x[cfa == c].mean()), n[cfa == c]) for c in range(3)]
                want = [model_variance(rec, s) for s, _ in per]
            for c, ((signal, v), w) in enumerate(zip(per, want, strict=True)):
                got = float(np.var(v, ddof=1))
                out.append({"gain": gain, "level": level, "channel": "RGB"[c],
                            "signal": signal, "measured": got, "model": w,
                            "ratio": got / w})  # fmt: skip
    return out


def row_power(n: Array) -> tuple[float, Array]:
    """The power of noise shared by each row of `n` (rows, photosites): the variance of
    the row means less what the rest of the noise leaves in them; and `n` less its row
    means (the noise per photosite)."""
    means = n.mean(axis=1)
    within = float(n.var(axis=1, ddof=1).mean())
    return float(np.var(means, ddof=1)) - within / n.shape[1], n - means[:, None]


def dark_frame(
    model: str, gain: float, shape: tuple[int, int] = DARK_SHAPE, views: int = DARK_VIEWS
) -> dict:
    """Row-noise power and the read noise's shape of an ELD camera's dark frames."""
    img = np.zeros((*shape, 3), np.float32)
    frames = [raw_noise(model, img, gain, view=v) for v in range(views)]
    rec = frames[0][2]
    row_sigma = rec["row_noise"]["sigma_dn"]
    power, read_rows = row_power(np.concatenate([n for _, n, _ in frames]))
    read = read_rows.ravel()
    lam, scale = rec["read_noise"]["lambda"], rec["read_noise"]["scale_dn"]
    fit, r = fit_lambda(read)
    q = {p: float(np.quantile(read, p) / (scale * tukey_quantile(np.array(p), lam))) for p in TAIL}
    return {
        "gain": gain,
        "system_gain_k": rec["system_gain_k"],
        "extrapolated": rec["extrapolated"],
        "row_sigma_dn": row_sigma,
        "row_power_dn2": power,
        "row_power_ratio": power / row_sigma**2,
        "read_scale_dn": scale,
        "lambda_published": lam,
        "lambda_fit": fit,
        "lambda_fit_ppcc": r,
        # The read noise's 0.1 % and 99.9 % quantiles over the model's.
        "q_low_over_model": q[TAIL[0]],
        "q_high_over_model": q[TAIL[1]],
    }


def correlation(model: str) -> dict:
    """Correlation of the demosaicked noise (linear output less the clean frame) between
    horizontal and vertical green neighbours and between red and green."""
    img = flat(CORR_SIZE, CORR_LEVEL)
    if model == "paper":
        sr, ss = noise_sigmas(CORR_GAIN, noise_default_levels())
        lin, _ = noise_image(img, sigma_read=sr, sigma_shot=ss, key=noise_key(SEED, CORR_GAIN),
                             gamma="srgb", white_balance=None)  # fmt: skip
        res = lin.astype(np.float64) - CORR_LEVEL
    else:
        noisy, _, _ = _call(model, img, CORR_GAIN)
        clean, _, _ = _call(model, img, CORR_GAIN, clean=True)
        res = noisy.astype(np.float64) - clean
    return residual_correlation(res)


def residual_correlation(res: Array) -> dict:
    g = res[..., 1]

    def corr(a: Array, b: Array) -> float:
        return float(np.corrcoef(a.ravel(), b.ravel())[0, 1])

    return {
        "green_right_corr": corr(g[:, :-1], g[:, 1:]),
        "green_down_corr": corr(g[:-1], g[1:]),
        "red_green_corr": corr(res[..., 0], g),
        "blue_green_corr": corr(res[..., 2], g),
    }


def extremes(model: str) -> dict:
    """Black, saturated and overexposed flat frames at the base, top and a far gain."""
    worst, finite, cases = 0.0, True, []
    for gain in EXTREME_GAINS:
        for level in EXTREME_LEVELS:
            img = flat(32, level)
            if model == "paper":
                sr, ss = noise_sigmas(gain, noise_default_levels())
                lin, png = noise_image(img, sigma_read=sr, sigma_shot=ss,
                                       key=noise_key(SEED, gain), gamma="srgb")  # fmt: skip
            else:
                lin, png, _ = _call(model, img, gain)
            finite &= bool(np.isfinite(lin).all())
            big = float(np.abs(lin).max())
            worst = max(worst, big)
            cases.append({"gain": gain, "level": level, "max_abs_linear": big,
                          "png_mean": float(png.mean()), "png_min": int(png.min()),
                          "png_max": int(png.max())})  # fmt: skip
    return {"all_finite": finite, "max_abs_linear": worst, "cases": cases}


def _slug(model: str) -> str:
    return model.replace(":", "_")


def measure(model: str) -> dict:
    """The evidence row of one model."""
    var = variance_per_channel(model)
    ratios = [v["ratio"] for v in var]
    worst = max(ratios, key=lambda r: abs(r - 1))
    row: dict = {
        "name": f"noise_evidence_{_slug(model)}",
        "ratio": worst,
        "ratio_is": "measured variance over the model's, the worst of every CFA channel "
        "(RGB channel for paper), level and gain",
        "contender": f"{model}: variance / model in [{min(ratios):.3f}, {max(ratios):.3f}]",
        "baseline": "the model's variance",
        "model": model,
        "variance_ratio_min": min(ratios),
        "variance_ratio_max": max(ratios),
        "variance_worst_deviation": abs(worst - 1),
        "variance": var,
        "variance_size_px": VARIANCE_SIZE,
        **correlation(model),
        "correlation_gain": CORR_GAIN,
        "correlation_level": CORR_LEVEL,
        "extremes": extremes(model),
        "seed": SEED,
    }
    if model.startswith("eld:"):
        dark = [dark_frame(model, g) for g in DARK_GAINS]
        row["dark"] = dark
        row["dark_frames"] = {"height": DARK_SHAPE[0], "width": DARK_SHAPE[1], "views": DARK_VIEWS}
        top = dark[-1]
        for k in ("row_power_ratio", "lambda_published", "lambda_fit", "lambda_fit_ppcc",
                  "read_scale_dn", "q_low_over_model", "q_high_over_model"):  # fmt: skip
            row[f"{k}_top"] = top[k]
        row["row_power_ratio_min"] = min(d["row_power_ratio"] for d in dark)
        row["row_power_ratio_max"] = max(d["row_power_ratio"] for d in dark)
        row["lambda_fit_worst_deviation"] = max(
            abs(d["lambda_fit"] - d["lambda_published"]) for d in dark
        )
    return row


def run() -> list[dict]:
    load = os.getloadavg()[0]
    return [{**measure(m), "loadavg_1min": load} for m in MODELS]


if __name__ == "__main__":
    models = sys.argv[1:] or list(MODELS)
    for m in models:
        r = measure(m)
        brief = {k: v for k, v in r.items() if not isinstance(v, (list, dict))}
        print(json.dumps(brief, indent=1))
