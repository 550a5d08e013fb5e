"""Is an image that missed its bound in bench_target_kinds an unlucky draw of its own
construction, or a defect of its kind? Rebuild the model as bench_target_kinds builds it
(the build is deterministic: the same images, samples and records), measure the image
against a reference of REPEAT_REF times its samples, then render its construction again
(the same frames and samples, two halves) on REPEATS other seed pairs and measure each.
If the repeats reach the target and the build's image does not, its miss is the tail of
its own noise (a few fireflies that neither half drew); if the repeats miss too, the
kind renders something its halves cannot see.

    python bench/check_target_repeat.py [--merge-json FILE]

BLURSET_REPEAT_GLB (../shared/data's WaterBottle), BLURSET_REPEAT_IMAGES ("0:shake_1,
1:shake_1,0:sharp": view:level), BLURSET_REPEAT_REF (16), BLURSET_REPEATS (6). The run's
measures are written to BLURSET_REPEAT_JSON (bench/work/target_repeat.json) as they come;
`--merge-json FILE` makes the rows of such a file and merges them into results.json.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_target as bt  # noqa: E402
from harness import merge_into_results, plan_object  # noqa: E402

HERE = Path(__file__).resolve().parent
GLB = Path(
    os.environ.get(
        "BLURSET_REPEAT_GLB",
        str(HERE.parent.parent / "shared" / "data" / "glb" / "WaterBottle_blender_reexport.glb"),
    )
)
IMAGES = [
    (int(v), lv)
    for v, lv in (
        x.split(":")
        for x in os.environ.get("BLURSET_REPEAT_IMAGES", "0:shake_1,1:shake_1,0:sharp").split(",")
    )
]
REF = int(os.environ.get("BLURSET_REPEAT_REF", "16"))
REPEATS = int(os.environ.get("BLURSET_REPEATS", "6"))
OUT = Path(os.environ.get("BLURSET_REPEAT_JSON", str(HERE / "work" / "target_repeat.json")))
RES, VIEWS = 128, 2  # bench_target_kinds' 128 px part


def measure(work: Path) -> dict:
    from blurset import image, layout
    from blurset.image import read_exr
    from blurset.services.worker_client import Worker

    bt.RES = RES
    out = work / "build"
    cfg = bt.config(out, GLB, RES, VIEWS, preset="balanced", target_psnr=bt.TARGET,
                    defocus=[1, 4], shake=[1, 4])  # fmt: skip
    _, setting, meta = bt.timed_build(cfg)
    res: dict = {"model": GLB.stem, "reference_factor": REF, "images": {}}
    with Worker(timeout=7200, workdir=work / "scratch", device=cfg.device.upper()) as w:
        plan = plan_object(cfg, GLB, w, work)
        frames_of: dict = {}
        for f in plan.renders(str(work / "r"), cfg.cycles_samples, sharp_views=[]):
            frames_of.setdefault((f["view"], f["level"]), []).append(f)
        for view, level in IMAGES:
            frames, rec = frames_of[(view, level)], meta["views"][view]["images"][level]
            m, spent = len(frames), rec["samples"]
            pin = max(cfg.target_max_samples // 2, REF * spent // 2)
            ref, ref_noise = bt._halves(w, frames, REF * spent // (2 * m), bt.SALTS, pin, cfg, work)
            name = layout.linear_name(layout.image_name(view, len(meta["views"])))
            built = image.object_error(read_exr(setting / level / "linear" / name), ref)
            r = {"record": rec, "frames": m, "ref_noise_db": bt._db(ref_noise),
                 "build_image_db": bt._db(max(built.mse - ref_noise, 1e-20)), "repeats": []}  # fmt: skip
            for i in range(REPEATS):
                salts = (0x1000 + 7 * i, 0x2000 + 13 * i)
                mean, est = bt._halves(w, frames, spent // (2 * m), salts, pin, cfg, work)
                e = image.object_error(mean, ref)
                r["repeats"].append({"measured_db": round(bt._db(max(e.mse - ref_noise, 1e-20)), 3),
                                     "plain_estimate_db": round(bt._db(est), 3)})  # fmt: skip
            res["images"][f"{view}:{level}"] = r
            OUT.parent.mkdir(parents=True, exist_ok=True)
            OUT.write_text(json.dumps(res, indent=1))
    return res


def rows(res: dict) -> list[dict]:
    """A row per image: the build's image and its repeats, against the reference."""
    out = []
    for key, r in res["images"].items():
        view, level = key.split(":")
        got = [x["measured_db"] for x in r["repeats"]]
        rec = r["record"]
        out.append(
            {
                "name": f"target_repeat_{res['model']}_{level}_view{view}",
                "ratio": round(r["build_image_db"] - statistics.median(got), 3),
                "ratio_is": "dB: the build's image against the median of its construction "
                "rendered again on other seeds (same frames and samples); negative: the "
                "build's draw was the worse",
                "model": res["model"],
                "view": int(view),
                "level": level,
                "samples": rec["samples"],
                "rounds": rec["rounds"],
                "target_db": bt.TARGET,
                "estimate_db": rec["render_psnr_db"],
                "bound_db": rec["render_psnr_bound_db"],
                "build_image_db": round(r["build_image_db"], 3),
                "reference_factor": res["reference_factor"],
                "reference_noise_db": round(r["ref_noise_db"], 2),
                "repeats": len(got),
                "repeats_measured_db": got,
                "repeats_median_db": round(statistics.median(got), 3),
                "repeats_min_db": min(got),
                "repeats_max_db": max(got),
                "repeats_at_target_share": round(
                    sum(g >= bt.TARGET - 0.5 for g in got) / len(got), 3
                ),
            }
        )
    return out


if __name__ == "__main__":
    if len(sys.argv) == 3 and sys.argv[1] == "--merge-json":
        print(merge_into_results(rows(json.loads(Path(sys.argv[2]).read_text()))))
    else:
        import tempfile

        with tempfile.TemporaryDirectory(prefix="blurset-repeat-") as d:
            print(merge_into_results(rows(measure(Path(d)))))
