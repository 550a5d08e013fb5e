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

The package: `cli` (the command, its --out folder), `grid` (presets, candidates, their
build configs), `render` (one image as the build renders it), `measure` (the reference and
every candidate), `report` (CSV, JSON, plot), `recommend` (the recommendation).
"""

from __future__ import annotations

from blurset.commands.tradeoff.cli import add_arguments, claim, run, run_tradeoff
from blurset.commands.tradeoff.grid import PRESETS, Candidate, Preset, candidates, preset_from_args
from blurset.commands.tradeoff.recommend import recommend, summary_lines
from blurset.commands.tradeoff.render import (
    DENOISED_REFERENCE_FACTOR,
    REFERENCE_SEED_SALT,
    RENDER_REFERENCE_FACTOR,
)
from blurset.commands.tradeoff.report import COLUMNS, plot

__all__ = [
    "COLUMNS",
    "DENOISED_REFERENCE_FACTOR",
    "PRESETS",
    "REFERENCE_SEED_SALT",
    "RENDER_REFERENCE_FACTOR",
    "Candidate",
    "Preset",
    "add_arguments",
    "candidates",
    "claim",
    "plot",
    "preset_from_args",
    "recommend",
    "run",
    "run_tradeoff",
    "summary_lines",
]
