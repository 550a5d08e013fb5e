"""The bpy side of the worker: import one GLB, normalize it, light it, render views.

Uses only the stdlib, bpy, mathutils and numpy, so a user's own Blender binary can run it.
Conventions (shared with the Rust sampling): world Z up; after normalization the
object's axis-aligned bounding box is centred at the origin with largest side 1; cameras
arrive as OpenGL camera-to-world matrices, which is exactly Blender's camera matrix_world.
"""

from __future__ import annotations

import math
import os
import tempfile
import time

import bpy
import glb_inspect
import numpy as np
from mathutils import Matrix, Vector

ROOT_NAME = "blurset_root"
DEFAULT_EXR_CODEC = "NONE"
EXR_CODECS = ("NONE", "ZIP", "ZIPS", "PIZ", "RLE", "PXR24", "B44", "DWAA")
CAMERA_NAME = "blurset_camera"

# Fixed world-space lights: (elevation deg, azimuth deg, strength W/m^2, angular size deg).
# A warm key from above, a cool fill and a rim from behind, so every side of the object
# gets shape-revealing shading under any camera azimuth; identical for every object.
SUNS = (
    ("key", 50.0, 35.0, 2.0, 6.0, (1.0, 0.97, 0.92)),
    ("fill", 20.0, 200.0, 0.6, 20.0, (0.85, 0.9, 1.0)),
    ("rim", 65.0, 250.0, 0.6, 10.0, (1.0, 1.0, 1.0)),
)
# Sky gradient for ambient light: ground colour below the horizon, zenith colour above.
SKY_ZENITH = (0.32, 0.35, 0.4)
SKY_GROUND = (0.1, 0.095, 0.09)


class LoadError(Exception):
    """An object-level failure with a one-line reason (the worker answers ok:false)."""


def set_threads(threads: int) -> None:
    r = bpy.context.scene.render
    if threads > 0:
        r.threads_mode = "FIXED"
        r.threads = threads
    else:
        r.threads_mode = "AUTO"


def draco_available() -> bool:
    try:
        from io_scene_gltf2.io.com import draco  # type: ignore[import-not-found]

        return bool(draco.dll_exists(quiet=True))
    except Exception:
        return False


# ----------------------------------------------------------------------------- import


def import_glb(path: str, workdir: str, unlit_mode: str) -> tuple[list[str], bool]:
    """Fresh factory scene + the GLB. Returns (warnings, unlit_fixed)."""
    if not os.path.isfile(path):
        raise LoadError(f"model file not found: {path}")
    warnings: list[str] = []
    try:
        doc, bin_chunk = glb_inspect.read_model(path)
    except (OSError, glb_inspect.GlbError) as e:
        raise LoadError(str(e)) from None
    problem = glb_inspect.compression_problem(doc, draco_available=draco_available())
    if problem:
        raise LoadError(problem)
    if glb_inspect.uses_draco(doc):
        warnings.append("Draco-compressed meshes decoded with Blender's Draco library")

    unlit_fixed = False
    source = path
    if glb_inspect.unlit_materials(doc):
        fixed_doc, n_fixed = glb_inspect.fix_unlit(doc, unlit_mode)
        unlit_fixed = n_fixed > 0 or unlit_mode == "lit"
        if unlit_fixed:
            doc = fixed_doc
            source = os.path.join(workdir, "unlit_fixed.glb")
            n_unlit = len(glb_inspect.unlit_materials(doc))
            warnings.append(
                f"{n_unlit} unlit material(s) (KHR_materials_unlit); {n_fixed} had a black "
                f"base colour and were rebuilt from their emissive colour; mode {unlit_mode}"
            )

    if source != path or bin_chunk is None:
        # A rewritten model lands in the scratch folder, away from the files it names: so
        # it, and every .gltf, is imported as one self-contained GLB.
        if source == path:
            source = os.path.join(workdir, "model.glb")
        try:
            doc, bin_chunk = glb_inspect.embed_external(doc, bin_chunk, os.path.dirname(path))
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise LoadError(f"cannot read the model's external files: {e}") from None
        glb_inspect.write_glb(source, doc, bin_chunk)

    bpy.ops.wm.read_factory_settings(use_empty=True)
    # GLBs are untrusted input; glTF carries no scripts, but keep auto-run off regardless.
    bpy.context.preferences.filepaths.use_scripts_auto_execute = False
    try:
        result = bpy.ops.import_scene.gltf(filepath=source)
    except Exception as e:  # the importer raises RuntimeError with its message
        msg = " ".join(str(e).split())
        raise LoadError(f"glTF import failed: {msg[:300]}") from None
    if "FINISHED" not in result:
        raise LoadError(f"glTF import failed ({', '.join(sorted(result))})")
    return warnings, unlit_fixed


def _strip_non_mesh(warnings: list[str]) -> None:
    """Imported lights and cameras would break the fixed lighting and our camera."""
    removed = [o for o in bpy.data.objects if o.type in {"LIGHT", "CAMERA"}]
    for o in removed:
        bpy.data.objects.remove(o, do_unlink=True)
    if removed:
        warnings.append(f"removed {len(removed)} imported light/camera object(s)")


def _world_vertices() -> tuple[np.ndarray, int]:
    """All rendered mesh vertices in world space (instances included) and the triangle count."""
    depsgraph = bpy.context.evaluated_depsgraph_get()
    chunks = []
    n_tri = 0
    for inst in depsgraph.object_instances:
        ob = inst.object
        if ob.type != "MESH":
            continue
        if inst.is_instance:
            mesh, owner = ob.data, None
        else:
            mesh, owner = ob.to_mesh(), ob
        try:
            if mesh is None or len(mesh.polygons) == 0:
                continue  # points / lines do not render in Cycles
            co = np.empty(len(mesh.vertices) * 3, dtype=np.float64)
            mesh.vertices.foreach_get("co", co)
            co = co.reshape(-1, 3)
            m = np.array(inst.matrix_world, dtype=np.float64)
            chunks.append(co @ m[:3, :3].T + m[:3, 3])
            n_tri += len(mesh.loop_triangles)
        finally:
            if owner is not None:
                owner.to_mesh_clear()
    if not chunks:
        return np.zeros((0, 3)), 0
    return np.concatenate(chunks), n_tri


def normalize(warnings: list[str]) -> dict:
    """Parent everything to one root and scale/shift it: bbox centred, largest side 1."""
    scene = bpy.context.scene
    _strip_non_mesh(warnings)
    if scene.frame_current != scene.frame_start:
        scene.frame_set(scene.frame_start)
    bpy.context.view_layer.update()
    verts, _ = _world_vertices()
    if len(verts) == 0:
        raise LoadError("no renderable mesh in the file (empty scene or only points/lines)")
    if not np.all(np.isfinite(verts)):
        raise LoadError("mesh has non-finite vertex coordinates")
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    center = (lo + hi) / 2.0
    size = float((hi - lo).max())
    if not size > 1e-12:
        raise LoadError(f"degenerate mesh: bounding box largest side is {size:g}")
    scale = 1.0 / size

    root = bpy.data.objects.new(ROOT_NAME, None)
    scene.collection.objects.link(root)
    for ob in list(scene.objects):
        if ob is not root and ob.parent is None:
            mw = ob.matrix_world.copy()
            ob.parent = root
            ob.matrix_parent_inverse = Matrix.Identity(4)
            ob.matrix_world = mw
    root.scale = (scale, scale, scale)
    root.location = Vector(-center * scale)
    bpy.context.view_layer.update()

    verts, n_tri = _world_vertices()
    lo, hi = verts.min(axis=0), verts.max(axis=0)
    dims = hi - lo
    if abs(dims.max() - 1.0) > 1e-4 or np.abs((lo + hi) / 2).max() > 1e-4:
        # Shear in a parent chain or drivers can defeat a root transform; the vertices
        # we hand back are still the truth, so report rather than fail.
        warnings.append(f"normalization inexact: bbox dims {dims.tolist()}")
    if n_tri > 2_000_000:
        warnings.append(f"large mesh: {n_tri} triangles")
    if any(a.users for a in bpy.data.actions):
        warnings.append(f"animated object rendered at frame {scene.frame_start}")
    return {
        "vertices": verts.astype(np.float32),
        "bbox_dims": [float(d) for d in dims],
        "n_vertices": int(len(verts)),
        "n_triangles": int(n_tri),
        "scale": scale,
        "center": [float(c) for c in center],
    }


# ----------------------------------------------------------------------- scene set-up


def _sun(name, elevation, azimuth, strength, angle, color) -> None:
    data = bpy.data.lights.new(name, type="SUN")
    data.energy = strength
    data.angle = math.radians(angle)
    data.color = color
    ob = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(ob)
    el, az = math.radians(elevation), math.radians(azimuth)
    to_light = Vector((math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)))
    # A sun shines along its local -Z, so its +Z must point toward the light.
    ob.rotation_euler = to_light.to_track_quat("Z", "Y").to_euler()


def _world() -> None:
    world = bpy.data.worlds.new("blurset_world")
    bpy.context.scene.world = world
    world.use_nodes = True
    nt = world.node_tree
    nt.nodes.clear()
    coord = nt.nodes.new("ShaderNodeTexCoord")
    sep = nt.nodes.new("ShaderNodeSeparateXYZ")
    ramp = nt.nodes.new("ShaderNodeMapRange")
    mix = nt.nodes.new("ShaderNodeMix")
    mix.data_type = "RGBA"
    bg = nt.nodes.new("ShaderNodeBackground")
    out = nt.nodes.new("ShaderNodeOutputWorld")
    # The world's Generated coordinate is the ray direction: blend ground -> zenith on Z.
    nt.links.new(coord.outputs["Generated"], sep.inputs[0])
    nt.links.new(sep.outputs["Z"], ramp.inputs["Value"])
    ramp.inputs["From Min"].default_value = -0.2
    ramp.inputs["From Max"].default_value = 0.6
    nt.links.new(ramp.outputs["Result"], mix.inputs["Factor"])
    mix.inputs["A"].default_value = (*SKY_GROUND, 1.0)
    mix.inputs["B"].default_value = (*SKY_ZENITH, 1.0)
    nt.links.new(mix.outputs["Result"], bg.inputs["Color"])
    bg.inputs["Strength"].default_value = 1.0
    nt.links.new(bg.outputs["Background"], out.inputs["Surface"])


def setup_scene(threads: int) -> None:
    """Lights, camera and render settings; everything fixed and object-independent."""
    scene = bpy.context.scene
    for args in SUNS:
        _sun(*args)
    _world()

    cam_data = bpy.data.cameras.new(CAMERA_NAME)
    cam_data.lens_unit = "FOV"
    cam_data.sensor_fit = "HORIZONTAL"
    cam_data.clip_start = 0.01
    cam_data.clip_end = 1000.0
    cam = bpy.data.objects.new(CAMERA_NAME, cam_data)
    scene.collection.objects.link(cam)
    scene.camera = cam

    r = scene.render
    r.engine = "CYCLES"
    r.film_transparent = True
    r.use_persistent_data = True
    r.use_compositing = False
    r.use_sequencer = False
    r.resolution_percentage = 100
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0
    r.use_file_extension = False
    r.use_motion_blur = False
    set_threads(threads)
    img = r.image_settings
    if hasattr(img, "media_type"):  # Blender >= 5.0 groups formats by media type
        img.media_type = "IMAGE"
    img.file_format = "OPEN_EXR"
    img.color_mode = "RGBA"
    img.color_depth = "32"
    # The EXRs are intermediate: read once, accumulated, deleted. Uncompressed costs no
    # codec time on either side (bench/bench_blur_cost.py measures the codecs).
    img.exr_codec = DEFAULT_EXR_CODEC
    # EXR keeps scene-linear data; Standard + no look also keeps any preview honest.
    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.look = "None"
    vs.exposure = 0.0
    vs.gamma = 1.0

    c = scene.cycles
    c.device = "CPU"
    c.use_adaptive_sampling = False  # s samples means s samples: m frames at s/m ≈ 1 at s
    c.use_denoising = False
    c.use_preview_denoising = False
    c.use_animated_seed = False
    c.max_bounces = 6
    c.diffuse_bounces = 2
    c.glossy_bounces = 2
    c.transmission_bounces = 4
    c.volume_bounces = 0
    c.transparent_max_bounces = 8
    c.caustics_reflective = False
    c.caustics_refractive = False
    c.sample_clamp_indirect = 10.0  # fireflies would survive averaging of latent frames


# ---------------------------------------------------------------------------- render


def _render_to(path: str) -> None:
    """Render the current camera to an EXR at exactly `path`, atomically."""
    scene = bpy.context.scene
    d = os.path.dirname(os.path.abspath(path)) or "."
    os.makedirs(d, exist_ok=True)
    # Blender expands '#' in output paths to the frame number; keep it out of the path
    # Blender sees, and make the final name appear only once the file is complete.
    if "#" in d:
        fd, tmp = tempfile.mkstemp(suffix=".exr")
        os.close(fd)
    else:
        tmp = os.path.join(d, f".blurset-{os.getpid()}.tmp.exr")
    scene.render.filepath = tmp
    bpy.ops.render.render(write_still=True)
    if not os.path.isfile(tmp):
        raise RuntimeError(f"Blender wrote no image for {path}")
    try:
        os.replace(tmp, path)
    except OSError:  # crosses file systems (the '#' case): copy next to it, then rename
        part = path + ".part"
        with open(tmp, "rb") as src, open(part, "wb") as dst:
            dst.write(src.read())
        os.replace(part, path)
        os.remove(tmp)


def set_camera(c2w, resolution: int, fov_deg: float, samples: int) -> None:
    scene = bpy.context.scene
    m = np.asarray(c2w, dtype=np.float64)
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise ValueError(f"c2w must be a finite 4x4 matrix, got shape {m.shape}")
    if not (1 <= resolution <= 16384):
        raise ValueError(f"resolution must be in [1, 16384], got {resolution}")
    if not (0.0 < fov_deg < 180.0):
        raise ValueError(f"fov_deg must be in (0, 180), got {fov_deg}")
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    scene.render.resolution_x = scene.render.resolution_y = int(resolution)
    scene.camera.data.angle = math.radians(fov_deg)
    scene.camera.matrix_world = Matrix(m.tolist())
    scene.cycles.samples = int(samples)


def set_exr_codec(codec: str) -> None:
    if codec not in EXR_CODECS:
        raise ValueError(f"exr_codec must be one of {', '.join(EXR_CODECS)}, got {codec!r}")
    bpy.context.scene.render.image_settings.exr_codec = codec


def render_motion_blur(keys, motion_steps: int, out: str, seed: int) -> float:
    """One render whose shutter spans the camera path `keys` (c2w matrices at t_k =
    k / 2^motion_steps): keys at frames 1 + t_k, a shutter of one frame opening at
    frame 1, and Cycles motion steps on the camera object, so its 2^steps + 1 motion
    samples fall on the keys; between them Cycles interpolates (linear position,
    slerp rotation), and each path sample gets a uniform time over the shutter.
    Camera, resolution and samples are set with `set_camera` first."""
    scene = bpy.context.scene
    cam = scene.camera
    n = len(keys)
    if not (1 <= motion_steps <= 7) or n != (1 << motion_steps) + 1:
        raise ValueError(f"{n} motion keys do not match motion_steps {motion_steps}")
    prefs = bpy.context.preferences.edit
    interp = prefs.keyframe_new_interpolation_type
    prefs.keyframe_new_interpolation_type = "LINEAR"
    cam.rotation_mode = "QUATERNION"
    prev = None
    try:
        for k, c2w in enumerate(keys):
            m = np.asarray(c2w, dtype=np.float64)
            if m.shape != (4, 4) or not np.all(np.isfinite(m)):
                raise ValueError(f"motion key {k} must be a finite 4x4 matrix")
            cam.matrix_world = Matrix(m.tolist())
            q = cam.rotation_quaternion.copy()
            if prev is not None and q.dot(prev) < 0.0:  # keep the shortest arc
                q.negate()
                cam.rotation_quaternion = q
            prev = q
            frame = 1.0 + k / (n - 1)
            cam.keyframe_insert("location", frame=frame)
            cam.keyframe_insert("rotation_quaternion", frame=frame)
        cam.cycles.motion_steps = motion_steps
        r = scene.render
        r.use_motion_blur = True
        r.motion_blur_shutter = 1.0
        r.motion_blur_position = "START"
        scene.frame_set(1)
        return render_frame(out, seed)
    finally:
        prefs.keyframe_new_interpolation_type = interp
        cam.animation_data_clear()
        scene.render.use_motion_blur = False
        scene.frame_set(1)


def render_frame(out: str, seed: int) -> float:
    scene = bpy.context.scene
    # Cycles takes a signed 32-bit seed; fold larger integers into that range.
    scene.cycles.seed = int(seed) % (2**31)
    t0 = time.perf_counter()
    _render_to(out)
    return time.perf_counter() - t0
