"""Every option and every reference to the inputs is checked before the first render:
one line naming the option, exit 2, no Blender worker started."""

from __future__ import annotations

from pathlib import Path

import pytest
from blurset.cli import main
from blurset.services import worker_client
from blurset.services.demo import make_demo_objects


@pytest.fixture
def no_render(monkeypatch):
    """A Blender worker started here fails the test."""

    def boom(*args, **kwargs):
        raise AssertionError("a Blender worker was started before the refusal")

    monkeypatch.setattr(worker_client.Worker, "__init__", boom)


@pytest.fixture(scope="module")
def glbs(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("glb")
    make_demo_objects(d)  # demo_box, demo_cylinder, demo_vase
    return d


def refused(capsys, *argv: str) -> str:
    # "Before the first render" is the `no_render` fixture's event (a worker started
    # fails the test), not a wall-clock bound: CI runs on a busy machine.
    assert main(list(argv)) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err, err
    return err


def test_an_unknown_test_object_fails_before_anything_is_written(capsys, tmp_path, glbs, no_render):
    out = tmp_path / "out"
    err = refused(
        capsys, "build", "--objects", str(glbs), "--out", str(out), "--test-objects", "chair"
    )
    assert err.startswith('blurset build: error: --test-objects "chair": not an object'), err
    assert "demo_box" in err  # the objects it could have named
    assert not out.exists()
    # Listed ids of the build pass; one unknown among them is named alone.
    err = refused(
        capsys,
        "build",
        "--objects",
        str(glbs),
        "--out",
        str(out),
        "--test-objects",
        "demo_box,chiar",
    )
    assert '--test-objects "chiar": not an object of this build' in err, err


def test_an_unknown_test_object_of_the_demo_fails_before_any_render(capsys, tmp_path, no_render):
    out = tmp_path / "out"
    err = refused(capsys, "build", "--demo", "--out", str(out), "--test-objects", "chair")
    assert '--test-objects "chair": not an object of this build' in err, err
    assert not (out / "dataset.json").exists()
    assert [p.name for p in out.iterdir()] == [".demo_objects"]


def test_an_unknown_test_object_in_toml_fails_early(capsys, tmp_path, glbs, no_render):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'objects = ["{glbs}"]\ntest-objects = ["demo_box", "chair"]\n')
    err = refused(capsys, "build", "--config", str(cfg), "--out", str(tmp_path / "out"))
    assert '"chair": not an object of this build' in err, err


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        (["--shard=-1/2"], '--shard "-1/2": must be i/N with 0 ≤ i < N'),
        (["--shard=+1/2"], '--shard "+1/2": must be i/N'),
        (["--shard", "1 /2"], '--shard "1 /2": must be i/N'),
        (["--shard", "1/2/3"], '--shard "1/2/3": must be i/N'),
        (["--timeout", "1e308"], "--timeout 1e308: must be a number in (0, 31536000]"),
        (["--object-timeout", "1e308"], "--object-timeout 1e308: must be a number in [0, 315"),
        (["--gpus-per-task", "1"], "--gpus-per-task 1.0: only with executor ray"),
        (["--executor", "ray", "--gpus", "0"], "--gpus [0]: only with executor local"),
        (["--executor", "ray", "--workers", "4"], "--workers 4: only with executor local"),
        (["--licenses", "cc-by-4"], '--licenses "cc-by-4": must be licence ids'),
        (["--licenses", "cc0-1.0,mit-ish"], '--licenses "cc0-1.0,mit-ish": must be licence ids'),
        (["--gpus", "0,0"], "--gpus [0, 0]: must be distinct integers"),
        (["--blender", "/no/such/blender"], "--blender '/no/such/blender': does not exist"),
    ],
)
def test_each_option_is_refused_in_one_line_naming_it(
    capsys, tmp_path, glbs, no_render, flags, message
):
    out = tmp_path / "out"
    err = refused(capsys, "build", "--objects", str(glbs), "--out", str(out), *flags)
    assert f"blurset build: error: {message}" in err, err
    assert not out.exists()


def test_a_blender_that_is_not_executable_is_refused(capsys, tmp_path, glbs, no_render):
    fake = tmp_path / "blender"
    fake.write_text("not a program")
    err = refused(
        capsys,
        "build",
        "--objects",
        str(glbs),
        "--out",
        str(tmp_path / "o"),
        "--blender",
        str(fake),
    )
    assert f"--blender '{fake}': is not executable" in err, err


@pytest.mark.parametrize("value", ['"no"', '"false"', "0", '"yes"'])
def test_toml_demo_must_be_a_boolean(capsys, tmp_path, no_render, value):
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"demo = {value}\n")
    err = refused(capsys, "build", "--config", str(cfg), "--out", str(tmp_path / "out"))
    assert f"{cfg}: demo {value}: must be true or false" in err, err
    assert not (tmp_path / "out").exists()


def test_ray_takes_gpus_per_task(tmp_path):
    from blurset.services.config import make_config

    cfg = make_config({}, {"demo": True, "out": tmp_path, "executor": "ray", "gpus_per_task": 2})
    assert cfg.gpus_per_task == 2.0
    assert make_config({}, {"demo": True, "out": tmp_path, "shard": "1/2"}).shard_index == (1, 2)
