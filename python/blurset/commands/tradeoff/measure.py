"""The measurement: the reference, then every candidate (and its denoised twin) against
it and against converged renders of its own latent positions, in one Blender worker."""

from __future__ import annotations

import argparse
import dataclasses
import shutil
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from blurset import _core, layout
from blurset.commands.tradeoff.grid import Candidate, Preset, candidate_config, candidates
from blurset.commands.tradeoff.recommend import recommend
from blurset.commands.tradeoff.render import (
    DENOISED_REFERENCE_FACTOR,
    REFERENCE_SEED_SALT,
    RENDER_REFERENCE_FACTOR,
    render_denoised,
    render_image,
    save_png,
    sharp_frames,
)
from blurset.commands.tradeoff.report import plot, write_csv, write_record
from blurset.exceptions import ConfigError
from blurset.services import outputs
from blurset.services.config import BuildConfig
from blurset.services.denoise import denoiser
from blurset.services.worker_client import Worker

if TYPE_CHECKING:
    from blurset import _records


@dataclass
class _Session:
    """The worker with the object loaded, and the plans of the measured view and level."""

    args: argparse.Namespace
    pre: Preset
    w: Worker
    work: Path
    uid: str
    info: _records.Loaded
    verts: Any

    def plan_of(self, cfg: BuildConfig):
        return _core.plan_setting(
            cfg,
            uid=self.uid,
            theta0_deg=self.args.theta0_deg,
            seed=self.args.seed,
            bbox_dims=self.info["bbox_dims"],
            vertices=self.verts,
        )

    def plan_level(self, cfg: BuildConfig) -> tuple[list[dict], dict]:
        """The renders of the measured image and its level plan (w_l, latents …)."""
        plan = self.plan_of(cfg)
        prefix = str(self.work / "f")
        return (
            plan.level_renders(self.args.view, self.pre.level, prefix),
            plan.level(self.args.view, self.pre.level),
        )

    def plan_view(self, cfg: BuildConfig) -> dict:
        return self.plan_of(cfg).to_dict()["views"][self.args.view]

    def config(self, c: Candidate) -> BuildConfig:
        a = self.args
        return candidate_config(self.pre, a.view, c, a.max_ghost_px, a.latent_sampling)


@dataclass
class _References:
    """What every candidate is scored against: the reference image, the converged sharp
    renders, and the converged renders of each set of latent positions (filled as the
    candidates need them)."""

    ref_cfg: BuildConfig
    ref: Any
    view: dict
    fov: float
    r_samples: int
    d_samples: int
    den: Any
    sharp_ref_d: Any
    sharp_ref: Any
    converged: dict[tuple, Any] = field(default_factory=dict)  # r_samples, other seeds
    sharp_at: dict[int, tuple[float, float]] = field(default_factory=dict)  # (PSNR, detail)
    converged_d: dict[tuple, Any] = field(default_factory=dict)  # at d_samples, denoised rows
    sharp_d: dict[int, tuple[float, float]] = field(default_factory=dict)

    def psnr_of(self, a: Any, b: Any) -> float:
        return float(_core.image_error(a, b, background=self.ref_cfg.background).psnr)

    def detail_of(self, a: Any, b: Any) -> float:
        return float(_core.image_error(a, b, background=self.ref_cfg.background).detail_ratio)

    def scores(
        self, mean: Any, converged: Any, sharp: tuple[float, float], factor: int
    ) -> dict[str, Any]:
        """A row's accuracy columns, in the row's column order: against the reference,
        against its own converged render (render noise), and its sharp image's; one
        place, so a denoised row and its undenoised twin are scored alike."""
        err = _core.image_error(mean, self.ref, background=self.ref_cfg.background)
        return {
            "psnr": round(err.psnr, 3),
            "psnr_linear": round(err.psnr_linear, 3),
            "render_psnr": round(self.psnr_of(mean, converged), 3),
            "sharp_render_psnr": round(sharp[0], 3),
            "detail_ratio": round(self.detail_of(mean, converged), 4),
            "sharp_detail_ratio": round(sharp[1], 4),
            "render_reference_factor": factor,
        }


# The worker's folder in OUT is `.work.tmp<pid>` (layout.temp_path): this run's alone.
WORK = "work"


def scratch(out: Path) -> Path:
    """The worker's log and scratch for this run: `.work.tmp<pid>` in OUT, made new (a
    `.work` of the user's, or a link by that name, is never used or removed); a killed
    run's is removed by the next run."""
    layout.remove_stale_temps(out, [WORK])
    work = layout.temp_path(out / WORK)
    if work.is_symlink() or work.is_file():
        raise ConfigError(f"--out holds {work.name}, which tradeoff did not write: {work}")
    # (A folder by this name is a dead run's of this very pid: this run's scratch.)
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir()
    return work


def measure(args: argparse.Namespace, pre: Preset, glb: Path, out: Path) -> dict:
    work = scratch(out)
    (out / layout.IMAGES).mkdir(exist_ok=True)
    say: Callable[[str], None] = (
        (lambda *_: None) if args.quiet else (lambda s: print(s, file=sys.stderr, flush=True))
    )
    cands = candidates(pre)
    rows: list[dict[str, Any]] = []
    t_start = time.time()
    with Worker.in_folder(
        work, blender=args.blender, threads=args.threads, timeout=args.timeout
    ) as w:
        info = w.load(glb, work / "vertices.npy")
        verts = np.ascontiguousarray(np.load(work / "vertices.npy"), dtype=np.float32)
        s = _Session(args, pre, w, work, glb.stem, info, verts)
        refs, ref_lp = _references(s, out, rows, say)
        for i, c in enumerate(cands):
            row, frames, lp = _candidate_row(s, refs, c, out)
            rows.append(row)
            say(
                f"[{i + 1}/{len(cands)}] {row['label']:<34} {row['latents']:>4} x "
                f"{row['samples_per_frame']:<4} {row['seconds']:7.2f} s  {row['psnr']:6.2f} dB"
            )
            if refs.den is not None:
                rows.append(_denoised_row(s, refs, row, c, frames, lp))
                say(f"      +oidn {rows[-1]['psnr']:6.2f} dB, render {rows[-1]['render_psnr']}")
    res = _finish(args, pre, glb, out, s.uid, rows, ref_lp, refs.r_samples, t_start)
    shutil.rmtree(work, ignore_errors=True)
    return res


def _references(
    s: _Session, out: Path, rows: list[dict[str, Any]], say: Callable[[str], None]
) -> tuple[_References, dict]:
    """The reference image (its row into `rows`) and the converged sharp renders, in the
    order the candidates' seeds do not depend on; (references, the reference's level)."""
    pre, args, w, work = s.pre, s.args, s.w, s.work
    m_ref, s_ref = pre.reference
    ref_cfg = BuildConfig(
        views=args.view + 1,
        levels=[pre.level],
        resolution=pre.resolution,
        latents=m_ref,
        latent_positions="stratified",
        samples=s_ref,
    )
    ref_frames, ref_lp = s.plan_level(ref_cfg)
    say(
        f"reference: {m_ref} stratified frames x {s_ref} samples, "
        f"{ref_lp['motion_px']:.1f} px of motion at {pre.resolution} px"
    )
    ref, t_ref = render_image(
        w, ref_frames, ref_lp, pre.resolution, ref_cfg.fov_deg, salt=REFERENCE_SEED_SALT
    )
    save_png(ref, out / layout.IMAGES / "reference.png", pre.resolution)
    rows.append(_reference_row(m_ref, s_ref, t_ref, ref_lp))
    r_samples = RENDER_REFERENCE_FACTOR * max(pre.budgets)
    view = s.plan_view(ref_cfg)
    fov = ref_cfg.fov_deg
    den = denoiser("cpu") if args.denoise == "oidn" else None
    d_samples = DENOISED_REFERENCE_FACTOR * max(pre.budgets)
    sharp_ref_d = None
    if den is not None:
        sharp_ref_d, _ = render_image(
            w, *sharp_frames(view, d_samples, work), pre.resolution, fov, REFERENCE_SEED_SALT
        )
    sharp_ref, _ = render_image(
        w, *sharp_frames(view, r_samples, work), pre.resolution, fov, REFERENCE_SEED_SALT
    )
    refs = _References(ref_cfg, ref, view, fov, r_samples, d_samples, den, sharp_ref_d, sharp_ref)
    return refs, ref_lp


def _reference_row(m_ref: int, s_ref: int, t_ref: dict, ref_lp: dict) -> dict[str, Any]:
    return {
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


def _candidate_row(
    s: _Session, refs: _References, c: Candidate, out: Path
) -> tuple[dict[str, Any], list[dict], dict]:
    """One candidate rendered and scored: (its row, its frames, its level plan)."""
    pre, w, fov = s.pre, s.w, refs.fov
    cfg = s.config(c)
    frames, lp = s.plan_level(cfg)
    mean, t = render_image(w, frames, lp, pre.resolution, cfg.fov_deg)
    key = (c.method, tuple(f["t"] for f in lp["latent_frames"]))
    if key not in refs.converged:
        frames_ref, lp_ref = s.plan_level(
            s.config(dataclasses.replace(c, samples_total=refs.r_samples))
        )
        assert [f["c2w"] for f in frames_ref] == [f["c2w"] for f in frames], (
            "a budget must not move the latent positions"
        )
        refs.converged[key], _ = render_image(
            w, frames_ref, lp_ref, pre.resolution, fov, REFERENCE_SEED_SALT
        )
    if c.samples_total not in refs.sharp_at:
        sharp, _ = render_image(
            w, *sharp_frames(refs.view, c.samples_total, s.work), pre.resolution, fov
        )
        refs.sharp_at[c.samples_total] = (
            refs.psnr_of(sharp, refs.sharp_ref),
            refs.detail_of(sharp, refs.sharp_ref),
        )
    name = c.label.replace(" ", "_").replace("=", "")
    save_png(mean, out / layout.IMAGES / f"{name}.png", pre.resolution)
    row = {
        "role": "candidate",
        "method": c.method,
        "sampling": c.sampling,
        "latents": lp["latents"],
        "samples_per_frame": lp["samples_per_frame"],
        "samples_total": lp["samples_per_frame"] * lp["latents"],
        "budget": c.samples_total,
        "seconds": round(t["seconds"], 3),
        "denoise": "none",
        **refs.scores(
            mean, refs.converged[key], refs.sharp_at[c.samples_total], RENDER_REFERENCE_FACTOR
        ),
        "cpu_seconds": round(t["cpu_seconds"], 3),
        "max_gap_px": round(lp["max_gap_px"], 4),
        "pareto": "",
        "label": c.label.replace("m=auto", f"m={lp['latents']}"),
    }
    return row, frames, lp


def _denoised_row(
    s: _Session, refs: _References, row: dict, c: Candidate, frames: list[dict], lp: dict
) -> dict[str, Any]:
    """The candidate rendered with its guides and denoised once after averaging, scored
    against converged undenoised renders of DENOISED_REFERENCE_FACTOR x the budget."""
    pre, w, fov, den = s.pre, s.w, refs.fov, refs.den
    _raw, dmean, t = render_denoised(w, frames, lp, pre.resolution, fov, den)
    key = (c.method, tuple(f["t"] for f in lp["latent_frames"]))
    if key not in refs.converged_d:
        c_ref = dataclasses.replace(c, samples_total=refs.d_samples)
        frames_ref, lp_ref = s.plan_level(s.config(c_ref))
        refs.converged_d[key], _ = render_image(
            w, frames_ref, lp_ref, pre.resolution, fov, REFERENCE_SEED_SALT
        )
    if c.samples_total not in refs.sharp_d:
        frames_s, lvl = sharp_frames(refs.view, c.samples_total, s.work)
        _r, sharp, _t = render_denoised(w, frames_s, lvl, pre.resolution, fov, den)
        refs.sharp_d[c.samples_total] = (
            refs.psnr_of(sharp, refs.sharp_ref_d),
            refs.detail_of(sharp, refs.sharp_ref_d),
        )
    return {
        **row,
        "seconds": round(t["seconds"], 3),
        "denoise": "oidn",
        **refs.scores(
            dmean, refs.converged_d[key], refs.sharp_d[c.samples_total], DENOISED_REFERENCE_FACTOR
        ),
        "cpu_seconds": "",
        "label": row["label"] + " +oidn",
    }


def _finish(
    args: argparse.Namespace,
    pre: Preset,
    glb: Path,
    out: Path,
    uid: str,
    rows: list[dict[str, Any]],
    ref_lp: dict,
    r_samples: int,
    t_start: float,
) -> dict:
    """The Pareto front marked, the set-up, the recommendation, and the files written."""
    cand_rows = [r for r in rows if r["role"] == "candidate"]
    front = _core.pareto_front([r["seconds"] for r in cand_rows], [r["psnr"] for r in cand_rows])
    for r, on in zip(cand_rows, front, strict=True):
        r["pareto"] = bool(on)
    m_ref, s_ref = pre.reference
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
    write_csv(out / "tradeoff.csv", rows)
    write_record(out / outputs.TRADEOFF_RECORD, setup, rows, rec)
    plot(out / "tradeoff.png", rows, setup)
    return {"setup": setup, "rows": rows, "recommendation": rec}
