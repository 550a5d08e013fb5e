"""target_speed: settings per hour at equal accuracy (issue 37, DESIGN §8–9): per model, the
paper preset against a `--target-psnr` build whose target is what the paper preset's own
images measure on that model, side by side in one run.

Per model (BLURSET_BENCH_GLBS, default ../shared/data's held-out textured panel,
2CylinderEngine and BoxTextured), one setting of BLURSET_BENCH_SPEED_VIEWS views at
BLURSET_BENCH_SPEED_RES px, every view rendering its blurry images:
1. the paper preset is built (timed);
2. its render noise per image is measured on the object's pixels: each image rendered
   again with the same frames and samples on other Cycles seeds, MSE(a, b) / 2 (two
   independent renders of equal samples: the expected MSE is twice either's);
3. two builds with `--preset balanced --target-psnr T` are timed: T the paper images'
   worst (every image at least as accurate as the paper preset's worst: equal worst-case
   accuracy, the ratio) and T their median (every image at least as accurate as the
   paper preset's median one). Settings per hour: 3600 / the build's wall time over its
   views, × views / 34 (a setting's 34 views), the worker start and object load included.
4. `--preset floor` (every image to the 8-bit floor, 58.92 dB) is timed the same way:
   whatever it costs on the model (on a hard model more than the paper preset).
5. Equal accuracy against the continuous blur, per image kind (`at_paper_continuous`): the
   paper preset's images measure what its ghosts and noise leave against the continuous
   blur (below), per kind (sharp, blur_1 … blur_4) their worst T_k. One
   `--preset balanced --target-psnr T_k` build per kind renders that kind alone (a level
   alone: `--levels l`, the same views, trajectories and seeds as in the whole plan; the
   sharp kind: `--levels none`), a blurry kind by Cycles motion blur (no ghosts: its error
   against the continuous blur is the render noise its target sets; averaged frames would
   add ghosts up to the preset's bound, which no target sees). The contender's time is the sum of those builds, each paying
   its own worker start, object load and a sharp image the kind alone does not need: the
   sum overstates what one build of all kinds would cost. Each kind is then scored against
   the continuous blur like every build here, from its own build.
The rows say what each image reached (the paper's measured, the targets' estimated:
worst, 5th percentile, median). Every build is also scored against the continuous blur
(stratified frames no more than 0.5 px apart, half the presets' ghost bound, sharing
1,024 samples; the sharp image at 1,024 samples; rendered twice, on two sets of seeds no
build uses), on object pixels: PSNR of the blurry and sharp images against the mean of
the two, that mean's own render noise taken out (MSE(r₁, r₂) / 4, as bench_target does:
left in, it would count against an image as error the image does not have, most where
the image is as noisy as the reference, the sharp kind; mean and worst), and the
detail ratio (high-frequency energy over the
reference's noise-free part; < 1 smoothed). The reference's own render noise is part of
its detail energy (at 512 px, 5 % at level 1 and 28 % at level 4:
bench/check_continuous_noise.py), so the ratio divides by the signal's share only, from
the two independent renders: E(signal) = 2 E(mean) - (E(r1) + E(r2)) / 2. Where the time goes: each
build's samples and render calls per view (a target image renders each frame once per
half and round), and per model a least-squares fit of seconds = a x calls + b x samples
over its four builds.
"""

from __future__ import annotations

import json
import math
import os
import statistics
import sys
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_target import _db  # noqa: E402
from harness import plan_object, render_mean, timed_build  # noqa: E402

if TYPE_CHECKING:
    from blurset import _records

HERE = Path(__file__).resolve().parent
RES = int(os.environ.get("BLURSET_BENCH_SPEED_RES", "128"))
VIEWS = int(os.environ.get("BLURSET_BENCH_SPEED_VIEWS", "2"))
# Which target builds beside the paper preset (a 512 px run on 2 cores fits only the
# first and the last): any of worst, median, floor, continuous.
RUNS = [
    r
    for r in os.environ.get("BLURSET_BENCH_SPEED_RUNS", "worst,median,floor,continuous").split(",")
    if r
]
SALT = 0x5BD1E995
CONT_SALT = 0x3C6EF372
# The continuous reference's second render (its noise, taken out of the detail ratio).
CONT_SALT2 = 0x9E3779B9
# The continuous reference: frames no more than this far apart on screen (px; finer than
# any preset's bound, so the reference's own ghosts do not count as the build's detail),
# sharing this many samples (at least one a frame); the sharp reference at as many.
CONTINUOUS_GHOST_PX = 0.5
CONTINUOUS_SAMPLES = 1024


def _config(out: Path, glb: Path, **flags):
    sys.path.insert(0, str(HERE))
    from bench_target import config

    return config(out, glb, RES, VIEWS, **flags)


def continuous_config(glb: Path, work: Path):
    """The build config whose plan gives the continuous reference's frames and samples."""
    return _config(work / "unused", glb, latents_auto=True, latent_positions="stratified",
                   max_ghost_px=CONTINUOUS_GHOST_PX, latents_max=4096,
                   samples_total=CONTINUOUS_SAMPLES, blur_budget="flat")  # fmt: skip


def _continuous(glb: Path, work: Path) -> dict:
    """Per (view, level dir): the continuous blur of each level and the sharp view at as
    many samples (premultiplied linear RGBA), rendered on each of two seed sets no build
    uses."""
    from blurset.services.worker_client import Worker

    cfg = continuous_config(glb, work)
    refs: dict[tuple[int, str], list[np.ndarray]] = {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        plan = plan_object(cfg, glb, w, work)
        for v in plan.to_dict()["views"]:
            for salt in (CONT_SALT, CONT_SALT2):
                sharp = [{"c2w": v["c2w"], "seed": (v["sharp_seed"] ^ salt) & 0x7FFFFFFF,
                          "out": str(work / "c.exr")}]  # fmt: skip
                refs.setdefault((v["index"], "sharp"), []).append(
                    render_mean(w, sharp, CONTINUOUS_SAMPLES, RES, cfg.fov_deg)
                )
                for lvl in v["levels"]:
                    frames = plan.level_renders(v["index"], int(lvl), str(work / "c"))
                    for f in frames:
                        f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
                    refs.setdefault((v["index"], f"blur_{lvl}"), []).append(
                        render_mean(w, frames, 1, RES, cfg.fov_deg)
                    )
    return refs


def signal_detail_ratio(img: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> float:
    """The image's detail energy over the noise-free part of a reference's, from two
    renders of the reference on independent seeds: their noise adds to the energy, halved
    in their mean, so E(signal) = 2 E(mean) - (E(r1) + E(r2)) / 2 (check_continuous_noise
    measures the same share). With a = E(img) / E(mean), b = E(img) / E(r):
    E(signal) / E(img) = 2 / a - (1 / b1 + 1 / b2) / 2."""
    from blurset import image

    a = image.image_error(img, (r1 + r2) / 2).detail_ratio
    b1 = image.image_error(img, r1).detail_ratio
    b2 = image.image_error(img, r2).detail_ratio
    share = 2 / a - (1 / b1 + 1 / b2) / 2
    return 1.0 / share if share > 0 else math.inf


def _vs_continuous_db(img: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> float:
    """PSNR of `img` against the continuous blur on object pixels: its MSE against the two
    renders' mean, less that mean's own render noise (independent seeds: the two add)."""
    from blurset import image

    return _db(image.object_error(img, (r1 + r2) / 2).mse - image.half_noise(r1, r2).mse)


def _kind_worst(setting: Path, cont: dict, only: str | None = None) -> dict[str, float]:
    """Per image kind (level folder: sharp, blur_1 …): the worst PSNR of the build's images
    of that kind against the continuous blur, on object pixels; `only`: that kind alone."""
    from blurset import layout
    from blurset.image import read_exr

    worst: dict[str, float] = {}
    for (view, level), (r1, r2) in cont.items():
        if only is not None and level != only:
            continue
        name = layout.linear_name(layout.image_name(view, VIEWS))
        psnr = _vs_continuous_db(read_exr(setting / level / "linear" / name), r1, r2)
        worst[level] = min(worst.get(level, math.inf), psnr)
    return worst


def _at_continuous(glb: Path, work: Path, cont: dict, paper_dir: Path) -> dict:
    """Item 5 of the docstring: per kind, a target build at the paper's worst image of that
    kind against the continuous blur; their summed time and what each kind reached."""
    paper_worst = _kind_worst(paper_dir, cont)
    kinds: dict[str, dict] = {}
    total_s = 0.0
    work_sum = {"samples_per_view": 0.0, "calls_per_view": 0.0}
    for kind, worst_db in sorted(paper_worst.items()):
        levels = [] if kind == "sharp" else [int(kind.removeprefix("blur_"))]
        target = round(worst_db, 2)
        # Motion blur has no ghosts: its error against the continuous blur is its render
        # noise, which the target sets. Averaged frames add their ghosts (up to the
        # preset's bound) on top, which no target sees.
        method = {"blur_method": "motion_blur"} if levels else {}
        cfg = _config(work / f"kind_{kind}_{glb.stem}", glb, preset="balanced",
                      target_psnr=target, levels=levels, **method)  # fmt: skip
        build_s, setting, meta = timed_build(cfg)
        reached = _kind_worst(setting, cont, only=kind)[kind]
        kinds[kind] = {
            "target_db": target,
            "paper_worst_db": round(worst_db, 2),
            "worst_db": round(reached, 2),
            "build_s": round(build_s, 2),
            "methods": sorted({lv["method"] for v in meta["views"] for lv in v["levels"].values()}),
            **_target_work(meta),
        }  # fmt: skip
        total_s += build_s
        for k in work_sum:
            work_sum[k] += kinds[kind][k]
    # How far the kind that came closest to the paper's figure sits above it (< 0: short).
    margin = min(k["worst_db"] - k["paper_worst_db"] for k in kinds.values())
    return {"kinds": kinds, "build_s": round(total_s, 2), **work_sum,
            "every_kind_at_paper": margin >= -0.5,
            "worst_margin_db": round(margin, 2)}  # fmt: skip


def _against_continuous(setting: Path, cont: dict) -> dict:
    """A build's images against the continuous references, on object pixels: PSNR against
    the mean of the two renders (its own noise taken out), the detail ratio against their noise-free part (noise on
    top of the image reads as detail: > 1), and the share of the texture kept (core
    `detail_kept`: render noise on neither side counts; < 1 smoothed away)."""
    from blurset import image, layout
    from blurset.image import read_exr

    per: dict[str, dict[str, list[float]]] = {"blur": {}, "sharp": {}}
    for (view, level), (r1, r2) in cont.items():
        name = layout.linear_name(layout.image_name(view, VIEWS))
        img = read_exr(setting / level / "linear" / name)
        acc = per["sharp" if level == "sharp" else "blur"]
        acc.setdefault("psnr", []).append(_vs_continuous_db(img, r1, r2))
        acc.setdefault("detail", []).append(signal_detail_ratio(img, r1, r2))
        acc.setdefault("kept", []).append(image.detail_kept(img, r1, r2))
    out: dict[str, Any] = {}
    for kind, xs in per.items():
        out[f"{kind}_vs_continuous_mean_db"] = round(statistics.fmean(xs["psnr"]), 2)
        out[f"{kind}_vs_continuous_worst_db"] = round(min(xs["psnr"]), 2)
        out[f"detail_ratio_{kind}"] = round(statistics.fmean(xs["detail"]), 3)
        out[f"detail_ratio_{kind}_range"] = [round(min(xs["detail"]), 3),
                                             round(max(xs["detail"]), 3)]  # fmt: skip
        out[f"detail_kept_{kind}"] = round(statistics.fmean(xs["kept"]), 3)
        out[f"detail_kept_{kind}_range"] = [round(min(xs["kept"]), 3), round(max(xs["kept"]), 3)]
    return out


def _target_work(meta: dict) -> dict:
    """Samples and render calls per view of a target build: every round renders each of an
    image's frames once per half."""
    samples = calls = 0
    for v in meta["views"]:
        for level, im in v["images"].items():
            m = 1 if level == "sharp" else v["levels"][level.removeprefix("blur_")]["latents"]
            samples += im["samples"]
            calls += 2 * m * im["rounds"]
    return {"samples_per_view": samples / VIEWS, "calls_per_view": calls / VIEWS}


def _paper_noise(cfg, glb: Path, setting: Path, work: Path) -> tuple[dict, dict]:
    """Per (view, level dir): the paper image's render PSNR on object pixels, from a
    second render of its frames on other seeds; and the paper build's samples and render
    calls per view."""
    from blurset import image, layout
    from blurset.image import read_exr
    from blurset.services.worker_client import Worker

    out = {}
    work_n = {"samples_per_view": 0.0, "calls_per_view": 0.0}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        plan = plan_object(cfg, glb, w, work)
        images: dict[tuple[int, str], list[_records.Render]] = {}
        for f in plan.renders(str(work / "r"), cfg.cycles_samples, sharp_views=[]):
            images.setdefault((f["view"], f["level"]), []).append(f)
        for (view, level), frames in images.items():
            for f in frames:
                f["seed"] = (f["seed"] ^ SALT) & 0x7FFFFFFF
            samples = cfg.effective_sharp_samples if level == "sharp" else cfg.samples
            work_n["samples_per_view"] += sum(f.get("samples") or samples for f in frames) / VIEWS
            work_n["calls_per_view"] += len(frames) / VIEWS
            name = layout.linear_name(layout.image_name(view, VIEWS))
            first = read_exr(setting / level / "linear" / name)
            e = image.object_error(first, render_mean(w, frames, samples, RES, cfg.fov_deg))
            out[(view, level)] = 200.0 if e.mse == 0 else float(-10.0 * np.log10(e.mse / 2.0))
    return out, work_n


def _spread(xs: list[float]) -> dict:
    from blurset import image

    s = image.spread(xs)
    return {"worst_db": round(s["worst"], 2), "p5_db": round(s["p5"], 2),
            "median_db": round(statistics.median(xs), 2)}  # fmt: skip


def _time_split(builds: list[dict]) -> dict:
    """seconds per view = a x calls + b x samples, least squares over the model's builds:
    what a render call costs beside its samples."""
    x = np.array([[b["calls_per_view"], b["samples_per_view"]] for b in builds], dtype=float)
    y = np.array([b["build_s"] / VIEWS for b in builds], dtype=float)
    (a, b), *_ = np.linalg.lstsq(x, y, rcond=None)
    return {"s_per_call": round(float(a), 4), "s_per_ksample": round(float(b) * 1000, 4)}


def measure_model(glb: Path, work: Path) -> dict:
    per_hour = lambda s: 3600.0 / (s * 34 / VIEWS)  # noqa: E731
    cont = _continuous(glb, work)
    paper_cfg = _config(work / f"paper_{glb.stem}", glb, preset="paper")
    paper_s, paper_dir, _ = timed_build(paper_cfg)
    noise, paper_work = _paper_noise(paper_cfg, glb, paper_dir, work)
    measured = list(noise.values())
    paper = {"build_s": round(paper_s, 2), **paper_work, **_against_continuous(paper_dir, cont)}
    row = {
        "model": glb.stem,
        "paper_measured": _spread(measured),
        "paper_build_s": round(paper_s, 2),
        "paper_settings_per_hour": round(per_hour(paper_s), 4),
        "paper": paper,
        "continuous": {
            "max_gap_px": CONTINUOUS_GHOST_PX,
            "samples": CONTINUOUS_SAMPLES,
            "renders": 2,
            "detail_ratio": "over the noise-free part",
            "reference_noise": "taken out",
        },
    }
    builds = [paper]
    runs = [("worst", {"preset": "balanced", "target_psnr": round(min(measured), 2)}),
            ("median", {"preset": "balanced",
                        "target_psnr": round(statistics.median(measured), 2)}),
            ("floor", {"preset": "floor"})]  # fmt: skip
    for what, flags in [(w, f) for w, f in runs if w in RUNS]:
        cfg = _config(work / f"target_{what}_{glb.stem}", glb, **flags)
        target_s, setting, meta = timed_build(cfg)
        est = [im["render_psnr_db"] for v in meta["views"] for im in v["images"].values()]
        entry = {
            "target_db": cfg.target_psnr,
            "estimated": _spread(est),
            "build_s": round(target_s, 2),
            "settings_per_hour": round(per_hour(target_s), 4),
            "ratio": round(paper_s / target_s, 3),
            **_target_work(meta),
            **_against_continuous(setting, cont),
        }
        entry["sample_ratio"] = round(paper_work["samples_per_view"] / entry["samples_per_view"], 3)
        # The ghost bound the preset promises, as the build's own plan recorded it.
        entry["max_gap_px"] = round(
            max(lv["max_gap_px"] for v in meta["views"] for lv in v["levels"].values()), 2
        )
        row["at_floor" if what == "floor" else f"at_paper_{what}"] = entry
        builds.append(entry)
    if "continuous" in RUNS:
        entry = _at_continuous(glb, work, cont, paper_dir)
        entry["settings_per_hour"] = round(per_hour(entry["build_s"]), 4)
        entry["ratio"] = round(paper_s / entry["build_s"], 3)
        entry["sample_ratio"] = round(paper_work["samples_per_view"] / entry["samples_per_view"], 3)
        row["at_paper_continuous"] = entry
    # Two unknowns (per call, per sample): a fit needs more builds than that.
    if len(builds) > 2:
        row["time_split"] = _time_split(builds)
    # The headline: equal worst-case render noise (a), else the continuous rule (b).
    row["ratio"] = (row.get("at_paper_worst") or row["at_paper_continuous"])["ratio"]
    return row


def _contender(m: dict) -> str:
    """What the headline ratio compares the paper preset with."""
    if "at_paper_worst" in m:
        w = m["at_paper_worst"]
        return (
            f"--preset balanced --target-psnr {w['target_db']}: {w['settings_per_hour']} settings/h"
        )
    c = m["at_paper_continuous"]
    return f"one target build per image kind: {c['settings_per_hour']} settings/h"


def run() -> list[dict]:
    res = []
    with tempfile.TemporaryDirectory(prefix="blurset-bench-speed-") as d:
        sys.path.insert(0, str(HERE))
        from bench_target import held_out_glbs

        for glb in held_out_glbs(None):
            m = measure_model(glb, Path(d))
            res.append(
                {
                    "name": f"target_speed_{RES}px_{m['model']}",
                    "ratio": m["ratio"],
                    "ratio_is": "settings per hour of a --target-psnr build at the paper "
                    "preset's worst measured image over the paper preset's, same run"
                    if "at_paper_worst" in m
                    else "settings per hour of target builds at the paper preset's accuracy "
                    "against the continuous blur, per image kind, over the paper preset's",
                    "contender": _contender(m),
                    "baseline": f"paper preset: {m['paper_settings_per_hour']} settings/h",
                    **m,
                    "resolution": RES,
                    "views_measured": VIEWS,
                    "load_average": os.getloadavg()[0],
                }
            )
    return res


if __name__ == "__main__":
    json.dump(run(), sys.stdout, indent=1, default=str)
    print()
