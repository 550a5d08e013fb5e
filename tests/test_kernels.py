"""The Cycles kernels a GPU waits for (issue 47): the notice before the first render, the
cache that outlives the process, the reply time the compile gets. The GPU is the stand-in
worker's (BLURSET_STANDIN_CUDA): it reports an arch Blender ships no kernel for and, at its
first render, writes into the CUDA cache it was given, as the driver's compile does."""

from __future__ import annotations

from pathlib import Path

from blurset.services import kernels
from blurset.services.demo import make_demo_objects
from blurset.services.worker_client import Worker

from tests.conftest import standin_build

NOTICE = "compiling Cycles kernels for sm_90: once per machine, about 8 min"


def test_the_cache_is_the_users_unless_set(tmp_path):
    env = kernels.worker_env({"HOME": str(tmp_path / "home")})
    assert env["CUDA_CACHE_PATH"] == str(tmp_path / "home" / ".cache" / "blurset" / "cuda")
    assert env["OPTIX_CACHE_PATH"] == str(tmp_path / "home" / ".cache" / "blurset" / "optix")
    # Large enough for Blender's 32 MB of kernels beside other programs'.
    assert int(env["CUDA_CACHE_MAXSIZE"]) >= 1 << 30
    env = kernels.worker_env({"HOME": "/h", "XDG_CACHE_HOME": str(tmp_path / "xdg")})
    assert env["CUDA_CACHE_PATH"] == str(tmp_path / "xdg" / "blurset" / "cuda")
    mine = {"HOME": "/h", "CUDA_CACHE_PATH": "/shared/cuda", "CUDA_CACHE_MAXSIZE": "5"}
    assert kernels.worker_env(mine) == kernels.worker_env(mine) | mine


def _ready(arch: str, driver: int = 13000, blender: str = "5.0.1") -> dict:
    cuda = {"archs": [arch], "kernels": ["sm_86", "sm_89", "sm_120"], "driver": driver}
    return {"blender_version": blender, "cuda": cuda}


def test_only_an_arch_blender_ships_no_kernel_for_waits_until_compiled_once(tmp_path):
    env = kernels.worker_env({"HOME": str(tmp_path)})
    assert kernels.to_compile(_ready("sm_89"), env) == []
    assert kernels.to_compile({"blender_version": "5.0.1"}, env) == []  # a CPU worker
    assert kernels.to_compile(_ready("sm_90"), env) == ["sm_90"]
    Path(env["CUDA_CACHE_PATH"]).mkdir(parents=True)
    kernels.mark_compiled(_ready("sm_90"), ["sm_90"], env)
    assert kernels.to_compile(_ready("sm_90"), env) == []
    # Another driver or Blender cannot use that cache: it compiles again.
    assert kernels.to_compile(_ready("sm_90", driver=13010), env) == ["sm_90"]
    assert kernels.to_compile(_ready("sm_90", blender="5.2.3"), env) == ["sm_90"]


def _gpu_env(monkeypatch, tmp_path: Path) -> Path:
    """A stand-in GPU of arch sm_90 and an empty user cache; the CUDA cache folder."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("BLURSET_STANDIN_CUDA", "sm_90")
    monkeypatch.delenv("CUDA_CACHE_PATH", raising=False)
    return tmp_path / "cache" / "blurset" / "cuda"


def test_a_worker_compiling_kernels_gets_the_time_until_its_first_frame(
    tmp_path, standin_blender, monkeypatch
):
    cache = _gpu_env(monkeypatch, tmp_path)
    monkeypatch.setattr(kernels, "_SAID", set())
    glb = make_demo_objects(tmp_path / "objs")[0]
    with Worker(blender=str(standin_blender), timeout=600) as w:
        assert w.reply_wait == 600 + kernels.COMPILE_ALLOWANCE_S
        w.load(glb, tmp_path / "v.npy")  # its QA renders are the first frames
        assert w.reply_wait == 600
    assert (cache / "standin-sm_90.jit").is_file()  # the worker was given this cache
    # and the next worker of this machine starts without the wait
    with Worker(blender=str(standin_blender), timeout=600) as w:
        assert w.reply_wait == 600


def test_a_build_says_so_once_before_its_first_render_and_not_again(
    tmp_path, standin_blender, monkeypatch
):
    cache = _gpu_env(monkeypatch, tmp_path)
    first = standin_build(tmp_path / "a", standin_blender, "--workers", "2")
    said = [ln for ln in first.stderr.splitlines() if ln.startswith("compiling Cycles")]
    # Two workers start together and both compile; one line says so.
    assert len(said) == 1 and said[0].startswith(NOTICE), first.stderr
    assert f"kept in {cache}" in said[0]
    assert (cache / "standin-sm_90.jit").is_file()
    again = standin_build(tmp_path / "b", standin_blender)
    assert "compiling Cycles" not in again.stderr


def test_a_users_cache_path_is_kept(tmp_path, standin_blender, monkeypatch):
    _gpu_env(monkeypatch, tmp_path)
    shared = tmp_path / "shared-cuda"
    monkeypatch.setenv("CUDA_CACHE_PATH", str(shared))
    run = standin_build(tmp_path / "a", standin_blender)
    assert f"kept in {shared}" in run.stderr
    assert (shared / "standin-sm_90.jit").is_file()
    assert not (tmp_path / "cache" / "blurset" / "cuda").exists()
