"""`blurset check-poses`: the command, its summaries and the level table."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from blurset import layout
from blurset.commands.check_poses import colmap
from blurset.commands.check_poses.check import _check_level_name, check_scene, is_setting
from blurset.commands.check_poses.colmap import _refuse_used_workdir
from blurset.commands.check_poses.report import PoseReport
from blurset.commands.check_poses.thresholds import (
    MIN_REGISTERED_FRACTION,
)
from blurset.commands.check_poses.verdict import _fmt, exit_code
from blurset.exceptions import ConfigError, InputError
from blurset.services import outputs


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("path", type=Path, help="a build setting directory or an LLFF scene")
    parser.add_argument(
        "--level",
        default="sharp",
        help="level directory of a build setting to check: sharp, blur_<l> (default sharp; a "
        "blur level is compared with its mean latent poses from meta.json); `all` checks "
        "every level and prints how blur degrades SfM (the exit code follows sharp)",
    )
    parser.add_argument(
        "--factor",
        type=int,
        default=None,
        help="use images_<F>/ and divide the focal length by F, as the LLFF loaders do "
        "(default: images/)",
    )
    parser.add_argument(
        "--json",
        type=Path,
        default=None,
        help="write the JSON report here (default: none); a file already there is replaced "
        "only when it is an earlier check-poses report",
    )
    parser.add_argument(
        "--workdir",
        type=Path,
        default=None,
        help="keep COLMAP's database and model here, in a folder that holds none yet "
        "(default: a temporary directory)",
    )
    parser.add_argument("--verbose", action="store_true", help="show COLMAP's own log")


def _summary(label: str, r: PoseReport) -> str:
    """The verdict and what it means on the first line, then the numbers and the reason."""
    secs = r["seconds"]["colmap"] + r["seconds"]["compare"]
    against = " (vs mean latent pose)" if r.get("pose_reference") == "mean_latent" else ""
    return (
        f"{label}: {r['verdict']} — {r.get('meaning', '')}\n"
        f"  {r['registered']}/{r['total']} registered, "
        f"median rotation error{against} {_fmt(r['median_rot_err_deg'], '.3f')} deg, "
        f"median centre error {_fmt(r['median_center_err_rel'], '.2%')}, "
        f"median reprojection {_fmt(r.get('median_reproj_px'), '.2f')} px "
        f"({secs:.1f} s)\n  {r['reason']}"
    )


def _change(level: str, x, ref, ratio: bool) -> str:
    """A blur level's value against the sharp level's: a percentage, or a factor."""
    if level == layout.SHARP or x is None or not ref:
        return ""
    return f" (×{x / ref:.1f})" if ratio else f" ({x / ref - 1:+.0%})"


TABLE_COLUMNS = [
    ("level", "<8"),
    ("registered", ">10"),
    ("SIFT/image", ">13"),
    ("COLMAP reproj px", ">16"),
    ("rot err deg", ">11"),
    ("written deg", ">11"),
    ("p→mean deg", ">10"),
    ("centre err", ">10"),
]


def _table(reports: dict[str, PoseReport]) -> str:
    """What blur changes in SfM first (registered views, SIFT features per image, COLMAP's
    own reprojection error, each against sharp), then the pose errors: against the mean
    latent pose (which decides a blur level), against the written pose, and the offset
    from the one to the other."""
    head = " ".join(format(name, spec) for name, spec in TABLE_COLUMNS) + "  verdict"
    rows = [head, "-" * len(head)]
    sharp = reports.get(layout.SHARP)
    for level, r in reports.items():
        wp = r.get("written_pose")
        written = r["median_rot_err_deg"] if wp is None else wp["median_rot_err_deg"]
        feats, reproj = r["median_features"], r.get("colmap_mean_reproj_px")
        enough = r["registered"] >= MIN_REGISTERED_FRACTION * r["total"]
        cells = [
            level,
            f"{r['registered']}/{r['total']}",
            f"{feats}{_change(level, feats, sharp and sharp['median_features'], False)}",
            _fmt(reproj, ".2f")
            # A model of a few registered views has a small error of its own: no ratio.
            + (
                _change(level, reproj, sharp and sharp["colmap_mean_reproj_px"], True)
                if enough
                else ""
            ),
            _fmt(r["median_rot_err_deg"], ".3f"),
            _fmt(written, ".3f"),
            _fmt(r.get("median_written_to_mean_deg"), ".3f"),
            _fmt(r["median_center_err_rel"], ".2%"),
        ]
        rows.append(
            " ".join(format(c, spec) for c, (_, spec) in zip(cells, TABLE_COLUMNS, strict=True))
            + f"  {r['verdict']}"
        )
    rows.append(
        "rot err: median against each blurry exposure's mean latent pose (the written pose "
        "for sharp); it decides the verdict. written: against the written pose p. "
        "p→mean: from p to the mean latent pose (half the blur under --trajectory start)."
    )
    return "\n".join(rows)


def is_report(doc: Any) -> bool:
    """A JSON report check-poses wrote: one scene's ({verdict, pass, …}) or one per
    level ({level: {verdict, pass, …}})."""

    def one(d: Any) -> bool:
        return isinstance(d, dict) and "verdict" in d and "pass" in d

    return one(doc) or (isinstance(doc, dict) and bool(doc) and all(one(v) for v in doc.values()))


def _write_json(path: Path, data) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    layout.write_json(path, data, indent=2)


def _starting(scene: Path) -> None:
    """A line before COLMAP runs (a minute or more per scene, silent otherwise)."""
    print(f"check-poses: {scene.name}: COLMAP features, matching and mapping (a minute or "
          "more a scene)", flush=True)  # fmt: skip


def run(args: argparse.Namespace) -> int:
    colmap.VERBOSE = bool(getattr(args, "verbose", False))
    path = Path(args.path)
    if not path.is_dir():
        raise InputError(f"not a directory: {path}")
    workdir = getattr(args, "workdir", None)
    if workdir:
        # COLMAP's database and model go into a folder of their own: never into the
        # scene or setting checked (its images_<f>/ …), nor into any blurset output.
        outputs.refuse_overlap(workdir, [path], "--workdir")
        outputs.refuse_inside_output(workdir, "--workdir", include_self=True)
        _refuse_used_workdir(workdir)
    if args.json:
        # Before COLMAP runs: a report never replaces a file it did not write, nor lands
        # in what it checks or in any blurset output.
        outputs.claim_report(args.json, is_report, "--json")
        outputs.refuse_overlap(args.json, [path], "--json")
        outputs.refuse_inside_output(args.json, "--json")
    if is_setting(path):
        if args.level != "all":
            _check_level_name(args.level)
        levels = layout.setting_levels(path) if args.level == "all" else [args.level]
        if workdir:
            # Every level's folder before the first COLMAP run: nothing half done.
            for level in levels:
                _refuse_used_workdir(workdir / level)
        data: PoseReport | dict[str, PoseReport]
        reports: dict[str, PoseReport] = {}
        for level in levels:
            scene = path / level
            if not scene.is_dir():
                raise InputError(f"no level directory {level} in setting {path}")
            wd = workdir / level if workdir else None
            _starting(scene)
            reports[level] = check_scene(scene, factor=args.factor, workdir=wd)
            print(_summary(level, reports[level]), flush=True)
        if args.level == "all":
            print(_table(reports))
            data = reports
            # Every level carries the same poses; blurred levels measure SfM, not the
            # poses, so the sharp level decides.
            decisive = reports.get("sharp") or next(iter(reports.values()))
        else:
            data = decisive = reports[args.level]
    else:
        if args.level not in ("sharp", "all"):
            raise ConfigError(f"--level {args.level}: {path} is an LLFF scene without levels")
        if workdir:
            _refuse_used_workdir(workdir)
        _starting(path)
        data = decisive = check_scene(path, factor=args.factor, workdir=workdir)
        print(_summary(path.name, decisive))
    if args.json:
        _write_json(args.json, data)
    return exit_code(decisive)
