"""`blurset tradeoff`: what each speed-up costs in quality, measured on your object.

One view's blurry image (one level) is rendered at several latent counts, samples per
frame, latent position schemes and with both methods (latent averaging, Cycles motion
blur), each against a reference: the average of many stratified latent frames with many
samples each. Every candidate goes through the build's own path (Blender worker → EXR →
Rust accumulator), on the same trajectory segment p → p + w_l·δ planned by blurset-core.

Writes DIR/tradeoff.csv (one row per candidate and one for the reference),
DIR/tradeoff.json (the same plus the set-up), DIR/tradeoff.png (seconds vs PSNR, Pareto
front) and DIR/images/*.png, and prints a short recommendation.

Render error, apart from the blur model (issue 15): `render_psnr` is the PSNR of a
candidate's blurry image against a converged render of the SAME latent positions (the
continuous segment for motion blur), so too few positions (ghosts) do not count there;
`sharp_render_psnr` is the PSNR of the sharp image a build with that candidate's budget
renders (S samples on the view's seed) against a converged sharp render. Converged means
RENDER_REFERENCE_FACTOR × the largest budget, on other seeds; a candidate's blurry image
carries no more render noise than its sharp truth when the two columns agree.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import json
import os
import shutil
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from blurset import _core, layout, outputs
from blurset.config import BuildConfig, from_flags
from blurset.exceptions import ConfigError

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


@dataclass(frozen=True)
class Preset:
    resolution: int
    level: int
    reference: tuple[int, int]  # (latent frames, samples per frame), stratified
    budgets: tuple[int, ...]  # samples per blurry image
    latents: tuple[int, ...]
    samplings: tuple[str, ...] = ("random", "stratified")


PRESETS = {
    # About 2-4 minutes on 2 shared cores.
    "quick": Preset(96, 4, (64, 32), (16, 64), (2, 8, 32)),
    # Tens of minutes: the paper's m = 34 and budgets up to 512 samples at 256 px.
    "full": Preset(256, 4, (128, 64), (32, 128, 512), (4, 16, 34, 64)),
}


@dataclass
class Candidate:
    method: str  # average | motion_blur
    sampling: str  # random | stratified | auto-stratified | continuous
    latents: int | str  # a count, or "auto"
    samples_total: int  # budget S: ceil(S / m) samples per frame
    role: str = "candidate"

    @property
    def label(self) -> str:
        if self.method == "motion_blur":
            return f"motion_blur S={self.samples_total}"
        return f"{self.sampling} m={self.latents} S={self.samples_total}"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--object", required=True, type=Path, help="a GLB file (required)")
    p.add_argument("--out", required=True, type=Path, help="output directory (required)")
    p.add_argument("--quick", action="store_true", help="small grid, 96 px: under a minute")
    p.add_argument("--level", type=int, help="blur level of the measured image (default: 4)")
    p.add_argument("--view", type=int, default=0, help="view index in the setting")
    p.add_argument(
        "--resolution", type=int, help="image side, px (default: 96 with --quick, else 256)"
    )
    p.add_argument(
        "--budgets", type=str, help="samples per blurry image, e.g. 16,64 (default: the preset's)"
    )
    p.add_argument("--latents", type=str, help="latent counts, e.g. 2,8,32 (default: the preset's)")
    p.add_argument(
        "--reference",
        type=str,
        help="reference M,S: M stratified frames of S samples each (default: the preset's)",
    )
    p.add_argument("--max-ghost-px", type=float, default=1.0, help="for the auto rows")
    p.add_argument(
        "--latent-sampling",
        choices=["subsets", "independent"],
        default="subsets",
        help="how the candidates' latent frames share samples",
    )
    p.add_argument("--seed", type=int, default=0, help="setting seed")
    p.add_argument("--theta0-deg", type=float, default=0.0, help="base azimuth, degrees")
    p.add_argument("--threads", type=int, default=0, help="Cycles threads (0: all cores)")
    p.add_argument(
        "--blender", help="a Blender binary instead of the bpy module (default: the bpy module)"
    )
    p.add_argument(
        "--denoise",
        type=str.lower,  # choices in any case, as build and noise take them
        choices=["none", "oidn"],
        default="none",
        help="oidn: every candidate is also measured denoised (Open Image Denoise on the "
        "mean of its frames and of their albedo/normal guides, the sharp image the same "
        "way) against references at 32x its samples",
    )
    p.add_argument("--timeout", type=float, default=1800.0, help="worker reply timeout, s")
    p.add_argument("--quiet", action="store_true", help="no per-candidate lines")


def _ints(text: str | None, option: str, as_option: str) -> tuple[int, ...] | None:
    """Comma-separated integers, each checked as the build option `as_option` (its range
    lives in the core's config)."""
    if text is None:
        return None
    try:
        vals = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise ConfigError(f"{option}: expected integers like 2,8,32, got {text!r}") from None
    if not vals:
        raise ConfigError(f"{option}: expected integers like 2,8,32, got {text!r}")
    for v in vals:
        try:
            BuildConfig(**{as_option: v})
        except ValueError as e:
            raise ConfigError(f"{option} {text}: value {getattr(e, 'detail', e)}") from None
    return vals


def preset_from_args(args: argparse.Namespace) -> Preset:
    base = PRESETS["quick" if args.quick else "full"]
    ref = _ints(args.reference, "--reference", "latents")
    if ref is not None and len(ref) != 2:
        raise ConfigError(f"--reference: expected M,S (frames, samples), got {args.reference!r}")
    reference = base.reference
    if ref is not None:
        from_flags(samples=ref[1])
        reference = (ref[0], ref[1])
    pre = Preset(
        # 0 is a value (refused by the build's own ranges below), not "the default".
        resolution=base.resolution if args.resolution is None else args.resolution,
        level=base.level if args.level is None else args.level,
        reference=reference,
        budgets=_ints(args.budgets, "--budgets", "samples_total") or base.budgets,
        latents=_ints(args.latents, "--latents", "latents") or base.latents,
        samplings=base.samplings,
    )
    if args.view < 0:
        raise ConfigError(f"--view {args.view}: must be an integer ≥ 0")
    # The options a build shares are checked by the build config's validator.
    from_flags(
        {"levels": "--level", "views": "--view (+1)"},
        seed=args.seed,
        timeout=args.timeout,
        threads=args.threads,
        # --max-ghost-px is the auto rows' (latents auto), checked as they use it.
        latents_auto=True,
        max_ghost_px=args.max_ghost_px,
        resolution=pre.resolution,
        levels=[pre.level],
        # the plan holds views 0..view
        views=args.view + 1,
    )
    try:
        _core.check_theta0_deg(args.theta0_deg)
    except _core.ConfigValueError as e:
        raise ConfigError(f"--theta0-deg {e.detail}") from None
    return pre


def candidates(pre: Preset) -> list[Candidate]:
    out: list[Candidate] = []
    for s in pre.budgets:
        for sampling in pre.samplings:
            out.extend(Candidate("average", sampling, m, s) for m in pre.latents)
        out.append(Candidate("average", "auto-stratified", "auto", s))
        out.append(Candidate("motion_blur", "continuous", 1, s))
    return out


def _config(
    pre: Preset, view: int, c: Candidate, max_ghost_px: float, latent_sampling: str = "subsets"
) -> BuildConfig:
    kw: dict[str, Any] = {
        "views": view + 1,
        "levels": [pre.level],
        "resolution": pre.resolution,
        "samples_total": c.samples_total,
        "latent_sampling": latent_sampling,
        # A candidate's budget is what its blurry image renders (the parity factor of a
        # default build would multiply it; the recommendation says so).
        "blur_budget": "flat",
    }
    if c.method == "motion_blur":
        kw["blur_method"] = "motion_blur"
    elif c.latents == "auto":
        kw.update(
            latents_auto=True,
            latent_positions="stratified",
            latents_max=max(pre.reference[0], max(pre.latents)),
            max_ghost_px=max_ghost_px,
        )
    else:
        kw.update(latents=int(c.latents), latent_positions=c.sampling)
    return BuildConfig(**kw)


def _proc_cpu(pid: int | None) -> float:
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


def _own_cpu() -> float:
    return time.process_time()


# The reference's frames get other Cycles seeds than the candidates' (which share the
# plan's seeds frame by frame): render noise common to both would flatter the candidates.
REFERENCE_SEED_SALT = 0x5BD1E995
# Converged renders of render_psnr / sharp_render_psnr: this many times the largest
# budget, so their own noise adds at most 1/8 of a candidate's MSE (≤ 0.5 dB), alike
# for the blurry and the sharp column.
RENDER_REFERENCE_FACTOR = 8
# A denoised image is scored against converged undenoised renders of at least 32 times
# its samples (issue 28): its error can sit far below the raw render noise.
DENOISED_REFERENCE_FACTOR = 32


def _render_image(
    worker, frames: list[dict], lp: dict, res: int, fov: float, salt: int = 0, **render_kw: Any
) -> tuple[Any, dict]:
    """Render and accumulate one blurry image as the build does; (mean, timings)."""
    for f in frames:
        f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
    acc = _core.Accumulator(res, res)

    def on_frame(_i: int, path: str, origin: tuple[int, int] | None) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    pid = worker._proc.pid if worker._proc is not None else None
    c0, o0, t0 = _proc_cpu(pid), _own_cpu(), time.perf_counter()
    worker.render(
        frames,
        resolution=res,
        fov_deg=fov,
        samples=lp["samples_per_frame"],
        on_frame=on_frame,
        crop=True,
        **render_kw,
    )
    mean = acc.mean()
    seconds = time.perf_counter() - t0
    cpu = _proc_cpu(pid) - c0 + _own_cpu() - o0
    return mean, {"seconds": seconds, "cpu_seconds": cpu, "frames": len(frames)}


def _render_denoised(
    worker, frames: list[dict], lp: dict, res: int, fov: float, denoiser: Any
) -> tuple[Any, Any, dict]:
    """Render one image with its guide passes, as a --denoise oidn build does:
    (undenoised mean, denoised mean, timings)."""
    acc = _core.Accumulator(res, res, guides=True)

    def on_frame(_i: int, path: str, origin: tuple[int, int] | None) -> None:
        acc.add_exr(path, origin)
        os.unlink(path)

    t0 = time.perf_counter()
    worker.render(frames, resolution=res, fov_deg=fov, samples=lp["samples_per_frame"],
                  on_frame=on_frame, crop=True, guides=True)  # fmt: skip
    raw = acc.mean()
    acc.denoise(denoiser)
    return raw, acc.mean(), {"seconds": time.perf_counter() - t0, "frames": len(frames)}


def _sharp(view: dict, samples: int, work: Path) -> tuple[list[dict], dict]:
    """The sharp render of a view at `samples`, as (frames, level) for _render_image."""
    frame = {"c2w": view["c2w"], "seed": view["sharp_seed"], "out": str(work / "s.exr")}
    return [frame], {"samples_per_frame": samples}


def _save_png(mean: Any, path: Path, res: int) -> None:
    acc = _core.Accumulator(res, res)
    acc.add(np.ascontiguousarray(mean, dtype=np.float32))
    acc.write_png(path)


def run_tradeoff(args: argparse.Namespace) -> dict:
    pre = preset_from_args(args)
    glb = Path(args.object)
    if not glb.is_file():
        raise ConfigError(f"--object: no such file {str(glb)!r}")
    out = Path(args.out)
    outputs.refuse_overlap(out, [glb])
    outputs.refuse_inside_settings(out)
    claim(out)  # refused before anything is created
    out.mkdir(parents=True, exist_ok=True)

    def busy(holder: str) -> None:
        raise ConfigError(
            f"--out is being written by another blurset tradeoff ({holder}): wait for it "
            f"to end, or give another --out: {out}"
        )

    with outputs.flock_file(out / outputs.TRADEOFF_LOCK, busy):
        claim(out)  # again under the lock
        if not outputs.is_tradeoff(out):
            # The record first: a stopped run's folder is still this command's own.
            layout.write_json(out / outputs.TRADEOFF_RECORD, {"kind": outputs.TRADEOFF_KIND})
        return _measure(args, pre, glb, out)


def claim(out: Path) -> None:
    """May tradeoff write into `out`? A new or empty folder, or an earlier tradeoff's
    (its tradeoff.json says so): it replaces only its own files there. Anything else (a
    build, any other output, a folder of other files, a folder inside an output) is
    refused by name: ConfigError."""
    outputs.refuse_inside_output(out, "--out")
    if (problem := outputs.path_problem(out, output=True)) is not None:
        raise ConfigError(f"--out {problem}")
    if not out.exists():
        return
    if not out.is_dir():
        raise ConfigError(f"--out exists and is not a directory: {out}")
    kind = outputs.kind_of(out)
    if kind is not None:
        raise ConfigError(
            f"--out is a blurset {kind.label} ({kind.record}), not a tradeoff folder: give a "
            f"new or empty folder (nothing was written): {out}"
        )
    if outputs.is_tradeoff(out):
        return
    if any(not p.name.startswith(".") for p in out.iterdir()):
        raise ConfigError(
            f"--out is a folder with other files, not an earlier blurset tradeoff's (no "
            f"{outputs.TRADEOFF_RECORD} of its own): give a new or empty folder (nothing "
            f"was written): {out}"
        )


def _measure(args: argparse.Namespace, pre: Preset, glb: Path, out: Path) -> dict:
    from blurset.worker_client import Worker

    work = out / ".work"
    shutil.rmtree(work, ignore_errors=True)
    (out / layout.IMAGES).mkdir(exist_ok=True)
    say = (lambda *_: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    cands = candidates(pre)
    rows: list[dict[str, Any]] = []
    t_start = time.time()
    with Worker(
        blender=args.blender,
        threads=args.threads,
        timeout=args.timeout,
        log_path=work / "worker.log",
        workdir=work / "scratch",
    ) as w:
        info = w.load(glb, work / "vertices.npy")
        verts = np.ascontiguousarray(np.load(work / "vertices.npy"), dtype=np.float32)
        uid = glb.stem

        def plan_of(cfg: BuildConfig):
            return _core.plan_setting(
                cfg,
                uid=uid,
                theta0_deg=args.theta0_deg,
                seed=args.seed,
                bbox_dims=info["bbox_dims"],
                vertices=verts,
            )

        def plan_level(cfg: BuildConfig) -> tuple[list[dict], dict]:
            """The renders of the measured image and its level plan (w_l, latents …)."""
            plan = plan_of(cfg)
            prefix = str(work / "f")
            return (
                plan.level_renders(args.view, pre.level, prefix),
                plan.level(args.view, pre.level),
            )

        def plan_view(cfg: BuildConfig) -> dict:
            return plan_of(cfg).to_dict()["views"][args.view]

        m_ref, s_ref = pre.reference
        ref_cfg = BuildConfig(
            views=args.view + 1,
            levels=[pre.level],
            resolution=pre.resolution,
            latents=m_ref,
            latent_positions="stratified",
            samples=s_ref,
        )
        ref_frames, ref_lp = plan_level(ref_cfg)
        say(
            f"reference: {m_ref} stratified frames x {s_ref} samples, "
            f"{ref_lp['motion_px']:.1f} px of motion at {pre.resolution} px"
        )
        ref, t_ref = _render_image(
            w, ref_frames, ref_lp, pre.resolution, ref_cfg.fov_deg, salt=REFERENCE_SEED_SALT
        )
        _save_png(ref, out / layout.IMAGES / "reference.png", pre.resolution)
        rows.append(
            {
                "role": "reference",
                "method": "average",
                "sampling": "stratified",
                "latents": m_ref,
                "samples_per_frame": s_ref,
                "samples_total": m_ref * s_ref,
                "budget": m_ref * s_ref,
                "seconds": round(t_ref["seconds"], 3),
                "psnr": "",
                "psnr_linear": "",
                "render_psnr": "",
                "sharp_render_psnr": "",
                "denoise": "none",
                "detail_ratio": "",
                "sharp_detail_ratio": "",
                "render_reference_factor": "",
                "cpu_seconds": round(t_ref["cpu_seconds"], 3),
                "max_gap_px": round(ref_lp["max_gap_px"], 4),
                "pareto": "",
                "label": f"reference m={m_ref} x {s_ref}",
            }
        )
        scheme = args.latent_sampling
        r_samples = RENDER_REFERENCE_FACTOR * max(pre.budgets)
        view = plan_view(ref_cfg)
        fov = ref_cfg.fov_deg

        def psnr_of(a: Any, b: Any) -> float:
            return float(_core.image_error(a, b, background=ref_cfg.background).psnr)

        def detail_of(a: Any, b: Any) -> float:
            return float(_core.image_error(a, b, background=ref_cfg.background).detail_ratio)

        den = None
        if args.denoise == "oidn":
            from blurset.denoise import denoiser

            den = denoiser("cpu")
        d_samples = DENOISED_REFERENCE_FACTOR * max(pre.budgets)
        converged_d: dict[tuple, Any] = {}  # at d_samples, for the denoised rows
        sharp_d: dict[int, tuple[float, float]] = {}
        sharp_ref_d = None
        if den is not None:
            sharp_ref_d, _ = _render_image(
                w, *_sharp(view, d_samples, work), pre.resolution, fov, REFERENCE_SEED_SALT
            )

        converged: dict[tuple, Any] = {}  # the same positions, r_samples, other seeds
        sharp_at: dict[int, tuple[float, float]] = {}  # sharp (render PSNR, detail) per budget
        sharp_ref, _ = _render_image(
            w, *_sharp(view, r_samples, work), pre.resolution, fov, REFERENCE_SEED_SALT
        )
        for i, c in enumerate(cands):
            cfg = _config(pre, args.view, c, args.max_ghost_px, scheme)
            frames, lp = plan_level(cfg)
            mean, t = _render_image(w, frames, lp, pre.resolution, cfg.fov_deg)
            err = _core.image_error(mean, ref, background=cfg.background)
            key = (c.method, tuple(f["t"] for f in lp["latent_frames"]))
            if key not in converged:
                c_ref = dataclasses.replace(c, samples_total=r_samples)
                frames_ref, lp_ref = plan_level(
                    _config(pre, args.view, c_ref, args.max_ghost_px, scheme)
                )
                assert [f["c2w"] for f in frames_ref] == [f["c2w"] for f in frames], (
                    "a budget must not move the latent positions"
                )
                converged[key], _ = _render_image(
                    w, frames_ref, lp_ref, pre.resolution, fov, REFERENCE_SEED_SALT
                )
            if c.samples_total not in sharp_at:
                sharp, _ = _render_image(
                    w, *_sharp(view, c.samples_total, work), pre.resolution, fov
                )
                sharp_at[c.samples_total] = (
                    psnr_of(sharp, sharp_ref),
                    detail_of(sharp, sharp_ref),
                )
            name = c.label.replace(" ", "_").replace("=", "")
            _save_png(mean, out / layout.IMAGES / f"{name}.png", pre.resolution)
            row = {
                "role": "candidate",
                "method": c.method,
                "sampling": c.sampling,
                "latents": lp["latents"],
                "samples_per_frame": lp["samples_per_frame"],
                "samples_total": lp["samples_per_frame"] * lp["latents"],
                "budget": c.samples_total,
                "seconds": round(t["seconds"], 3),
                "psnr": round(err.psnr, 3),
                "psnr_linear": round(err.psnr_linear, 3),
                "render_psnr": round(psnr_of(mean, converged[key]), 3),
                "sharp_render_psnr": round(sharp_at[c.samples_total][0], 3),
                "denoise": "none",
                "detail_ratio": round(detail_of(mean, converged[key]), 4),
                "sharp_detail_ratio": round(sharp_at[c.samples_total][1], 4),
                "render_reference_factor": RENDER_REFERENCE_FACTOR,
                "cpu_seconds": round(t["cpu_seconds"], 3),
                "max_gap_px": round(lp["max_gap_px"], 4),
                "pareto": "",
                "label": c.label.replace("m=auto", f"m={lp['latents']}"),
            }
            rows.append(row)
            say(
                f"[{i + 1}/{len(cands)}] {row['label']:<34} {row['latents']:>4} x "
                f"{row['samples_per_frame']:<4} {row['seconds']:7.2f} s  {row['psnr']:6.2f} dB"
            )
            if den is not None:
                rows.append(
                    _denoised_row(
                        row, c, w, frames, lp, den, plan_level, pre, args, work, fov, view,
                        ref, d_samples, converged_d, sharp_d, sharp_ref_d, psnr_of, detail_of,
                        scheme,
                    )
                )  # fmt: skip
                say(f"      +oidn {rows[-1]['psnr']:6.2f} dB, render {rows[-1]['render_psnr']}")
    cand_rows = [r for r in rows if r["role"] == "candidate"]
    front = _core.pareto_front([r["seconds"] for r in cand_rows], [r["psnr"] for r in cand_rows])
    for r, on in zip(cand_rows, front, strict=True):
        r["pareto"] = bool(on)
    setup = {
        "object": str(glb),
        "uid": uid,
        "view": args.view,
        "level": pre.level,
        "resolution": pre.resolution,
        "seed": args.seed,
        "theta0_deg": args.theta0_deg,
        "motion_px": ref_lp["motion_px"],
        "w_l": ref_lp["w_l"],
        "reference": {"latents": m_ref, "samples_per_frame": s_ref, "sampling": "stratified"},
        "latent_sampling": args.latent_sampling,
        "render_reference_samples": r_samples,
        "render_psnr": "blurry image against a converged render of its own latent positions "
        "(render noise only); sharp_render_psnr: the sharp image at the candidate's budget "
        "against a converged sharp render",
        "max_ghost_px": args.max_ghost_px,
        "denoise": args.denoise,
        "denoised_reference_samples": DENOISED_REFERENCE_FACTOR * max(pre.budgets),
        "detail_ratio": "high-frequency energy (squared Laplacian of sRGB luma) of the image "
        "over its converged render's: < 1 smoothed, > 1 noisier",
        "psnr": "sRGB over a white background, peak 1, against the reference",
        "seconds": "wall clock of rendering + accumulating one blurry image (worker running)",
        "quick": bool(args.quick),
        "total_seconds": round(time.time() - t_start, 1),
        "blurset_version": _core.__version__,
    }
    rec = recommend(cand_rows)
    _write_csv(out / "tradeoff.csv", rows)
    layout.write_text_atomic(
        out / outputs.TRADEOFF_RECORD,
        json.dumps(
            {"kind": outputs.TRADEOFF_KIND, "setup": setup, "rows": rows, "recommendation": rec},
            indent=1,
        )
        + "\n",
    )
    plot(out / "tradeoff.png", rows, setup)
    shutil.rmtree(work, ignore_errors=True)
    return {"setup": setup, "rows": rows, "recommendation": rec}


def _denoised_row(
    row, c, w, frames, lp, den, plan_level, pre, args, work, fov, view, ref, d_samples,
    converged_d, sharp_d, sharp_ref_d, psnr_of, detail_of, scheme,
) -> dict[str, Any]:  # fmt: skip
    """The candidate rendered with its guides and denoised once after averaging, scored
    against converged undenoised renders of DENOISED_REFERENCE_FACTOR x the budget."""
    _raw, dmean, t = _render_denoised(w, frames, lp, pre.resolution, fov, den)
    key = (c.method, tuple(f["t"] for f in lp["latent_frames"]))
    if key not in converged_d:
        c_ref = dataclasses.replace(c, samples_total=d_samples)
        frames_ref, lp_ref = plan_level(_config(pre, args.view, c_ref, args.max_ghost_px, scheme))
        converged_d[key], _ = _render_image(
            w, frames_ref, lp_ref, pre.resolution, fov, REFERENCE_SEED_SALT
        )
    if c.samples_total not in sharp_d:
        frames_s, lvl = _sharp(view, c.samples_total, work)
        _r, sharp, _t = _render_denoised(w, frames_s, lvl, pre.resolution, fov, den)
        sharp_d[c.samples_total] = (psnr_of(sharp, sharp_ref_d), detail_of(sharp, sharp_ref_d))
    err = _core.image_error(dmean, ref)
    return {
        **row,
        "seconds": round(t["seconds"], 3),
        "psnr": round(err.psnr, 3),
        "psnr_linear": round(err.psnr_linear, 3),
        "render_psnr": round(psnr_of(dmean, converged_d[key]), 3),
        "sharp_render_psnr": round(sharp_d[c.samples_total][0], 3),
        "denoise": "oidn",
        "detail_ratio": round(detail_of(dmean, converged_d[key]), 4),
        "sharp_detail_ratio": round(sharp_d[c.samples_total][1], 4),
        "render_reference_factor": DENOISED_REFERENCE_FACTOR,
        "cpu_seconds": "",
        "label": row["label"] + " +oidn",
    }


def _write_csv(path: Path, rows: list[dict]) -> None:
    buf = io.StringIO(newline="")
    wr = csv.DictWriter(buf, fieldnames=list(COLUMNS))
    wr.writeheader()
    for r in rows:
        wr.writerow({k: r[k] for k in COLUMNS})
    layout.write_text_atomic(path, buf.getvalue())


def recommend(rows: list[dict], tolerance_db: float = 1.0) -> dict:
    """The best candidate, the fastest within `tolerance_db` of it, and the fastest
    average-method candidate within the tolerance (for those who keep the paper's method)."""
    best = max(rows, key=lambda r: r["psnr"])
    near = [r for r in rows if r["psnr"] >= best["psnr"] - tolerance_db]
    fastest = min(near, key=lambda r: r["seconds"])
    avg = [r for r in near if r["method"] == "average"]
    return {
        "tolerance_db": tolerance_db,
        "best": best["label"],
        "best_psnr": best["psnr"],
        "fastest_near_best": fastest["label"],
        "fastest_near_best_psnr": fastest["psnr"],
        "fastest_near_best_seconds": fastest["seconds"],
        "fastest_average_near_best": min(avg, key=lambda r: r["seconds"])["label"] if avg else None,
    }


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
        if not pts:
            continue
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


def summary_lines(res: dict) -> list[str]:
    setup, rec = res["setup"], res["recommendation"]
    cands = [r for r in res["rows"] if r["role"] == "candidate"]
    by = {r["label"]: r for r in cands}
    fast, best = by[rec["fastest_near_best"]], by[rec["best"]]
    lines = [
        f"blurset tradeoff: {setup['uid']} view {setup['view']} level {setup['level']}: "
        f"{setup['motion_px']:.1f} px of motion at {setup['resolution']} px; "
        f"{len(cands)} candidates in {setup['total_seconds']:.0f} s",
        f"  best: {best['label']} ({best['latents']} x {best['samples_per_frame']} samples): "
        f"{best['psnr']:.1f} dB in {best['seconds']:.2f} s",
        f"  fastest within {rec['tolerance_db']:g} dB of it: {fast['label']}: "
        f"{fast['psnr']:.1f} dB in {fast['seconds']:.2f} s",
    ]
    if rec["fastest_average_near_best"] and rec["fastest_average_near_best"] != fast["label"]:
        a = by[rec["fastest_average_near_best"]]
        lines.append(
            f"  keeping latent averaging: {a['label']} ({a['latents']} x "
            f"{a['samples_per_frame']}): {a['psnr']:.1f} dB in {a['seconds']:.2f} s"
        )
    lines.append(f"  recommendation: {_flags(fast)}")
    return lines


def _flags(r: dict) -> str:
    budget = f"--samples-total {r['budget']} --blur-budget flat"
    if r["method"] == "motion_blur":
        return f"--blur-method motion_blur {budget}"
    if r["sampling"] == "auto-stratified":
        return f"--latents auto --latent-positions stratified {budget}"
    return f"--latents {r['latents']} --latent-positions {r['sampling']} {budget}"


def run(args: argparse.Namespace) -> int:
    res = run_tradeoff(args)
    for line in summary_lines(res):
        print(line)
    print(f"  wrote {Path(args.out) / 'tradeoff.csv'} and tradeoff.png")
    return 0
