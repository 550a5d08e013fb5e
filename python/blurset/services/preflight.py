"""Pre-flight of a GLB before Blender sees it (DESIGN §10, issue 7).

A bad file gets a clear one-line reason in `failures.jsonl` in milliseconds, instead of
a Blender start, an obscure importer traceback or a hang: empty or foreign files,
truncated chunks, JSON that does not parse, buffers and buffer views that point past
their data, external textures/buffers that are missing, compressions the importer
cannot decode, and meshes or textures beyond the budget.

The GLB container and the compression rules are read by `blender_scripts/glb_inspect.py`
(stdlib only, so a user's own Blender binary can run it too); this module loads that
file, so the rules live in one place.
"""

from __future__ import annotations

import base64
import importlib.util
import json
import struct
from dataclasses import dataclass, field
from pathlib import Path, PureWindowsPath
from typing import Any
from urllib.parse import unquote

import numpy as np

from blurset import _core
from blurset.exceptions import BlursetError
from blurset.services.scripts import blender_script

_GLB_INSPECT = blender_script("glb_inspect.py")
_spec = importlib.util.spec_from_file_location("blurset_glb_inspect", _GLB_INSPECT)
assert _spec is not None and _spec.loader is not None
glb_inspect = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(glb_inspect)

# glTF primitive modes: 4 triangles, 5 strip, 6 fan (0–3 points/lines do not render).
_TRIANGLE_MODES = {4: lambda n: n // 3, 5: lambda n: max(0, n - 2), 6: lambda n: max(0, n - 2)}
# Keyed by what a glTF file may hold there (any JSON value; unknown ones are refused).
_COMPONENT_BYTES: dict[object, int] = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_FLOAT = 5126
_TYPE_COMPONENTS: dict[object, int] = {
    "SCALAR": 1,
    "VEC2": 2,
    "VEC3": 3,
    "VEC4": 4,
    "MAT2": 4,
    "MAT3": 9,
    "MAT4": 16,
}


class PreflightError(BlursetError):
    """The file cannot be rendered; the message is the one-line reason."""


_CORE_DEFAULTS = _core.BuildConfig()


@dataclass(frozen=True)
class Budget:
    # The core's BuildConfig owns the defaults (--max-triangles, --max-texture-pixels).
    max_triangles: int = _CORE_DEFAULTS.max_triangles
    max_texture_pixels: int = _CORE_DEFAULTS.max_texture_pixels


@dataclass(frozen=True)
class Report:
    triangles: int
    texture_pixels: int
    textures: int
    extensions: list[str]
    # The glTF `asset` object as the file has it ({} when absent): who made the model
    # and under which licence, for blurset.services.attribution.
    asset: dict = field(default_factory=dict)


def check(path: Path, budget: Budget = Budget()) -> Report:
    """Raise PreflightError with the reason a file cannot be rendered; else its numbers."""
    path = Path(path)
    try:
        size = path.stat().st_size
    except OSError as e:
        raise PreflightError(f"cannot read: {e.strerror}") from None
    if size == 0:
        raise PreflightError("empty file (0 bytes)")
    try:
        with open(path, "rb") as f:
            head = f.read(4)
    except OSError as e:
        raise PreflightError(f"cannot read: {e.strerror}") from None
    if head == glb_inspect.GLB_MAGIC:
        try:
            doc, bin_chunk = glb_inspect.read_glb(str(path))
        except glb_inspect.GlbError as e:
            raise PreflightError(e.reason) from None
        except (OSError, MemoryError) as e:
            raise PreflightError(f"cannot read: {e}") from None
    elif head.lstrip()[:1] == b"{":
        try:
            doc, bin_chunk = json.loads(path.read_text("utf-8")), None
        except UnicodeDecodeError as e:
            raise PreflightError(
                f"the glTF JSON is not UTF-8 (glTF requires UTF-8; byte {e.start})"
            ) from None
        except ValueError as e:
            raise PreflightError(f"glTF JSON does not parse ({e})") from None
        if not isinstance(doc, dict):
            raise PreflightError("glTF JSON is not an object")
    else:
        raise PreflightError(f"not a glTF/GLB file (starts with {head!r}, expected b'glTF')")
    try:
        return _check_document(doc, bin_chunk, path.parent, budget)
    except PreflightError:
        raise
    except (TypeError, ValueError, AttributeError, KeyError, IndexError, OverflowError) as e:
        # A wrongly typed field anywhere (`"count": "x"`, `"primitives": {}` …) is this
        # file's failure, never the build's.
        text = " ".join(str(e).split())[:200]
        raise PreflightError(f"malformed glTF JSON ({type(e).__name__}: {text})") from None


def _check_document(doc: dict, bin_chunk: bytes | None, base: Path, budget: Budget) -> Report:
    version = str((doc.get("asset") or {}).get("version", ""))
    if not version.startswith("2"):
        raise PreflightError(f"glTF asset version {version or 'missing'!r} (need 2.x)")
    problem = glb_inspect.compression_problem(doc, draco_available=True)
    if problem:
        raise PreflightError(problem)
    buffers = [_buffer_length(i, b, bin_chunk, base) for i, b in enumerate(_list(doc, "buffers"))]
    views = _list(doc, "bufferViews")
    for i, v in enumerate(views):
        b = v.get("buffer")
        if not isinstance(b, int) or not 0 <= b < len(buffers):
            raise PreflightError(f"bufferView {i} names buffer {b!r}, which does not exist")
        end = int(v.get("byteOffset", 0)) + int(v.get("byteLength", 0))
        if end > buffers[b]:
            raise PreflightError(
                f"truncated data: bufferView {i} ends at byte {end} of buffer {b}, "
                f"which has {buffers[b]} bytes"
            )
    accessors = _list(doc, "accessors")
    for i, a in enumerate(accessors):
        _check_accessor(i, a, views)
    _check_positions(doc, accessors, views, _Buffers(_list(doc, "buffers"), bin_chunk, base))
    triangles = _triangles(doc, accessors)
    if triangles == 0:
        raise PreflightError("no triangles: the file has no renderable mesh")
    if triangles > budget.max_triangles:
        raise PreflightError(
            f"mesh too large: {triangles} triangles (budget --max-triangles {budget.max_triangles})"
        )
    pixels, n_tex = _texture_pixels(doc, views, buffers, bin_chunk, base)
    if pixels > budget.max_texture_pixels:
        raise PreflightError(
            f"textures too large: {pixels} pixels in {n_tex} images "
            f"(budget --max-texture-pixels {budget.max_texture_pixels})"
        )
    asset = doc.get("asset")
    return Report(
        triangles,
        pixels,
        n_tex,
        sorted(glb_inspect._extensions(doc)),
        asset if isinstance(asset, dict) else {},
    )


def _list(doc: dict, key: str) -> list[dict]:
    v = doc.get(key) or []
    if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
        raise PreflightError(f"glTF {key!r} is not a list of objects")
    return v


def _external(uri: object, base: Path, what: str) -> Path:
    """The file an external URI names. URIs are relative references inside the model's
    folder: an absolute path, a NUL or one that leaves the folder is refused (Blender's
    importer would open whatever it names)."""
    if not isinstance(uri, str):
        raise PreflightError(f"{what} has a uri that is not a string: {uri!r}")
    name = unquote(uri)
    if "\0" in name or "://" in name or name.startswith(("/", "\\")) or PureWindowsPath(name).drive:
        raise PreflightError(
            f"{what}: uri {uri!r} is not a relative path inside the model's folder"
        )
    root = base.resolve()
    p = (root / name).resolve()
    if not p.is_relative_to(root):
        raise PreflightError(f"{what}: uri {uri!r} leaves the model's folder")
    if not p.is_file():
        raise PreflightError(f"missing {what}: {uri!r} is not next to the file")
    return p


def _data_uri(uri: object) -> bytes | None:
    if not isinstance(uri, str) or not uri.startswith("data:"):
        return None
    try:
        return base64.b64decode(uri.split(",", 1)[1], validate=False)
    except (IndexError, ValueError):
        raise PreflightError("a data: URI does not decode as base64") from None


def _buffer_length(i: int, b: dict, bin_chunk: bytes | None, base: Path) -> int:
    declared = int(b.get("byteLength", 0))
    uri = b.get("uri")
    if uri is None:
        have = len(bin_chunk) if bin_chunk is not None else 0
        what = "the GLB BIN chunk"
    elif (data := _data_uri(uri)) is not None:
        have, what = len(data), "its data: URI"
    else:
        have, what = _external(uri, base, f"buffer {i}").stat().st_size, repr(uri)
    if have < declared:
        raise PreflightError(
            f"truncated data: buffer {i} declares {declared} bytes, {what} has {have}"
        )
    return declared


def _check_accessor(i: int, a: dict, views: list[dict]) -> None:
    for key in ("count", "byteOffset"):
        n = a.get(key, 0)
        if isinstance(n, bool) or not isinstance(n, int) or n < 0:
            raise PreflightError(f"accessor {i} has {key} {n!r}, not a count ≥ 0")
    v = a.get("bufferView")
    if v is None:
        return  # all zeros (or sparse only): nothing to read out of bounds
    if not isinstance(v, int) or not 0 <= v < len(views):
        raise PreflightError(f"accessor {i} names bufferView {v!r}, which does not exist")
    comp = _COMPONENT_BYTES.get(a.get("componentType"))
    ncomp = _TYPE_COMPONENTS.get(a.get("type"))
    if comp is None or ncomp is None:
        raise PreflightError(f"accessor {i} has an unknown component type or element type")
    count = int(a.get("count", 0))
    elem = comp * ncomp
    stride = int(views[v].get("byteStride") or elem)
    need = int(a.get("byteOffset", 0)) + (stride * (count - 1) + elem if count else 0)
    if need > int(views[v].get("byteLength", 0)):
        raise PreflightError(
            f"truncated data: accessor {i} needs {need} bytes of bufferView {v}, "
            f"which has {views[v].get('byteLength', 0)}"
        )


class _Buffers:
    """A file's buffers by index, each read once when first asked for: the GLB's BIN
    chunk, a data: URI's bytes, or an external file mapped (not read) into memory."""

    def __init__(self, buffers: list[dict], bin_chunk: bytes | None, base: Path) -> None:
        self.buffers, self.bin_chunk, self.base = buffers, bin_chunk, base
        self.data: dict[int, Any] = {}

    def __getitem__(self, i: int) -> Any:
        if i not in self.data:
            uri = self.buffers[i].get("uri")
            if uri is None:
                self.data[i] = self.bin_chunk or b""
            elif (data := _data_uri(uri)) is not None:
                self.data[i] = data
            else:
                path = _external(uri, self.base, f"buffer {i}")
                self.data[i] = np.memmap(path, mode="r") if path.stat().st_size else b""
        return self.data[i]


def _position_accessors(doc: dict) -> dict[int, str]:
    """The accessors that place vertices (each primitive's POSITION, its morph targets'),
    with how a message names them."""
    found: dict[int, str] = {}
    for mi, mesh in enumerate(_list(doc, "meshes")):
        for prim in mesh.get("primitives") or []:
            for k, attrs in enumerate([prim.get("attributes") or {}, *(prim.get("targets") or [])]):
                a = attrs.get("POSITION")
                if isinstance(a, int) and not isinstance(a, bool):
                    found.setdefault(a, f"mesh {mi}" + (f" morph target {k - 1}" if k else ""))
    return found


def _check_positions(doc: dict, accessors: list[dict], views: list[dict], data: _Buffers) -> None:
    """Every vertex position is a finite number. Blender's importer sets a NaN or
    infinite coordinate to 0 without a word (its mesh validation), so such a file would
    build as another shape, normalized as if whole: it is this file's failure instead.
    (Draco-compressed positions are decoded by Blender only; not seen here.)"""
    for i, where in sorted(_position_accessors(doc).items()):
        if not 0 <= i < len(accessors) or accessors[i].get("componentType") != _FLOAT:
            continue  # a missing accessor is the importer's to refuse; integers are finite
        a = accessors[i]
        ncomp = _TYPE_COMPONENTS[a.get("type")]
        parts = []
        if isinstance(v := a.get("bufferView"), int):
            start = int(views[v].get("byteOffset", 0)) + int(a.get("byteOffset", 0))
            stride = int(views[v].get("byteStride") or 4 * ncomp)
            arr = _floats(data[views[v]["buffer"]], start, int(a["count"]), ncomp, stride)
            parts.append(("vertex", arr))
        sparse = a.get("sparse")
        if isinstance(sparse, dict):
            values = sparse["values"]
            view = views[values["bufferView"]]
            start = int(view.get("byteOffset", 0)) + int(values.get("byteOffset", 0))
            arr = _floats(data[view["buffer"]], start, int(sparse["count"]), ncomp, 4 * ncomp)
            parts.append(("sparse value", arr))
        for what, arr in parts:
            bad = ~np.isfinite(arr).all(axis=1)
            if bad.any():
                k = int(np.argmax(bad))
                raise PreflightError(
                    f"non-finite vertex position: accessor {i} (POSITION of {where}) holds "
                    f"{arr[k].tolist()} at {what} {k} (Blender's importer would set it to 0 without a word)"
                )


def _floats(buf: Any, start: int, count: int, ncomp: int, stride: int) -> Any:
    """`count` little-endian float32 elements of `ncomp` components at `start`, `stride`
    bytes apart, viewed in `buf` without a copy (ValueError/TypeError past its end)."""
    if count == 0:
        return np.zeros((0, ncomp), dtype="<f4")
    return np.ndarray((count, ncomp), dtype="<f4", buffer=buf, offset=start, strides=(stride, 4))


def _triangles(doc: dict, accessors: list[dict]) -> int:
    """Triangles drawn: each mesh's primitives times the nodes that instance it."""
    uses: dict[int, int] = {}
    for node in _list(doc, "nodes"):
        m = node.get("mesh")
        if isinstance(m, int):
            uses[m] = uses.get(m, 0) + 1
    total = 0
    for mi, mesh in enumerate(_list(doc, "meshes")):
        for prim in mesh.get("primitives") or []:
            per = _TRIANGLE_MODES.get(int(prim.get("mode", 4)))
            if per is None:
                continue
            idx = prim.get("indices")
            src = idx if isinstance(idx, int) else (prim.get("attributes") or {}).get("POSITION")
            if isinstance(src, int) and 0 <= src < len(accessors):
                total += per(int(accessors[src].get("count", 0))) * uses.get(mi, 0)
            elif "KHR_draco_mesh_compression" in (prim.get("extensions") or {}):
                total += uses.get(mi, 0)  # decoded by Blender; count unknown but present
    return total


def _texture_pixels(
    doc: dict, views: list[dict], buffers: list[int], bin_chunk: bytes | None, base: Path
) -> tuple[int, int]:
    total, n = 0, 0
    for i, img in enumerate(_list(doc, "images")):
        head = b""
        uri = img.get("uri")
        if uri is not None:
            data = _data_uri(uri)
            if data is None:
                with open(_external(uri, base, f"texture (image {i})"), "rb") as f:
                    head = f.read(1 << 16)
            else:
                head = data[: 1 << 16]
        elif isinstance(img.get("bufferView"), int) and bin_chunk is not None:
            v = views[img["bufferView"]]
            if v.get("buffer") == 0 and not (_list(doc, "buffers")[0].get("uri")):
                off = int(v.get("byteOffset", 0))
                head = bin_chunk[off : off + min(int(v.get("byteLength", 0)), 1 << 16)]
        wh = image_size(head)
        if wh is not None:
            total += wh[0] * wh[1]
            n += 1
    return total, n


def image_size(head: bytes) -> tuple[int, int] | None:
    """(width, height) from the first bytes of a PNG or JPEG, else None."""
    if head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) >= 24:
        return struct.unpack(">II", head[16:24])
    if head[:2] == b"\xff\xd8":
        i = 2
        while i + 9 < len(head):
            if head[i] != 0xFF:
                i += 1
                continue
            marker = head[i + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
                i += 2
                continue
            (length,) = struct.unpack(">H", head[i + 2 : i + 4])
            if 0xC0 <= marker <= 0xCF and marker not in (0xC4, 0xC8, 0xCC):
                h, w = struct.unpack(">HH", head[i + 5 : i + 9])
                return w, h
            i += 2 + length
    return None
