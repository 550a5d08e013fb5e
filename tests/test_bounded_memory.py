"""Issue 48, untrusted input: what a command allocates is bounded by the images it
finally holds. An EXR header at the pixel limit (16384² dataWindow) over a whole offset
table of tiny blocks used to make `verify` allocate 4 GiB before the blocks were checked,
and `noise` over three such files abort under an address-space cap (rc 134). Real
commands on a stand-in build, each under a 1.5 GB address-space cap."""

from __future__ import annotations

import resource
import struct
import subprocess
import sys
from pathlib import Path

import pytest
from blurset import layout

from tests.conftest import one_error_line, standin_build

CAP = 1536 << 20  # bytes of address space: a third of one 16384² RGBA f32 frame


def exr_header(channels: bytes, pixel_type: int, compression: int, side: int) -> bytes:
    """A scan-line EXR's magic, version and header: `channels` (one byte a name) of
    `pixel_type` (1 half, 2 float), a `side`² data and display window, `compression`
    (2 ZIPS, 3 ZIP)."""

    def attr(name: str, ty: str, value: bytes) -> bytes:
        return name.encode() + b"\0" + ty.encode() + b"\0" + struct.pack("<i", len(value)) + value

    chlist = b"".join(
        bytes([c]) + b"\0" + struct.pack("<iiii", pixel_type, 0, 1, 1) for c in channels
    )
    window = struct.pack("<iiii", 0, 0, side - 1, side - 1)
    return struct.pack("<ii", 20000630, 2) + b"".join([
        attr("channels", "chlist", chlist + b"\0"),
        attr("compression", "compression", bytes([compression])),
        attr("dataWindow", "box2i", window),
        attr("displayWindow", "box2i", window),
        attr("lineOrder", "lineOrder", b"\0"),
        attr("pixelAspectRatio", "float", struct.pack("<f", 1.0)),
        attr("screenWindowCenter", "v2f", struct.pack("<ff", 0, 0)),
        attr("screenWindowWidth", "float", struct.pack("<f", 1.0)),
    ]) + b"\0"  # fmt: skip


def tiny_blocks(side: int = 16384, block: int = 16) -> bytes:
    """A ZIPS scan-line EXR (R, G, B half; a block a line) with a `side`² data and
    display window and a whole, valid offset table of blocks of `block` zero bytes:
    525 KB at 16384², the issue's file."""
    head = exr_header(b"BGR", 1, 2, side)  # ZIPS: one line a block
    first = len(head) + 8 * side
    table = b"".join(struct.pack("<Q", first + y * (8 + block)) for y in range(side))
    blocks = b"".join(struct.pack("<ii", y, block) + bytes(block) for y in range(side))
    return head + table + blocks


def _capped() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (CAP, CAP))


def run_capped(*args: str) -> subprocess.CompletedProcess:
    """`blurset ARGS` in a child whose address space is capped at CAP."""
    return subprocess.run(
        [sys.executable, "-m", "blurset.cli", *args],
        capture_output=True, text=True, preexec_fn=_capped,
    )  # fmt: skip


@pytest.fixture
def crafted(standin_blender, tmp_path) -> tuple[Path, list[Path]]:
    """A `--keep-linear` stand-in build whose first setting's first three sharp linear
    EXRs are issue 48's file."""
    out = tmp_path / "b"
    standin_build(out, standin_blender, "--keep-linear")
    setting = layout.complete_settings(out)[0]
    exrs = sorted((setting / "sharp" / "linear").glob("*.exr"))[:3]
    for p in exrs:
        p.write_bytes(tiny_blocks())
    return out, exrs


def test_verify_refuses_a_header_at_the_pixel_limit_over_tiny_blocks(crafted):
    out, exrs = crafted
    proc = run_capped("verify", str(out))
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])
    # Its size is named from the header before any decode (issue 60); the decoders'
    # own refusal of such a file is tested beside them (rust/core/src/image/exr/read.rs).
    for p in exrs:
        line = next(x for x in proc.stdout.splitlines() if p.name in x and "16384" in x)
        assert "16384x16384 px, not 32x32" in line, line
    assert "panicked" not in proc.stderr and "Traceback" not in proc.stderr, proc.stderr


def test_noise_refuses_three_such_files_with_one_line(crafted, tmp_path):
    out, exrs = crafted
    proc = run_capped("noise", str(out), "--gains", "1", "--out", str(tmp_path / "n"))
    line = one_error_line(proc, "16384x16384 px, not 32x32", code=proc.returncode)
    assert proc.returncode not in (0, 134, -6), proc.stderr
    assert any(p.name in line for p in exrs), line
    assert not (tmp_path / "n").exists() or not any((tmp_path / "n").rglob("*.png"))
