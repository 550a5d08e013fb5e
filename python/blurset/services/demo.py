"""Built-in demo objects: procedural, richly textured GLBs made on the fly (no download).

They go through exactly the import path of real objects (GLB -> Blender worker). The
textures are dense multi-scale random patches, so SIFT finds many distinct features at
96-320 px and a COLMAP check of a demo build has something to match; every face of an
object shows a different part of its texture, so no two views look alike by symmetry.
Deterministic for a seed: the same seed gives byte-identical files.

They are part of blurset and carry its licence (MIT) in the glTF `asset.extras`, the
same record Sketchfab exports carry, so a build attributes them like any other object.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import trimesh
from PIL import Image, ImageDraw, ImageFilter
from trimesh.visual.material import PBRMaterial

from blurset import layout

TEXTURE_SIZE = 512
# (file stem, builder name): order is part of the contract (index k gets sub-seed k).
DEMO_OBJECTS = ("demo_box", "demo_cylinder", "demo_vase")
# Who made them and under which licence: blurset's own (pyproject.toml), as glTF
# `asset.extras` in the fields blurset.services.attribution reads.
AUTHOR = "blurset"
LICENSE = "MIT (https://opensource.org/licenses/MIT)"


def make_demo_objects(out_dir: Path, seed: int = 0) -> list[Path]:
    """Write the demo GLBs into `out_dir` and return their paths (sorted by name).

    A box of 1 x 0.7 x 0.5, a cylinder and a vase-like surface of revolution, each with
    its own seeded 512 x 512 texture.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    builders = {"demo_box": _box, "demo_cylinder": _cylinder, "demo_vase": _vase}
    paths = []
    for k, name in enumerate(DEMO_OBJECTS):
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, k])
        texture = patch_texture(rng, TEXTURE_SIZE)
        vertices, faces, normals, uv = builders[name]()
        extras = {
            "title": f"blurset {name.removeprefix('demo_')} (procedural demo object, seed {seed})",
            "author": AUTHOR,
            "license": LICENSE,
        }
        data = _glb_bytes(vertices, faces, normals, uv, texture, extras)
        path = out_dir / f"{name}.glb"
        layout.write_bytes_atomic(path, data)
        paths.append(path)
    return paths


# --------------------------------------------------------------------------- texture


def patch_texture(rng: np.random.Generator, size: int = TEXTURE_SIZE) -> Image.Image:
    """An RGB texture of random coloured patches over a smooth colour field.

    Patches span three scales (large blobs, medium shapes, small marks) so corners and
    blobs exist at every image resolution SIFT sees between 96 and 320 px.
    """
    # Smooth background: bilinear upsampling of a coarse random colour grid.
    coarse = rng.uniform(0.15, 0.85, size=(6, 6, 3)).astype(np.float32)
    bg = Image.fromarray((coarse * 255).astype(np.uint8)).resize(
        (size, size), Image.Resampling.BILINEAR
    )
    img = bg.copy()
    draw = ImageDraw.Draw(img)
    for n, (lo, hi) in ((40, (40, 120)), (160, (12, 40)), (500, (3, 12))):
        for _ in range(n):
            r = float(rng.uniform(lo, hi)) / 2
            cx, cy = rng.uniform(0, size, 2)
            color = tuple(int(c) for c in _saturated(rng))
            kind = int(rng.integers(0, 4))
            box = [cx - r, cy - r, cx + r, cy + r]
            if kind == 0:
                draw.ellipse(box, fill=color)
            elif kind == 1:
                draw.rectangle(box, fill=color)
            elif kind == 2:
                angles = np.sort(rng.uniform(0, 2 * np.pi, 3))
                pts = [(cx + r * np.cos(a), cy + r * np.sin(a)) for a in angles]
                draw.polygon([(float(x), float(y)) for x, y in pts], fill=color)
            else:
                ang = rng.uniform(0, np.pi)
                dx, dy = r * np.cos(ang), r * np.sin(ang)
                draw.line(
                    [cx - dx, cy - dy, cx + dx, cy + dy], fill=color, width=max(1, int(r / 4))
                )
    # A slight blur keeps the texture free of aliasing at texel scale.
    return img.filter(ImageFilter.GaussianBlur(0.6))


def _saturated(rng: np.random.Generator) -> np.ndarray:
    """A random vivid colour (HSV with high saturation), 0..255."""
    h = rng.uniform(0, 6)
    s = rng.uniform(0.55, 1.0)
    v = rng.uniform(0.35, 1.0)
    c = v * s
    x = c * (1 - abs(h % 2 - 1))
    rgb = [(c, x, 0), (x, c, 0), (0, c, x), (0, x, c), (x, 0, c), (c, 0, x)][int(h) % 6]
    return (np.array(rgb) + (v - c)) * 255


# ---------------------------------------------------------------------------- meshes
# Each builder returns (vertices (N,3), faces (M,3) counter-clockwise seen from outside,
# vertex normals (N,3), uv (N,2)) in glTF's Y-up frame; Blender's importer turns it to Z up.


def _box(dims=(1.0, 0.5, 0.7)):
    """A box of 1 x 0.7 x 0.5 in Blender's x, y, z (glTF is Y up: x, z, y here); every
    face shows its own cell of a 3 x 2 texture atlas."""
    hx, hy, hz = (d / 2 for d in dims)
    # (normal, u axis, v axis) per face; corners = n*h + (±u)*h + (±v)*h
    faces_def = [
        ((1, 0, 0), (0, 0, -1), (0, 1, 0)),
        ((-1, 0, 0), (0, 0, 1), (0, 1, 0)),
        ((0, 1, 0), (1, 0, 0), (0, 0, -1)),
        ((0, -1, 0), (1, 0, 0), (0, 0, 1)),
        ((0, 0, 1), (1, 0, 0), (0, 1, 0)),
        ((0, 0, -1), (-1, 0, 0), (0, 1, 0)),
    ]
    half = np.array([hx, hy, hz])
    verts: list[np.ndarray] = []
    norms: list[np.ndarray] = []
    uvs: list[tuple[float, float]] = []
    faces: list[tuple[int, int, int]] = []
    for k, axes in enumerate(faces_def):
        n, u, v = (np.array(a, float) for a in axes)
        cu, cv = (k % 3) / 3.0, (k // 3) / 2.0  # 3 x 2 atlas
        base = len(verts)
        for su, sv in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            verts.append((n + su * u + sv * v) * half)
            norms.append(n)
            uvs.append(
                (cu + (su + 1) / 2 / 3.0 * 0.96 + 0.005, cv + (sv + 1) / 2 / 2.0 * 0.96 + 0.005)
            )
        faces += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return np.array(verts), np.array(faces), np.array(norms), np.array(uvs)


def _revolve(profile: np.ndarray, segments: int = 64):
    """A closed surface of revolution about glTF's Y axis from a (K, 2) (radius, height)
    profile running bottom to top; lateral surface in the top 3/4 of the atlas, the two
    caps in the bottom quarter."""
    radius, height = profile[:, 0], profile[:, 1]
    k = len(profile)
    # Arc length along the profile for an even v parametrisation.
    seg = np.hypot(np.diff(radius), np.diff(height))
    t = np.concatenate([[0.0], np.cumsum(seg)]) / seg.sum()
    # Profile normals: perpendicular to the profile tangent, pointing outward.
    dr = np.gradient(radius)
    dh = np.gradient(height)
    pn = np.stack([dh, -dr], axis=1)
    pn /= np.linalg.norm(pn, axis=1, keepdims=True)
    verts, norms, uvs, faces = [], [], [], []
    for j in range(segments + 1):  # the seam is duplicated so u runs 0..1 cleanly
        a = 2 * np.pi * j / segments
        ca, sa = np.cos(a), np.sin(a)
        for i in range(k):
            verts.append((radius[i] * ca, height[i], -radius[i] * sa))
            norms.append((pn[i, 0] * ca, pn[i, 1], -pn[i, 0] * sa))
            uvs.append((j / segments, 0.25 + 0.75 * t[i]))
    for j in range(segments):
        for i in range(k - 1):
            p, q = j * k + i, (j + 1) * k + i
            faces += [(p, q, q + 1), (p, q + 1, p + 1)]
    for end, (ucen, sign) in ((0, (0.125, -1.0)), (k - 1, (0.375, 1.0))):
        r, h = radius[end], height[end]
        center = len(verts)
        verts.append((0.0, h, 0.0))
        norms.append((0.0, sign, 0.0))
        uvs.append((ucen, 0.125))
        for j in range(segments):
            a = 2 * np.pi * j / segments
            verts.append((r * np.cos(a), h, -r * np.sin(a)))
            norms.append((0.0, sign, 0.0))
            uvs.append((ucen + 0.12 * np.cos(a), 0.125 + 0.12 * np.sin(a)))
        for j in range(segments):
            p, q = center + 1 + j, center + 1 + (j + 1) % segments
            faces.append((center, q, p) if sign < 0 else (center, p, q))
    return np.array(verts), np.array(faces), np.array(norms), np.array(uvs)


def _cylinder():
    """Radius 0.3, height 0.8: largest side 0.8, normalized to 1 by the worker."""
    h = np.linspace(-0.4, 0.4, 9)
    return _revolve(np.stack([np.full_like(h, 0.3), h], axis=1))


def _vase():
    """A vase profile: a bulging body, a waist and a flared lip (self-occluding)."""
    s = np.linspace(0.0, 1.0, 33)
    radius = 0.22 + 0.13 * np.sin(np.pi * s * 1.3) - 0.08 * np.sin(np.pi * s * 2.6) ** 2
    radius += 0.06 * np.clip((s - 0.8) / 0.2, 0.0, 1.0) ** 2
    return _revolve(np.stack([radius, s - 0.5], axis=1))


def _glb_bytes(vertices, faces, normals, uv, texture: Image.Image, extras: dict) -> bytes:
    material = PBRMaterial(
        name="demo_texture",
        baseColorTexture=texture,
        baseColorFactor=[255, 255, 255, 255],
        metallicFactor=0.0,
        roughnessFactor=0.55,
    )
    mesh = trimesh.Trimesh(
        vertices=vertices,
        faces=faces,
        vertex_normals=normals,
        visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
        process=False,
    )
    buf = io.BytesIO()

    def attribute(tree: dict) -> None:
        tree.setdefault("asset", {})["extras"] = extras

    glb = trimesh.exchange.gltf.export_glb(
        trimesh.Scene(mesh), include_normals=True, tree_postprocessor=attribute
    )
    buf.write(glb)
    return buf.getvalue()
