"""What every `blurset export` target shares (`--for llff`, `nerfstudio`, `geonerf` in
blurset.export, `hub` in blurset.export_hub): the output kind and its record, the temp
names, the options read against the build (--levels, --gains), and the rules of what an
export may write over (DESIGN §10): never an input, never an entry an earlier export
here did not write, never an export of another build or --noise by itself.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from blurset import layout, outputs
from blurset.exceptions import ConfigError

if TYPE_CHECKING:
    from blurset import _records

EXPORT = outputs.OutputKind.EXPORT
EXPORT_FILE = EXPORT.record
# Temp names (`.<name>.tmp<pid>`) of the staged scenes and of what makes way.
STAGE, TRASH = "export", "export.old"
# The files an export writes at the top of --out besides its scenes.
LISTS = ("train.txt", "test.txt", EXPORT_FILE)


def levels(value: str | None, available: list[str]) -> list[str]:
    """The levels `--levels` names (all without it), in the build's order."""
    if value is None:
        return available
    names = [s.strip() for s in value.split(",") if s.strip()]
    for n in names:
        if n not in available:
            raise ConfigError(f"--levels: the build has no level {n!r} ({', '.join(available)})")
    return [lvl for lvl in available if lvl in names]


def gains(noise: Path, doc: dict, value: list[str] | None) -> list[str]:
    """The gain folders `--gains` names of the noise output `noise` (all without it)."""
    have = [layout.gain_name(g["gain"]) for g in doc["gains"]]
    if value is None:
        return have
    names = []
    for v in value:
        try:
            name = layout.gain_name(float(v))
        except ValueError:
            raise ConfigError(f"--gains {v!r}: not a number") from None
        if name not in have:
            raise ConfigError(f"--gains {v}: {noise} has no {name} ({', '.join(have)})")
        names.append(name)
    return names


def refuse_overlap(out: Path, doc: _records.ExportDoc, inputs: list[Path]) -> None:
    """--out may hold the build (IBRNet's `data/` may keep it beside the export), but it
    may not be or lie in an input, and no entry the export writes may touch one."""
    o = out.resolve()
    for i in inputs:
        r = Path(i).resolve()
        if o == r or o.is_relative_to(r):
            outputs.refuse_overlap(out, [i])
        if r.is_relative_to(o):
            top = doc["scenes_dir"] if doc["scenes_dir"] != "." else None
            mine = [top] if top else list(doc["scenes"])
            for e in [*mine, *LISTS]:
                if r == o / e or r.is_relative_to(o / e):
                    raise ConfigError(f"--out/{e} would hold the input {str(i)!r}: {out}")


def _other_noise(was: str | None, now: str | None, out: Path) -> str:
    """Why an export of the build with another --noise (or none) does not replace the one
    in OUT by itself: a loader reads one root, so clean and noisy scenes need two."""

    def of(noise: str | None) -> str:
        return f"the noise output {noise!r}" if noise else "the build without --noise"

    return (
        f"--out holds the export of {of(was)}; this export of {of(now)} would replace it. "
        "To keep both, give this one its own root (IBRNet and GNT read only "
        "<rootdir>/data/nerf_llff_data/: --out ROOTN/data, then --rootdir ROOTN), or "
        f"--overwrite to replace it: {out}"
    )


def refuse_other_export(old: dict, doc: _records.ExportDoc, out: Path, overwrite: bool) -> None:
    """An export of another build, or with another --noise, is not replaced by itself."""
    # (an export.json of an older blurset names the build by its absolute path)
    was_of = Path(str(old.get("build"))).name if old.get("build") else doc["build"]
    if was_of != doc["build"] and not overwrite:
        raise ConfigError(
            f"--out holds an export of the build {was_of!r}: give another --out, "
            f"or --overwrite to replace that export: {out}"
        )
    if old.get("state") != "replacing" and old.get("noise") != doc["noise"] and not overwrite:
        raise ConfigError(_other_noise(old.get("noise"), doc["noise"], out))


def refuse_foreign(out: Path, doc: _records.ExportDoc, owned: set[str], new: list[str]) -> None:
    """Nothing an earlier export did not write is replaced, and a scene folder that makes
    way holds only what an export writes: a user's file there (a note) is named, never
    deleted with it."""
    for rel in new:
        p = out / rel
        if (p.exists() or p.is_symlink()) and rel not in owned:
            raise ConfigError(
                f"--out already holds {rel}, which no earlier export here wrote: move it, or "
                f"give another --out: {out}"
            )
    if doc["scenes_dir"] != "." and (out / doc["scenes_dir"]).is_file():
        raise ConfigError(f"--out holds a file {doc['scenes_dir']}: {out}")
    # (The core's rule of what an exported scene holds: images/, images_<f>/, the passes'
    # folders and links, nerfstudio's depths/, poses_bounds.npy, transforms.json.)
    scenes = [rel for rel in sorted(owned) if rel not in LISTS]
    outputs.refuse_not_written(out, EXPORT, scenes, "export")


def record_replacing(out: Path, doc: _records.ExportDoc, owns: set[str]) -> None:
    """What a run may put in place, recorded before it writes: an export stopped half-way
    still owns every entry it wrote, and its rerun replaces (or keeps) them."""
    outputs.write_record(
        out / EXPORT_FILE,
        {
            "kind": "blurset export",
            "state": "replacing",
            "build": doc["build"],
            "scenes_dir": doc["scenes_dir"],
            "scenes": {},
            "owns": sorted(owns),
        },
    )


def prune_empty_parents(out: Path, rel: str) -> None:
    """The folders above an entry that made way (`data/blur_4`, `nerf_llff_data`), once
    empty, go too; never `out` itself."""
    d = (out / rel).parent
    while d != out and d.is_relative_to(out):
        try:
            d.rmdir()
        except OSError:
            return  # not empty (or not ours to remove)
        d = d.parent
