"""The measured grid: presets, the command's grid options, the candidates and the build
configuration each one renders with."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import Any

from blurset import _core
from blurset.exceptions import ConfigError
from blurset.services.config import BuildConfig, from_flags
from blurset.services.options import check_range


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
    check_range("--view", args.view, 0)
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


def candidate_config(
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
