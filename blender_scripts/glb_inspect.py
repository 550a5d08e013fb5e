"""Read and rewrite the JSON chunk of a GLB before Blender sees it (stdlib only).

Two jobs that are easier on the glTF JSON than on Blender's imported node trees:
refuse compressions this Blender cannot decode, with a clear reason, before the importer
fails obscurely; and repair unlit (KHR_materials_unlit) materials whose colour lives in
the emissive slot, which Blender's importer would render black.
"""

from __future__ import annotations

import base64
import copy
import json
import os
import struct
from urllib.parse import unquote

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

# Extensions whose data the importer cannot read at all: the mesh or texture would be
# missing or garbage, so the object must fail rather than render wrong.
MESHOPT = ("EXT_meshopt_compression", "KHR_meshopt_compression")
DRACO = "KHR_draco_mesh_compression"
BASISU = "KHR_texture_basisu"

BLACK = 1e-6

# The largest JSON chunk a GLB may declare: a glTF document is kilobytes to a few
# megabytes (the data lives in the BIN chunk); past this the header is taken as hostile
# and refused before anything of its size is read.
MAX_GLB_JSON_BYTES = 256 * 1024 * 1024


class GlbError(ValueError):
    """The file is not a GLB this tool can read; the message is one line: `reason`, then
    the file (`path`), both kept as fields so no caller parses the message."""

    def __init__(self, reason: str, path: str) -> None:
        super().__init__(f"{reason}: {path}")
        self.reason, self.path = reason, path


def read_glb(path: str) -> tuple[dict, bytes | None]:
    """The JSON document and the BIN chunk (or None) of a binary glTF file. The file is
    not trusted: every length its header declares is checked before anything of that
    size is read (the total against the file's real size, a chunk against the bytes
    left, the JSON chunk against MAX_GLB_JSON_BYTES), so a hostile or truncated header
    is a GlbError naming the file, never a huge allocation or a traceback."""
    with open(path, "rb") as f:
        total = _glb_total(f, path)
        offset = 12
        doc = None
        bin_chunk = None
        while offset + 8 <= total:
            chunk_head = f.read(8)
            if len(chunk_head) != 8:
                raise GlbError(f"truncated GLB chunk header at byte {offset}", path)
            length, ctype = struct.unpack("<II", chunk_head)
            left = total - offset - 8
            if ctype == CHUNK_JSON and doc is None and length > MAX_GLB_JSON_BYTES:
                raise GlbError(
                    f"GLB JSON chunk of {length} bytes is larger than the limit "
                    f"MAX_GLB_JSON_BYTES ({MAX_GLB_JSON_BYTES})",
                    path,
                )
            if length > left:
                raise GlbError(
                    f"truncated GLB chunk at byte {offset}: it declares {length} bytes, "
                    f"{left} remain",
                    path,
                )
            wanted = (ctype == CHUNK_JSON and doc is None) or (
                ctype == CHUNK_BIN and bin_chunk is None
            )
            if not wanted:  # another chunk (allowed by the spec): skipped, not read
                f.seek(length, os.SEEK_CUR)
                offset += 8 + length
                continue
            body = f.read(length)
            if len(body) != length:
                raise GlbError(f"truncated GLB chunk at byte {offset}", path)
            if ctype == CHUNK_JSON:
                doc = _glb_json(body, path)
            else:
                bin_chunk = body
            offset += 8 + length
    if not isinstance(doc, dict):
        raise GlbError("GLB has no JSON chunk", path)
    return doc, bin_chunk


def _glb_total(f, path: str) -> int:
    """The byte count a GLB's 12-byte header declares, checked against the file's real
    size and the least a chunk needs; `f` is left after the header."""
    size = os.fstat(f.fileno()).st_size
    head = f.read(12)
    if len(head) < 12 or head[:4] != GLB_MAGIC:
        raise GlbError("not a binary glTF (GLB) file", path)
    version, total = struct.unpack_from("<II", head, 4)
    if version != 2:
        raise GlbError(f"glTF version {version} is not supported (need 2)", path)
    if total > size:
        raise GlbError(
            f"truncated GLB: its header declares {total} bytes, the file has {size}", path
        )
    if total < 20:
        raise GlbError(f"GLB header declares {total} bytes, too few for one chunk", path)
    return total


def _glb_json(body: bytes, path: str) -> object:
    """A GLB's JSON chunk, decoded (glTF requires UTF-8)."""
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError as e:
        raise GlbError(
            f"the JSON chunk is not UTF-8 (glTF requires UTF-8; byte {e.start})", path
        ) from None
    try:
        return json.loads(text)
    except (ValueError, RecursionError) as e:
        raise GlbError(f"GLB JSON chunk is not valid JSON ({e})", path) from None


def read_model(path: str) -> tuple[dict, bytes | None]:
    """The JSON document and BIN chunk of a .glb, or the document of a .gltf (None)."""
    if not path.lower().endswith(".gltf"):
        return read_glb(path)
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except UnicodeDecodeError as e:
        raise GlbError(
            f"the glTF JSON is not UTF-8 (glTF requires UTF-8; byte {e.start})", path
        ) from None
    except ValueError as e:
        raise GlbError(f"glTF JSON does not parse ({e})", path) from None
    if not isinstance(doc, dict):
        raise GlbError("glTF JSON is not an object", path)
    return doc, None


_MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".webp": "image/webp"}


def _uri_bytes(uri: str, base: str) -> bytes:
    if uri.startswith("data:"):
        return base64.b64decode(uri.split(",", 1)[1])
    with open(os.path.join(base, unquote(uri)), "rb") as f:
        return f.read()


def has_external_uris(doc: dict) -> bool:
    items = (doc.get("buffers") or []) + (doc.get("images") or [])
    return any(isinstance(x.get("uri"), str) and not x["uri"].startswith("data:") for x in items)


def embed_external(doc: dict, bin_chunk: bytes | None, base: str) -> tuple[dict, bytes]:
    """A self-contained GLB of a model whose buffers or images are separate files (a
    .gltf with its .bin and textures, or a .glb with external textures): every buffer
    becomes a slice of one BIN chunk and every external image a buffer view, so the
    model can be written anywhere (the worker's scratch folder) and still import whole.
    URIs were checked by the pre-flight to stay inside the model's folder."""
    doc = copy.deepcopy(doc)
    blob = bytearray()

    def append(data: bytes) -> int:
        offset = len(blob)
        blob.extend(data)
        blob.extend(b"\0" * (-len(blob) % 4))
        return offset

    offsets = []
    for b in doc.get("buffers") or []:
        uri = b.get("uri")
        data = (bin_chunk or b"") if uri is None else _uri_bytes(uri, base)
        offsets.append(append(data[: int(b.get("byteLength", len(data)))]))
    for v in doc.get("bufferViews") or []:
        v["byteOffset"] = int(v.get("byteOffset", 0)) + offsets[int(v.get("buffer", 0))]
        v["buffer"] = 0
    views = doc.setdefault("bufferViews", [])
    for img in doc.get("images") or []:
        uri = img.get("uri")
        if not isinstance(uri, str) or uri.startswith("data:"):
            continue
        data = _uri_bytes(uri, base)
        offset = append(data)
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data)})
        img.pop("uri")
        img["bufferView"] = len(views) - 1
        ext = os.path.splitext(unquote(uri))[1].lower()
        img.setdefault("mimeType", _MIME.get(ext, "image/png"))
    if not views:
        doc.pop("bufferViews")
    doc["buffers"] = [{"byteLength": len(blob)}] if blob else []
    if not doc["buffers"]:
        doc.pop("buffers")
    return doc, bytes(blob)


def write_glb(path: str, doc: dict, bin_chunk: bytes | None) -> None:
    """Write a GLB (JSON padded with spaces, BIN with zeros, as the spec requires)."""
    js = json.dumps(doc, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    parts = [struct.pack("<II", len(js), CHUNK_JSON), js]
    if bin_chunk is not None:
        b = bin_chunk + b"\0" * (-len(bin_chunk) % 4)
        parts += [struct.pack("<II", len(b), CHUNK_BIN), b]
    body = b"".join(parts)
    tmp = f"{path}.part"
    with open(tmp, "wb") as f:
        f.write(GLB_MAGIC + struct.pack("<II", 2, 12 + len(body)) + body)
    os.replace(tmp, path)


def _extensions(doc: dict) -> set[str]:
    names = set(doc.get("extensionsUsed") or []) | set(doc.get("extensionsRequired") or [])
    for mesh in doc.get("meshes") or []:
        for prim in mesh.get("primitives") or []:
            names |= set((prim.get("extensions") or {}).keys())
    for view in doc.get("bufferViews") or []:
        names |= set((view.get("extensions") or {}).keys())
    return names


def compression_problem(doc: dict, *, draco_available: bool) -> str | None:
    """A one-line reason when the file uses a compression we cannot decode, else None."""
    used = _extensions(doc)
    for name in MESHOPT:
        if name in used:
            return (
                f"unsupported compression: {name} (meshopt) buffers cannot be decoded "
                "by Blender's glTF importer"
            )
    if DRACO in used and not draco_available:
        return (
            f"unsupported compression: Draco ({DRACO}); this Blender has no Draco decoder "
            "library (glTF-Blender-IO #2184)"
        )
    if BASISU in used:
        # A texture with a plain `source` next to the basisu one has a PNG/JPEG fallback.
        for tex in doc.get("textures") or []:
            if BASISU in (tex.get("extensions") or {}) and tex.get("source") is None:
                return (
                    f"unsupported compression: {BASISU} (KTX2/Basis Universal) textures "
                    "without a PNG/JPEG fallback cannot be decoded by Blender"
                )
    return None


def uses_draco(doc: dict) -> bool:
    return DRACO in _extensions(doc)


def unlit_materials(doc: dict) -> list[int]:
    return [
        i
        for i, m in enumerate(doc.get("materials") or [])
        if "KHR_materials_unlit" in (m.get("extensions") or {})
    ]


def fix_unlit(doc: dict, mode: str = "lit") -> tuple[dict, int]:
    """Rewrite unlit materials so Blender shows the colour the author meant.

    Sketchfab exports unlit materials with a black base colour and the visible colour
    in emissiveFactor / emissiveTexture; Blender's unlit node tree follows the base
    colour and renders them black. Such materials get the emissive colour moved into
    the base colour slot. `mode` "emission" keeps them unlit (Blender builds camera-only
    emission, so pixels equal the intended colour, as on Sketchfab); "lit" drops the
    unlit extension from every unlit material so our fixed lights shade them like any
    other surface. Returns the new document and how many materials were rewritten.
    """
    if mode not in ("emission", "lit"):
        raise ValueError(f"unlit mode must be 'emission' or 'lit', got {mode!r}")
    doc = copy.deepcopy(doc)
    fixed = 0
    for i in unlit_materials(doc):
        mat = doc["materials"][i]
        pbr = mat.setdefault("pbrMetallicRoughness", {})
        base = list(pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]))
        emissive = list(mat.get("emissiveFactor", [0.0, 0.0, 0.0]))
        emissive_tex = mat.get("emissiveTexture")
        strength = (mat.get("extensions") or {}).get("KHR_materials_emissive_strength", {})
        if emissive_tex is not None and max(emissive) <= BLACK:
            # An emissive texture with no factor is black by the spec, but the author
            # clearly meant the texture; take it at full strength.
            emissive = [1.0, 1.0, 1.0]
        scale = float(strength.get("emissiveStrength", 1.0)) if strength else 1.0
        emissive = [min(1.0, max(0.0, c * scale)) for c in emissive]
        if max(base[:3]) <= BLACK and max(emissive) > BLACK:
            pbr["baseColorFactor"] = emissive[:3] + [base[3] if len(base) > 3 else 1.0]
            if emissive_tex is not None:
                pbr["baseColorTexture"] = emissive_tex
            else:
                pbr.pop("baseColorTexture", None)
            # The colour now lives in the base slot; leaving it in emissive too would
            # make the lit variant glow.
            mat.pop("emissiveTexture", None)
            mat["emissiveFactor"] = [0.0, 0.0, 0.0]
            fixed += 1
        if mode == "lit":
            mat["extensions"].pop("KHR_materials_unlit", None)
    if mode == "lit":
        for key in ("extensionsUsed", "extensionsRequired"):
            if key in doc:
                doc[key] = [e for e in doc[key] if e != "KHR_materials_unlit"]
                if not doc[key]:
                    del doc[key]
    return doc, fixed


# Material extensions whose light passes through the surface (Cycles transmission paths).
TRANSMISSION = (
    "KHR_materials_transmission",
    "KHR_materials_diffuse_transmission",
    "KHR_materials_volume",
)


def light_paths(doc: dict) -> dict:
    """What light transport the materials of a glTF document can produce.

    `transmission`: a material transmits light (KHR_materials_transmission with a
    non-zero factor or a texture, diffuse transmission, volume). `transparency`: a
    material is alpha-blended or alpha-masked (glTF `alphaMode` BLEND / MASK; OPAQUE
    materials ignore alpha, as Blender's importer does). `unlit_only`: every rendered
    primitive uses a KHR_materials_unlit material, which Blender imports as camera-only
    emission: nothing it shows depends on light bouncing. A primitive without a material
    gets glTF's default (lit, opaque) material.
    """
    mats = doc.get("materials") or []

    def transmits(m: dict) -> bool:
        ext = m.get("extensions") or {}
        for name in TRANSMISSION:
            e = ext.get(name)
            if not isinstance(e, dict):
                continue
            factor_key = {
                "KHR_materials_transmission": "transmissionFactor",
                "KHR_materials_diffuse_transmission": "diffuseTransmissionFactor",
                "KHR_materials_volume": "thicknessFactor",
            }[name]
            texture_key = factor_key.replace("Factor", "Texture")
            if float(e.get(factor_key, 0.0) or 0.0) > 0.0 or e.get(texture_key) is not None:
                return True
        return False

    used: set[int | None] = set()
    for mesh in doc.get("meshes") or []:
        for prim in mesh.get("primitives") or []:
            mi = prim.get("material")
            used.add(mi if isinstance(mi, int) and 0 <= mi < len(mats) else None)
    rendered = [mats[i] for i in used if i is not None]
    return {
        "transmission": any(transmits(m) for m in rendered),
        "transparency": any(
            str(m.get("alphaMode", "OPAQUE")) in ("BLEND", "MASK") for m in rendered
        ),
        "unlit_only": bool(used)
        and None not in used
        and all("KHR_materials_unlit" in (m.get("extensions") or {}) for m in rendered),
    }
