"""The flags that reproduce a dataset built before this round's new defaults (sample
subsets, the parity sample budget, light paths from materials, Deblur-NeRF test views,
images_4/): with them, the
demo build's images and poses are the bytes blurset wrote before (e6029c3, the commit
before the redesign), so a researcher can extend or re-make an existing dataset.

Cycles' CPU renders differ in their last bits between processors (the same AVX2 kernel
gives other bytes on an AMD EPYC and on an Intel Xeon), so the digest of e6029c3's demo
is recorded per processor it was made on; a processor without one skips, except under
CI=true."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from tests.conftest import IN_CI, run_cli

LEGACY_FLAGS = (
    "--latent-sampling", "independent", "--light-paths", "fixed", "--blurry-test-views",
    "--downsample", "none", "--trajectory", "start", "--blur-budget", "flat",
)  # fmt: skip

# `find . -name '*.png' -o -name '*.npy' | LC_ALL=C sort | xargs sha256sum | sha256sum`
# of `blurset build --demo` at e6029c3 (255 PNGs and 15 poses_bounds.npy), by the CPU's
# `model name` in /proc/cpuinfo; each made by checking out e6029c3 and running `make demo`.
BEFORE = {
    "AMD EPYC": "4247aa6bca8330d210f3d98b9055d184e69c872841786f61f9e424c1cdb2b228",
    "Intel(R) Xeon(R) Processor": "b2b2738df3a9e86da6c03ba060151734deb4f92523905b069e68e4eeb808454b",
}


def cpu_model() -> str:
    """The first `model name` of /proc/cpuinfo ("" where there is none)."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def digest_before() -> str:
    """e6029c3's digest on this processor; skip (fail under CI) without one."""
    model = cpu_model()
    for prefix, d in BEFORE.items():
        if model.startswith(prefix):
            return d
    msg = f"no digest of e6029c3's demo recorded for this CPU ({model or 'unknown'})"
    if IN_CI:
        pytest.fail(f"CI=true: {msg}")
    pytest.skip(msg)


def digest(root: Path) -> tuple[str, int]:
    files = sorted(
        (p for p in root.rglob("*") if p.suffix in (".png", ".npy")),
        key=lambda p: str(p.relative_to(root)).encode(),
    )
    lines = "".join(
        f"{hashlib.sha256(p.read_bytes()).hexdigest()}  ./{p.relative_to(root)}\n" for p in files
    )
    return hashlib.sha256(lines.encode()).hexdigest(), len(files)


@pytest.mark.blender
def test_legacy_flags_reproduce_the_demo_build_of_before(tmp_path):
    before = digest_before()
    out = tmp_path / "demo"
    run_cli("build", "--demo", "--out", str(out), "--quiet", *LEGACY_FLAGS)
    assert digest(out) == (before, 270)
