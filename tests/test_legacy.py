"""The flags that reproduce a dataset built before this round's new defaults (sample
subsets, the parity sample budget, light paths from materials, Deblur-NeRF test views,
images_4/): with them, the
demo build's images and poses are the bytes blurset wrote before (e6029c3, the commit
before the redesign), so a researcher can extend or re-make an existing dataset.

The digest is of bpy 5.0.1's Cycles on this CPU kernel (what CI runs); a different
Cycles build may differ in the last bits, which is why only CI pins it."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest

from tests.conftest import run_cli

LEGACY_FLAGS = (
    "--latent-sampling", "independent", "--light-paths", "fixed", "--blurry-test-views",
    "--downsample", "none", "--trajectory", "start", "--blur-budget", "flat",
)  # fmt: skip

# `find . -name '*.png' -o -name '*.npy' | LC_ALL=C sort | xargs sha256sum | sha256sum`
# of `blurset build --demo` at e6029c3: 255 PNGs and 15 poses_bounds.npy.
BEFORE = "4247aa6bca8330d210f3d98b9055d184e69c872841786f61f9e424c1cdb2b228"


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
    out = tmp_path / "demo"
    run_cli("build", "--demo", "--out", str(out), "--quiet", *LEGACY_FLAGS)
    assert digest(out) == (BEFORE, 270)
