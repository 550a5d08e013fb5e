"""`blurset export --for hub` at scale (issue 50): 1,000 settings at 128 px.

Files: a build of the three demo objects by the stand-in worker (tests/standin_worker.py:
real orchestration, analytic images) at 128 px, 34 views, levels sharp, blur_1, blur_4
and images_4/ copies, its settings cloned (hard links, each clone's meta.json, dataset.json,
splits.json and MANIFEST.sha256 rewritten as a build would write them) to SETTINGS
settings: ~200,000 PNG files, the file count the Hub handles badly.

Contender: `blurset export BUILD --for hub --shard-size SHARD_MB` in a subprocess (the
whole command: plan, shard keys, every shard written and hashed). Baseline: copying the
same files (shutil.copytree of every level's images and images_4/, the files the shards
hold) from the page cache; both after a warm-up read. The ratio is copy time / export
time (above 1: the export is faster than copying the files).

Against the whole build (`hub_export_vs_cp_build`, SMALL_SETTINGS settings, the size a
user measured at): `cp -r BUILD` (every file of the build, what a user copying it would
copy), `shutil.copytree` of the image folders and the export, one after the other in
each of SMALL_REPEATS rounds, the medians side by side. `BLURSET_BENCH_HUB=small` runs
this comparison only.

Memory: one more export with BIG_SHARD_MB shards, its peak RSS (ru_maxrss of the
process) above that of an idle process importing the same modules, against the largest
shard it wrote (`ratio` above 1: no whole shard was ever held), and the peak RSS of the
small-shard runs beside it (the same: memory does not grow with the shard size).
"""

from __future__ import annotations

import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

SETTINGS = 1_000
SHARD_MB = 20
# The memory run: shards ten times larger; a peak memory that does not grow with them
# (and stays below one shard) holds no whole shard.
BIG_SHARD_MB = 200
REPEATS = 2
SMALL_SETTINGS = 100
SMALL_REPEATS = 5
BUILD_ARGS = (
    "--demo", "--views", "34", "--levels", "1,4", "--latents", "2", "--samples", "2",
    "--resolution", "128", "--settings-per-object", "2", "--quiet",
)  # fmt: skip


def _blurset(*args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "blurset.cli", *args],
        capture_output=True,
        text=True,
        check=True,
        env=dict(os.environ, **(env or {})),
    )


def make_build(work: Path, n: int) -> Path:
    """A finished build of `n` settings: the stand-in's six, cloned."""
    from blurset import layout
    from blurset.services import outputs, publish

    blender = work / "blender"
    script = ROOT / "tests" / "standin_worker.py"
    blender.write_text(f'#!/bin/sh\nexec "{sys.executable}" "{script}" "$@"\n')
    blender.chmod(0o755)
    b = work / "b"
    _blurset("build", *BUILD_ARGS, "--blender", str(blender), "--out", str(b))
    seeds = layout.complete_settings(b)
    dataset = outputs.read_record(b / layout.DATASET)
    splits = outputs.read_record(b / layout.SPLITS)
    names = [s.name for s in seeds]
    test = set(splits["test"])
    for k in range(n - len(seeds)):
        src = seeds[k % len(seeds)]
        meta = json.loads((src / layout.META).read_text())
        uid = f"{meta['uid']}{k // len(seeds):04d}"
        name = layout.setting_name(uid, meta["theta0_deg"])
        dst = b / name
        subprocess.run(["cp", "-al", str(src), str(dst)], check=True)
        meta["uid"] = uid
        os.unlink(dst / layout.META)  # a link to the source's: a file of its own
        layout.write_json(dst / layout.META, meta)
        names.append(name)
        if src.name in test:
            test.add(name)
        splits["test_views"][name] = splits["test_views"][src.name]
    names.sort()
    splits["train"] = [s for s in names if s not in test]
    splits["test"] = [s for s in names if s in test]
    dataset["settings"] = names
    views = len(json.loads((seeds[0] / layout.META).read_text())["views"])
    dataset["counts"]["settings"] = len(names)
    dataset["counts"]["objects"] = len({s.rsplit("_", 1)[0] for s in names})
    dataset["counts"]["images"] = len(names) * views * len(dataset["levels"])
    layout.write_json(b / layout.SPLITS, splits)
    layout.write_json(b / layout.DATASET, dataset)
    publish.write_manifest(b)
    outputs.finished_build(b)  # the export would refuse it otherwise
    return b


def image_dirs(b: Path) -> list[Path]:
    return sorted(d for d in b.glob("*/*/images*") if d.is_dir())


def copy_files(b: Path, dst: Path) -> None:
    for d in image_dirs(b):
        shutil.copytree(d, dst / d.relative_to(b))


def warm(b: Path) -> int:
    """Read every image once (the page cache holds them for both sides); the bytes."""
    n = 0
    for d in image_dirs(b):
        for p in d.iterdir():
            n += len(p.read_bytes())
    return n


def timed_export(b: Path, out: Path, shard_mb: int) -> tuple[float, float]:
    """Seconds and peak RSS (MB) of one `blurset export --for hub` process."""
    cmd = [sys.executable, "-m", "blurset.cli", "export", str(b), "--for", "hub",
           "--out", str(out), "--shard-size", str(shard_mb)]  # fmt: skip
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    dt = time.perf_counter() - t0
    code = os.waitstatus_to_exitcode(status)
    if code != 0:
        raise RuntimeError(f"blurset export exited {code}")
    return dt, usage.ru_maxrss / 1024  # Linux: KB


def idle_rss_mb() -> float:
    """Peak RSS of a process that imports what the export imports and does nothing."""
    code = "import blurset.cli, blurset.commands.export.cli, blurset.commands.export.hub, pyarrow.parquet"
    proc = subprocess.Popen([sys.executable, "-c", code])
    _, _, usage = os.wait4(proc.pid, 0)
    return usage.ru_maxrss / 1024


def against_the_build() -> dict:
    """The export against `cp -r` of the build and a copy of its image folders, side by
    side, at SMALL_SETTINGS settings: medians of SMALL_REPEATS rounds."""
    work = Path(tempfile.mkdtemp(prefix="bench-hub-small-"))
    try:
        b = make_build(work, SMALL_SETTINGS)
        total = warm(b)
        build_files = sum(len(fs) for _, _, fs in os.walk(b))
        build_bytes = sum(p.stat().st_size for p in b.rglob("*") if p.is_file())
        t: dict[str, list[float]] = {"cp_r": [], "images": [], "export": []}
        for _ in range(SMALL_REPEATS):
            t0 = time.perf_counter()
            subprocess.run(["cp", "-r", str(b), str(work / "cp")], check=True)
            t["cp_r"].append(time.perf_counter() - t0)
            t0 = time.perf_counter()
            copy_files(b, work / "images")
            t["images"].append(time.perf_counter() - t0)
            t["export"].append(timed_export(b, work / "hub", SHARD_MB)[0])
            for d in ("cp", "images", "hub"):
                shutil.rmtree(work / d)
        med = {k: statistics.median(v) for k, v in t.items()}
        return {
            "name": "hub_export_vs_cp_build",
            "ratio": med["cp_r"] / med["export"],
            "ratio_is": "cp -r of the build's time / the export's (above 1: the export is faster)",
            "contender": f"blurset export --for hub ({SMALL_SETTINGS} settings, 128 px)",
            "baseline": "cp -r of the whole build",
            "export_s": med["export"],
            "cp_r_s": med["cp_r"],
            "copy_images_s": med["images"],
            "images_ratio": med["images"] / med["export"],
            "runs_s": t,
            # The least loaded round of each side: a shared machine's load swings a median.
            "fastest_s": {k: min(v) for k, v in t.items()},
            "settings": SMALL_SETTINGS,
            "build_files": build_files,
            "build_megabytes": build_bytes / 1e6,
            "image_megabytes": total / 1e6,
            "repeats": SMALL_REPEATS,
        }
    finally:
        shutil.rmtree(work, ignore_errors=True)


def run() -> list[dict]:
    small = against_the_build()
    if os.environ.get("BLURSET_BENCH_HUB") == "small":
        return [small]
    return [small, *at_scale()]


def at_scale() -> list[dict]:
    work = Path(tempfile.mkdtemp(prefix="bench-hub-"))
    try:
        idle = idle_rss_mb()
        b = make_build(work, SETTINGS)
        total = warm(b)
        files = sum(len(os.listdir(d)) for d in image_dirs(b))
        t_export, t_copy, rss = [], [], []
        shards = 0
        for i in range(REPEATS):
            c = work / f"copy{i}"
            t0 = time.perf_counter()
            copy_files(b, c)
            t_copy.append(time.perf_counter() - t0)
            shutil.rmtree(c)
            dt, peak = timed_export(b, work / f"hub{i}", SHARD_MB)
            t_export.append(dt)
            rss.append(peak)
            shards = len(json.loads((work / f"hub{i}" / "export.json").read_text())["shards"])
            shutil.rmtree(work / f"hub{i}")
        _, big_peak = timed_export(b, work / "big", BIG_SHARD_MB)
        doc = json.loads((work / "big" / "export.json").read_text())
        biggest = max(r["bytes"] for r in doc["shards"].values()) / 1e6
        te, tc = statistics.median(t_export), statistics.median(t_copy)
        return [
            {
                "name": "hub_export_vs_copy",
                "ratio": tc / te,
                "contender": f"blurset export --for hub ({SETTINGS} settings, 128 px)",
                "baseline": "copying the same image files",
                "export_s": te,
                "copy_s": tc,
                "settings": SETTINGS,
                "files": files,
                "megabytes": total / 1e6,
                "shards": shards,
                "shard_mb": SHARD_MB,
                "repeats": REPEATS,
            },
            {
                "name": "hub_export_memory",
                "ratio": biggest / max(big_peak - idle, 1e-9),
                "contender": "blurset export --for hub: peak RSS above an idle process "
                f"({SETTINGS} settings, {BIG_SHARD_MB} MB shards)",
                "baseline": "the largest shard written",
                "peak_rss_mb": big_peak,
                "peak_rss_small_shards_mb": max(rss),
                "idle_rss_mb": idle,
                "growth_mb": big_peak - idle,
                "shard_mb": BIG_SHARD_MB,
                "small_shard_mb": SHARD_MB,
                "largest_shard_mb": biggest,
                "settings": SETTINGS,
            },
        ]
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    for r in run():
        print(json.dumps(r))
