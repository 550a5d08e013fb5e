"""Check a setting's depth and normal files against the mesh they were rendered from
(issue 35). Run with the venv's Python (bpy): it imports and normalizes the GLB with the
worker's own code (blender_scripts/blender_scene.py), puts every pixel that has a depth
back into the world through the written pose (sharp/transforms.json) and finds the
nearest point of the mesh.

    python tests/geometry_probe.py GLB SETTING_DIR OUT.json [--per-view N]

OUT.json: per view, over the pixels with depth (at most N, spread evenly): `dist_px`,
the distance to the surface in units of the pixel's footprint at that depth (depth /
focal); `angle_deg`, the angle between the written normal and the mesh's face normal
turned towards the camera; `facing`, the share of written normals facing the camera;
`pixels`, how many were checked.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "blender_scripts"))

import blender_scene  # noqa: E402
import bpy  # noqa: E402
import numpy as np  # noqa: E402
from blurset import layout  # noqa: E402
from blurset.image import read_depth, read_exr  # noqa: E402
from mathutils import Vector  # noqa: E402
from mathutils.bvhtree import BVHTree  # noqa: E402


def mesh_tree() -> BVHTree:
    """One BVH of every mesh of the scene, in world coordinates (after normalize)."""
    deps = bpy.context.evaluated_depsgraph_get()
    verts: list[Vector] = []
    polys: list[list[int]] = []
    for ob in bpy.context.scene.objects:
        if ob.type != "MESH":
            continue
        ev = ob.evaluated_get(deps)
        me = ev.to_mesh()
        base = len(verts)
        verts += [ob.matrix_world @ v.co for v in me.vertices]
        polys += [[base + i for i in p.vertices] for p in me.polygons]
        ev.to_mesh_clear()
    return BVHTree.FromPolygons(verts, polys)


def probe(glb: Path, setting: Path, per_view: int, workdir: Path) -> list[dict]:
    warnings: list[str] = []
    _, _, _ = blender_scene.import_glb(str(glb), str(workdir), "lit")
    blender_scene.normalize(warnings)
    tree = mesh_tree()
    tf = json.loads((setting / layout.SHARP / layout.TRANSFORMS).read_text())
    f, cx, cy = float(tf["fl_x"]), float(tf["cx"]), float(tf["cy"])
    out = []
    for frame in tf["frames"]:
        name = Path(frame["file_path"]).name
        c2w = np.asarray(frame["transform_matrix"], dtype=np.float64)
        depth = read_depth(
            setting / layout.SHARP / layout.pass_dir("depth", 1) / layout.pass_file("depth", name)
        )
        normal = read_exr(
            setting / layout.SHARP / layout.pass_dir("normal", 1) / layout.pass_file("normal", name)
        )[..., :3]
        ys, xs = np.nonzero(depth > 0)
        step = max(1, len(ys) // per_view)
        ys, xs = ys[::step], xs[::step]
        d = depth[ys, xs].astype(np.float64)
        # The pixel centre's ray in OpenGL camera axes (x right, y up, z backwards).
        cam = np.stack([(xs + 0.5 - cx) / f * d, -(ys + 0.5 - cy) / f * d, -d, np.ones_like(d)], -1)
        world = cam @ c2w.T
        dist, angle, facing = [], [], []
        for k in range(len(d)):
            p = Vector(world[k, :3])
            hit, n_mesh, _, dd = tree.find_nearest(p)
            dist.append(dd / (d[k] / f))
            to_cam = Vector(c2w[:3, 3]) - p
            n_mesh = n_mesh if n_mesh.dot(to_cam) >= 0 else -n_mesh
            n = Vector(normal[ys[k], xs[k]].astype(np.float64))
            facing.append(n.dot(to_cam) > 0)
            cos = max(-1.0, min(1.0, n.normalized().dot(n_mesh.normalized())))
            angle.append(float(np.degrees(np.arccos(cos))))
        out.append(
            {
                "view": name,
                "pixels": len(d),
                "dist_px": [float(x) for x in dist],
                "angle_deg": angle,
                "facing": float(np.mean(facing)) if facing else 0.0,
            }
        )
    return out


def main(argv: list[str]) -> int:
    glb, setting, dest = Path(argv[0]), Path(argv[1]), Path(argv[2])
    per_view = int(argv[argv.index("--per-view") + 1]) if "--per-view" in argv else 400
    work = dest.parent / f".{dest.stem}-work"
    work.mkdir(parents=True, exist_ok=True)
    dest.write_text(json.dumps(probe(glb, setting, per_view, work)))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
