"""The bpy side of the worker: import one GLB, normalize it, light it, render views.

Uses only the stdlib, bpy, mathutils and numpy, so a user's own Blender binary can run it.
Conventions (shared with the Rust sampling): world Z up; after normalization the
object's axis-aligned bounding box is centred at the origin with largest side 1; cameras
arrive as OpenGL camera-to-world matrices, which is exactly Blender's camera matrix_world.
"""

from __future__ import annotations

import math
import os
import shutil
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
# Longest sample sequence Cycles renders (its `samples` property tops out here).
MAX_SEQUENCE = 1 << 24

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


def import_glb(path: str, workdir: str, unlit_mode: str) -> tuple[list[str], bool, dict]:
    """Fresh factory scene + the GLB. Returns (warnings, unlit_fixed, the glTF JSON that
    was imported: the file's, or its unlit-fixed rewrite)."""
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
    return warnings, unlit_fixed, doc


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
    c.use_adaptive_sampling = False  # s samples means s samples (set_noise_threshold)
    c.use_denoising = False
    c.use_preview_denoising = False
    c.use_animated_seed = False
    for name, value in FIXED_BOUNCES.items():
        setattr(c, name, value)
    c.caustics_reflective = False
    c.caustics_refractive = False
    c.sample_clamp_indirect = 10.0  # fireflies would survive averaging of latent frames
    # Render regions (the core's plan/region.rs) assume rays land at most this far from
    # their pixel: 1.5 px wide, i.e. 0.75 px around the pixel centre.
    c.pixel_filter_type = "BLACKMAN_HARRIS"
    c.filter_width = FILTER_PX


# The pixel filter of every colour render (Blackman-Harris, px), and of a geometry
# render (set_passes): Cycles' smallest, so its one sample is at the pixel's centre.
FILTER_PX = 1.5
GEOMETRY_FILTER_PX = 0.01

# The light paths of every object before issue 15 (`--light-paths fixed`).
FIXED_BOUNCES = {
    "max_bounces": 6,
    "diffuse_bounces": 2,
    "glossy_bounces": 2,
    "transmission_bounces": 4,
    "volume_bounces": 0,
    "transparent_max_bounces": 8,
}


def bounces_for(needs: dict) -> dict:
    """Cycles bounce limits for what the materials can do (glb_inspect.light_paths):
    no transmission → no transmission bounces, no alpha blend/mask → no transparent
    bounces, unlit (camera-only emission) everywhere → no bounce at all: the camera ray
    sees the emission directly. Everything else keeps FIXED_BOUNCES."""
    b = dict(FIXED_BOUNCES)
    if not needs.get("transmission"):
        b["transmission_bounces"] = 0
    if not needs.get("transparency"):
        b["transparent_max_bounces"] = 0
    if needs.get("unlit_only"):
        b.update(max_bounces=0, diffuse_bounces=0, glossy_bounces=0, transmission_bounces=0)
    return b


def set_light_paths(doc: dict, mode: str) -> dict:
    """Apply the bounce limits of `mode` ("auto": from the imported glTF's materials;
    "fixed": FIXED_BOUNCES); returns what meta.json records."""
    if mode not in ("auto", "fixed"):
        raise ValueError(f"light_paths must be auto or fixed, got {mode!r}")
    needs = glb_inspect.light_paths(doc)
    bounces = bounces_for(needs) if mode == "auto" else dict(FIXED_BOUNCES)
    c = bpy.context.scene.cycles
    for name, value in bounces.items():
        setattr(c, name, value)
    return {"mode": mode, **needs, "bounces": bounces}


def set_passes(guides: bool, geometry: bool = False) -> None:
    """The passes every EXR of a render command holds beside the combined RGBA, in a
    multi-layer EXR; neither: the single RGBA layer of every build before them.

    guides: Cycles' denoising guide passes (Denoising Albedo, Denoising Normal; the driver
    averages them with the colour and denoises the mean once: issue 28).
    geometry: the Depth (along the camera's viewing axis) and Normal (world) data passes
    of the surface each pixel's centre sees (issue 35). Cycles writes data passes from a
    pixel's first sample only, so a geometry render takes one sample with a pixel filter
    of GEOMETRY_FILTER_PX: that sample sits at the pixel's centre, and an edge pixel's
    depth is one surface's, never a blend of the two sides.
    The EXR's depth and codec stay what they were."""
    scene = bpy.context.scene
    img = scene.render.image_settings
    codec, depth = img.exr_codec, img.color_depth
    layer = scene.view_layers[0]
    layer.cycles.denoising_store_passes = bool(guides)
    layer.use_pass_z = layer.use_pass_normal = bool(geometry)
    scene.cycles.filter_width = GEOMETRY_FILTER_PX if geometry else FILTER_PX
    multi = bool(guides or geometry)
    if hasattr(img, "media_type"):  # Blender >= 5.0 groups formats by media type
        img.media_type = "MULTI_LAYER_IMAGE" if multi else "IMAGE"
    img.file_format = "OPEN_EXR_MULTILAYER" if multi else "OPEN_EXR"
    if not multi:
        img.color_mode = "RGBA"
    img.color_depth = depth
    img.exr_codec = codec


def set_noise_threshold(threshold: float | None) -> None:
    """Cycles adaptive sampling: off (every pixel gets all its samples), or on with this
    noise threshold; min samples stay Cycles' automatic choice."""
    c = bpy.context.scene.cycles
    if threshold is None:
        c.use_adaptive_sampling = False
        return
    t = float(threshold)
    if not (math.isfinite(t) and 0.0 < t <= 1.0):
        raise ValueError(f"noise_threshold must be in (0, 1], got {threshold}")
    c.use_adaptive_sampling = True
    c.adaptive_threshold = t
    c.adaptive_min_samples = 0


# ----------------------------------------------------------------------------- devices

# Cycles GPU backends, best first: `--device auto` takes the first one with a device.
GPU_BACKENDS = ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL")


def _cycles_prefs():
    return bpy.context.preferences.addons["cycles"].preferences


def cpu_kernel() -> str:
    """The CPU kernel Cycles runs: it picks the widest instruction set the CPU has."""
    import _cycles  # type: ignore[import-not-found]

    info = _cycles.system_info()
    caps = ""
    for line in info.splitlines():
        if "capabilities" in line:
            caps = line.split(":", 1)[1].strip()
    return f"CPU {caps.split()[-1]}" if caps else "CPU"


def list_devices() -> dict:
    """Every backend Cycles reports here with its devices, CPU last:
    {"OPTIX": ["NVIDIA …", …], …, "CPU": ["AMD EPYC"]}."""
    prefs = _cycles_prefs()
    prefs.refresh_devices()
    out: dict[str, list[str]] = {}
    for backend in GPU_BACKENDS:
        try:
            devs = prefs.get_devices_for_type(backend)
        except Exception:  # a backend this build of Blender does not know (Metal on Linux)
            continue
        names = [d.name for d in devs if d.type == backend]
        if names:
            out[backend] = names
    cpus = [d.name for d in prefs.devices if d.type == "CPU"]
    out["CPU"] = cpus[:1] or ["CPU"]
    return out


def use_device(backend: str, gpus: list[int] | None) -> dict:
    """Render on `backend` (CPU or a GPU backend) with the devices at indices `gpus`
    of that backend's list (None: all); AUTO takes the first of GPU_BACKENDS that has a
    device, else the CPU. Returns {backend, devices, kernel}; a missing backend or index
    is a ValueError naming what exists."""
    scene = bpy.context.scene
    if backend == "AUTO":
        found = list_devices()
        backend = next((b for b in GPU_BACKENDS if found.get(b)), "CPU")
    if backend == "CPU":
        scene.cycles.device = "CPU"
        return {"backend": "CPU", "devices": list_devices()["CPU"], "kernel": cpu_kernel()}
    if backend not in GPU_BACKENDS:
        raise ValueError(f"unknown Cycles backend {backend!r}")
    prefs = _cycles_prefs()
    prefs.compute_device_type = backend
    prefs.refresh_devices()
    devs = prefs.get_devices_for_type(backend)
    gpu = [d for d in devs if d.type == backend]
    if not gpu:
        raise ValueError(f"no {backend} device (Cycles reports: {list_devices()})")
    idx = list(range(len(gpu))) if gpus is None else list(gpus)
    bad = [i for i in idx if not 0 <= i < len(gpu)]
    if bad:
        raise ValueError(f"{backend} has no device {bad[0]} (it has 0..{len(gpu) - 1})")
    for d in devs:
        d.use = False
    for i in idx:
        gpu[i].use = True
    scene.cycles.device = "GPU"
    return {"backend": backend, "devices": [gpu[i].name for i in idx], "kernel": backend}


def cuda_kernels() -> dict:
    """What the first CUDA or OptiX render will need, as facts for the driver to judge
    (blurset.services.kernels): {"archs": ["sm_90", ...] of the GPUs this process sees, "kernels":
    ["sm_89", ...] that Cycles ships compiled, "driver": the CUDA driver's version}.
    Cycles takes a shipped cubin for a GPU's arch; otherwise the driver compiles
    Blender's PTX before the first frame. No archs where there is no CUDA driver."""
    import ctypes

    archs: list[str] = []
    driver = ctypes.c_int(0)
    try:
        cuda = ctypes.CDLL("libcuda.so.1")
    except OSError:
        cuda = None
    if cuda is not None and cuda.cuInit(0) == 0:
        cuda.cuDriverGetVersion(ctypes.byref(driver))
        n = ctypes.c_int(0)
        cuda.cuDeviceGetCount(ctypes.byref(n))
        for i in range(n.value):
            dev, major, minor = ctypes.c_int(), ctypes.c_int(), ctypes.c_int()
            if cuda.cuDeviceGet(ctypes.byref(dev), i) != 0:
                continue
            # CU_DEVICE_ATTRIBUTE_COMPUTE_CAPABILITY_MAJOR / _MINOR
            cuda.cuDeviceGetAttribute(ctypes.byref(major), 75, dev)
            cuda.cuDeviceGetAttribute(ctypes.byref(minor), 76, dev)
            arch = f"sm_{major.value}{minor.value}"
            if arch not in archs:
                archs.append(arch)
    lib = os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core", "cycles", "lib")
    try:
        names = os.listdir(lib)
    except OSError:
        names = []
    kernels = sorted(
        {n.split(".")[0][len("kernel_") :] for n in names if n.startswith("kernel_sm_")}
    )
    return {"archs": archs, "kernels": kernels, "driver": driver.value}


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
    _move(tmp, path)  # crosses file systems in the '#' case


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
    set_samples(int(samples))


def set_samples(samples: int, offset: int | None = None, sequence: int | None = None) -> None:
    """Render `samples` Cycles samples: the first ones of the seed's sequence, or with
    `offset` the block [offset, offset + samples) of a `sequence`-sample sequence
    (Cycles sample subsets: `samples` = the sequence, `sample_offset`,
    `sample_subset_length`; `sample_offset` alone changes nothing)."""
    c = bpy.context.scene.cycles
    if samples < 1:
        raise ValueError(f"samples must be >= 1, got {samples}")
    if offset is None:
        c.use_sample_subset = False
        c.samples = int(samples)
        return
    seq = int(sequence if sequence is not None else offset + samples)
    if not (0 <= offset and offset + samples <= seq <= MAX_SEQUENCE):
        raise ValueError(
            f"sample block [{offset}, {offset + samples}) does not fit a sequence of {seq} "
            f"samples (at most {MAX_SEQUENCE})"
        )
    c.samples = seq
    c.use_sample_subset = True
    c.sample_offset = int(offset)
    c.sample_subset_length = int(samples)


def apply_frame(fr: dict, resolution: int, fov_deg: float, samples: int) -> None:
    """Camera, samples (or sample block) and seed of one frame of a render command."""
    set_camera(fr["c2w"], resolution, fov_deg, int(fr.get("samples", samples)))
    set_samples(
        int(fr.get("samples", samples)),
        None if fr.get("sample_offset") is None else int(fr["sample_offset"]),
        None if fr.get("sample_sequence") is None else int(fr["sample_sequence"]),
    )
    # Cycles takes a signed 32-bit seed; fold larger integers into that range.
    bpy.context.scene.cycles.seed = int(fr["seed"]) % (2**31)
    set_dof(fr.get("dof"))


def set_dof(dof: dict | None) -> None:
    """A defocus frame's thin lens (issue 35): focus at "focus_distance" along the viewing
    axis, an aperture of "aperture_radius" (world units); None: the pinhole camera of
    every other frame. Blender takes the aperture as an f-number of the camera's focal
    length (Cycles: radius = lens / (2 · f-number), lens in mm, world units metres)."""
    cam = bpy.context.scene.camera.data
    if not dof or float(dof["aperture_radius"]) <= 0.0:
        cam.dof.use_dof = False
        return
    cam.dof.use_dof = True
    cam.dof.focus_object = None
    cam.dof.focus_distance = float(dof["focus_distance"])
    cam.dof.aperture_fstop = cam.lens * 1e-3 / (2.0 * float(dof["aperture_radius"]))
    cam.dof.aperture_blades = 0  # a round aperture: the circle of confusion is a disk
    cam.dof.aperture_ratio = 1.0


def scene_is_animated() -> bool:
    """Whether anything in the scene changes with the frame number (actions, drivers,
    NLA): then frames must not be rendered as an animation job."""
    for coll in (
        bpy.data.objects,
        bpy.data.meshes,
        bpy.data.shape_keys,
        bpy.data.materials,
        bpy.data.node_groups,
        bpy.data.cameras,
        bpy.data.lights,
        bpy.data.worlds,
        bpy.data.armatures,
    ):
        for idb in coll:
            trees = [idb, getattr(idb, "node_tree", None)]
            for t in trees:
                ad = getattr(t, "animation_data", None) if t is not None else None
                if ad is not None and (ad.action or len(ad.drivers) or len(ad.nla_tracks)):
                    return True
    return False


def render_job(
    frames: list[dict], resolution: int, fov_deg: float, samples: int, on_frame, crop: bool = False
):
    """Render `frames` (each as `apply_frame` takes it, with "out") as ONE animation job:
    one render operator call, persistent data, frame k + 1 of the job set up by a
    frame-change handler, each EXR moved to its "out" by a render-write handler, which
    also calls on_frame(k, out, seconds, origin) as soon as the frame is on disk (origin:
    see set_region; `crop` writes each EXR cropped to the job's region). Blender's
    per-call work (operator, render pipeline set-up, result allocation) is paid once per
    job instead of once per frame; Cycles still starts a session per frame (its API has
    no way to render two cameras in one session). Pixels equal `render_frame` per frame:
    the same camera, samples and seed reach Cycles, nothing depends on the frame number
    (the caller checks scene_is_animated). Raises the first error a handler met."""
    scene = bpy.context.scene
    n = len(frames)
    if n == 0:
        return
    for fr in frames:  # refuse bad input before the job starts
        apply_frame(fr, resolution, fov_deg, samples)
    origin = set_region(job_region(frames), resolution, crop)
    d = os.path.dirname(os.path.abspath(str(frames[0]["out"]))) or "."
    os.makedirs(d, exist_ok=True)
    # '#' in a directory would be read as the frame number: stage in a temp dir then.
    stage = tempfile.mkdtemp(prefix="blurset-job-") if "#" in d else d
    pattern = os.path.join(stage, f".blurset-{os.getpid()}-job-#########.exr")
    state: dict = {"error": None, "t": time.perf_counter(), "done": 0}

    def k_of(sc) -> int:
        return sc.frame_current - 1

    def on_change(sc, *_):
        k = k_of(sc)
        if state["error"] is not None or not 0 <= k < n:
            return
        try:
            apply_frame(frames[k], resolution, fov_deg, samples)
            # Scene settings changed in a handler reach the render's copy of the scene
            # only when the scene is tagged (the camera object tags itself).
            sc.update_tag()
        except Exception as e:
            state["error"] = e

    def on_write(sc, *_):
        k = k_of(sc)
        if state["error"] is not None or not 0 <= k < n:
            return
        try:
            tmp = pattern.replace("#########", f"{k + 1:09d}")
            out = str(frames[k]["out"])
            _move(tmp, out)
            now = time.perf_counter()
            secs, state["t"] = now - state["t"], now
            state["done"] += 1
            on_frame(k, out, secs, origin)
        except Exception as e:
            state["error"] = e

    try:
        _render_animation(scene, n, pattern, (on_change, on_write), state)
    finally:
        if stage != d:
            shutil.rmtree(stage, ignore_errors=True)
    if state["error"] is not None:
        raise state["error"]
    if state["done"] != n:
        raise RuntimeError(f"Blender wrote {state['done']} of {n} frames")


def _render_animation(scene, n: int, pattern: str, handlers, state: dict) -> None:
    """Frames 1..n of `scene` as one animation render to `pattern`, with `handlers`
    (frame change, render write) installed for its duration; the scene's frame range
    and output settings are restored after it, whatever happens."""
    on_change, on_write = handlers
    r = scene.render
    saved = (scene.frame_start, scene.frame_end, scene.frame_current, scene.frame_step)
    saved_r = (r.filepath, r.use_overwrite, r.use_placeholder)
    h = bpy.app.handlers
    h.frame_change_pre.append(on_change)
    h.render_write.append(on_write)
    try:
        scene.frame_start, scene.frame_end, scene.frame_step = 1, n, 1
        r.filepath = pattern
        r.use_overwrite, r.use_placeholder = True, False
        scene.frame_set(1)
        state["t"] = time.perf_counter()
        bpy.ops.render.render(animation=True)
    finally:
        h.frame_change_pre.remove(on_change)
        h.render_write.remove(on_write)
        r.filepath, r.use_overwrite, r.use_placeholder = saved_r
        scene.frame_start, scene.frame_end, _, scene.frame_step = saved
        scene.frame_set(saved[2])


def _move(tmp: str, path: str) -> None:
    """Rename a finished EXR into place (copy + rename across file systems)."""
    if not os.path.isfile(tmp):
        raise RuntimeError(f"Blender wrote no image for {path}")
    try:
        os.replace(tmp, path)
    except OSError:
        part = path + ".part"
        shutil.copyfile(tmp, part)
        os.replace(part, path)
        os.remove(tmp)


def set_exr_codec(codec: str) -> None:
    if codec not in EXR_CODECS:
        raise ValueError(f"exr_codec must be one of {', '.join(EXR_CODECS)}, got {codec!r}")
    bpy.context.scene.render.image_settings.exr_codec = codec


def render_motion_blur(
    keys, motion_steps: int, out: str, seed: int, rolling: bool = False
) -> float:
    """One render whose shutter spans the camera path `keys` (c2w matrices at t_k =
    k / 2^motion_steps): keys at frames 1 + t_k, a shutter of one frame opening at
    frame 1, and Cycles motion steps on the camera object, so its 2^steps + 1 motion
    samples fall on the keys; between them Cycles interpolates (linear position,
    slerp rotation), and each path sample gets a uniform time over the shutter.
    `rolling`: through Cycles' rolling shutter instead (issue 59), each row at its own
    time, the top row at t = 0 and the bottom one at t = 1, read at once (scanline
    exposure 0): skew without blur.
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
        set_rolling_shutter(rolling)
        scene.frame_set(1)
        return render_frame(out, seed)
    finally:
        prefs.keyframe_new_interpolation_type = interp
        cam.animation_data_clear()
        scene.render.use_motion_blur = False
        set_rolling_shutter(False)
        scene.frame_set(1)


def set_rolling_shutter(on: bool) -> None:
    """Cycles' rolling shutter over the motion blur shutter: rows read top to bottom,
    each at once (scanline exposure 0); off: every row over the whole shutter."""
    c = bpy.context.scene.cycles
    c.rolling_shutter_type = "TOP" if on else "NONE"
    c.rolling_shutter_duration = 0.0 if on else 0.1


def set_region(region, resolution: int, crop: bool = False):
    """Render only the pixel rectangle `region` = [x0, y0, x1, y1) (y down from the top
    row), the rest of the image transparent 0 (the core's plan/region.rs says why those
    pixels are exactly what a full render gives); None renders the whole image. Blender
    reads the border once per render call, so a job's frames share one region.
    `crop` writes only the region's pixels (the same values: Cycles samples a pixel by
    its place in the whole image) and returns where they sit, [x0, y0]; None when the
    EXR is the whole image."""
    r = bpy.context.scene.render
    if region is None:
        r.use_border = False
        return None
    x0, y0, x1, y1 = (int(v) for v in region)
    n = int(resolution)
    if not (0 <= x0 < x1 <= n and 0 <= y0 < y1 <= n):
        raise ValueError(f"region {list(region)} does not fit a {n}x{n} image")
    r.use_border = True
    # Cropped EXRs save the write, the read and the disk space of pixels known to be 0.
    r.use_crop_to_border = bool(crop)
    # Blender's border is fractions from the bottom-left corner.
    r.border_min_x, r.border_max_x = x0 / n, x1 / n
    r.border_min_y, r.border_max_y = (n - y1) / n, (n - y0) / n
    return [x0, y0] if crop else None


def job_region(frames: list[dict]):
    """The region one render call of `frames` needs: all their regions together, or None
    (the whole image) when any frame needs the whole image."""
    regions = [fr.get("region") for fr in frames]
    if not regions or any(g is None for g in regions):
        return None
    return [
        min(g[0] for g in regions),
        min(g[1] for g in regions),
        max(g[2] for g in regions),
        max(g[3] for g in regions),
    ]


def render_frame(out: str, seed: int) -> float:
    scene = bpy.context.scene
    # Cycles takes a signed 32-bit seed; fold larger integers into that range.
    scene.cycles.seed = int(seed) % (2**31)
    t0 = time.perf_counter()
    _render_to(out)
    return time.perf_counter() - t0
