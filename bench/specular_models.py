"""Specular PBR models of our own for the target bench (issue 47): metal/roughness
materials with normal and emissive maps, the kind of surface whose render noise is
heavy-tailed (fireflies on glossy metal). No preset, threshold or constant of blurset was
chosen from them; they test that the render-noise estimate's bound holds where a few
pixels carry much of the error. Deterministic for a seed, like the demo objects.

    python bench/specular_models.py OUT_DIR     # writes specular_*.glb
"""

from __future__ import annotations

import io
import sys
from pathlib import Path

import numpy as np
import trimesh
from blurset import layout
from blurset.services import demo
from PIL import Image, ImageFilter
from trimesh.visual.material import PBRMaterial

SIZE = 256
MODELS = ("specular_orb", "specular_vase")


def _maps(rng: np.random.Generator) -> dict[str, Image.Image]:
    """Base colour, metallic-roughness (G roughness, B metallic), a normal map of random
    bumps and an emissive map of a few small bright marks."""
    base = demo.patch_texture(rng, SIZE)
    # Mostly polished metal (roughness 0.04-0.25) with rougher patches.
    rough = rng.uniform(0.04, 0.25, (8, 8))
    rough[rng.uniform(size=(8, 8)) < 0.2] = 0.6
    rough_img = Image.fromarray((rough * 255).astype(np.uint8)).resize((SIZE, SIZE))
    metal = np.where(rng.uniform(size=(8, 8)) < 0.8, 1.0, 0.0)
    metal_img = Image.fromarray((metal * 255).astype(np.uint8)).resize((SIZE, SIZE))
    zero = Image.new("L", (SIZE, SIZE), 0)
    mr = Image.merge("RGB", (zero, rough_img, metal_img))
    # Bumps: a height field of smooth blobs, its gradient as a tangent-space normal.
    h = np.zeros((SIZE, SIZE))
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    for _ in range(120):
        cx, cy = rng.uniform(0, SIZE, 2)
        r = rng.uniform(3, 14)
        h += rng.uniform(-1, 1) * np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * r * r))
    gy, gx = np.gradient(h)
    n = np.stack([-gx * 2.0, -gy * 2.0, np.ones_like(h)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    normal = Image.fromarray(((n * 0.5 + 0.5) * 255).astype(np.uint8))
    emis = Image.new("RGB", (SIZE, SIZE), (0, 0, 0))
    px = emis.load()
    for _ in range(12):
        cx, cy = (int(v) for v in rng.integers(0, SIZE, 2))
        col = tuple(int(c) for c in demo._saturated(rng))
        for dx in range(-2, 3):
            for dy in range(-2, 3):
                px[(cx + dx) % SIZE, (cy + dy) % SIZE] = col  # type: ignore[index]
    return {
        "base": base,
        "mr": mr,
        "normal": normal,
        "emissive": emis.filter(ImageFilter.GaussianBlur(0.5)),
    }


def _orb():
    s = np.linspace(0.0, 1.0, 33)
    a = np.pi * s
    return demo._revolve(np.stack([0.45 * np.sin(a) + 1e-3, -0.45 * np.cos(a)], axis=1))


def make_specular_models(out_dir: Path, seed: int = 0) -> list[Path]:
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    builders = {"specular_orb": _orb, "specular_vase": demo._vase}
    paths = []
    for k, name in enumerate(MODELS):
        rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 1000 + k])
        maps = _maps(rng)
        vertices, faces, normals, uv = builders[name]()
        material = PBRMaterial(
            name="specular",
            baseColorTexture=maps["base"],
            metallicFactor=1.0,
            roughnessFactor=1.0,
            metallicRoughnessTexture=maps["mr"],
            normalTexture=maps["normal"],
            emissiveTexture=maps["emissive"],
            emissiveFactor=[1.0, 1.0, 1.0],
        )
        mesh = trimesh.Trimesh(
            vertices=vertices,
            faces=faces,
            vertex_normals=normals,
            visual=trimesh.visual.TextureVisuals(uv=uv, material=material),
            process=False,
        )
        extras = {
            "title": f"blurset {name} (procedural specular bench model, seed {seed})",
            "author": demo.AUTHOR,
            "license": demo.LICENSE,
        }

        def attribute(tree: dict, extras: dict = extras) -> None:
            tree.setdefault("asset", {})["extras"] = extras

        buf = io.BytesIO()
        buf.write(
            trimesh.exchange.gltf.export_glb(
                trimesh.Scene(mesh), include_normals=True, tree_postprocessor=attribute
            )
        )
        path = out_dir / f"{name}.glb"
        layout.write_bytes_atomic(path, buf.getvalue())
        paths.append(path)
    return paths


if __name__ == "__main__":
    for p in make_specular_models(Path(sys.argv[1])):
        print(p)
