#!/usr/bin/env python3
"""Run a training client's own dataset code on a `blurset export` and say what it reads.

    python scripts/check_clients.py CLIENT EXPORT --checkout DIR --python PY [--build BUILD]

CLIENT is one of ibrnet, gnt, nan, deblur-nerf, geonerf, nerfstudio; EXPORT the folder
`blurset export --out` wrote (its export.json says for which loader); DIR a checkout of
the client's repository; PY the Python of an environment with the client's
dependencies (torch and the rest: never blurset's own environment). The client's
modules are imported from DIR in a subprocess of PY and its dataset classes are built
and indexed as its train and eval scripts do, on the CPU; what needs a GPU, a network
or weights (the model, training) is not run. Nothing of the client is changed: the
only hook is a wrapper around its image reader that records which files it opens.

The report: the scenes the client found, the images and poses it read, their shapes
and focal length, the held-out views it chooses, and for every degraded scene (a blur
level or a gain) whether a target or a source it draws is a sharp copy, i.e. the same
bytes as an image of the setting's sharp level; and in the gain scenes of a noise export,
whether an image it draws is noise-free (the bytes of the build's image of that level:
only the clean held-out views may be). Expected: for IBRNet, GNT, NAN and
Deblur-NeRF with the export's llffhold, the held-out targets are the sharp views and no
source is; for GeoNeRF on a `--for geonerf` export no source is ever sharp; for
nerfstudio no train image is. The exit status is 0 when the expectations hold, 1 when
one fails, 2 when the client's code could not run (its error is printed).

This file imports only the standard library and NumPy; the client's side runs the
same file with `--child` under PY.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

CLIENTS = ("ibrnet", "gnt", "nan", "deblur-nerf", "geonerf", "nerfstudio")
# Which export each client reads.
WANTS = {
    "ibrnet": ("llff",),
    "gnt": ("llff",),
    "nan": ("llff",),
    "deblur-nerf": ("llff",),
    "geonerf": ("geonerf", "llff"),  # llff: to show what --for geonerf avoids
    "nerfstudio": ("nerfstudio",),
}
SHARP = "sharp"
# Deblur-NeRF's config of one exported scene, as docs/training/deblur-nerf.md gives it:
# run_nerf.py's config_parser requires basedir, datadir and tbdir, and train() builds
# no kernel but deformablesparsekernel or none (its default, `kernel`, it refuses).
DEBLUR_NERF_CONFIG = (
    "expname = {scene}\nbasedir = {root}/logs\ntbdir = {root}/tensorboard\n"
    "datadir = {datadir}\ndataset_type = llff\nfactor = 4\nllffhold = {llffhold}\n"
    "kernel_type = deformablesparsekernel\n"
)


# --------------------------------------------------------------------------------------
# The parent: blurset's side (standard library + NumPy)


def _digest(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def _find_build(export: Path, doc: dict) -> Path | None:
    """The build an export of symlinks points into (a --copy export needs --build)."""
    for p in sorted(export.rglob("*")):
        if p.is_symlink():
            for parent in p.resolve().parents:
                if (parent / "dataset.json").is_file() and parent.name == doc["build"]:
                    return parent
    return None


def _level_digests(build: Path, level: str) -> set[str]:
    """The digests of a level's images (`setting/level` of the build), at every size."""
    lvl = build / level
    out = {_digest(p) for d in lvl.glob("images*") for p in d.glob("*.png")}
    if not out:
        raise SystemExit(f"check_clients: no images in {lvl}")
    return out


def _sharp_digests(build: Path, settings: set[str]) -> dict[str, set[str]]:
    """Per setting, the digests of its sharp level's images, at every size."""
    return {s: _level_digests(build, f"{s}/{SHARP}") for s in sorted(settings)}


def _scene_of(path: str, root: Path, keys: set[str]) -> str | None:
    """The export.json scene key of a scene folder (or a file in one) the client read."""
    p = Path(path)
    for cand in [p, *p.parents]:
        try:
            rel = cand.relative_to(root).as_posix()
        except ValueError:
            continue
        if rel in keys:
            return rel
    return None


class Verdict:
    def __init__(self) -> None:
        self.failed: list[str] = []

    def expect(self, ok: bool, what: str) -> str:
        if not ok:
            self.failed.append(what)
        return "ok" if ok else "FAILED"


def analyse(client: str, export: Path, doc: dict, build: Path, result: dict) -> tuple[str, int]:
    """The report, from what the client's code read (the child's result)."""
    scenes_root = export / doc["scenes_dir"] if doc["scenes_dir"] != "." else export
    keys = set(doc["scenes"])
    settings = {rel.split("/", 1)[0] for rel in doc["scenes"].values()}
    sharp = _sharp_digests(build, settings)
    digests: dict[str, str] = {}

    def is_sharp(path: str, key: str) -> bool:
        if path not in digests:
            digests[path] = _digest(Path(path))
        return digests[path] in sharp[doc["scenes"][key].split("/", 1)[0]]

    def degraded(key: str) -> bool:
        parts = doc["scenes"][key].split("/")
        return parts[1] != SHARP or len(parts) > 2  # a blur level, or a gain

    # A gain scene (an export with --noise) reads noisy images: one with the bytes of an
    # image of the build's own level (setting/level) is a noise-free copy.
    clean: dict[str, set[str]] = {}

    def gain(key: str) -> bool:
        return len(doc["scenes"][key].split("/")) > 2

    def is_noise_free(path: str, key: str) -> bool:
        level = "/".join(doc["scenes"][key].split("/")[:2])
        if level not in clean:
            clean[level] = _level_digests(build, level)
        if path not in digests:
            digests[path] = _digest(Path(path))
        return digests[path] in clean[level]

    lines = [
        f"check_clients: {client} on {export} (export for {doc['for']}, llffhold "
        f"{doc['llffhold']}, {len(doc['scenes'])} scenes: {len(doc['train'])} train, "
        f"{len(doc['test'])} test; sharp images from {build})",
        f"python: {result['python']} ({', '.join(f'{k} {v}' for k, v in result['versions'])})",
    ]
    lines += [f"ran: {r}" for r in result["ran"]]
    lines += [f"args: {result['args']}"] if result.get("args") else []
    # Scenes as the client read them.
    found = result["scenes"]
    unknown = [s["dir"] for s in found if _scene_of(s["dir"], scenes_root, keys) is None]
    v = Verdict()

    def summary(field: str) -> str:
        vals = sorted({json.dumps(s[field]) for s in found})
        return " | ".join(vals) if len(vals) <= 4 else f"{len(vals)} different"

    lines.append(
        f"scenes read: {len(found)}; images per scene {summary('images')}, poses "
        f"{summary('poses')}; image {summary('shape')} (H, W, C); focal {summary('focal')} px"
    )
    if unknown:
        lines.append(f"  not scenes of the export: {unknown[:3]} ({len(unknown)}) FAILED")
        v.failed.append("scenes outside the export")
    mismatch = [s["dir"] for s in found if s["images"] != s["poses"]]
    lines.append(f"  images = poses in every scene: {v.expect(not mismatch, 'images != poses')}")
    lines.append(f"  held-out views it chooses: {summary('held_out')}")
    for note in result.get("notes", []):
        lines.append(f"  note: {note}")
    # Checks the client's reader made of what else it read (depth, masks).
    for c in result.get("checks", []):
        lines.append(f"  {c['what']}: {c['detail']} ({v.expect(c['ok'], c['what'])})")
    # What each phase draws.
    for phase in result["phases"]:
        draws = phase["draws"]
        n_t = n_s = n_t_deg = n_s_deg = t_sharp = s_sharp = 0
        target_in_sources = 0
        scenes_with_sharp: set[str] = set()
        n_t_gain = n_s_gain = t_clean = s_clean = 0
        for d in draws:
            key = _scene_of(d["dir"], scenes_root, keys)
            if key is None:
                continue
            n_t += 1
            n_s += len(d["sources"])
            if d["target"] in d["sources"]:
                target_in_sources += 1
            if gain(key):
                n_t_gain += 1
                n_s_gain += len(d["sources"])
                t_clean += d["target"] is not None and is_noise_free(d["target"], key)
                s_clean += sum(is_noise_free(s, key) for s in d["sources"])
            if not degraded(key):
                continue
            n_t_deg += 1
            n_s_deg += len(d["sources"])
            t_sharp += d["target"] is not None and is_sharp(d["target"], key)
            k = sum(is_sharp(s, key) for s in d["sources"])
            s_sharp += k
            if k:
                scenes_with_sharp.add(key)
        held = sorted({json.dumps(d["target_index"]) for d in draws})
        lines.append(f"{phase['name']}:")
        lines.append(
            f"  {n_t} targets in {len({d['dir'] for d in draws})} scenes (target views "
            f"{', '.join(held) if len(held) <= 8 else f'{len(held)} different'}); "
            f"{n_s} sources drawn ({n_s / max(n_t, 1):.3g} a target)"
        )
        exp = dict(phase.get("expect", {}))
        if doc.get("test_view_images") not in ("sharp", "clean"):
            exp["targets_sharp"] = None  # held-out views degraded by the build's choice
        t_line = f"  degraded scenes: {n_t_deg} targets, {t_sharp} of them sharp"
        if exp.get("targets_sharp") is not None:
            want = n_t_deg if exp["targets_sharp"] else 0
            t_line += f" (expected {want}: {v.expect(t_sharp == want, phase['name'] + ' targets')})"
        lines.append(t_line)
        s_line = f"  degraded scenes: {n_s_deg} sources, {s_sharp} of them a sharp copy"
        if s_sharp:
            s_line += f" (in {len(scenes_with_sharp)} scenes)"
        if exp.get("sources_sharp") is not None:
            want_any = exp["sources_sharp"]
            ok = (s_sharp > 0) if want_any else (s_sharp == 0)
            s_line += (
                f" (expected {'some' if want_any else 'none'}: "
                f"{v.expect(ok, phase['name'] + ' sources')})"
            )
        lines.append(s_line)
        if n_t_gain:
            # Held-out targets stay clean (blurset noise keeps the test views clean):
            # judged by the sharp check above; every other image read is noisy.
            g_line = (
                f"  gain scenes: {n_t_gain} targets, {t_clean} of them noise-free; "
                f"{n_s_gain} sources, {s_clean} of them noise-free"
            )
            for what, n, judged in (
                ("targets", t_clean, exp.get("targets_sharp") is False),
                ("sources", s_clean, exp.get("sources_sharp") is False),
            ):
                if judged:
                    said = v.expect(n == 0, f"{phase['name']} noise-free {what}")
                    g_line += f" ({what} expected 0: {said})"
            lines.append(g_line)
        if target_in_sources:
            lines.append(f"  the target itself is among the sources in {target_in_sources} draws")
        for note in phase.get("notes", []):
            lines.append(f"  note: {note}")
    if v.failed:
        lines.append(f"verdict: FAILED ({'; '.join(v.failed)})")
        return "\n".join(lines), 1
    lines.append("verdict: ok")
    return "\n".join(lines), 0


def is_report(doc: object) -> bool:
    """Whether `doc` is what `--json` writes: a child's result (what a client read)."""
    return isinstance(doc, dict) and {"python", "versions", "ran", "scenes", "phases"} <= set(doc)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__.split("\n\n")[0], formatter_class=argparse.RawTextHelpFormatter
    )
    p.add_argument("client", choices=CLIENTS)
    p.add_argument("export", type=Path, help="the folder `blurset export --out` wrote")
    p.add_argument("--checkout", type=Path, required=True, help="the client's repository")
    p.add_argument("--python", required=True, help="a Python with the client's dependencies")
    p.add_argument("--build", type=Path, help="the build (found from the export's links)")
    p.add_argument("--nb-views", type=int, default=6, help="GeoNeRF's --nb_views (6)")
    p.add_argument("--json", type=Path, help="also write what the client read here")
    p.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.child:
        return child(*a.child)
    if a.json:
        # The parent side only: the child runs under the client's Python, without blurset.
        from blurset.exceptions import ConfigError
        from blurset.services.outputs import claim_report

        try:
            claim_report(a.json, is_report, "--json")
        except ConfigError as e:
            print(f"check_clients: {e}", file=sys.stderr)
            return 2
    export = a.export.resolve()
    try:
        doc = json.loads((export / "export.json").read_text())
        if not isinstance(doc, dict):
            raise ValueError("not a JSON object")
    except (OSError, ValueError) as e:
        why = e.strerror if isinstance(e, OSError) and e.strerror else str(e)
        print(
            f"check_clients: EXPORT is not a `blurset export` folder (its export.json: "
            f"{why}): {a.export}",
            file=sys.stderr,
        )
        return 2
    if not a.checkout.is_dir():
        print(f"check_clients: --checkout is not a directory: {a.checkout}", file=sys.stderr)
        return 2
    if doc.get("for") not in WANTS[a.client]:
        print(
            f"check_clients: {a.client} reads an export --for {' or '.join(WANTS[a.client])}, "
            f"this one is --for {doc.get('for')}: {export}",
            file=sys.stderr,
        )
        return 2
    if a.client in ("ibrnet", "gnt") and export.name != "data":
        # Their datasets read <rootdir>/data/nerf_llff_data/ and nothing else: an export
        # beside ROOT/data (ROOT/data_noisy, say) is never read by --rootdir ROOT.
        print(
            f"check_clients: {a.client} reads only <rootdir>/data/nerf_llff_data/, so an "
            f"export in {export.name}/ is never read: export into ROOT/data (blur + noise "
            f"scenes into a second root, ROOTN/data, read with --rootdir ROOTN): {a.export}",
            file=sys.stderr,
        )
        return 2
    build = a.build.resolve() if a.build else _find_build(export, doc)
    if build is None:
        print(
            "check_clients: give --build (the export has no links into a build: made with "
            "--copy, or from a noise output)",
            file=sys.stderr,
        )
        return 2
    params = {
        "client": a.client,
        "export": str(export),
        "checkout": str(a.checkout.resolve()),
        "doc": doc,
        "nb_views": a.nb_views,
    }
    # The child starts inside the checkout: a --python or --checkout given relative to
    # here must still name the same files there (a bare name like python3 is PATH's).
    python = str(Path(a.python).absolute()) if os.sep in a.python else a.python
    checkout = str(a.checkout.absolute())
    with tempfile.TemporaryDirectory(prefix="check_clients.") as tmp:
        pin, pout = Path(tmp) / "params.json", Path(tmp) / "result.json"
        pin.write_text(json.dumps(params))
        env = dict(os.environ, CUDA_VISIBLE_DEVICES="", PYTHONDONTWRITEBYTECODE="1")
        env.pop("PYTHONPATH", None)
        try:
            proc = subprocess.run(
                [python, str(Path(__file__).resolve()), a.client, str(export), "--checkout",
                 checkout, "--python", python, "--child", a.client, str(pin), str(pout)],
                cwd=checkout, env=env, capture_output=True, text=True,
            )  # fmt: skip
        except OSError as e:
            print(f"check_clients: --python {a.python}: {e.strerror or e}", file=sys.stderr)
            return 2
        if proc.returncode != 0 or not pout.exists():
            tail = "\n".join((proc.stdout + proc.stderr).strip().splitlines()[-12:])
            print(f"check_clients: {a.client}'s code failed (exit {proc.returncode}):\n{tail}")
            return 2
        result = json.loads(pout.read_text())
    if a.json:
        a.json.write_text(json.dumps(result, indent=1))
    report, status = analyse(a.client, export, doc, build, result)
    print(report)
    return status


# --------------------------------------------------------------------------------------
# The child: the client's side, under its own Python, cwd = its checkout


class _Reads:
    """A stand-in for a module (imageio, PIL.Image) that records the paths opened by one
    of its functions and otherwise is that module."""

    def __init__(self, module, name: str) -> None:
        self._module, self._name = module, name
        self.paths: list[str] = []

    def __getattr__(self, attr):
        fn = getattr(self._module, attr)
        if attr != self._name:
            return fn

        def recorded(path, *args, **kwargs):
            self.paths.append(os.path.abspath(os.fspath(path)))
            return fn(path, *args, **kwargs)

        return recorded

    def take(self) -> list[str]:
        out, self.paths = self.paths, []
        return out


def _versions(*names: str) -> list[tuple[str, str]]:
    import importlib
    import importlib.metadata

    out = []
    for n in names:
        mod = importlib.import_module(n)
        if hasattr(mod, "__version__"):
            out.append((n, str(mod.__version__)))
            continue
        try:
            out.append((n, importlib.metadata.version(n)))
        except importlib.metadata.PackageNotFoundError:  # imported from the checkout
            assert mod.__file__ is not None  # a module or a package's __init__, not a namespace
            out.append((n, f"from {Path(mod.__file__).parent.parent}"))
    return out


def _seed(i: int) -> None:
    import random

    import torch

    random.seed(i)
    np.random.seed(i)
    torch.manual_seed(i)


def _items(ds: Any, n: int, reads: _Reads) -> Iterator[tuple[int, Any, list[str]]]:
    """Items 0 to n - 1 of `ds`, each drawn with every RNG seeded by its index, with the
    files that drawing it opened."""
    for i in range(n):
        _seed(i)
        reads.take()
        item = ds[i]
        yield i, item, reads.take()


def _scene_lists(export: Path) -> list[str]:
    """The README's `--train_scenes $(cat train.txt) --eval_scenes $(cat test.txt)`."""
    argv = []
    for flag, name in (("--train_scenes", "train.txt"), ("--eval_scenes", "test.txt")):
        scenes = (export / name).read_text().split()
        argv += [flag, *scenes] if scenes else []
    return argv


def _ibrnet_like(p: dict, pkg: str, config: str) -> dict:
    """IBRNet and GNT: config.config_parser on the documented command line, then
    <pkg>.data_loaders.llff_test.LLFFTestDataset in train's 'train' and 'validation'
    modes, indexed as their DataLoader does."""
    import imageio
    from config import config_parser  # the client's config.py

    llff_test: Any = __import__(f"{pkg}.data_loaders.llff_test", fromlist=["x"])
    llff_utils = __import__(f"{pkg}.data_loaders.llff_data_utils", fromlist=["x"])
    export, doc = Path(p["export"]), p["doc"]
    notes = []
    argv = ["--config", config, "--rootdir", str(export.parent)]
    argv += ["--train_dataset", "llff_test", "--eval_dataset", "llff_test"]
    argv += _scene_lists(export)
    argv += ["--llffhold", str(doc["llffhold"])]
    args = config_parser().parse_args(argv)
    if getattr(args, "distributed", False):
        notes.append(
            f"{config} sets distributed = True: a single-GPU `python train.py` needs "
            "distributed = False in the config (or torch.distributed.launch)"
        )
    reads = _Reads(imageio, "imread")
    llff_test.imageio = reads
    scenes = []
    for name in sorted(os.listdir(export.parent / "data" / "nerf_llff_data")):
        d = export / "nerf_llff_data" / name
        _, poses, bds, _, _, rgb_files = llff_utils.load_llff_data(
            str(d), load_imgs=False, factor=4
        )
        intr, _ = llff_utils.batch_parse_llff_poses(poses)
        shape = list(imageio.imread(rgb_files[0]).shape)
        scenes.append({
            "dir": str(d), "images": len(rgb_files), "poses": int(poses.shape[0]), "shape": shape,
            "focal": round(float(intr[0][0, 0]), 2),
            "held_out": np.arange(poses.shape[0])[:: args.llffhold].tolist(),
        })  # fmt: skip
    phases = []
    for mode, scene_list, expect in (
        ("validation", args.eval_scenes, {"targets_sharp": True, "sources_sharp": False}),
        ("train", args.train_scenes, {"targets_sharp": False, "sources_sharp": False}),
    ):
        ds = llff_test.LLFFTestDataset(args, mode, scenes=scene_list)
        draws = []
        for i, item, opened in _items(ds, len(ds.render_rgb_files), reads):
            target, sources = opened[0], opened[1:]
            files = ds.render_rgb_files[i]
            draws.append({
                "dir": str(Path(files).parent.parent), "target": target, "sources": sources,
                "target_index": int(Path(files).stem) if Path(files).stem.isdigit() else files,
                "shapes": [list(item["rgb"].shape), list(item["src_rgbs"].shape)],
            })  # fmt: skip
        shapes = sorted({json.dumps(d["shapes"]) for d in draws})
        phases.append({
            "name": f"{pkg} LLFFTestDataset(args, '{mode}', scenes=--"
            f"{'eval' if mode == 'validation' else 'train'}_scenes)",
            "draws": draws, "expect": expect,
            "notes": [f"rgb, src_rgbs shapes: {' | '.join(shapes)}"],
        })  # fmt: skip
    return {
        "ran": [
            f"{config_parser.__module__}.py config_parser({' '.join(argv[:6])} … --llffhold "
            f"{args.llffhold})",
            f"{pkg}/data_loaders/llff_data_utils.py load_llff_data(factor=4), "
            "batch_parse_llff_poses",
            f"{pkg}/data_loaders/llff_test.py LLFFTestDataset.__getitem__ for every target",
        ],
        "args": f"llffhold {args.llffhold}, num_source_views {args.num_source_views}, "
        f"rootdir {args.rootdir}",
        "versions": _versions("torch", "imageio", "numpy"),
        "scenes": scenes,
        "phases": phases,
        "notes": notes,
    }


def _nan(p: dict) -> dict:
    """NAN: its CustomArgumentParser on configs/train.yml with the documented options,
    then nan.dataloaders.llff_data.LLFFTestDataset in Mode.train (training) and
    Mode.test (eval/init_eval.py), with include_target as the config sets it and off."""
    import copy

    import imageio
    from configs.config import CustomArgumentParser
    from configs.local_setting import DATA_DIR
    from nan.dataloaders import basic_dataset, llff_data
    from nan.dataloaders.basic_dataset import Mode

    export, doc = Path(p["export"]), p["doc"]
    if Path(DATA_DIR).resolve() != export:
        raise SystemExit(
            f"NAN reads DATA_DIR/nerf_llff_data/ with DATA_DIR = {DATA_DIR} (configs/"
            f"local_setting.py: the data/ folder beside its checkout), not {export}"
        )
    argv = ["--config", "configs/train.yml", "--train_dataset", "llff_test"]
    argv += ["--eval_dataset", "llff_test", "--llffhold", str(doc["llffhold"])]
    argv += _scene_lists(export)
    argv += ["--eval_gain", "0"]
    args = CustomArgumentParser.config_parser().parse_args(args=argv)
    reads = _Reads(imageio, "imread")
    basic_dataset.imageio = reads  # BurstDataset.read_image
    scenes = []
    for d in sorted((export / "nerf_llff_data").iterdir()):
        _, poses, _, _, _, rgb_files = llff_data.load_llff_data(
            d, load_imgs=False, factor=args.factor
        )
        intr, _ = llff_data.batch_parse_llff_poses(poses)
        scenes.append({
            "dir": str(d), "images": len(rgb_files), "poses": int(poses.shape[0]),
            "shape": list(imageio.imread(rgb_files[0]).shape),
            "focal": round(float(intr[0][0, 0]), 2),
            "held_out": np.arange(poses.shape[0])[:: args.llffhold].tolist(),
        })  # fmt: skip
    phases = []
    configured = bool(args.include_target)
    runs = [
        (Mode.test, args.eval_scenes, configured),
        (Mode.test, args.eval_scenes, False),
        (Mode.train, args.train_scenes, configured),
    ]
    for mode, scene_list, include in runs:
        a = copy.copy(args)
        a.include_target = include
        ds = llff_data.LLFFTestDataset(a, mode, scenes=scene_list)
        draws = []
        for i, item, opened in _items(ds, len(ds.render_rgb_files), reads):
            f = Path(ds.render_rgb_files[i])
            draws.append({
                "dir": str(f.parent.parent), "target": opened[0], "sources": opened[1:],
                "target_index": int(f.stem) if f.stem.isdigit() else str(f),
                "shapes": [list(item["rgb"].shape), list(item["src_rgbs"].shape)],
            })  # fmt: skip
        eval_ = mode is Mode.test
        # With include_target the target's own image is a source: reported, not judged.
        expect = {"targets_sharp": eval_, "sources_sharp": None if eval_ and include else False}
        shapes = sorted({json.dumps(d["shapes"]) for d in draws})
        notes = [f"rgb, src_rgbs shapes: {' | '.join(shapes)}"]
        if eval_ and include:
            notes.append(
                "include_target puts the target's own image first among the sources "
                "(burst denoising): in a blur level that is the sharp image"
            )
        phases.append({
            "name": f"NAN LLFFTestDataset(args, {mode}, scenes=--"
            f"{'eval' if eval_ else 'train'}_scenes), include_target "
            f"{include}{' (configs/train.yml)' if include == configured else ''}",
            "draws": draws, "expect": expect, "notes": notes,
        })  # fmt: skip
    return {
        "ran": [
            f"configs/config.py CustomArgumentParser.config_parser().parse_args("
            f"{' '.join(argv[:8])} … --eval_gain 0)",
            "nan/dataloaders/llff_data_utils.py load_llff_data(factor=args.factor), "
            "batch_parse_llff_poses",
            "nan/dataloaders/llff_data.py LLFFTestDataset.__getitem__ for every target",
        ],
        "args": f"llffhold {args.llffhold}, factor {args.factor}, num_source_views "
        f"{args.num_source_views}, include_target {configured} (train.yml), eval_gain 0 "
        f"(train.yml's {16}: needs KPN's noise file in DATA_DIR)",
        "versions": _versions("torch", "imageio", "numpy"),
        "scenes": scenes,
        "phases": phases,
        "notes": [f"DATA_DIR = {DATA_DIR}"],
    }


def _deblur_nerf(p: dict) -> dict:
    """Deblur-NeRF: run_nerf.config_parser on a scene config with the documented keys,
    load_llff.load_llff_data as run_nerf.train() calls it, and train()'s hold-out rule
    (i_test = arange(N)[::llffhold], i_train the rest), per exported scene."""
    import imageio
    import load_llff
    from run_nerf import config_parser

    export, doc = Path(p["export"]), p["doc"]
    reads = _Reads(imageio, "imread")
    load_llff.imageio = reads
    scenes, draws = [], []
    tmp = Path(tempfile.mkdtemp(prefix="deblur_cfg."))
    for d in sorted((export / "nerf_llff_data").iterdir()):
        cfg = tmp / f"{d.name}.txt"
        cfg.write_text(
            DEBLUR_NERF_CONFIG.format(scene=d.name, root=tmp, datadir=d, llffhold=doc["llffhold"])
        )
        args = config_parser().parse_args(["--config", str(cfg)])
        reads.take()
        images, poses, bds, _, _ = load_llff.load_llff_data(
            args, args.datadir, args.factor, recenter=True, bd_factor=0.75,
            spherify=args.spherify, path_epi=args.render_epi,
        )  # fmt: skip
        files = reads.take()[-images.shape[0] :]  # the last N reads are imgs in order
        hwf = poses[0, :3, -1]
        i_test = np.arange(images.shape[0])[:: args.llffhold]
        i_train = [i for i in range(images.shape[0]) if i not in i_test]
        scenes.append({
            "dir": str(d), "images": int(images.shape[0]), "poses": int(poses.shape[0]),
            "shape": list(images.shape[1:]), "focal": round(float(hwf[2]), 2),
            "held_out": i_test.tolist(),
        })  # fmt: skip
        for t in i_test:
            draws.append({
                "dir": str(d), "target": files[t], "sources": [files[i] for i in i_train],
                "target_index": int(t),
            })  # fmt: skip
    return {
        "ran": [
            "run_nerf.py config_parser() on a config: dataset_type = llff, factor = 4, "
            f"llffhold = {doc['llffhold']}",
            "load_llff.py load_llff_data(args, datadir, factor, recenter=True, "
            "bd_factor=.75) as run_nerf.train() calls it (images read with "
            "imageio.imread(…, ignoregamma=True))",
            "run_nerf.train()'s split, restated: i_test = arange(N)[::llffhold]",
        ],
        "versions": _versions("imageio", "numpy"),
        "scenes": scenes,
        "phases": [
            {
                "name": "Deblur-NeRF per scene: test views (targets) and the train views it "
                "fits (sources)",
                "draws": draws,
                "expect": {"targets_sharp": True, "sources_sharp": False},
            }
        ],  # fmt: skip
    }


def _geonerf(p: dict) -> dict:
    """GeoNeRF: utils.options.config_parser on configs/config_general.txt with the
    export's paths, data.get_datasets.get_validation_dataset (what training validates
    on and --eval renders) and the LLFF_Dataset that get_training_dataset builds from
    llff_path; every target of each is indexed, and the images its model takes as
    sources are the first nb_views that __getitem__ stacks (run_geo_nerf.py slices
    batch["images"][:, :nb_views])."""
    import data.llff as llff
    import PIL.Image
    from data.get_datasets import get_validation_dataset
    from utils.options import config_parser

    export, doc = Path(p["export"]), p["doc"]
    nb = int(p["nb_views"])
    top_notes = [
        "GeoNeRF resizes every image to 960 x 720 (downSample 1.0) and scales fx, fy by the ratios"
    ]
    if doc["for"] == "geonerf":
        train_root, test_root = export / "geonerf" / "train", export / "geonerf" / "test"
    else:  # a plain LLFF export: one folder of scenes for both, judged the same way
        train_root = test_root = export / "nerf_llff_data"
        top_notes.append(
            "a plain LLFF export: GeoNeRF holds out every 8th image and draws sources from "
            "all the others (blurset export --for geonerf writes scenes where it cannot)"
        )
    argv = ["run_geo_nerf.py", "--config", "configs/config_general.txt"]
    argv += ["--llff_path", str(train_root), "--llff_test_path", str(test_root)]
    argv += ["--nb_views", str(nb)]
    sys.argv = argv
    args = config_parser()
    reads = _Reads(PIL.Image, "open")
    llff.Image = reads
    val = get_validation_dataset(args)
    train = llff.LLFF_Dataset(
        root_dir=args.llff_path, split="train", max_len=-1, downSample=1.0,
        nb_views=args.nb_views, imgs_folder_name="images_4",
    )  # fmt: skip
    scenes = []
    for ds, root in (
        ((train, train_root), (val, test_root)) if train_root != test_root else ((val, test_root),)
    ):
        for scan in ds.scans:
            files = ds.image_paths[scan]
            rows = np.load(root / scan / "poses_bounds.npy")
            scenes.append({
                "dir": str(root / scan), "images": len(files), "poses": int(rows.shape[0]),
                "shape": [int(ds.img_wh[1]), int(ds.img_wh[0]), 3],
                "focal": [round(float(f), 2) for f in (ds.intrinsics[scan][0][0, 0],
                                                         ds.intrinsics[scan][0][1, 1])],
                "held_out": list(range(0, len(files), 8)),
            })  # fmt: skip
    phases = []
    for name, ds, expect in (
        (
            f"GeoNeRF get_validation_dataset(args) (split val, llff_test_path), nb_views {nb}",
            val,
            {"targets_sharp": True, "sources_sharp": False},
        ),
        (
            f"GeoNeRF LLFF_Dataset(llff_path, split train) as get_training_dataset builds "
            f"it, nb_views {nb}",
            train,
            {"sources_sharp": False},
        ),
    ):
        draws = []
        # Every target (validation's __len__ stops at 2); `opened`: the sources in their
        # order, then the target.
        for i, item, opened in _items(ds, len(ds.meta), reads):
            scan, t = ds.meta[i]["scan"], ds.meta[i]["target_idx"]
            draws.append({
                "dir": str(Path(ds.root_dir) / scan), "target": opened[-1],
                "sources": opened[:-1][:nb] if len(opened) - 1 >= nb else opened[:nb],
                "target_index": int(t), "shape": list(item["images"].shape),
            })  # fmt: skip
        shapes = sorted({json.dumps(d["shape"]) for d in draws})
        notes = [f"images stacked per item: {' | '.join(shapes)} (sources…, target)"]
        if ds is val:
            notes.append(
                f"len(dataset) = {len(ds)} (max_len {ds.max_len}: with scene None GeoNeRF "
                f"validates on the first {len(ds)} items; {len(ds.meta)} targets in all)"
            )
            every = get_validation_dataset(argparse.Namespace(**{**vars(args), "scene": "*"}))
            notes.append(
                f"with --scene '*' (a glob to LLFF_Dataset) len(dataset) = {len(every)}: every "
                f"target of the {len(every.scans)} scenes"
            )
        phases.append({"name": name, "draws": draws, "expect": expect, "notes": notes})
    return {
        "ran": [
            f"utils/options.py config_parser() with {' '.join(argv[1:])}",
            "data/get_datasets.py get_validation_dataset(args); data/llff.py "
            "LLFF_Dataset(args.llff_path, 'train', downSample=1.0, imgs_folder_name="
            "'images_4'); LLFF_Dataset.__getitem__ for every target (sources from "
            "utils/utils.py get_nearest_pose_ids)",
        ],
        "versions": _versions("torch", "kornia", "numpy", "PIL"),
        "scenes": scenes,
        "phases": phases,
        "notes": top_notes,
    }  # fmt: skip


def _nerfstudio(p: dict) -> dict:
    """nerfstudio: NerfstudioDataParserConfig(data=scene, center_method="focus"[,
    downscale_factor=4]).setup().get_dataparser_outputs(split) for train, val and test,
    and InputDataset(outputs)[0] to read an image, per exported scene."""
    import torch
    from nerfstudio.data.dataparsers.nerfstudio_dataparser import NerfstudioDataParserConfig
    from nerfstudio.data.datasets.base_dataset import InputDataset

    export, doc = Path(p["export"]), p["doc"]
    scenes, phases = [], []
    notes: list[str] = []
    checks: list[dict] = []
    for df in (None, 4):
        draws, axis_miss = [], []
        for key in sorted(doc["scenes"]):
            d = export / key
            cfg = NerfstudioDataParserConfig(data=d, center_method="focus", downscale_factor=df)
            parser = cfg.setup()
            out = {s: parser.get_dataparser_outputs(split=s) for s in ("train", "val", "test")}
            image = InputDataset(out["train"])[0]["image"]
            if doc.get("passes"):
                checks += _nerfstudio_passes(d, out["train"], df, doc["passes"])
            cams = out["train"].cameras
            c2w = cams.camera_to_worlds.to(torch.float64)
            o, ax = c2w[:, :3, 3], -c2w[:, :3, 2]  # OpenGL: the camera looks along -z
            miss = torch.linalg.norm(o - (o * ax).sum(-1, keepdim=True) * ax, dim=-1)
            axis_miss.append(float(miss.max() / o.norm(dim=-1).mean()))
            train = [str(f) for f in out["train"].image_filenames]
            if df is None:
                scenes.append({
                    "dir": str(d), "images": len(train) + len(out["val"].image_filenames),
                    "poses": int(cams.shape[0]) + int(out["val"].cameras.shape[0]),
                    "shape": list(image.shape), "focal": round(float(cams.fx[0]), 2),
                    "held_out": [int(Path(f).stem) for f in out["val"].image_filenames],
                })  # fmt: skip
            for split in ("val", "test"):
                for f in out[split].image_filenames:
                    draws.append({
                        "dir": str(d), "target": str(f), "sources": train,
                        "target_index": f"{split} {Path(f).parent.name}/{Path(f).name}",
                        "shape": list(image.shape),
                    })  # fmt: skip
        shapes = sorted({json.dumps(x["shape"]) for x in draws})
        phases.append({
            "name": f"nerfstudio-data --center-method focus"
            f"{f' --downscale-factor {df}' if df else ''}: val and test images (targets), "
            "train images (sources)",
            "draws": draws, "expect": {"targets_sharp": True, "sources_sharp": False},
            "notes": [
                f"InputDataset image: {' | '.join(shapes)}",
                f"optical axes pass the origin within {max(axis_miss):.1e} of the camera "
                "distance (the object centred by focus)",
            ],
        })  # fmt: skip
    return {
        "ran": [
            "nerfstudio/data/dataparsers/nerfstudio_dataparser.py NerfstudioDataParserConfig"
            "(data=scene, center_method='focus', downscale_factor=None | 4).setup()"
            ".get_dataparser_outputs('train' | 'val' | 'test')",
            "nerfstudio/data/datasets/base_dataset.py InputDataset(outputs)[0]",
            *(
                ["nerfstudio/data/datasets/depth_dataset.py DepthDataset(outputs)[0]"]
                if doc.get("passes")
                else []
            ),
        ],
        "versions": _versions("nerfstudio", "torch", "imageio", "numpy"),
        "scenes": scenes,
        "phases": phases,
        "notes": notes,
        "checks": _merge_checks(checks),
    }


def _nerfstudio_passes(d: Path, outputs, df: int | None, passes: list[str]) -> list[dict]:
    """nerfstudio's DepthDataset item of a scene's first train image: its depth (over
    the parser's scale) against blurset's depth EXR of that view at that size, read by
    OpenCV; its mask against the EXR's surface pixels."""
    os.environ.setdefault("OPENCV_IO_ENABLE_OPENEXR", "1")  # before OpenCV's first EXR
    import cv2
    import numpy as np
    from nerfstudio.data.datasets.depth_dataset import DepthDataset

    item = DepthDataset(outputs)[0]
    name = Path(outputs.image_filenames[0]).name
    sub = "depth" if df is None else f"depth_{df}"
    truth = cv2.imread(str(d / sub / Path(name).with_suffix(".exr")), cv2.IMREAD_ANYDEPTH)
    checks = []
    if "depth" in passes:
        depth = item["depth_image"][..., 0].numpy() / float(outputs.dataparser_scale)
        err = float(np.abs(depth - truth).max())
        checks.append({"what": "DepthDataset depth_image / dataparser_scale = blurset's depth "
                       "EXR (world units)", "ok": err <= 6e-4, "err": err})  # fmt: skip
    if "mask" in passes:
        agree = float((item["mask"][..., 0].numpy() == (truth > 0)).mean())
        checks.append({"what": "InputDataset mask = the pixels with depth", "ok": agree >= 0.9,
                       "agree": agree})  # fmt: skip
    return checks


def _merge_checks(checks: list[dict]) -> list[dict]:
    """One line per kind of check: all must hold; the worst value found."""
    out = []
    for what in dict.fromkeys(c["what"] for c in checks):
        cs = [c for c in checks if c["what"] == what]
        ok = all(c["ok"] for c in cs)
        if "err" in cs[0]:
            detail = f"largest difference {max(c['err'] for c in cs):.2g} in {len(cs)} scenes"
        else:
            detail = f"lowest agreement {min(c['agree'] for c in cs):.3f} in {len(cs)} scenes"
        out.append({"what": what, "ok": ok, "detail": detail})
    return out


def child(client: str, params: str, out: str) -> int:
    p = json.loads(Path(params).read_text())
    checkout = p["checkout"]
    here = str(Path(__file__).resolve().parent)
    sys.path[:] = [checkout] + [s for s in sys.path if s not in ("", here)]
    os.chdir(checkout)
    run = {
        "ibrnet": lambda: _ibrnet_like(p, "ibrnet", "configs/pretrain.txt"),
        "gnt": lambda: _ibrnet_like(p, "gnt", "configs/gnt_llff.txt"),
        "nan": lambda: _nan(p),
        "deblur-nerf": lambda: _deblur_nerf(p),
        "geonerf": lambda: _geonerf(p),
        "nerfstudio": lambda: _nerfstudio(p),
    }[client]
    result = run()
    result["python"] = f"{sys.executable} {sys.version.split()[0]}"
    Path(out).write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
