"""blur_cost_vs_sharp: one blurry image at m = 34 with the sample budget split (⌈S/34⌉
samples per latent frame, the frames the 34 blocks of one S-sample sequence) against one
sharp image with the same S samples, through the build's own path (Blender worker process
→ EXR → Rust accumulator → PNG), at 512 px on a demo object. DESIGN §9: the limit is 1.0;
issue 16's goal ≤ 1.05.

Where the extra time of the blurry image goes, measured in the same run:
- `blur_per_call`: the same frames with one Blender render call each (the worker before
  issue 16), against `blur`, where the worker renders them as one animation job;
- `blur_independent`: the frames with their own seeds and first samples (before issue 15),
  to show that sample subsets cost nothing;
- `split_at_p`: the same budget split over 34 renders that all sit at p: the cost of
  splitting alone, without the camera moving — Cycles' fixed cost per render session
  (session reset, a cold first pass, its thread arena, result transfer), the EXR write
  and our read;
- `content_factor` = blur / split_at_p: what the moving camera itself costs (a blurred
  object covers more pixels, and object pixels cost more than background) — a cost no
  method avoids: the one-render motion blur pays it too;
- `render_s` / `outside_render_s`: time inside Blender's render calls (Cycles + EXR write)
  and the rest of the wall time (JSON round trips, the last frame's read, the PNG);
  `accumulate_s` is our Rust accumulator's time (read + add + delete), which runs in this
  process while the worker renders the next frame;
- `worker_start_s`, `load_s`: process start and object load, paid once per object.
Also `motion_blur_cost_vs_sharp`: the same budget as one Cycles motion blur render;
`blur_cost_vs_sharp_same_content`: the blurry image against sharp images (S samples) at
latent positions spread over the exposure, their mean cost: what its pixels cost without
any splitting, since the moving camera sees more of the object than the camera at p
(`content_vs_sharp_cpu`); `blur_cost_vs_sharp_views`: the blur_4 images of a setting's VIEWS views against their
sharp images, CPU time (trajectories point every way, so the content's cost averages out
over a dataset); `blur_cost_vs_sharp_centered`: with p mid-exposure
(`--trajectory centered`); `render_region_saving`: the sharp and blurry image traced in
the plan's regions (plan/region.rs) against the same renders over the whole image;
`exr_crop_saving`: the blurry image with its EXRs cropped to their call's region (as a
build writes them) against full-size EXRs (the worker before), CPU time and EXR bytes.

`traced_px_ratio`: the pixels Cycles traces per frame, blurry over sharp (each frame's
render-call region), and `cpu_ratio_per_traced_px` the CPU ratio divided by it: what the
blurry image costs per pixel it traces; the rest of the ratio is where the object is.

Wall-clock medians of interleaved repeats, and CPU-time medians (the worker process's and
ours): the machine is shared, and CPU time is what contention disturbs least.
`--device` (bench/run.py) or BLURSET_BENCH_DEVICE picks the Cycles device (default CPU).
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from harness import proc_cpu

RESOLUTION = int(os.environ.get("BLURSET_BENCH_RES", "512"))
LATENTS = 34
SAMPLES_TOTAL = int(os.environ.get("BLURSET_BENCH_SAMPLES", "136"))
REPEATS = int(os.environ.get("BLURSET_BENCH_REPEATS", "3"))
THREADS = int(os.environ.get("BLURSET_BENCH_THREADS", "0"))  # Cycles threads, 0 = all
DEVICE = os.environ.get("BLURSET_BENCH_DEVICE", "CPU")  # a Cycles backend, or AUTO
CONTENT_FRAMES = (0, 11, 22, 33)  # latent frames rendered as sharp images (content cost)
VIEWS = int(os.environ.get("BLURSET_BENCH_VIEWS", "6"))  # blurry vs sharp over a setting
VIEW_REPEATS = 2


def _own_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


class Timed:
    """Render one image's frames through a worker, accumulate them as the build does."""

    def __init__(self, worker, work: Path, res: int) -> None:
        self.w, self.work, self.res = worker, work, res
        self.frame_seconds: list[float] = []
        orig = worker._receive_in_sync

        def receive():
            msg = orig()
            if "seconds" in msg:
                self.frame_seconds.append(float(msg["seconds"]))
            return msg

        worker._receive_in_sync = receive

    def image(
        self, frames, samples: int, codec: str, batch: bool = True, crop: bool = True
    ) -> dict:
        """crop: as a build renders, each EXR cropped to its render call's region."""
        from blurset.image import Accumulator

        acc = Accumulator(self.res, self.res)
        acc_s = 0.0
        exr_bytes = 0

        def on_frame(_i: int, path: str, origin) -> None:
            nonlocal acc_s, exr_bytes
            t = time.perf_counter()
            exr_bytes += os.path.getsize(path)
            acc.add_exr(path, origin)
            os.unlink(path)
            acc_s += time.perf_counter() - t

        self.frame_seconds.clear()
        c0, o0, t0 = proc_cpu(self.w._proc.pid), _own_cpu(), time.perf_counter()
        self.w.render(
            frames,
            resolution=self.res,
            fov_deg=40.0,
            samples=samples,
            on_frame=on_frame,
            exr_codec=codec,
            batch=batch,
            crop=crop,
        )
        acc.write_png(self.work / "out.png")
        wall = time.perf_counter() - t0
        cpu = proc_cpu(self.w._proc.pid) - c0 + _own_cpu() - o0
        render = sum(self.frame_seconds)
        return {
            "wall": wall,
            "cpu": cpu,
            "render_s": render,
            "accumulate_s": acc_s,
            "outside_render_s": wall - render,
            "exr_mb": exr_bytes / 1e6,
        }


def _mean_of(rows: list[dict]) -> dict:
    return {k: statistics.fmean(r[k] for r in rows) for k in rows[0]}


def _med(rows: list[dict], key: str) -> float:
    return statistics.median(r[key] for r in rows)


def traced_px(frames, res: int) -> float:
    """Pixels Cycles traces per frame, on average: each frame's render-call region (the
    whole image without one). A moving camera's frames trace more than the camera at p
    when the object grows in them, or when a call's union spans its motion."""
    area = [res * res if (g := f.get("region")) is None else (g[2] - g[0]) * (g[3] - g[1])
            for f in frames]  # fmt: skip
    return statistics.fmean(area)


def measure(res: int = RESOLUTION, repeats: int = REPEATS) -> dict:
    from blurset.plan import BuildConfig, plan_setting
    from blurset.services.demo import make_demo_objects
    from blurset.services.worker_client import Worker

    with tempfile.TemporaryDirectory(prefix="blurset-bench-") as tmp:
        work = Path(tmp)
        glb = make_demo_objects(work / "objects")[0]
        t0 = time.perf_counter()
        with Worker(threads=THREADS, timeout=3600, workdir=work / "scratch", device=DEVICE) as w:
            t_start = time.perf_counter() - t0
            t1 = time.perf_counter()
            info = w.load(glb, work / "v.npy")
            t_load = time.perf_counter() - t1
            verts = np.ascontiguousarray(np.load(work / "v.npy"), dtype=np.float32)

            def plan(views: int = 1, **kw):
                # Equal total samples is what this compares: the budget split flat.
                cfg = BuildConfig(views=views, levels=[4], resolution=res, blur_budget="flat", **kw)
                return plan_setting(
                    cfg,
                    uid="bench",
                    theta0_deg=0.0,
                    seed=7,
                    bbox_dims=info["bbox_dims"],
                    vertices=verts,
                )

            subsets = plan(latents=LATENTS, samples_total=SAMPLES_TOTAL)
            view = subsets.to_dict()["views"][0]
            spf = view["levels"]["4"]["samples_per_frame"]
            latent = subsets.level_renders(0, 4, str(work / "l"))
            centered = plan(
                latents=LATENTS, samples_total=SAMPLES_TOTAL, trajectory="centered"
            ).level_renders(0, 4, str(work / "c"))
            independent = plan(
                latents=LATENTS, samples_total=SAMPLES_TOTAL, latent_sampling="independent"
            ).level_renders(0, 4, str(work / "i"))
            # The plan's sharp render (first samples of the view's seed, its region).
            sharp = [dict(subsets.renders(str(work / "r"), None)[0], out=str(work / "s.exr"))]
            region = sharp[0].get("region")
            mb = plan(blur_method="motion_blur", samples_total=SAMPLES_TOTAL).to_dict()["views"][0][
                "levels"
            ]["4"]
            keys = [k["c2w"] for k in mb["motion_blur"]["keys"]]
            motion = [
                {
                    "c2w": keys[0],
                    "seed": mb["motion_blur"]["seed"],
                    "out": str(work / "m.exr"),
                    "motion": {"steps": mb["motion_blur"]["motion_steps"], "keys": keys},
                }
            ]
            # One render call, like the blurry image's frames before issue 16.
            at_p = [
                dict(f, c2w=view["c2w"], region=region, call=None, out=str(work / f"p{k}.exr"))
                for k, f in enumerate(latent)
            ]
            whole = [{k: v for k, v in f.items() if k != "region"} for f in latent]
            # Sharp images at latent positions spread over the exposure: what the pixels
            # the blurry image covers cost without any splitting.
            at_latents = [
                dict(
                    sharp[0],
                    c2w=latent[k]["c2w"],
                    region=latent[k].get("region"),
                    out=str(work / f"q{k}.exr"),
                )  # fmt: skip
                for k in CONTENT_FRAMES
            ]
            timed = Timed(w, work, res)
            cases = {
                "sharp": lambda: timed.image(sharp, SAMPLES_TOTAL, "NONE"),
                "sharp_whole": lambda: timed.image(
                    [{k: v for k, v in sharp[0].items() if k != "region"}], SAMPLES_TOTAL, "NONE"
                ),
                "sharp_at_latents": lambda: _mean_of(
                    [timed.image([f], SAMPLES_TOTAL, "NONE") for f in at_latents]
                ),
                "blur_whole": lambda: timed.image(whole, spf, "NONE"),
                "blur_centered": lambda: timed.image(centered, spf, "NONE"),
                "split_at_p": lambda: timed.image(at_p, spf, "NONE"),
                "blur": lambda: timed.image(latent, spf, "NONE"),
                "blur_per_call": lambda: timed.image(latent, spf, "NONE", batch=False),
                "blur_uncropped": lambda: timed.image(latent, spf, "NONE", crop=False),
                "blur_independent": lambda: timed.image(independent, spf, "NONE"),
                "motion_blur": lambda: timed.image(motion, SAMPLES_TOTAL, "NONE"),
            }
            timed.image(sharp, 1, "NONE")  # warm-up: kernels, BVH, persistent data
            runs: dict[str, list[dict]] = {k: [] for k in cases}
            for _ in range(repeats):
                for name, f in cases.items():
                    runs[name].append(f())
            # A setting's views: their trajectories point every way, so what the moving
            # camera's content costs averages out over a dataset.
            many = plan(latents=LATENTS, samples_total=SAMPLES_TOTAL, views=VIEWS)
            all_renders = many.renders(str(work / "v"), None)
            per_view = [
                (
                    [f for f in all_renders if f["view"] == v and f["level"] == "sharp"],
                    [f for f in all_renders if f["view"] == v and f["level"] == "blur_4"],
                )
                for v in range(VIEWS)
            ]
            views_px = (
                sum(traced_px(s, res) for s, _ in per_view),
                sum(traced_px(b, res) for _, b in per_view),
            )
            views_runs = []
            for _ in range(VIEW_REPEATS):
                s_cpu = b_cpu = 0.0
                for s_frames, b_frames in per_view:
                    s_cpu += timed.image(s_frames, SAMPLES_TOTAL, "NONE")["cpu"]
                    b_cpu += timed.image(b_frames, spf, "NONE")["cpu"]
                views_runs.append((s_cpu, b_cpu))
            load = os.getloadavg()
            device = w.info.get("device")
    med = {k: {m: _med(v, m) for m in v[0]} for k, v in runs.items()}
    return {
        "device": device,
        "resolution": res,
        "latents": LATENTS,
        "samples_total": SAMPLES_TOTAL,
        "samples_per_frame": spf,
        "repeats": repeats,
        "medians": med,
        "views_cpu": views_runs,
        "views_traced_px": views_px,
        "traced_px": {
            "sharp": traced_px(sharp, res),
            "blur": traced_px(latent, res),
            "centered": traced_px(centered, res),
        },  # fmt: skip
        "worker_start_s": t_start,
        "load_s": t_load,
        "load_average": load,
    }


def run() -> list[dict]:
    m = measure()
    med = m["medians"]
    sharp, blur, mb = med["sharp"], med["blur"], med["motion_blur"]
    per_call, ind, split = med["blur_per_call"], med["blur_independent"], med["split_at_p"]
    whole, sharp_whole, at_lat = med["blur_whole"], med["sharp_whole"], med["sharp_at_latents"]
    where = {
        "sharp_at_latents_s": at_lat["wall"],
        "content_vs_sharp_cpu": at_lat["cpu"] / sharp["cpu"],
        "blur_vs_sharp_at_latents_cpu": blur["cpu"] / at_lat["cpu"],
        "blur_whole_cpu_s": whole["cpu"],
        "sharp_whole_cpu_s": sharp_whole["cpu"],
        "split_at_p_s": split["wall"],
        "split_cost_ratio": split["wall"] / sharp["wall"],
        "split_cost_ratio_cpu": split["cpu"] / sharp["cpu"],
        "per_render_overhead_s": (split["wall"] - sharp["wall"]) / (m["latents"] - 1),
        "per_render_overhead_cpu_s": (split["cpu"] - sharp["cpu"]) / (m["latents"] - 1),
        "content_factor": blur["wall"] / split["wall"],
        "content_factor_cpu": blur["cpu"] / split["cpu"],
        "blur_render_s": blur["render_s"],
        "blur_accumulate_s": blur["accumulate_s"],
        "blur_outside_render_s": blur["outside_render_s"],
        "sharp_render_s": sharp["render_s"],
        "per_call_s": per_call["wall"],
        "per_call_cpu_s": per_call["cpu"],
        "independent_s": ind["wall"],
        "worker_start_s": m["worker_start_s"],
        "load_s": m["load_s"],
    }
    common = {
        "resolution": m["resolution"],
        "samples_total": m["samples_total"],
        "repeats": m["repeats"],
        "load_average": m["load_average"],
        "device": m["device"],
    }
    spec = f"{m['latents']} x {m['samples_per_frame']} samples"
    return [
        {
            "name": "blur_cost_vs_sharp",
            # A cost ratio, blurry / sharp time (limit 1.0, goal <= 1.05), not a speed-up.
            "ratio": blur["wall"] / sharp["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": blur["cpu"] / sharp["cpu"],
            "contender": f"blurry image, {spec} as sample subsets, one animation job: "
            f"{blur['wall']:.2f} s",
            "baseline": f"sharp image, {m['samples_total']} samples: {sharp['wall']:.2f} s",
            "blur_s": blur["wall"],
            "sharp_s": sharp["wall"],
            # The pixels traced decide most of the cost: per traced pixel-frame the
            # blurry image costs this much more than the sharp one.
            "traced_px_ratio": m["traced_px"]["blur"] / m["traced_px"]["sharp"],
            "cpu_ratio_per_traced_px": blur["cpu"]
            / sharp["cpu"]
            / (m["traced_px"]["blur"] / m["traced_px"]["sharp"]),
            **where,
            **common,
        },
        {
            "name": "blur_cost_vs_sharp_views",
            "ratio": statistics.median(b / s for s, b in m["views_cpu"]),
            "ratio_is": "contender CPU time / baseline CPU time",
            "cpu_ratio": statistics.median(b / s for s, b in m["views_cpu"]),
            "contender": f"the blur_4 images of {VIEWS} views of one setting, {spec} each: "
            f"{statistics.median(b for _, b in m['views_cpu']):.1f} s CPU",
            "baseline": f"their sharp images, {m['samples_total']} samples: "
            f"{statistics.median(s for s, _ in m['views_cpu']):.1f} s CPU",
            "views": VIEWS,
            "view_repeats": VIEW_REPEATS,
            "traced_px_ratio": m["views_traced_px"][1] / m["views_traced_px"][0],
            "cpu_ratio_per_traced_px": statistics.median(b / s for s, b in m["views_cpu"])
            / (m["views_traced_px"][1] / m["views_traced_px"][0]),
            **common,
        },
        {
            "name": "blur_cost_vs_sharp_same_content",
            "ratio": blur["wall"] / at_lat["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": blur["cpu"] / at_lat["cpu"],
            "contender": f"blurry image, {spec}: {blur['wall']:.2f} s",
            "baseline": f"sharp images at latent frames {list(CONTENT_FRAMES)}, "
            f"{m['samples_total']} samples each, their mean: {at_lat['wall']:.2f} s",
            **common,
        },
        {
            "name": "blur_cost_vs_sharp_centered",
            "ratio": med["blur_centered"]["wall"] / sharp["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": med["blur_centered"]["cpu"] / sharp["cpu"],
            "traced_px_ratio": m["traced_px"]["centered"] / m["traced_px"]["sharp"],
            "contender": f"blurry image, {spec}, --trajectory centered (p mid-exposure): "
            f"{med['blur_centered']['wall']:.2f} s",
            "baseline": f"sharp image: {sharp['wall']:.2f} s",
            **common,
        },
        {
            "name": "render_region_saving",
            "ratio": (sharp_whole["cpu"] + whole["cpu"]) / (sharp["cpu"] + blur["cpu"]),
            "ratio_is": "baseline CPU time / contender CPU time",
            "sharp_cpu_ratio": sharp_whole["cpu"] / sharp["cpu"],
            "blur_cpu_ratio": whole["cpu"] / blur["cpu"],
            "contender": f"sharp + blurry image in their object regions: "
            f"{sharp['cpu'] + blur['cpu']:.1f} s CPU",
            "baseline": f"the same renders over the whole image: "
            f"{sharp_whole['cpu'] + whole['cpu']:.1f} s CPU",
            **common,
        },
        {
            "name": "exr_crop_saving",
            "ratio": med["blur_uncropped"]["cpu"] / blur["cpu"],
            "ratio_is": "baseline CPU time / contender CPU time",
            "contender": f"blurry image, {spec}, EXRs cropped to their call's region: "
            f"{blur['cpu']:.1f} s CPU, {blur['exr_mb']:.0f} MB of EXR",
            "baseline": f"the same, full-size EXRs: {med['blur_uncropped']['cpu']:.1f} s CPU, "
            f"{med['blur_uncropped']['exr_mb']:.0f} MB of EXR",
            "exr_mb_ratio": med["blur_uncropped"]["exr_mb"] / blur["exr_mb"],
            "accumulate_s": blur["accumulate_s"],
            "accumulate_uncropped_s": med["blur_uncropped"]["accumulate_s"],
            **common,
        },
        {
            "name": "blur_cost_vs_sharp_per_call",
            "ratio": per_call["wall"] / sharp["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": per_call["cpu"] / sharp["cpu"],
            "contender": f"blurry image, {spec}, one render call per frame (before issue 16): "
            f"{per_call['wall']:.2f} s",
            "baseline": f"sharp image: {sharp['wall']:.2f} s",
            **common,
        },
        {
            "name": "blur_cost_vs_sharp_independent",
            "ratio": ind["wall"] / sharp["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": ind["cpu"] / sharp["cpu"],
            "contender": f"blurry image, {spec}, independent seeds (before issue 15): "
            f"{ind['wall']:.2f} s",
            "baseline": f"sharp image: {sharp['wall']:.2f} s",
            **common,
        },
        {
            "name": "motion_blur_cost_vs_sharp",
            "ratio": mb["wall"] / sharp["wall"],
            "ratio_is": "contender time / baseline time",
            "cpu_ratio": mb["cpu"] / sharp["cpu"],
            "contender": f"one Cycles motion blur render, {m['samples_total']} samples: "
            f"{mb['wall']:.2f} s",
            "baseline": f"sharp image: {sharp['wall']:.2f} s",
            **common,
        },
    ]


if __name__ == "__main__":
    json.dump(measure(), sys.stdout, indent=1)
    print()
