"""render_parity_<preset>_level<l>_x<F>: what parity of render noise costs (issue 15).

With sample subsets a blurry image at zero motion carries exactly the sharp image's
render noise (bench_render_noise). With motion it does not: each latent frame sees other
content at a pixel, so the frames' blocks no longer add up to one stratified sequence,
and every frame's error is that of its own L samples. This measures, for one view of a
demo object (96 px, levels 1 and 4, the paper and balanced presets), the blurry image's
render-noise MSE (against a converged render of the same latent positions, REF× the
budget, other seeds) over the sharp image's (against its own converged render), when
the blurry image gets F times the preset's budget (`--samples-total F·S`). Parity is 1;
the issue's bound is 1.12 (0.5 dB). `cpu_s`: the blurry image's CPU seconds.

`x<F>` rows split the budget flat (`--blur-budget flat`, F times it); the `parity` rows
are the default build (`--blur-budget parity`: m^0.4 times the budget), at every level.
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

RESOLUTION = int(os.environ.get("BLURSET_BENCH_NOISE_RES", "96"))
REF = 32  # converged renders: REF × the preset's own budget
FACTORS = (1, 2, 4)
LEVELS = (1, 2, 3, 4)
FLAT_LEVELS = (1, 4)  # the x<F> rows
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")
PRESETS = {
    # name: (build options of the blurry image at budget factor F, sharp samples)
    # f = None: the default parity budget; else f times the budget, split flat.
    "paper": (lambda f: {"latents": 34, "samples": 32 * (f or 1), **_budget(f)}, 1088),
    "balanced": (
        lambda f: {
            "latents_auto": True,
            "latent_positions": "stratified",
            "samples_total": 256 * (f or 1),
            **_budget(f),
        },
        256,
    ),
}


def _budget(f: int | None) -> dict:
    return {} if f is None else {"blur_budget": "flat"}


def _mse(a, b) -> float:
    return float(np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2))


def measure(res: int = RESOLUTION) -> dict:
    """The images as a build renders them: per preset and budget a fresh worker renders
    the sharp image and the blurry ones with every render pinned to that build's Cycles
    `samples` (BuildConfig.cycles_samples: Cycles sizes its sample pattern from the
    largest `samples` a process has rendered, so the pin shapes the sharp image's noise
    too). The converged references come from another worker."""
    from blurset.commands.tradeoff.render import REFERENCE_SEED_SALT
    from blurset.commands.tradeoff.render import render_image as _render_image
    from blurset.commands.tradeoff.render import sharp_frames as _sharp
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker

    out: dict = {"resolution": res, "reference_factor": REF, "rows": {}}
    with tempfile.TemporaryDirectory(prefix="blurset-bench-") as tmp:
        work = Path(tmp)
        glb = make_demo_objects(work / "objects")[0]

        def worker() -> Worker:
            return Worker(threads=0, timeout=7200, workdir=work / "scratch", device=DEVICE)

        with worker() as ref_w:
            info = ref_w.load(glb, work / "v.npy")
            verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)

            def config(levels, **kw) -> BuildConfig:
                return BuildConfig(views=1, levels=list(levels), resolution=res, **kw)

            def plan(cfg: BuildConfig):
                return plan_setting(cfg, uid="bench", theta0_deg=0.0, seed=11,
                                    bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip

            def image(w, p, level: int, salt: int = 0, pin=None):
                frames = p.level_renders(0, level, str(work / "f"), pin)
                return _render_image(w, frames, p.level(0, level), res, 40.0, salt)

            for name, (options, sharp_n) in PRESETS.items():
                base = plan(config(LEVELS, **options(1)))
                v = base.to_dict()["views"][0]  # the view is every budget's
                sharp_ref, _ = _render_image(
                    ref_w, *_sharp(v, REF * sharp_n, work), res, 40.0, REFERENCE_SEED_SALT
                )
                conv = {}
                for level in LEVELS:
                    lp = base.level(0, level)
                    conv_kw = {k: x for k, x in options(1).items() if k != "samples"}
                    conv_kw["samples_total"] = REF * lp["samples_per_frame"] * lp["latents"]
                    if "latents_auto" not in conv_kw:
                        conv_kw["latents"] = lp["latents"]
                    pc = plan(config([level], **conv_kw))
                    assert pc.level(0, level)["latents"] == lp["latents"]
                    conv[level], _ = image(ref_w, pc, level, REFERENCE_SEED_SALT)
                    out["rows"][f"{name}_level{level}"] = {
                        "motion_px": lp["motion_px"],
                        "latents": lp["latents"],
                        "sharp_samples": sharp_n,
                    }
                for f in (*FACTORS, None):
                    case = "parity" if f is None else f"x{f}"
                    cfg = config(LEVELS if f is None else FLAT_LEVELS, **options(f))
                    p, pin = plan(cfg), cfg.cycles_samples
                    with worker() as w:
                        w.load(glb, work / "v2.npy")
                        frames, lvl = _sharp(v, sharp_n, work)
                        frames[0].update(sample_offset=0, sample_sequence=pin)
                        sharp, _ = _render_image(w, frames, lvl, res, 40.0)
                        for level in cfg.levels:
                            row = out["rows"][f"{name}_level{level}"]
                            blur, t = image(w, p, level, pin=pin)
                            sharp_mse = _mse(sharp, sharp_ref)
                            row[case] = {
                                "samples_per_frame": p.level(0, level)["samples_per_frame"],
                                "cycles_samples": pin,
                                "sharp_mse": sharp_mse,
                                "mse_vs_sharp": _mse(blur, conv[level]) / sharp_mse,
                                "cpu_s": t["cpu_seconds"],
                            }
            out["device"] = ref_w.info.get("device")
            out["load_average"] = os.getloadavg()
    return out


def run() -> list[dict]:
    m = measure()
    rows = []
    for key, row in m["rows"].items():
        for case in (k for k in row if k == "parity" or k.startswith("x")):
            e = row[case]
            how = (
                "the default parity budget" if case == "parity" else f"{case[1:]}x the budget, flat"
            )
            rows.append(
                {
                    "name": f"render_parity_{key}_{case}",
                    "ratio": e["mse_vs_sharp"],
                    "ratio_is": "blurry render-noise MSE / sharp render-noise MSE",
                    "contender": f"blurry, {row['latents']} x {e['samples_per_frame']} "
                    f"samples (subsets, {how}; every render pinned to {e['cycles_samples']} "
                    f"Cycles samples, as the build): {e['cpu_s']:.1f} s CPU",
                    "baseline": f"sharp, {row['sharp_samples']} samples",
                    "motion_px": row["motion_px"],
                    "resolution": m["resolution"],
                    "reference_factor": m["reference_factor"],
                    "device": m["device"],
                    "load_average": m["load_average"],
                }
            )
    return rows


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1)
    print()
