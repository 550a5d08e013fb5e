"""The build path is no slower than before a round of output-owner and reader-limit work
(issue 34), and writes the same bytes.

Two installations side by side in one run: the one this checkout runs (contender) and
the commit the round started from (baseline, `BLURSET_BENCH_BASE`, default 5ae37d3),
built from `git archive` into a wheel once and put first on PYTHONPATH of its runs. The
same `blurset build` command, alternating base and head, repeated; medians.

- `build_path_blender`: the demo objects rendered by the real Blender worker (small
  size, the demo's defaults): renders, accumulation, the owner's checks, records. The
  two outputs are compared with ../shared/tools/compare_builds.py (bytes; JSON without
  timings): `differs` lists what is not the same, `data_identical` says whether any
  image, pose or array differs (records may: the round added fields to them).
- `build_path_orchestration`: the stand-in worker (tests/standin_worker.py: analytic
  EXRs, no Cycles), so what is timed is what the round touched: locks, layout and owner
  checks, EXR reads within limits, accumulation, records, publish.
"""

from __future__ import annotations

import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASE = os.environ.get("BLURSET_BENCH_BASE", "5ae37d3")
REPEATS = int(os.environ.get("BLURSET_BENCH_BUILD_REPEATS", "5"))
COMPARE = ROOT.parent / "shared" / "tools" / "compare_builds.py"

BLENDER_ARGS = ("--demo", "--resolution", "64", "--views", "6", "--quiet")
STANDIN_ARGS = (
    "--demo", "--views", "12", "--levels", "1,2,3,4", "--latents", "8", "--samples", "2",
    "--resolution", "96", "--settings-per-object", "2", "--quiet",
)  # fmt: skip


def base_site(commit: str, cache: Path) -> Path:
    """A site folder holding blurset as of `commit` (its wheel, built once per commit)."""
    full = subprocess.run(
        ["git", "-C", str(ROOT), "rev-parse", commit], check=True, capture_output=True, text=True
    ).stdout.strip()
    site = cache / f"site-{full[:12]}"
    if (site / "blurset" / "__init__.py").is_file():
        return site
    with tempfile.TemporaryDirectory(prefix="blurset-base-") as tmp:
        src, wheels = Path(tmp) / "src", Path(tmp) / "wheels"
        src.mkdir()
        subprocess.run(
            f"git -C {shlex.quote(str(ROOT))} archive {full} | tar -x -C {shlex.quote(str(src))}",
            shell=True,
            check=True,
        )
        # The checkout's target folder: the dependencies compiled once serve both builds.
        env = dict(os.environ, CARGO_TARGET_DIR=str(ROOT / "target"))
        maturin = Path(sys.executable).with_name("maturin")
        subprocess.run(
            [str(maturin), "build", "--release", "-q", "-o", str(wheels)],
            cwd=src,
            env=env,
            check=True,
        )
        (wheel,) = wheels.glob("*.whl")
        subprocess.run(
            [
                sys.executable,
                "-m",
                "pip",
                "install",
                "-q",
                "--no-deps",
                "--target",
                str(site),
                str(wheel),
            ],
            check=True,
        )
    return site


# The CLI of whichever blurset comes first on the path (no console script for the base).
_MAIN = "import sys; from blurset.cli import main; sys.exit(main(sys.argv[1:]))"


def _build(out: Path, site: Path | None, args: tuple[str, ...]) -> float:
    env = dict(os.environ)
    if site is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(site), env.get("PYTHONPATH", "")]).rstrip(
            os.pathsep
        )
    cmd = [sys.executable, "-c", _MAIN, "build", *args, "--out", str(out)]
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, check=True, cwd=out.parent)
    return time.perf_counter() - t0


def _differences(a: Path, b: Path) -> list[str]:
    """The files compare_builds.py finds different (bytes; JSON without timings)."""
    done = subprocess.run(
        [sys.executable, str(COMPARE), str(a), str(b)], capture_output=True, text=True
    )
    return [
        line.removeprefix("differs: ")
        for line in done.stdout.splitlines()
        if line.startswith("differs: ")
    ]


# What may differ between two versions without a pixel or a pose differing: the markers'
# timestamps, the checksums of the records, and the records themselves where the round
# added fields (dataset.json's config gained preset and target_*).
RECORDS = (".complete", "MANIFEST.sha256", ".json")


def side_by_side(name: str, args: tuple[str, ...], site: Path, work: Path) -> dict:
    times: dict[str, list[float]] = {"base": [], "head": []}
    outs: dict[str, Path] = {}
    for i in range(REPEATS):
        # Alternating, base first then head first: neither always runs on a warm cache.
        order = ("base", "head") if i % 2 == 0 else ("head", "base")
        for who in order:
            out = work / f"{name}-{who}-{i}" / "build"
            out.parent.mkdir(parents=True)
            times[who].append(_build(out, site if who == "base" else None, args))
            outs[who] = out
    base, head = statistics.median(times["base"]), statistics.median(times["head"])
    return {
        "name": name,
        "ratio": base / head,
        "ratio_is": "base seconds / this checkout's (above 1: faster)",
        "contender": "this checkout",
        # The commit stays in the record; the pages that show it name no commit.
        "baseline": "blurset without the output-owner and reader-limit checks",
        "base_commit": BASE,
        "median_s": {"base": base, "head": head},
        "times_s": times,
        "repeats": REPEATS,
        "command": "blurset build " + " ".join(args),
        "differs": (differs := _differences(outs["base"], outs["head"])),
        "data_identical": not [f for f in differs if not f.endswith(RECORDS)],
    }


def _standin_blender(work: Path) -> Path:
    wrapper = work / "standin" / "blender"
    wrapper.parent.mkdir()
    script = ROOT / "tests" / "standin_worker.py"
    wrapper.write_text(
        f'#!/bin/sh\nexec {shlex.quote(sys.executable)} {shlex.quote(str(script))} "$@"\n'
    )
    wrapper.chmod(0o755)
    return wrapper


def run() -> list[dict]:
    cache = ROOT / "target" / "bench-base"
    cache.mkdir(parents=True, exist_ok=True)
    site = base_site(BASE, cache)
    with tempfile.TemporaryDirectory(prefix="bench-build-path-") as tmp:
        work = Path(tmp)
        standin = ("--blender", str(_standin_blender(work)), *STANDIN_ARGS)
        return [
            side_by_side("build_path_orchestration", standin, site, work),
            side_by_side("build_path_blender", BLENDER_ARGS, site, work),
        ]


if __name__ == "__main__":
    for r in run():
        print(r)
