"""`blurset noise`: reproducible LLFF-N style noisy copies of an LLFF scene (DESIGN §5).

Per gain g, OUT/gain_<g>/ is a complete LLFF scene: the images under the name of the
folder read (images/ or images_<F>/: processed sRGB PNG), linear/ or linear_<F>/ (float
EXR of the unclipped linear noisy image, same stems; not with --no-linear), the scene's
poses_bounds.npy (hwf unchanged) and noise.json; the views i % llffhold == 0 stay clean;
OUT/noise_scene.json says what OUT is. The gains are written into a staging folder inside OUT and each moves
into place whole; the record comes last. `--overwrite` replaces the gains and the record
of an earlier noise output, nothing else in OUT, and never a build or a foreign folder.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from blurset import _core, layout
from blurset.commands.noise.params import kpn_path, noise_table, planned
from blurset.exceptions import ConfigError
from blurset.services import outputs
from blurset.services.stop import interruptible, remove_tree

NOISE_SCENE = outputs.OutputKind.NOISE_SCENE
STAGE = "noise"  # `.noise.tmp<pid>` in OUT: the gains before they move in


def run(scene: Path, cfg: _core.NoiseConfig) -> int:
    """The single-scene mode: SCENE is one LLFF scene."""
    assert cfg.out is not None  # a required flag
    out = Path(cfg.out)
    _refuse_build_options(scene, cfg)
    # The scene is refused whole (files, sizes, options) before anything is written.
    plan = planned(_core.plan_noise_scene, scene, out, cfg, noise_table(kpn_path(cfg)))
    unit = plan.units[0]
    outputs.refuse_overlap(out, [scene])
    outputs.refuse_inside_settings(out)
    if outputs.claim(out, NOISE_SCENE, "--out") == "same" and not cfg.overwrite:
        raise ConfigError(
            f"--out is a noise output already (pass --overwrite to replace it): {out}"
        )
    with outputs.lock(out, NOISE_SCENE):
        # Claimed again under the lock: another run may have written it meanwhile.
        if outputs.claim(out, NOISE_SCENE, "--out") == "same":
            if not cfg.overwrite:
                raise ConfigError(f"--out is a noise output already (pass --overwrite): {out}")
            # Refused before the gains are written: their old folders go whole.
            owned = outputs.owned_entries(out, NOISE_SCENE)
            outputs.refuse_links(out, owned, "noise")
            outputs.refuse_not_written(out, NOISE_SCENE, owned, "noise")
        # A killed run's staging tree (SIGKILL leaves it; SIGINT/SIGTERM remove their own).
        # (and an old gain a killed replace_dir had moved aside)
        layout.remove_stale_temps(out, [STAGE, *(g.name for g in out.glob("gain_*"))])
        tmp = layout.temp_path(out / STAGE)
        shutil.rmtree(tmp, ignore_errors=True)
        try:
            gain_dirs = _write_gains(tmp, unit)
            # The previous output's own entries make way (nothing else in OUT), then each
            # gain moves in whole; the record comes last.
            outputs.remove_owned(out, NOISE_SCENE)
            for gdir in gain_dirs:
                layout.replace_dir(gdir, out / gdir.name)
            doc = plan.write_scene_record(out)
        finally:
            remove_tree(tmp)
    folder = unit.gains[0].record["files"][0]["image"].split("/")[0]
    hold = doc.get("llffhold")
    clean = f"views {', '.join(map(str, unit.clean_views))} clean (llffhold {hold})"
    print(
        f"blurset noise: wrote {len(gain_dirs)} scene(s) x {unit.images} images to {out} "
        f"({', '.join(g.name for g in gain_dirs)}; {folder}/; "
        f"{clean if hold else 'every view noisy'})"
    )
    return 0


def _refuse_build_options(scene: Path, cfg: _core.NoiseConfig) -> None:
    """The options that choose among a build's levels and views mean nothing here."""
    if cfg.levels is not None:
        raise ConfigError(f"--levels applies to a build (no dataset.json in {scene})")
    if cfg.noisy_test_views and cfg.clean_views is not None:
        raise ConfigError("--clean-views and --noisy-test-views: pass one (clean targets or none)")
    if cfg.source != "auto":
        raise ConfigError(f"--source applies to a build (no dataset.json in {scene})")


def _write_gains(tmp: Path, unit: _core.NoiseUnit) -> list[Path]:
    """Every gain's noisy scene under `tmp`, in the order of the gains given: the
    images in one pass over the sources, then each gain's poses, clean views and
    noise.json."""
    dirs = [tmp / g.dir for g in unit.gains]
    interruptible(unit.write_images, list(enumerate(dirs)))
    for i, gdir in enumerate(dirs):
        unit.write_gain_files(i, gdir)
    return dirs
