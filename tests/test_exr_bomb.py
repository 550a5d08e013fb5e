"""Issue 60 (H5z), untrusted input: a 4.2 MB ZIP EXR that is a valid, blank 16384² RGBA
float frame (blank frames compress about 1000:1, the deflate bound issue 48's check
allows) made `verify` peak at 4.26 GB, `noise --source linear` over three such files at
8.2 GB, and both abort (rc 134) under an address-space cap. A caller that knows the size
a file must have checks its header first; a reader that does not fails cleanly when the
frame cannot be held. Each command runs under issue 48's 1.5 GB cap."""

from __future__ import annotations

import struct
import subprocess
import sys
import zlib
from pathlib import Path

import pytest
from blurset import layout

from tests.conftest import one_error_line, standin_build
from tests.test_bounded_memory import _capped, exr_header, run_capped, tiny_blocks


def zip_bomb(side: int = 16384, lines: int = 16, channels: bytes = b"ABGR") -> bytes:
    """A valid ZIP scan-line EXR (`lines` a block) of a `side`² float frame of zeros
    (RGBA, or `channels`): 4.2 MB at 16384²."""
    head = exr_header(channels, 2, 3, side)  # ZIP: 16 lines a block

    def data(rows: int) -> bytes:
        # Zeros after ZIP's byte predictor: the first byte 0, every other one 128.
        return zlib.compress(b"\0" + b"\x80" * (rows * side * 4 * len(channels) - 1), 9)

    full = data(lines)
    blocks = []
    for y in range(0, side, lines):
        d = full if y + lines <= side else data(side - y)
        blocks.append(struct.pack("<ii", y, len(d)) + d)
    offsets, at = [], len(head) + 8 * len(blocks)
    for b in blocks:
        offsets.append(at)
        at += len(b)
    return head + struct.pack(f"<{len(blocks)}Q", *offsets) + b"".join(blocks)


def test_the_crafted_file_is_a_valid_frame(tmp_path):
    """The small one decodes whole: the big one is no broken file but a blank frame."""
    from blurset.image import read_exr

    p = tmp_path / "small.exr"
    p.write_bytes(zip_bomb(40))
    frame = read_exr(p)
    assert frame.shape == (40, 40, 4) and float(abs(frame).max()) == 0.0
    assert 4_000_000 < len(zip_bomb()) < 4_400_000


@pytest.fixture
def bombed(standin_blender, tmp_path) -> tuple[Path, list[Path]]:
    """A `--keep-linear` stand-in build (32 px) whose first setting's first three sharp
    linear EXRs are the 16384² ZIP frame."""
    out = tmp_path / "b"
    standin_build(out, standin_blender, "--keep-linear")
    setting = layout.complete_settings(out)[0]
    exrs = sorted((setting / "sharp" / "linear").glob("*.exr"))[:3]
    bomb = zip_bomb()
    for p in exrs:
        p.write_bytes(bomb)
    return out, exrs


def _no_abort(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode not in (134, -6), proc.stderr[-2000:]
    for words in ("memory allocation of", "panicked", "Traceback"):
        assert words not in proc.stderr, proc.stderr[-2000:]


def test_verify_names_the_size_from_the_header(bombed):
    out, exrs = bombed
    proc = run_capped("verify", str(out))
    _no_abort(proc)
    assert proc.returncode == 1, (proc.returncode, proc.stderr[-2000:])
    for p in exrs:
        said = [x for x in proc.stdout.splitlines() if p.name in x and str(p.parent.name) in x]
        assert any("16384x16384" in x and "32x32" in x for x in said), proc.stdout
        assert not any("decode" in x for x in said), said


def test_noise_linear_refuses_the_file_before_decoding(bombed, tmp_path):
    """The build's cheap check names the size from the header (the noise run refuses a
    damaged setting before it plans a unit)."""
    out, exrs = bombed
    proc = run_capped("noise", str(out), "--gains", "1", "--out", str(tmp_path / "n"))
    _no_abort(proc)
    line = one_error_line(proc, "16384x16384 px, not 32x32", code=proc.returncode)
    assert proc.returncode != 0
    assert any(p.name in line for p in exrs), line
    assert not (tmp_path / "n").exists() or not any((tmp_path / "n").rglob("*.png"))


def test_the_linear_writer_reads_every_size_before_decoding(tmp_path):
    """`noise_write_variants_linear` (no size given: the first source's) over a 32 px
    frame and two 16384² ones: refused from the second's header, nothing decoded."""
    good = tmp_path / "src" / "000.exr"
    good.parent.mkdir()
    good.write_bytes(zip_bomb(32))
    for name in ("001.exr", "002.exr"):
        (good.parent / name).write_bytes(zip_bomb())
    code = (
        "import sys\nfrom pathlib import Path\n"
        "from blurset.noise.model import noise_write_variants_linear\n"
        "src = sorted(Path(sys.argv[1]).glob('*.exr'))\n"
        "try:\n    noise_write_variants_linear(src, [p.stem for p in src],"
        " [(sys.argv[2], 0.01, 0.01, 1)])\n"
        "except Exception as e:\n    print(type(e).__name__, e)\n    sys.exit(3)\n"
    )
    out = tmp_path / "out"
    proc = subprocess.run(
        [sys.executable, "-c", code, str(good.parent), str(out)],
        capture_output=True, text=True, preexec_fn=_capped,
    )  # fmt: skip
    _no_abort(proc)
    assert proc.returncode == 3, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    said = "EXR is 16384x16384, expected 32x32; refused before decoding it"
    assert said in proc.stdout and "001.exr" in proc.stdout, proc.stdout
    assert not any(out.rglob("*.png")), "a frame was written"


def test_a_reader_without_a_size_fails_cleanly_when_the_frame_cannot_be_held(tmp_path):
    """`blurset.image.read_exr` knows no size: the 4 GiB frame the valid file holds, past the cap, is an
    ImageError naming the file, not an abort."""
    bomb = tmp_path / "bomb.exr"
    bomb.write_bytes(zip_bomb())
    code = (
        "import sys\nfrom blurset.image import read_exr\n"
        "try:\n    read_exr(sys.argv[1])\n"
        "except Exception as e:\n    print(type(e).__name__, e)\n    sys.exit(3)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, str(bomb)],
        capture_output=True, text=True, preexec_fn=_capped,
    )  # fmt: skip
    _no_abort(proc)
    assert proc.returncode == 3, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    assert "cannot allocate" in proc.stdout and "16384x16384" in proc.stdout, proc.stdout
    assert "bomb.exr" in proc.stdout, proc.stdout


_OPEN = (
    "import sys\nfrom blurset.data import open_scene\n"
    "try:\n    open_scene(sys.argv[1], sys.argv[2])\n"
    "except Exception as e:\n    print(type(e).__name__, e)\n    sys.exit(3)\n"
)


def _open_capped(root: Path, setting: str) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [sys.executable, "-c", _OPEN, str(root), setting],
        capture_output=True, text=True, preexec_fn=_capped,
    )  # fmt: skip
    _no_abort(proc)
    assert proc.returncode == 3, (proc.returncode, proc.stdout, proc.stderr[-2000:])
    return proc


@pytest.fixture
def passes_build(standin_blender, tmp_path) -> Path:
    out = tmp_path / "p"
    standin_build(
        out, standin_blender, "--passes", "depth,normal,mask", "--settings-per-object", "1"
    )
    return out


def test_open_scene_refuses_a_pass_file_of_another_size_from_its_header(passes_build):
    """open_scene reads a build's depth and normals at the images' size: a 16384² depth
    file is refused from its header, named, under the cap (it aborted: a 1 GiB frame)."""
    setting = layout.complete_settings(passes_build)[0]
    bombed = setting / "sharp" / "depth" / "000.exr"
    bombed.write_bytes(zip_bomb())
    proc = _open_capped(passes_build, setting.name)
    assert "EXR is 16384x16384, expected 32x32" in proc.stdout, proc.stdout
    assert str(bombed) in proc.stdout, proc.stdout


def test_open_scene_refuses_an_image_or_mask_of_another_size_from_its_header(passes_build):
    """Issue 72: the scene's size is its poses' record, and a PNG of another is refused
    from its header, named, under the cap: a 16384² RGBA16 image (2 GiB decoded) as the
    first image, whose size the others were once compared with, or as a mask; and a pose
    file promising a million rows it does not hold."""
    setting = layout.complete_settings(passes_build)[0]
    sharp = setting / "sharp"
    bomb = png_bomb()
    first = sorted((sharp / layout.images_dir(1)).glob("*.png"))[0]
    mask = sharp / layout.pass_dir("mask", 1) / layout.pass_file("mask", first.name)
    for p in (first, mask):
        kept = p.read_bytes()
        p.write_bytes(bomb)
        proc = _open_capped(passes_build, setting.name)
        assert "image is 16384x16384 px, the scene's are 32x32" in proc.stdout, proc.stdout
        assert str(p) in proc.stdout, proc.stdout
        p.write_bytes(kept)
    poses = sharp / layout.POSES_BOUNDS
    head = b"{'descr': '<f8', 'fortran_order': False, 'shape': (1048576, 17), }"
    poses.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(head)) + head)
    proc = _open_capped(passes_build, setting.name)
    assert "for 1048576 rows" in proc.stdout and str(poses) in proc.stdout, proc.stdout


def test_open_scene_refuses_a_hub_pass_cell_of_another_size_naming_it(passes_build, tmp_path):
    """The same through a hub export whose depth cell was swapped for the 16384² frame
    (shard and export.json rewritten to match, as a hostile upload would): refused from
    the cell's header, named by setting, view and column."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    hub = tmp_path / "h"
    subprocess.run([sys.executable, "-m", "blurset.cli", "export", str(passes_build),
                    "--for", "hub", "--out", str(hub)], check=True, capture_output=True)  # fmt: skip
    shard = next((hub / "data" / "sharp").glob("*.parquet"))
    table = pq.read_table(shard)
    i = table.schema.get_field_index("depth")
    cells = table.column(i).to_pylist()
    cells[0] = zip_bomb()
    table = table.set_column(i, table.schema.field(i), pa.array(cells, pa.binary()))
    pq.write_table(table.replace_schema_metadata(pq.read_schema(shard).metadata), shard)
    setting = table.column("setting")[0].as_py()
    proc = _open_capped(hub, setting)
    said = f"the depth cell of {setting} view {table.column('view')[0].as_py()} does not decode"
    assert said in proc.stdout and "EXR is 16384x16384, expected 32x32" in proc.stdout, proc.stdout


def rle_bomb(side: int = 16384) -> bytes:
    """A valid RLE scan-line EXR (a line a block) of a `side`² RGB half frame of zeros,
    which the crate decodes: 25 MB promising 1.5 GiB of samples (RLE's bound is 64:1)."""
    head = exr_header(b"BGR", 1, 1, side)
    n = side * 3 * 2 - 1  # after the predictor: a 0, then 128s, in runs of at most 128
    runs = b"\x00\x00" + b"\x7f\x80" * (n // 128) + bytes([n % 128 - 1, 0x80])
    blocks = [struct.pack("<ii", y, len(runs)) + runs for y in range(side)]
    first = len(head) + 8 * side
    table = struct.pack(f"<{side}Q", *(first + y * len(blocks[0]) for y in range(side)))
    return head + table + b"".join(blocks)


def png_bomb(side: int = 16384, color: int = 6, depth: int = 16) -> bytes:
    """A valid PNG of a `side`² black image (`color` 2 RGB, 6 RGBA; `depth` bits a
    sample): 2.1 MB promising 2 GiB at 16384² RGBA16, 0.8 MB promising 768 MiB as RGB8."""

    def chunk(kind: bytes, body: bytes) -> bytes:
        return (
            struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
        )

    rows = bytes(1 + side * {2: 3, 6: 4}[color] * depth // 8) * 16  # filter byte 0, zeros
    # Deflated once: after a full flush the stream forgets what came before, so each
    # further 16 rows deflate to the same bytes; the Adler-32 of n zeros is n << 16 | 1.
    z = zlib.compressobj(9)
    first, again = (z.compress(rows) + z.flush(zlib.Z_FULL_FLUSH) for _ in range(2))
    end = z.flush()[:-4] + struct.pack(">I", (len(rows) * side // 16 % 65521) << 16 | 1)
    idat = first + again * (side // 16 - 1) + end
    ihdr = struct.pack(">IIBBBBB", side, side, depth, color, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", idat) + chunk(b"IEND", b"")


#: Each public reader of a file, and the crafted files: issue 72 (`read_depth` of
#: zip_bomb() peaked at 4.14 GB and aborted under a 3 GB cap; here, under 1.5 GB).
READERS = ("read_exr", "read_depth", "read_image", "image_info")
CRAFTED = {
    "rgba.exr": lambda: zip_bomb(),
    "depth.exr": lambda: zip_bomb(channels=b"Y"),
    "depth_8192.exr": lambda: zip_bomb(8192, channels=b"Y"),  # 256 MiB: it fits
    "rle.exr": rle_bomb,
    "tiny.exr": tiny_blocks,
    "rgba16.png": lambda: png_bomb(),
    "rgb8.png": lambda: png_bomb(color=2, depth=8),  # 768 MiB: it fits
}
_READ = (
    "import sys\nimport numpy as np\nfrom blurset import image\n"
    "try:\n    a = getattr(image, sys.argv[1])(sys.argv[2])\n"
    "except Exception as e:\n    print(type(e).__name__, e)\n    sys.exit(3)\n"
    # VmHWM, this process's own peak: ru_maxrss keeps the parent's across fork and exec
    # (a large pytest process read as the reader's peak).
    "hwm = [ln for ln in open('/proc/self/status') if ln.startswith('VmHWM:')][0]\n"
    "print(np.asarray(a).nbytes, int(hwm.split()[1]) << 10)\n"
)


@pytest.fixture(scope="module")
def crafted_files(tmp_path_factory) -> Path:
    d = tmp_path_factory.mktemp("crafted")
    for name, make in CRAFTED.items():
        (d / name).write_bytes(make())
    return d


@pytest.mark.parametrize("name", CRAFTED)
@pytest.mark.parametrize("reader", READERS)
def test_every_public_reader_refuses_cleanly_or_holds_little_more_than_its_output(
    crafted_files, reader, name
):
    """Under the 1.5 GB cap each reader either refuses the file in one error naming it, or
    returns its array having held at most that array and the interpreter (RSS peak),
    never an abort: what a decode holds is known from the header before it allocates."""
    path = crafted_files / name
    proc = subprocess.run(
        [sys.executable, "-c", _READ, reader, str(path)],
        capture_output=True, text=True, preexec_fn=_capped,
    )  # fmt: skip
    _no_abort(proc)
    assert proc.returncode in (0, 3), (proc.returncode, proc.stdout, proc.stderr[-2000:])
    if proc.returncode == 3:
        assert str(path) in proc.stdout and proc.stdout.count("\n") == 1, proc.stdout
    else:
        held, peak = map(int, proc.stdout.split())
        assert peak < held + (160 << 20), (reader, name, held, peak)
