"""How small a scene can `blurset check-poses` still judge? Measured, not assumed.

Renders real builds of the demo GLBs (vase, box) at several image sizes with 34 views,
runs the real pycolmap pipeline of check-poses on the first k views (k = 8 … 34; the
views are i.i.d. draws in the ±7.5° window, so the first k are a random k-view scene),
and plants a 5° rotation error in each registered view in turn, about the camera's x
(tilt), y (pan) and z (roll, the optical axis). COLMAP sees only the images, so its model
is the same whatever our poses say: one COLMAP run per scene serves every planted error,
and each planted error is judged exactly as check-poses judges a scene.

    python bench/check_poses_sensitivity.py [--work DIR] [--sizes 64,96,…] [--views 8,12,…]

Writes bench/check_poses_sensitivity.json and prints the table. Each size (its render
and its checks) runs under the machine's Blender lock (`flock /work/.blender.lock`)
where it exists; a size already measured (WORK/rows_<size>.json) is not measured again.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
OBJECTS = ("demo_vase", "demo_box")
LEVELS = ("sharp", "blur_1", "blur_3")
LOCK = Path("/work/.blender.lock")


def _locked(cmd: list[str]) -> list[str]:
    """One size at a time under the machine's Blender lock, where there is one."""
    return ["flock", str(LOCK), *cmd] if LOCK.exists() and shutil.which("flock") else cmd


def render(work: Path, size: int) -> Path:
    """A build of the demo vase and box at `size` px, 34 views, levels 1 and 3 (demo
    defaults otherwise: 6 latent frames, 4 samples); resumed if it exists."""
    from blurset.services.demo import make_demo_objects

    # Made once: a build resumes only with the very files it was made from.
    objects = sorted((work / "objects").glob("demo_*.glb")) or make_demo_objects(
        work / "objects", seed=0
    )
    out = work / f"build_{size}"
    glbs = [str(p) for p in objects if p.stem in OBJECTS]
    cmd = [
        sys.executable, "-m", "blurset.cli", "build", "--objects", *glbs, "--out", str(out),
        "--views", "34", "--levels", "1,3", "--latents", "6", "--samples", "4",
        "--resolution", str(size), "--settings-per-object", "1", "--downsample", "none",
        "--quiet",
    ]  # fmt: skip
    subprocess.run(cmd, check=True, cwd=ROOT)
    return out


def subset_scene(setting: Path, level: str, k: int, dst: Path) -> Path:
    """The first k views of one level as a scene of its own (images linked, poses and
    meta.json cut to k views), laid out as a build setting so check-poses reads the
    mean latent poses of a blur level."""
    scene = dst / setting.name / level
    if scene.exists():
        shutil.rmtree(scene.parent)
    (scene / "images").mkdir(parents=True)
    names = sorted(p.name for p in (setting / level / "images").iterdir())[:k]
    for n in names:
        os.symlink(setting / level / "images" / n, scene / "images" / n)
    pb = np.load(setting / level / "poses_bounds.npy")[:k]
    np.save(scene / "poses_bounds.npy", pb)
    meta = json.loads((setting / "meta.json").read_text())
    meta["views"] = meta["views"][:k]
    meta["test_views"] = [i for i in meta["test_views"] if i < k]
    (scene.parent / "meta.json").write_text(json.dumps(meta))
    return scene


def measure(work: Path, sizes: list[int], view_counts: list[int]) -> list[dict]:
    rows = []
    for size in sizes:
        build = render(work, size)
        for obj in OBJECTS:
            setting = next(build.glob(f"{obj}_*"))
            for level in LEVELS:
                for k in view_counts:
                    scene = subset_scene(setting, level, k, work / "subsets")
                    t = time.perf_counter()
                    report = work / "report.json"
                    cmd = [sys.executable, "-c", _ONE, str(scene), str(report)]
                    subprocess.run(cmd, check=True, capture_output=True, cwd=ROOT)
                    r = json.loads(report.read_text())
                    planted = r.get("planted") or {}
                    row = {
                        "object": obj,
                        "size_px": size,
                        "views": k,
                        "level": level,
                        "verdict": r["verdict"],
                        "registered": r["registered"],
                        "consistent": r.get("consistent"),
                        "median_features": r["median_features"],
                        "median_rot_err_deg": r["median_rot_err_deg"],
                        "agree_with_colmap": r.get("agree_with_colmap"),
                        "planted_caught": planted.get("caught"),
                        "planted_tried": planted.get("tried"),
                        "planted_by_axis": planted.get("by_axis"),
                        "colmap_runs": len(r.get("colmap_runs") or []),
                        "seconds_colmap": r["seconds"]["colmap"],
                        "seconds_compare": r["seconds"]["compare"],
                        "seconds": round(time.perf_counter() - t, 1),
                    }
                    rows.append(row)
                    print(_line(row), flush=True)
    return rows


# One check in a process of its own (COLMAP's memory and threads).
_ONE = (
    "import json, sys, pathlib; from blurset.commands import check_poses; "
    "pathlib.Path(sys.argv[2]).write_text(json.dumps(check_poses.check_scene(sys.argv[1])))"
)


def _line(r: dict) -> str:
    planted = (
        f"{r['planted_caught']}/{r['planted_tried']} {r['planted_by_axis']}"
        if r["planted_tried"]
        else "-"
    )
    rot = "-" if r["median_rot_err_deg"] is None else f"{r['median_rot_err_deg']:.2f}"
    return (
        f"{r['object']:<10} {r['size_px']:>4}px {r['views']:>3} views {r['level']:<7} "
        f"reg {r['registered']:>2} cons {r['consistent'] if r['consistent'] is not None else '-':>2} "
        f"rot {rot:>6} agree {r['agree_with_colmap'] if r['agree_with_colmap'] is not None else '-':>2} "
        f"planted {planted:<44} {r['verdict']}"
    )


def table(rows: list[dict]) -> str:
    """Per object and level: one line per size, one cell per view count (planted 5°
    errors caught / tried, and the verdict's first word)."""
    counts = sorted({r["views"] for r in rows})
    head = f"{'object':<10} {'level':<7} {'px':>4} " + " ".join(f"{k:>16}" for k in counts)
    out = [head, "-" * len(head)]
    key = lambda r: (r["object"], LEVELS.index(r["level"]), r["size_px"])  # noqa: E731
    seen: dict[tuple[str, int, int], dict[int, dict]] = {}  # (object, level, px): views: row
    for r in sorted(rows, key=key):
        seen.setdefault(key(r), {})[r["views"]] = r
    for (obj, lv, size), cells in seen.items():
        txt = []
        for k in counts:
            row = cells.get(k)
            if row is None:
                txt.append(f"{'':>16}")
                continue
            v = {"pass": "pass", "fail": "FAIL"}.get(row["verdict"], "n/c")
            c = f"{row['planted_caught']}/{row['planted_tried']}" if row["planted_tried"] else "-"
            txt.append(f"{v + ' ' + c:>16}")
        out.append(f"{obj:<10} {LEVELS[lv]:<7} {size:>4} " + " ".join(txt))
    out.append(
        "cell: verdict (pass, FAIL, n/c = not checkable) and planted 5° errors caught / tried "
        "(registered views × tilt, pan, roll)"
    )
    return "\n".join(out)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--work", type=Path, default=Path("/tmp/blurset-check-poses-sensitivity"))
    ap.add_argument("--sizes", default="64,96,128,160,192")
    ap.add_argument("--views", default="8,12,17,24,34")
    ap.add_argument("--out", type=Path, default=HERE / "check_poses_sensitivity.json")
    ap.add_argument("--one-size", type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    counts = [int(x) for x in args.views.split(",")]
    part = lambda size: args.work / f"rows_{size}.json"  # noqa: E731
    if args.one_size:
        rows = measure(args.work, [args.one_size], counts)
        part(args.one_size).write_text(json.dumps(rows))
        return 0
    rows = []
    for size in (int(x) for x in args.sizes.split(",")):
        if not part(size).is_file():
            cmd = [sys.executable, __file__, "--work", str(args.work), "--views", args.views]
            subprocess.run(_locked([*cmd, "--one-size", str(size)]), check=True, cwd=ROOT)
        rows += json.loads(part(size).read_text())
    print(table(rows))
    args.out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
