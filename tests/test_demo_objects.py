"""Built-in demo objects: deterministic GLBs, textured richly enough for SIFT/COLMAP."""

from __future__ import annotations

import hashlib
import math

import numpy as np
import pytest
import trimesh
from blurset.services.demo import DEMO_OBJECTS, make_demo_objects, patch_texture


def _digests(paths):
    return [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]


def test_same_seed_same_bytes_other_seed_other_textures(tmp_path):
    a = make_demo_objects(tmp_path / "a", seed=5)
    b = make_demo_objects(tmp_path / "b", seed=5)
    c = make_demo_objects(tmp_path / "c", seed=6)
    assert [p.name for p in a] == [f"{n}.glb" for n in DEMO_OBJECTS]
    assert _digests(a) == _digests(b)
    assert all(x != y for x, y in zip(_digests(a), _digests(c), strict=True))
    # Only the output files, no temporaries.
    assert sorted(p.name for p in (tmp_path / "a").iterdir()) == sorted(p.name for p in a)


def test_glbs_are_textured_meshes_with_the_stated_shapes(tmp_path):
    paths = make_demo_objects(tmp_path, seed=0)
    extents = {}
    for p in paths:
        scene = trimesh.load(p, force="scene")
        (mesh,) = scene.geometry.values()
        closed = mesh.copy()
        closed.merge_vertices(merge_tex=True, merge_norm=True)  # faces carry UV seams
        assert closed.is_watertight, p.name
        assert mesh.visual.uv is not None and len(mesh.visual.uv) == len(mesh.vertices)
        tex = mesh.visual.material.baseColorTexture
        assert tex.size == (512, 512)
        # Outward normals: the signed volume of a closed mesh is positive.
        assert mesh.volume > 0, p.name
        extents[p.stem] = mesh.extents
    # glTF is Y up: the box is 1 (x) by 0.5 (y, up) by 0.7 (z).
    np.testing.assert_allclose(extents["demo_box"], [1.0, 0.5, 0.7], atol=1e-6)
    np.testing.assert_allclose(extents["demo_cylinder"], [0.6, 0.8, 0.6], atol=1e-3)
    assert extents["demo_vase"][1] == pytest.approx(1.0)


def test_texture_has_structure_at_every_scale():
    tex = np.asarray(patch_texture(np.random.default_rng(0)), dtype=np.float64) / 255
    assert tex.shape == (512, 512, 3)
    gray = tex.mean(axis=2)
    # A face spans ~170 texels and ~20-60 px on screen at 96-320 px: texture steps of
    # 2-8 texels are what SIFT sees there.
    for step in (2, 4, 8):
        g = gray[::step, ::step]
        grad = np.abs(np.diff(g, axis=0)).mean() + np.abs(np.diff(g, axis=1)).mean()
        assert grad > 0.025, f"too smooth at step {step}: {grad}"
    # Colourful, not grey: saturated patches dominate.
    chroma = tex.max(axis=2) - tex.min(axis=2)
    assert chroma.mean() > 0.2


@pytest.mark.blender
def test_demo_objects_render_with_many_sift_features(tmp_path):
    import OpenEXR
    import pycolmap
    from blurset.services.worker_client import Worker

    extractor = pycolmap.FeatureExtractor.create(
        pycolmap.FeatureExtractionOptions(), pycolmap.Device.cpu
    )
    counts = {}
    with Worker(threads=2, timeout=120) as w:
        for glb in make_demo_objects(tmp_path, seed=0):
            info = w.load(glb, tmp_path / "v.npy")
            assert abs(max(info["bbox_dims"]) - 1.0) < 1e-4
            dist = 0.5 * np.linalg.norm(info["bbox_dims"]) / math.sin(math.radians(20)) * 1.05
            p, t = math.radians(60), math.radians(30)
            pos = dist * np.array(
                [math.sin(p) * math.cos(t), math.sin(p) * math.sin(t), math.cos(p)]
            )
            back = pos / dist
            right = np.cross([0, 0, 1], back)
            right /= np.linalg.norm(right)
            c2w = np.eye(4)
            c2w[:3, 0], c2w[:3, 1], c2w[:3, 2], c2w[:3, 3] = right, np.cross(back, right), back, pos
            out = tmp_path / f"{glb.stem}.exr"
            w.render([{"c2w": c2w, "seed": 0, "out": out}], resolution=96, fov_deg=40, samples=8)
            with OpenEXR.File(str(out)) as f:
                rgba = np.asarray(f.channels()["RGBA"].pixels)
            # Composite on white and encode roughly as a viewer would (gamma 2.2).
            rgb = rgba[..., :3] + (1 - rgba[..., 3:4])
            gray = np.clip(rgb.mean(axis=2), 0, 1) ** (1 / 2.2)
            keypoints, _ = extractor.extract_from_float32_array(gray.astype(np.float32))
            counts[glb.stem] = len(keypoints)
    print("SIFT keypoints at 96 px:", counts)
    assert all(n >= 30 for n in counts.values()), counts


def test_demo_objects_carry_blursets_licence(tmp_path):
    """The demo objects are blurset's own: their glTF asset says so, and a build
    attributes them (MIT, author blurset) as it does a Sketchfab export, not `unknown`."""
    from blurset.services import attribution, preflight

    for p in make_demo_objects(tmp_path, seed=2):
        a = attribution.attribution(attribution.from_asset(preflight.check(p).asset))
        assert a["license"] == "MIT", a
        assert a["license_text"] == "MIT (https://opensource.org/licenses/MIT)"
        assert a["author"] == "blurset" and a["title"].startswith("blurset ")
        assert attribution.hf_license(a["license"]) == "mit"
        assert attribution.allowed(a["license"], ["MIT"])
