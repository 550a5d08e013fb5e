"""The build config (issue 14 U1, U2, T2–T6; issue 17): one validator in blurset-core,
whose errors name the option (flag or file and key), the value and the range; TOML
files are read strictly; every refusal comes before anything is written."""

from __future__ import annotations

import pickle
from pathlib import Path

import pytest
from blurset.cli import main
from blurset.exceptions import ConfigError
from blurset.plan import BuildConfig
from blurset.services.config import load_toml, make_config


def refused(capsys, out: Path, *argv: str) -> str:
    """Run `blurset ARGV`; it must exit 2 with one line and leave OUT unwritten."""
    assert main(list(argv)) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    assert not out.exists(), f"{out} was written before the refusal"
    return err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--views", "-1"], "--views -1: must be an integer in 1..=4096"),
        (["--fov-deg", "nan"], "--fov-deg nan: must be a number in (1, 150)"),
        (
            ["--seed", str(2**64)],
            "--seed 18446744073709551616: must be an integer in 0..=18446744073709551615",
        ),
        (["--seed", "-1"], "--seed -1: must be an integer in 0..=18446744073709551615"),
        (["--timeout", "inf"], "--timeout inf: must be a number in (0, 31536000]"),
        (["--timeout", "nan"], "--timeout nan: must be a number in (0, 31536000]"),
        (["--samples", "0"], "--samples 0: must be an integer in 1..=1048576"),
        (["--sharp-samples", str(2**21)], "--sharp-samples 2097152: must be an integer in 1..="),
        (["--levels", "1,65"], "--levels [1, 65]: must be distinct integers in 1..=64"),
        (["--levels", "2,2"], "--levels [2, 2]: must be distinct integers"),
        (["--threads", "-3"], "--threads -3: must be an integer in 0..=4096"),
        (["--max-texture-pixels", "-1"], "--max-texture-pixels -1: must be an integer in 0.."),
        (["--shard", "2/2"], '--shard "2/2": must be i/N with 0 ≤ i < N'),
        (["--resolution", "4"], "--resolution 4: must be an integer in 8..=16384"),
        (["--downsample", "1"], "--downsample [1]: must be distinct integers in 2..=64 (or none)"),
        (["--downsample", "4", "4"], "--downsample [4, 4]: must be distinct integers"),
        (["--downsample", "5"], "--downsample 5: does not divide resolution 96"),
        (["--downsample", "four"], "--downsample: expected factors like 4 8, or none"),
        (["--test-settings", "0"], "--test-settings 0: must be an integer in 1..="),
        (["--test-view-stride", "0"], "--test-view-stride 0: must be an integer in 1..=4096"),
        (["--test-objects", "1.5"], "--test-objects 1.5: must be a number in [0, 1]"),
        (["--licenses", "cc-by-4"], '--licenses "cc-by-4": must be licence ids'),
        (["--licenses", ","], '--licenses ",": must be licence ids'),
        (["--gpus", "0,0"], "--gpus [0, 0]: must be distinct integers in 0..=1023"),
        (["--gpus", "0,x"], "--gpus: expected GPU indices like 0,2 or all, got '0,x'"),
        (["--gpus-per-task", "-1"], "--gpus-per-task -1.0: must be a number in [0, 64]"),
        (
            ["--latents", "4096", "--samples", "8192", "--blur-budget", "flat"],
            "--latent-sampling subsets: 4096 latents × 8192 samples = 33554432 samples",
        ),
    ],
)
def test_flags_out_of_range_name_the_flag_value_and_range(capsys, tmp_path, flags, message):
    out = tmp_path / "out"
    err = refused(capsys, out, "build", "--demo", "--out", str(out), *flags)
    assert f"blurset build: error: {message}" in err, err
    assert "line 1 column" not in err


def write(tmp_path: Path, text: str | bytes) -> Path:
    p = tmp_path / "c.toml"
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("views = 2\n[build]\nlevels = [1]\n", "'views' beside the [build] table"),
        ("[build]\nviews = 2\n[render]\nsamples = 4\n", "'render' beside the [build] table"),
        ("views = 2\n[render]\nsamples = 4\n", "unknown table [render]"),
        ("build = 5\n", "build must be a table ([build]), got 5"),
        ("vews = 2\n", "unknown option 'vews'"),
        ("[build]\nlatents_mx = 3\n", "unknown option 'latents_mx'"),
        ("levels = [1, 2.5]\n", "levels [1, 2.5]: must be distinct integers in 1..=64"),
        ("max_texture_pixels = 1e400\n", "max_texture_pixels inf: must be an integer"),
        ("views = true\n", "views true: must be an integer in 1..=4096"),
        ("fov_deg = nan\n", "fov_deg nan: must be a number in (1, 150)"),
        ("background = [1, 1]\n", "background [1, 1]: must be 3 numbers in [0, 1]"),
        ("views = 2\nviews_ = 3\n", "unknown option 'views_'"),
        ("keep-linear = true\nkeep_linear = false\n", "given twice"),
        ('trajectory = "middle"\n', 'trajectory "middle": must be one of start, centered'),
        ("downsample = [5]\n", "downsample 5: does not divide resolution 96"),
        ("test-view-stride = 0\n", ": test-view-stride 0: must be an integer in 1..=4096"),
        ("keep-linear = 3\n", ": keep-linear 3: "),
        ("test-settings = 5\ntest-objects = 0.3\n", "either N random test settings"),
        ('licenses = "cc-by-nc"\n', 'licenses "cc-by-nc": must be licence ids'),
        ("licenses = [4]\n", "licenses [4]: must be licence ids"),
        ('latent_sampling = "mixed"\n', 'latent_sampling "mixed": must be one of subsets, indep'),
        ('light_paths = "none"\n', 'light_paths "none": must be one of auto, fixed'),
        ('device = "tpu"\n', 'device "tpu": must be one of auto, cpu, optix, cuda, hip'),
        ("gpus = [-1]\n", "gpus [-1]: must be distinct integers in 0..=1023"),
    ],
)
def test_toml_is_read_strictly_and_errors_name_the_file_and_key(capsys, tmp_path, text, message):
    cfg = write(tmp_path, text)
    out = tmp_path / "out"
    err = refused(capsys, out, "build", "--demo", "--config", str(cfg), "--out", str(out))
    assert message in err, err
    assert str(cfg) in err, err


def test_binary_or_missing_config_names_the_file(capsys, tmp_path):
    out = tmp_path / "out"
    cfg = write(tmp_path, b"\x89PNG\r\n\x1a\n\x00\xff\xfe binary")
    err = refused(capsys, out, "build", "--demo", "--config", str(cfg), "--out", str(out))
    assert str(cfg) in err and "not UTF-8" in err, err
    err = refused(
        capsys, out, "build", "--demo", "--config", str(tmp_path / "nope.toml"), "--out", str(out)
    )
    assert "no such file" in err and "nope.toml" in err, err
    err = refused(capsys, out, "build", "--demo", "--config", str(tmp_path), "--out", str(out))
    assert "is a directory" in err, err


def test_toml_spellings_and_layers():
    # Flags override the file; the keep_linear alias and latents = "auto" map.
    cfg = make_config(
        {"views": 5, "write_linear": True, "latents": "auto", "levels": [4, 1]},
        {"views": 3, "out": Path("o"), "demo": True},
    )
    assert (cfg.views, cfg.write_linear, cfg.latents_auto, cfg.levels) == (3, True, True, [1, 4])
    assert cfg.out == "o" and cfg.settings_per_object == 1  # the demo's defaults
    with pytest.raises(ConfigError, match="--latents-max 5: only used with latents auto"):
        make_config({}, {"latents_max": 5, "out": "o", "demo": True})


def test_trajectory_from_toml_and_flags_reaches_the_plan(capsys, tmp_path):
    """`trajectory` (issue 18): default start (the paper), a TOML value, a flag over it;
    the choice reaches the sampling of every plan and dataset.json's config record."""
    base = {"demo": True, "out": tmp_path / "o"}
    assert make_config({}, base).trajectory == "start"
    toml = load_toml(write(tmp_path, 'trajectory = "centered"\n'))
    cfg = make_config(toml, base)
    assert cfg.trajectory == "centered"
    assert cfg.sampling().to_dict()["trajectory"] == "centered"
    assert cfg.record()["trajectory"] == "centered"
    assert make_config(toml, {**base, "trajectory": "start"}).trajectory == "start"
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        main(["build", "--demo", "--out", str(out), "--trajectory", "middle"])
    assert e.value.code == 2
    assert "--trajectory: invalid choice: 'middle'" in capsys.readouterr().err
    assert not out.exists()


def test_training_options_map_onto_the_core(tmp_path):
    # Deblur-NeRF test views and images_4/ by default; `none`, fractions and id lists map.
    cfg = make_config({}, {"out": "o", "demo": True})
    assert (cfg.downsample, cfg.blurry_test_views, cfg.test_view_images) == ([4], False, "sharp")
    assert cfg.sharp_views(17) == [0, 16] and cfg.record()["downsample"] == [4]
    p = write(
        tmp_path,
        'downsample = "none"\ntest-view-stride = 8\ntest-objects = "a,b"\n'
        "blurry-test-views = true\n",
    )
    cfg = make_config(load_toml(p), {"out": "o", "demo": True}, config_path=p)
    assert (cfg.downsample, cfg.view_stride, cfg.test_objects) == ([], 8, ["a", "b"])
    assert cfg.sharp_views(17) == [] and cfg.test_view_images == "blurry"
    cfg = make_config(
        load_toml(write(tmp_path, "test-settings = 52\n")), {"out": "o", "demo": True}
    )
    assert (cfg.test_settings, cfg.test_objects) == (52, None)
    cfg = make_config({}, {"out": "o", "demo": True, "downsample": [8, 4], "test_fraction": 0.5})
    assert (cfg.downsample, cfg.test_fraction) == ([4, 8], 0.5)


def test_licenses_flag_and_toml_key():
    # Issue 19: ids are canonical (SPDX case, other, unknown), once each, in order.
    cfg = make_config({"licenses": ["cc-by-4.0", "Other"]}, {"out": "o", "demo": True})
    assert cfg.licenses == ["CC-BY-4.0", "other"]
    cfg = make_config(
        {}, {"licenses": "cc0-1.0, CC-BY-4.0,cc0-1.0,unknown", "out": "o", "demo": True}
    )
    assert cfg.licenses == ["CC0-1.0", "CC-BY-4.0", "unknown"]
    assert make_config({}, {"out": "o", "demo": True}).licenses is None


def test_issue_15_16_options_and_their_spellings():
    """latent_sampling, light_paths (output-shaping) and device, gpus, gpus_per_task
    (run-only) from flags and TOML; `--gpus 0,2` and `gpus = "all"` spellings; CUDA."""
    cfg = make_config(
        {"latent_sampling": "independent", "light_paths": "fixed", "gpus": "all"},
        {"out": "o", "demo": True, "device": "CUDA", "gpus_per_task": 0.5, "executor": "ray"},
    )
    assert (cfg.latent_sampling, cfg.light_paths) == ("independent", "fixed")
    assert (cfg.device, cfg.gpus, cfg.gpus_per_task) == ("cuda", None, 0.5)
    assert cfg.cycles_samples is None  # independent frames render their own samples
    d = make_config({"gpus": [3, 1]}, {"out": "o", "demo": True, "gpus": "0,2"})
    assert (d.gpus, d.latent_sampling, d.light_paths, d.device) == (
        [0, 2],
        "subsets",
        "auto",
        "auto",
    )
    # Subsets pin every render to the longest sequence or the sharp budget. The demo's
    # 6 frames × 4 samples under parity: 6 × ⌈4 · 6^0.4⌉ = 54; flat: 6 × 4.
    assert (d.blur_budget, d.cycles_samples) == ("parity", 54)
    assert d.replace(blur_budget="flat").cycles_samples == 24
    assert d.replace(sharp_samples=100).cycles_samples == 100
    assert d.replace(sharp_samples=100, blur_budget="flat").cycles_samples == 100
    auto = BuildConfig(latents_auto=True, latents_max=47, samples_total=100, blur_budget="flat")
    assert auto.cycles_samples == 141
    assert auto.replace(blur_budget="parity").cycles_samples == 506  # 47 × ⌈100 · 47^0.4 / 47⌉
    assert make_config({"blur_budget": "flat"}, {"out": "o", "demo": True}).blur_budget == "flat"
    with pytest.raises(ConfigError, match='blur_budget "even": must be one of parity, flat'):
        make_config({"blur_budget": "even"}, {"out": "o", "demo": True})


def test_toml_values_name_their_file_and_key(tmp_path):
    p = write(tmp_path, "[build]\nsettings-per-object = 0\n")
    with pytest.raises(ConfigError) as e:
        make_config(load_toml(p), {"out": "o", "demo": True}, config_path=p)
    # The key as the file spells it, not the option's name.
    assert str(e.value) == f"{p}: settings-per-object 0: must be an integer in 1..=360"


def test_the_core_owns_limits_and_derived_numbers():
    cfg = BuildConfig(views=4, levels=[2], latents=3, samples=5)
    assert cfg.level_dirs == ["sharp", "blur_2"]
    assert (cfg.max_latents, cfg.blur_samples_total, cfg.effective_sharp_samples) == (3, 15, 15)
    assert cfg.frames_per_setting == 4 * (1 + 3)
    assert cfg.theta0s == [0.0, 90.0, 180.0, 270.0]
    mb = cfg.replace(blur_method="motion_blur", samples_total=64)
    assert (mb.max_latents, mb.blur_samples_total, mb.views) == (1, 64, 4)
    assert cfg.replace(latents_auto=True, latents_max=9).record()["latents"] == "auto"
    # One cap for samples, in Rust: 2^20 for per-frame, budget and sharp samples alike.
    # (16 latents: under sample subsets one sequence of 16 × 2^20 is Cycles' most, 2^24.)
    for option in ("samples", "samples_total", "sharp_samples"):
        BuildConfig(**{option: 2**20}, latents=16)
        with pytest.raises(ValueError, match=f"{option} 1048577: must be an integer in 1..="):
            BuildConfig(**{option: 2**20 + 1})
    # Frozen, comparable and picklable (Ray sends it to its tasks).
    assert pickle.loads(pickle.dumps(mb)) == mb
    with pytest.raises(AttributeError):
        cfg.views = 3  # type: ignore[misc]


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--seed", "-1"], "--seed -1: must be an integer in 0.."),
        (["--theta0-deg", "nan"], "--theta0-deg nan: must be a finite number"),
        (["--timeout", "inf"], "--timeout inf: must be a number in (0, 31536000]"),
        (["--threads", "-3"], "--threads -3: must be an integer in 0..=4096"),
        # Its grids are checked against the build's ranges (the core's, not a copy).
        (["--budgets", "16,0"], "--budgets 16,0: value 0: must be an integer in 1..=1048576"),
        (["--latents", "2,5000"], "--latents 2,5000: value 5000: must be an integer in 1..=4096"),
        (["--level", "65"], "--level [65]: must be distinct integers in 1..=64"),
    ],
)
def test_tradeoff_refuses_bad_flags_up_front(capsys, tmp_path, flags, message):
    glb = tmp_path / "x.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    err = refused(capsys, out, "tradeoff", "--object", str(glb), "--out", str(out), *flags)
    assert message in err, err


def test_an_out_built_before_sample_subsets_is_not_resumed_with_them(tmp_path):
    """An OUT whose dataset.json predates latent_sampling and light_paths was built with
    independent seeds and fixed bounces: resuming it with today's defaults would mix two
    noise schemes, so it is refused, naming the option; the old scheme resumes it, and
    run-only options (device, gpus) never count."""
    import json

    from blurset.commands.builder.dataset import check_same_options

    out = tmp_path / "out"
    out.mkdir()
    cfg = make_config({}, {"out": str(out), "demo": True})
    old = {k: v for k, v in cfg.record().items() if k not in ("latent_sampling", "light_paths")}
    (out / "dataset.json").write_text(json.dumps({"name": "x", "config": old}))
    with pytest.raises(ConfigError, match="--latent-sampling 'independent' → 'subsets'"):
        check_same_options(out, cfg)
    same = make_config(
        {},
        {"out": str(out), "demo": True, "latent_sampling": "independent",
         "light_paths": "fixed", "device": "cpu", "gpus_per_task": 1, "executor": "ray"},
    )  # fmt: skip
    check_same_options(out, same)
