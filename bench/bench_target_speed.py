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
The rows say what each image reached (the paper's measured, the targets' estimated:
worst, 5th percentile, median).
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from blurset import _records

HERE = Path(__file__).resolve().parent
RES = int(os.environ.get("BLURSET_BENCH_SPEED_RES", "128"))
VIEWS = int(os.environ.get("BLURSET_BENCH_SPEED_VIEWS", "2"))
SALT = 0x5BD1E995


def _config(out: Path, glb: Path, **flags):
    sys.path.insert(0, str(HERE))
    from bench_target import config

    return config(out, glb, RES, VIEWS, **flags)


def _build(cfg) -> tuple[float, Path, dict]:
    from blurset.build import build

    t0 = time.perf_counter()
    summary = build(cfg, progress=False)
    wall = time.perf_counter() - t0
    if summary["settings_complete"] != 1:
        raise RuntimeError(f"bench build failed: {summary['failures']}")
    out = Path(cfg.out)
    (setting,) = [d for d in out.iterdir() if (d / ".complete").exists()]
    return wall, setting, json.loads((setting / "meta.json").read_text())


def _paper_noise(cfg, glb: Path, setting: Path, work: Path) -> dict:
    """Per (view, level dir): the paper image's render PSNR on object pixels, from a
    second render of its frames on other seeds."""
    from blurset import image, layout
    from blurset.image import read_exr
    from blurset.plan import plan_setting, seed_for
    from blurset.worker_client import Worker

    out = {}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        info = w.load(glb, work / "v.npy")
        verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)
        plan = plan_setting(cfg, uid=glb.stem, theta0_deg=0.0, seed=seed_for(cfg.seed, glb.stem, 0),
                            bbox_dims=info["bbox_dims"], vertices=verts)  # fmt: skip
        images: dict[tuple[int, str], list[_records.Render]] = {}
        for f in plan.renders(str(work / "r"), cfg.cycles_samples, sharp_views=[]):
            images.setdefault((f["view"], f["level"]), []).append(f)
        for (view, level), frames in images.items():
            acc = image.Accumulator(RES, RES)
            for f in frames:
                f["seed"] = (f["seed"] ^ SALT) & 0x7FFFFFFF

            def on_frame(_i: int, path: str, origin, acc=acc) -> None:
                acc.add_exr(path, origin)
                os.unlink(path)

            samples = cfg.effective_sharp_samples if level == "sharp" else cfg.samples
            w.render(frames, resolution=RES, fov_deg=cfg.fov_deg,
                     samples=samples, on_frame=on_frame, crop=True)  # fmt: skip
            name = layout.linear_name(layout.image_name(view, VIEWS))
            first = read_exr(setting / level / "linear" / name)
            e = image.object_error(first, acc.mean())
            out[(view, level)] = 200.0 if e.mse == 0 else float(-10.0 * np.log10(e.mse / 2.0))
    return out


def _spread(xs: list[float]) -> dict:
    from blurset import image

    s = image.spread(xs)
    return {"worst_db": round(s["worst"], 2), "p5_db": round(s["p5"], 2),
            "median_db": round(statistics.median(xs), 2)}  # fmt: skip


def measure_model(glb: Path, work: Path) -> dict:
    paper_cfg = _config(work / f"paper_{glb.stem}", glb, preset="paper")
    paper_s, paper_dir, _ = _build(paper_cfg)
    noise = _paper_noise(paper_cfg, glb, paper_dir, work)
    measured = list(noise.values())
    per_hour = lambda s: 3600.0 / (s * 34 / VIEWS)  # noqa: E731
    row = {
        "model": glb.stem,
        "paper_measured": _spread(measured),
        "paper_build_s": round(paper_s, 2),
        "paper_settings_per_hour": round(per_hour(paper_s), 4),
    }
    for what, target in (("worst", min(measured)), ("median", statistics.median(measured))):
        target = round(target, 2)
        cfg = _config(work / f"target_{what}_{glb.stem}", glb, preset="balanced",
                      target_psnr=target)  # fmt: skip
        target_s, _, meta = _build(cfg)
        est = [im["render_psnr_db"] for v in meta["views"] for im in v["images"].values()]
        row[f"at_paper_{what}"] = {
            "target_db": target,
            "estimated": _spread(est),
            "build_s": round(target_s, 2),
            "settings_per_hour": round(per_hour(target_s), 4),
            "ratio": round(paper_s / target_s, 3),
            "samples_per_view": sum(
                im["samples"] for v in meta["views"] for im in v["images"].values()
            )
            / VIEWS,
        }
    row["ratio"] = row["at_paper_worst"]["ratio"]
    return row


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
                    "preset's worst measured image over the paper preset's, same run",
                    "contender": "--preset balanced --target-psnr "
                    f"{m['at_paper_worst']['target_db']}: "
                    f"{m['at_paper_worst']['settings_per_hour']} settings/h",
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
