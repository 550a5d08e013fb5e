"""Is a target build's per-image estimate honest where sRGB bends over the halves' spread,
and once the rounds have stopped on it (issue 59, item 2)?

A sharp view of a model rendered as two halves on independent seeds at each of a grid of
sample counts (the first n samples of one pinned Cycles sequence, as a target build's
rounds take them), repeated on REPS independent seed pairs, against a reference of two
halves of REF_N samples on other seeds (its own noise taken out). For every repeat and
count: the two estimates of the merged image's render noise, `plain` (MSE of the halves /
4, the estimate before) and `about_merged` (metrics::halves_se: each half's sRGB distance
from the image their mean writes, the estimate now), and the merged image's measured
error. Then the target rule (plan/target.rs: pilot, α fit, first step, aim, accept, on
the bound) is replayed on the grid, each count rounded up to the next one, once per
estimate: where it stops, the estimate and bound it would record and what the image
measures there.

    python bench/check_half_noise.py render MODEL.glb WORK_DIR [VIEWS] [REPS]
    python bench/check_half_noise.py summarize WORK_DIR [WORK_DIR ...]   # -> check_half_noise.json

Rendering takes about 10 minutes per view on 2 cores at 128 px (8 repeats)."""

from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_target as bt  # noqa: E402
from harness import plan_object  # noqa: E402

HERE = Path(__file__).resolve().parent
RES = 128
TARGET = 45.0
GRID = (4, 6, 8, 11, 16, 23, 32, 45, 64, 91, 128, 181, 256, 362, 512)
REF_N = 4096
REF_SALTS = (0x5BD1E995, 0x2545F491)
# The rule's constants (plan/target.rs) and the bound's z (metrics.rs), replayed here.
ACCEPT_DB, AIM_DB, MAX_ROUNDS, FIRST_STEP, Z = 0.25, 0.2, 6, 8.0, 2.808716591058786


def _render(w, cfg, frames, per_frame: int, seed_xor: int, pin: int, work: Path):
    from blurset import image

    acc = image.Accumulator(RES, RES)
    half = []
    for k, f in enumerate(frames):
        g = {x: f[x] for x in ("c2w", "region", "call", "motion", "dof") if f.get(x) is not None}
        g.update(seed=(f["seed"] ^ seed_xor) & 0x7FFFFFFF, samples=per_frame,
                 sample_offset=k * per_frame, sample_sequence=pin,
                 out=str(work / f"tmp_{k:04d}.exr"))  # fmt: skip
        half.append(g)

    def on_frame(_i, path, origin):
        acc.add_exr(path, origin)
        os.unlink(path)

    w.render(half, resolution=RES, fov_deg=cfg.fov_deg, samples=per_frame,
             on_frame=on_frame, crop=True)  # fmt: skip
    return acc.mean().astype(np.float32)


def render(glb: Path, out: Path, views: int, reps: int) -> None:
    """Every view's sharp image: the reference's halves and each repeat's halves at each
    count, as .npy files under `out` (a run that is stopped resumes)."""
    from blurset.services.worker_client import Worker

    bt.RES = RES
    out.mkdir(parents=True, exist_ok=True)
    cfg = bt.config(out / "build", glb, RES, views, preset="balanced", target_psnr=TARGET)
    with Worker(timeout=7200, workdir=out / "scratch", device="CPU") as w:
        plan = plan_object(cfg, glb, w, out)
        pin = max(cfg.target_max_samples // 2, REF_N)
        meta: dict[str, Any] = {
            "model": glb.stem,
            "grid": list(GRID),
            "reps": reps,
            "ref_n": REF_N,
            "images": [],
        }
        for f in plan.renders(str(out / "r"), cfg.cycles_samples, sharp_views=[]):
            if f["level"] != "sharp":
                continue
            d = out / f"v{f['view']}_sharp"
            d.mkdir(exist_ok=True)
            for h, salt in enumerate(REF_SALTS):
                if not (d / f"ref_{'ab'[h]}.npy").exists():
                    np.save(d / f"ref_{'ab'[h]}.npy", _render(w, cfg, [f], REF_N, salt, pin, out))
            for r in range(reps):
                for n in GRID:
                    for h in (0, 1):
                        p = d / f"r{r}_n{n}_{'ab'[h]}.npy"
                        # Repeat 0's first half is the plan's own seed, as a build's is.
                        xor = 0 if r == h == 0 else (0x9E3779B1 * (2 * r + h + 1)) & 0x7FFFFFFF
                        if not p.exists():
                            np.save(p, _render(w, cfg, [f], n, xor, pin, out))
            meta["images"].append(d.name)
            (out / "meta.json").write_text(json.dumps(meta, indent=1))


def _srgb(c):
    c = np.clip(c, 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def _composite(img):
    """sRGB-ready RGB over the white background, and the covered pixels."""
    return img[..., :3] + (1 - np.clip(img[..., 3:4], 0, 1)), img[..., 3] > 1e-6


def _db(mse: float) -> float:
    return 200.0 if mse <= 0 else min(200.0, -10 * math.log10(mse))


def estimates(a_img, b_img, ref, ref_noise, ref_mask) -> dict:
    """Both estimates with their bounds, and the merged image's measured error."""
    a, ma = _composite(a_img)
    b, mb = _composite(b_img)
    m = ma | mb
    n = int(m.sum())
    merged = _srgb((a + b) / 2)
    qs = {
        "plain": ((_srgb(a) - _srgb(b)) ** 2).sum(-1)[m],
        "about_merged": (2 * ((_srgb(a) - merged) ** 2 + (_srgb(b) - merged) ** 2)).sum(-1)[m],
    }
    row: dict[str, Any] = {}
    for name, q in qs.items():
        est = float(q.sum()) / (12 * n)
        n_eff = float(q.sum() ** 2 / (q**2).sum()) if q.sum() > 0 else n
        row[name] = (est, est * (1 + Z * math.sqrt(4 / (3 * n_eff))))
    mm = m | ref_mask
    k = int(mm.sum())
    real = ((merged - ref) ** 2).sum(-1)[mm].sum() / (3 * k) - ref_noise[mm].sum() / (12 * k)
    row["measured"] = max(float(real), 1e-20)
    return row


def _next(spent: int, mse: float, rounds: int, previous) -> float | None:
    """plan/target.rs TargetRule::next_round's samples per half (before the cap)."""
    target = 10 ** (-TARGET / 10)
    if rounds >= MAX_ROUNDS or mse <= target * 10 ** (ACCEPT_DB / 10):
        return None
    aim = target * 10 ** (-AIM_DB / 10)
    if previous and spent > previous[0] and previous[1] > 0 and mse > 0:
        alpha = math.log(previous[1] / mse) / math.log(spent / previous[0])
        return spent * (mse / aim) ** (1 / min(2.0, max(1.0, alpha)))
    return min(spent * (mse / aim) ** 0.5, spent * FIRST_STEP)


def replay(per_n: dict, name: str, pilot: int = 16) -> int:
    """The count the rule stops at when it stops on `name`'s bound (counts rounded up to
    the grid; past its top, the top)."""
    spent, rounds, previous = pilot, 1, None
    while True:
        bound = per_n[spent][name][1]
        want = _next(spent, bound, rounds, previous)
        up = [x for x in GRID if want is not None and x >= max(want, spent + 1)]
        if not up:
            return spent
        previous, spent, rounds = (spent, bound), up[0], rounds + 1


def summarize(dirs: list[Path]) -> dict:
    per_image = []
    for root in dirs:
        meta = json.loads((root / "meta.json").read_text())
        for name in meta["images"]:
            d = root / name
            ra, ma = _composite(np.load(d / "ref_a.npy"))
            rb, mb = _composite(np.load(d / "ref_b.npy"))
            ref, ref_noise = _srgb((ra + rb) / 2), ((_srgb(ra) - _srgb(rb)) ** 2).sum(-1)
            for r in range(meta["reps"]):
                per_n = {
                    n: estimates(
                        np.load(d / f"r{r}_n{n}_a.npy"),
                        np.load(d / f"r{r}_n{n}_b.npy"),
                        ref,
                        ref_noise,
                        ma | mb,
                    )  # fmt: skip
                    for n in GRID
                }
                row = {"model": meta["model"], "image": name, "rep": r,
                       "fixed": {n: {k: (v[0] if isinstance(v, tuple) else v)
                                     for k, v in e.items()} for n, e in per_n.items()}}  # fmt: skip
                for est in ("plain", "about_merged"):
                    n = replay(per_n, est)
                    e = per_n[n]
                    row[f"stopped_{est}"] = {
                        "samples_per_half": n,
                        "estimate_over_measured_db": round(_db(e[est][0]) - _db(e["measured"]), 3),
                        "bound_over_measured_db": round(_db(e[est][1]) - _db(e["measured"]), 3),
                        "measured_db": round(_db(e["measured"]), 3),
                    }
                per_image.append(row)
    return {"rows": per_image, "summary": _summary(per_image)}


def _summary(rows: list[dict]) -> dict:
    out: dict = {"images": len(rows), "models": sorted({r["model"] for r in rows})}
    for model in [None, *out["models"]]:
        mine = [r for r in rows if model is None or r["model"] == model]
        key = model or "all"
        out[key] = {"images": len(mine)}
        for est in ("plain", "about_merged"):
            ratio = {
                str(n): round(
                    float(np.mean([r["fixed"][n][est] / r["fixed"][n]["measured"] for r in mine])),
                    3,
                )  # fmt: skip
                for n in GRID
            }
            s = [r[f"stopped_{est}"] for r in mine]
            e = np.array([x["estimate_over_measured_db"] for x in s])
            b = np.array([x["bound_over_measured_db"] for x in s])
            m = np.array([x["measured_db"] for x in s])
            out[key][est] = {
                "mean_estimate_over_measured_by_samples": ratio,
                "stopped_estimate_over_measured_db_median": round(float(np.median(e)), 3),
                "stopped_estimate_within_1db_share": round(float(np.mean(abs(e) <= 1)), 3),
                "stopped_bound_holds_share": round(float(np.mean(b <= 0.25)), 3),
                "stopped_at_target_share": round(float(np.mean(m >= TARGET - 0.5)), 3),
                "stopped_samples_per_half_median": float(
                    np.median([x["samples_per_half"] for x in s])
                ),  # fmt: skip
            }
    return out


def result_rows(summary: dict) -> list[dict]:
    """bench/results.json's rows of a summary: per model (and every model) and estimate."""
    rows = []
    for model in ["all", *summary["models"]]:
        for est in ("plain", "about_merged"):
            s = summary[model][est]
            rows.append(
                {
                    "name": f"half_noise_{model}_{est}",
                    "ratio": s["stopped_bound_holds_share"],
                    "ratio_is": "share of images stopped by the target rule whose bound holds",
                    "model": model,
                    "estimator": est,
                    "images": summary[model]["images"],
                    "target_db": TARGET,
                    "resolution": RES,
                    "reference_samples_per_half": REF_N,
                    **s,
                }
            )
    return rows


if __name__ == "__main__":
    if sys.argv[1] == "render":
        views = int(sys.argv[4]) if len(sys.argv) > 4 else 2
        reps = int(sys.argv[5]) if len(sys.argv) > 5 else 8
        render(Path(sys.argv[2]), Path(sys.argv[3]), views, reps)
    else:
        res = summarize([Path(p) for p in sys.argv[2:]])
        (HERE / "check_half_noise.json").write_text(json.dumps(res, indent=1) + "\n")
        from harness import merge_into_results

        print(merge_into_results(result_rows(res["summary"])))
