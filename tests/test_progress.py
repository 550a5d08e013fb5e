"""Progress and resume messages of a build, without rendering: piped progress lines
carry the time elapsed and an ETA (a fake clock, no waiting), a resumed build counts
what it found complete, and an interrupted build says how to resume."""

from __future__ import annotations

import subprocess
import sys

from blurset.commands.builder import resumed_settings
from blurset.services.config import make_config
from blurset.services.objects import ObjectSpec
from blurset.services.progress import Progress, duration

from tests.conftest import ROOT


class Clock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_durations():
    assert [duration(s) for s in (0, 42.4, 60, 187, 3599, 3600, 7500)] == [
        "0s", "42s", "1m00s", "3m07s", "59m59s", "1h00m", "2h05m",
    ]  # fmt: skip


def test_piped_lines_carry_elapsed_and_eta(capsys):
    clock = Clock()
    p = Progress(4, frames_per_setting=10, clock=clock)
    p.skip(1)  # found complete: not work left, not work done in this run
    clock.t += 30
    p.frame_done(10)
    p.setting_done()
    clock.t += 45
    p.frame_done(4)
    p.write("failed: x_090: render: boom")
    p.object_failed(1)  # the rest of that object's settings will not be rendered
    p.setting_done()
    lines = capsys.readouterr().err.splitlines()
    # 10 frames in 30 s, 20 left → 60 s.
    assert lines[0] == "2/4 settings done (30s elapsed, ETA 1m00s)"
    assert lines[1] == "failed: x_090: render: boom"
    # 14 frames in 75 s; the failed setting's 10 frames are no longer to do: 6 left.
    assert lines[2] == "3/4 settings done, 1 failed (1m15s elapsed, ETA 32s)"


def test_a_log_hears_from_a_long_setting_every_minute(capsys):
    """Within a setting (hours at 512 px) a log gets a line with frames and an ETA once
    a minute at least, not only when the setting ends; a setting's line resets it."""
    clock = Clock()
    p = Progress(2, frames_per_setting=100, clock=clock)
    for _ in range(5):
        clock.t += 20
        p.frame_done(10)
    p.setting_done()
    clock.t += 59
    p.frame_done(10)
    lines = capsys.readouterr().err.splitlines()
    # 30 frames in 60 s, 170 left: 5m40s; the setting's own line (50 in 100 s, 150 left),
    # and 59 s after it none.
    assert lines == [
        "30/200 frames, 0/2 settings done (1m00s elapsed, ETA 5m40s)",
        "1/2 settings done (1m40s elapsed, ETA 5m00s)",
    ], lines


def test_eta_before_any_frame_and_when_nothing_is_left(capsys):
    clock = Clock()
    p = Progress(2, frames_per_setting=5, clock=clock)
    assert p.timing() == "0s elapsed, ETA -"
    p.skip(2)
    clock.t += 3
    assert p.timing() == "3s elapsed, ETA 0s"


def test_a_resumed_build_counts_the_settings_it_found_complete(tmp_path):
    out = tmp_path / "out"
    cfg = make_config({}, {"out": str(out), "demo": True, "settings_per_object": 2})
    objs = [ObjectSpec(uid=u, path=tmp_path / f"{u}.glb", source="file") for u in ("a", "b")]
    for name, done in (("a_000", True), ("a_180", False), ("b_180", True), ("zz_000", True)):
        (out / name).mkdir(parents=True)
        if done:
            (out / name / ".complete").write_text("x\n")
    # a_180 has no marker; zz_000 is not one of this job's settings.
    assert resumed_settings(out, objs, cfg) == 2


def test_an_interrupted_build_says_how_to_resume(tmp_path):
    code = (
        "import sys, blurset.commands.builder.cli as c\n"
        "def run(args): raise KeyboardInterrupt()\n"
        "c.run = run\n"
        "from blurset.cli import main\n"
        f"sys.exit(main(['build', '--demo', '--out', {str(tmp_path / 'o')!r}]))\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert p.returncode == 130, p.stderr
    assert p.stderr.strip() == (
        "blurset build: interrupted; complete settings are kept: rerun the same command to resume"
    )


def test_a_dry_run_prints_the_plan_and_estimate_and_writes_nothing(tmp_path):
    """`build --dry-run` prints the plan (settings, images, renders, samples, disk) and a
    time estimate, refuses a bad option before it, and leaves no folder behind; the
    README's build of real models at the paper's defaults is priced in hours, with the
    cheaper choices beside it."""
    from tests.conftest import run_cli, shared

    out = tmp_path / "out"
    p = run_cli("build", "--demo", "--out", str(out), "--dry-run")
    lines = p.stderr.splitlines()
    assert lines[0].startswith("plan: 3 objects x 1 settings = 3 settings of 17 views at 96 px")
    assert "255 images" in lines[0] and " renders, " in lines[0], lines
    # The demo's --samples 4 is a frame's share: the parity budget renders 9 a frame.
    assert lines[1].startswith("  each latent frame renders 9 samples (--samples 4 "), lines
    assert lines[2].startswith("estimate: ") and "cheaper" not in p.stderr, lines
    assert not out.exists() and not list(tmp_path.iterdir())
    bad = run_cli("build", "--demo", "--out", str(out), "--dry-run", "--views", "0", check=False)
    assert bad.returncode != 0 and "--views" in bad.stderr and not out.exists()
    glb = shared("glb", "khronos_BoxTextured.glb")
    readme = run_cli("build", "--objects", str(glb), "--out", str(out), "--dry-run")
    est = next(ln for ln in readme.stderr.splitlines() if ln.startswith("estimate: "))
    assert "h" in est.split(" on this machine")[0], readme.stderr  # hours at 512 px
    cheaper = next(ln for ln in readme.stderr.splitlines() if "cheaper:" in ln)
    assert "--resolution 256" in cheaper and "--device optix" in cheaper, cheaper
    assert not out.exists()
