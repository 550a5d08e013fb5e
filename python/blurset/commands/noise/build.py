"""`blurset noise BUILD_DIR`: blur + noise on a whole build (issue 9).

Every chosen level of every complete setting of a build becomes LLFF-N style noisy
copies, mirroring the build's layout:

    DIR/noise_dataset.json            seed, options, the seed of every (setting, level)
    DIR/splits.json                   the build's splits, unchanged (same test views)
    DIR/<setting>/<level>/gain_<g>/   a complete LLFF scene, as `blurset noise SCENE` writes:
        images/  linear/  poses_bounds.npy  noise.json  .complete

The unit of work is one gain of one level of one setting. It is written under
`gain_<g>.partial/` and renamed into place after its `.complete` marker, the last file
written: a rerun skips complete units and redoes partial ones; an error removes what
the failing call had started and leaves complete units alone.

blurset-core plans every unit before anything is written (`plan_noise_build`,
rust/core/src/dataset/noise_plan.rs: inputs checked, seeds, keys, sigmas, each gain's
noise.json, the options record) and writes it, and assembles and writes
noise_dataset.json (rust/core/src/dataset/noise_output.rs); this module schedules: the
lock, when each record is written, partial folders, the fault injection, progress,
publishing.

The seed of a (setting, level) is derived in blurset-core from the one `--seed`
(`noise_scene_seed`) and plays the role of the single-scene `--seed`, so the PNG path
of a unit is byte-identical to `blurset noise <build>/<setting>/<level> --factor 1
--seed <that seed> --gamma srgb` (its noisy views: the clean ones are the build's test
views, not llffhold's).

Source of the clean image: the build's linear EXRs (`blurset build --keep-linear`),
composited over the build's background exactly as its PNGs were, or the sRGB PNGs
inverted (`--source png`). Both share the same draws, so they differ only by what the
8-bit PNG did to the clean image.
"""

from __future__ import annotations

import os
import shutil
import signal
import sys
import time
from pathlib import Path

from blurset import _core, layout
from blurset.commands.noise.params import kpn_path, noise_table, planned
from blurset.exceptions import ConfigError
from blurset.services import outputs, publish
from blurset.services.stop import fault_index, interruptible, remove_tree

NOISE = outputs.OutputKind.NOISE
DATASET_FILE = NOISE.record


def is_build(path: Path) -> bool:
    """A build directory (as `blurset build` writes it) rather than one LLFF scene."""
    return outputs.kind_of(path) is outputs.OutputKind.BUILD


def _prepare_out(out: Path, build: Path, plan: _core.NoisePlan, overwrite: bool) -> None:
    """Claim OUT for this noise run (call under its lock): a new or empty folder, or a
    noise output made with the same options; `--overwrite` replaces a noise output's own
    units and records, nothing else in the folder, and never a build or a foreign folder."""
    how = outputs.claim(out, NOISE, "--out")
    units = [(u.dst / g.dir).relative_to(out).as_posix() for u in plan.units for g in u.gains]
    outputs.refuse_links(out, units + outputs.owned_entries(out, NOISE), "noise")
    if how == "same":
        old = outputs.read_record(out / DATASET_FILE)
        if old["build"] != build.resolve().name and not overwrite:
            raise ConfigError(
                f"--out holds the noise of the build {old['build']!r}: use another --out, or "
                f"--overwrite to replace it: {out}"
            )
        if overwrite:
            outputs.refuse_not_written(out, NOISE, outputs.owned_entries(out, NOISE), "noise")
            outputs.remove_owned(out, NOISE)
        else:
            # Both sides' keys: a record leaves out an option at its default (no_linear).
            for k in sorted({*plan.params, *old["params"]}):
                if old["params"].get(k) != (v := plan.params.get(k)):
                    raise ConfigError(
                        f"--out was written with {k} = {old['params'].get(k)!r}, not {v!r}: use "
                        f"another --out, or --overwrite to replace it: {out / DATASET_FILE}"
                    )
    # A killed run's partial units go (below): none may hold a file of the user's.
    partials = [r for r in outputs.owned_entries(out, NOISE) if r.endswith(layout.PARTIAL_SUFFIX)]
    outputs.refuse_not_written(out, NOISE, partials, "noise")
    out.mkdir(parents=True, exist_ok=True)
    if not (out / DATASET_FILE).is_file():
        # Written first (options only) so that a run killed before its end resumes;
        # rewritten with the seeds and counts at the end.
        plan.write_dataset_start(out)
    for stale in out.glob("*/*/gain_*.partial"):
        shutil.rmtree(stale, ignore_errors=True)
    # The old unit a killed publish had moved aside (replace_dir), beside the new one.
    for level in {g.parent for g in out.glob("*/*/gain_*")}:
        layout.remove_stale_temps(level, [g.name for g in level.glob("gain_*")])


# Fault injection, as the worker's BLURSET_WORKER_FAULT: "kill_in:K" SIGKILLs this
# process inside the K-th unit it writes, once that unit's noisy images are on disk and
# before any of its gains is complete, so a test of the resume kills at a known point
# instead of racing the run.
FAULT = "BLURSET_NOISE_FAULT"


def _write_unit(unit: _core.NoiseUnit, pending: list[int], die: bool = False) -> None:
    """The gains `pending` of `unit` written under their partial folders, each published
    once whole; an error removes the partial folders this call started."""
    finals = {i: unit.dst / unit.gains[i].dir for i in pending}
    partials = {i: layout.partial_dir(d) for i, d in finals.items()}
    # A gain folder this replaces (not complete, or redone) may not hold a user's file.
    outputs.refuse_not_written(unit.dst, NOISE, [d.name for d in finals.values()], "noise")
    unit.dst.mkdir(parents=True, exist_ok=True)
    for p in partials.values():
        shutil.rmtree(p, ignore_errors=True)
    try:
        interruptible(unit.write_images, list(partials.items()))
        if die:
            os.kill(os.getpid(), signal.SIGKILL)
        for i, part in partials.items():
            unit.write_gain_files(i, part)
            layout.publish(part, finals[i])
    except BaseException:
        for p in partials.values():
            remove_tree(p)
        raise


def _refuse_scene_options(cfg: _core.NoiseConfig) -> None:
    """The options that pick a scene's images or held-out views mean nothing here."""
    if cfg.factor is not None:
        raise ConfigError("--factor: a build has no images_<F>/ directories; omit it")
    if cfg.clean_views is not None:
        raise ConfigError(
            "--clean-views applies to a scene: a build keeps its own test views clean "
            "(splits.json), or none with --noisy-test-views"
        )


def _pending(out: Path, unit: _core.NoiseUnit) -> list[int]:
    """The gains of `unit` to write: those not complete, and a complete one whose files
    are not the bytes OUT's manifest certifies (damaged or copied over since), or, with
    no manifest to compare with (a run killed before it), whose PNGs are cut short:
    named on stderr and redone, never certified anew."""
    pending = set(unit.pending())
    has_manifest = (out / publish.MANIFEST).is_file()
    for i, g in enumerate(unit.gains):
        if i in pending:
            continue
        rel = (unit.dst / g.dir).relative_to(out).as_posix()
        if has_manifest:
            problem = publish.manifest_problem(out, rel)
        else:
            problem = _png_problem(unit.dst / g.dir)
        if problem:
            print(f"redoing {rel}: {problem}", file=sys.stderr)
            pending.add(i)
    return sorted(pending)


def _png_problem(gain: Path) -> str | None:
    """The first PNG of a gain folder that is not whole (signature, end chunk), in
    words: the check of a setting's images, for a gain no manifest vouches for."""
    for png in sorted(gain.glob("images*/*.png")):
        if problem := layout.png_problem(png):
            return f"{png.relative_to(gain).as_posix()}: {problem}"
    return None


def _write_pending(
    out: Path, plan: _core.NoisePlan, quiet: bool, fault: int | None
) -> tuple[list[str], list[str]]:
    """Every unit's pending gains, a unit at a time (a count on a terminal); returns the
    gain folders written and those reused, complete and matching the manifest (relative
    to OUT)."""
    written: list[str] = []
    checked: list[str] = []
    todo = []
    for u in plan.units:
        p = _pending(out, u)
        if p:
            todo.append((u, p))
        rel = u.dst.relative_to(out).as_posix()
        checked += [f"{rel}/{g.dir}" for i, g in enumerate(u.gains) if i not in p]
    show = not quiet and sys.stderr.isatty()
    for n, (u, pending) in enumerate(todo, 1):
        _write_unit(u, pending, die=n == fault)
        written += [(u.dst / u.gains[i].dir).relative_to(out).as_posix() for i in pending]
        if show:
            print(f"\r{n}/{len(todo)} levels noised", end="", file=sys.stderr, flush=True)
    if show and todo:
        print(file=sys.stderr)
    return written, checked


def run(build: Path, cfg: _core.NoiseConfig) -> int:
    assert cfg.out is not None  # a required flag
    out = Path(cfg.out)
    _refuse_scene_options(cfg)
    # A build still being written (or stopped) would be noised half, with stale splits.
    complete = outputs.finished_build(build, "SCENE").complete
    table = noise_table(kpn_path(cfg))
    # Every unit checked before writing anything: a bad build fails with nothing written.
    plan = planned(_core.plan_noise_build, build, out, list(complete), cfg, table)
    outputs.refuse_overlap(out, [build])
    outputs.refuse_inside_settings(out)
    fault = fault_index(FAULT)  # a bad spec is refused before anything is written
    outputs.claim(out, NOISE, "--out")  # refused before the lock creates anything
    with outputs.lock(out, NOISE):
        _prepare_out(out, build, plan, cfg.overwrite)
        layout.write_text_atomic(out / layout.SPLITS, (build / layout.SPLITS).read_text())
        n_gains = len(cfg.gain_values)
        # Pending under the lock: --overwrite may just have removed units.
        written, checked = _write_pending(out, plan, cfg.quiet, fault)
        skipped = len(plan.units) * n_gains - len(written)
        # Over every complete unit on disk, earlier runs' too.
        doc = plan.write_dataset(out, time.strftime("%Y-%m-%dT%H:%M:%S"))
        # Hashed: what this run wrote or checked; the rest keeps the line it had, except
        # under --overwrite, which replaced every unit of the old output.
        publish.rewrite_manifest(
            out, [*written, *checked, DATASET_FILE, layout.SPLITS], keep_old=not cfg.overwrite
        )
    print(
        f"blurset noise: {len(written)} scene(s) written, {skipped} complete skipped "
        f"({len(complete)} settings x {len(plan.levels)} levels x {n_gains} gains, "
        f"source {plan.source}) -> {out} [{doc['counts']['units']} scenes in total]"
    )
    return 0
