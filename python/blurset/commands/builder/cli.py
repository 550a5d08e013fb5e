"""`blurset build` on the command line: its flags, and the config they make."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from blurset import layout
from blurset.services.config import BUILD, BuildConfig, load_toml, make_config, out_dir


def default_text(option: str) -> str:
    """The default of a build option as help states it: the core's value (and the
    demo's, when it has its own)."""
    return BUILD.default_text(option)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config", type=Path, help="TOML file of options (flags override it; default: none)"
    )
    # A flag per option the core declares (rust/core/src/plan/config.rs, build_options!).
    BUILD.add_flags(p)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="print the plan (settings, images, renders, samples, disk) and its time estimate "
        "for this machine after every check that needs no render; write nothing",
    )


def config_from_args(args: argparse.Namespace) -> BuildConfig:
    file_values = load_toml(args.config) if args.config else {}
    return make_config(file_values, BUILD.from_args(args), config_path=args.config)


def run(args: argparse.Namespace) -> int:
    from blurset.commands.builder import build, dry_run

    cfg = config_from_args(args)
    if args.dry_run:
        print("\n".join(dry_run(cfg)), file=sys.stderr)
        return 0
    summary = build(cfg, progress=not args.quiet)
    skipped = summary.get("objects_skipped", 0)
    n, bad = summary["objects"] - skipped, summary["objects_failed"]
    rate = bad / n if n else 0.0
    line = (
        f"blurset build: {summary['settings_complete']} settings complete "
        f"({summary['settings_new']} new), {bad} of {n} objects failed ({100 * rate:.0f}%)"
    )
    if skipped:
        line += f", {skipped} skipped by --licenses"
    if summary["settings_failed"]:
        line += f", {summary['settings_failed']} settings failed QA"
    print(f"{line} -> {cfg.out}", file=sys.stderr)
    asked, got = cfg.test_settings, summary["test_settings"]
    if asked is not None and got < asked:
        # The core keeps one setting for training at least: say so, not only in splits.json.
        print(
            f"  --test-settings {asked}: {got} test settings, as the build has "
            f"{summary['settings_complete']} complete and one at least stays train",
            file=sys.stderr,
        )
    if asked is None and summary["settings_complete"] and not got:
        print(
            "  the test split is empty: --test-objects holds out whole objects, and a "
            "fraction of this build's objects rounds to none; give --test-settings N "
            "(the paper's 52) or --test-objects with a list",
            file=sys.stderr,
        )
    for f in summary["failures"][:5]:
        where = f.get("setting") or f["uid"]
        print(f"  {where}: {f['stage']}: {f['reason']}", file=sys.stderr)
    if len(summary["failures"]) > 5:
        print(f"  … see {out_dir(cfg) / layout.FAILURES}", file=sys.stderr)
    if summary["objects"] and summary["settings_complete"] == 0:
        return 1  # nothing built (every object failed, or --licenses left none)
    if rate > cfg.max_failure_rate:
        print(
            f"blurset build: error: {100 * rate:.0f}% of objects failed, more than "
            f"--max-failure-rate {cfg.max_failure_rate:g}",
            file=sys.stderr,
        )
        return 1
    return 0
