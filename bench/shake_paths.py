"""What the shake benches share (issue 61): the image centre's path of a shake level, as
the core plans it; the same statistics measured on a recorded blur kernel and on a path
drawn into a kernel; a reader of MATLAB v5 files (recorded kernels are published as
`.mat`); and a port of the shake model before issue 61, for its frame counts.

Not a bench itself (bench/run.py runs `bench_*.py` only).

**The statistics of a kernel.** A blur kernel is where one scene point's light landed
over the exposure: a path with its time order lost. On its support (the pixels at least
[`SUPPORT_SHARE`] of its largest value), largest 8-connected part:

- `extent_px`: the largest distance between two support pixels;
- `length_over_extent`: the longest shortest path through the support (8-neighbour steps,
  diagonal √2; the stroke's length along itself, each part once) over the extent: 1 for
  a straight stroke, larger the more it bends or folds;
- `ends_share`: the straight distance between that path's two ends over the extent: near
  1 for a stroke that goes one way (and for a closed ring, whose longest shortest path
  is half of it: length_over_extent π/2 tells it apart), small for a stroke that bends
  back on itself (a U);
- `dwell_share`: the share of the kernel's mass in the brightest fifth of its support:
  a fifth for a stroke drawn at constant speed, more where the hand slowed down;
- `width_px`: the support's pixels over the longest shortest path's length plus one: the
  stroke's width (px), wider where a path scribbles back and forth over itself.

A model path is drawn into a kernel at a given extent (its points at equal times,
splatted bilinearly) and measured by the same code. Its time order also gives
`drift_share` (the distance between where it starts and ends over its extent) and
`path_over_extent` (its length through the planned frames over its extent), which a
kernel cannot give.
"""

from __future__ import annotations

import heapq
import math
import struct
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np
import numpy.typing as npt

Array = npt.NDArray[np.float64]

# The resolution shake levels are stated at (shake.rs: REFERENCE_PX).
REFERENCE_PX = 512
# A kernel's support: the pixels at least this share of its largest value.
SUPPORT_SHARE = 0.05
# dwell_share: the brightest share of the support whose mass is measured.
DWELL_TOP = 0.2

# -- the image centre's path, from the core's plan --------------------------------------


def focal_px(resolution: int, fov_deg: float) -> float:
    """The focal length in pixels of a square view `fov_deg` wide."""
    return resolution / 2 / math.tan(math.radians(fov_deg) / 2)


def turn_matrix(yaw_deg: float, pitch_deg: float, roll_deg: float) -> Array:
    """The camera's turn `Rz(roll) · Ry(yaw) · Rx(pitch)` of a recorded pose (shake.rs:
    `pose_turn`)."""
    y, p, r = (math.radians(a) for a in (yaw_deg, pitch_deg, roll_deg))
    rz = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
    ry = np.array([[math.cos(y), 0, math.sin(y)], [0, 1, 0], [-math.sin(y), 0, math.cos(y)]])
    rx = np.array([[1, 0, 0], [0, math.cos(p), -math.sin(p)], [0, math.sin(p), math.cos(p)]])
    return rz @ ry @ rx


def centre_path(poses: list[dict], focal: float) -> Array:
    """(N, 2) px: where the direction seen at the image centre at the written pose
    appears in the camera turned as each pose (shake.rs: `image_at` of the centre)."""
    out = np.empty((len(poses), 2))
    for i, q in enumerate(poses):
        d = turn_matrix(q["yaw_deg"], q["pitch_deg"], q.get("roll_deg", 0.0)).T @ (0, 0, -focal)
        out[i] = focal * d[0] / -d[2], focal * d[1] / -d[2]
    return out


def polyline_length(p: Array) -> float:
    return float(np.hypot(*np.diff(p, axis=0).T).sum()) if len(p) > 1 else 0.0


def extent(p: Array) -> float:
    """The largest distance between two points of `p` (N, 2)."""
    if len(p) < 2:
        return 0.0
    d = p[:, None, :] - p[None, :, :]
    return float(np.sqrt((d**2).sum(-1)).max())


def plan_shake(
    views: int, levels: list[int], *, resolution: int, ghost_px: float, seed: int,
    method: str = "average",
) -> dict:  # fmt: skip
    """The core's plan of one setting with shake `levels` (no object: an empty box),
    each level taking the fewest evenly spread frames within `ghost_px` (latents auto,
    up to 4096 frames), or one motion-blur render along keys (`method` motion_blur)."""
    from blurset.plan import SamplingConfig, plan_setting

    cfg = SamplingConfig(
        views=views, shake=levels, levels=[1], resolution=resolution, latents_auto=True,
        max_ghost_px=ghost_px, latents_max=4096, blur_method=method,
    )  # fmt: skip
    p = plan_setting(cfg, uid="shake", theta0_deg=90.0, seed=seed, bbox_dims=[1.0, 0.7, 0.5],
                     vertices=np.zeros((0, 3), np.float32))  # fmt: skip
    return {"fov_deg": p.fov_deg, "views": p.to_dict()["views"]}


def model_paths(
    views: int, levels: list[int], *, resolution: int = REFERENCE_PX, ghost_px: float = 0.25,
    seed: int = 5,
) -> dict[int, list[dict]]:  # fmt: skip
    """Per level, per view: the image centre's path through the core's frames (px at
    `resolution`, frames no more than `ghost_px` apart), and the level's record."""
    plan = plan_shake(views, levels, resolution=resolution, ghost_px=ghost_px, seed=seed)
    f = focal_px(resolution, plan["fov_deg"])
    out: dict[int, list[dict]] = {lv: [] for lv in levels}
    for v in plan["views"]:
        for lv in levels:
            rec = v["shake"][str(lv)]
            out[lv].append({"path": centre_path(rec["poses"], f), "record": rec})
    return out


# -- kernels and their statistics --------------------------------------------------------


def rasterize(path: Array, extent_px: float, margin: int = 2) -> Array:
    """`path` (points at equal times) scaled to `extent_px`, drawn into a kernel: each
    point's equal weight splatted bilinearly; the kernel sums to 1."""
    e = extent(path)
    p = (path - path.min(axis=0)) * (extent_px / e if e > 0 else 1.0) + margin
    size = int(math.ceil(p.max())) + margin + 2
    k = np.zeros((size, size))
    i0 = np.floor(p).astype(int)
    fr = p - i0
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        w = (fr[:, 0] if dx else 1 - fr[:, 0]) * (fr[:, 1] if dy else 1 - fr[:, 1])
        np.add.at(k, (i0[:, 1] + dy, i0[:, 0] + dx), w)
    return k / k.sum()


_NEIGHBOURS = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]


def _component(mask: npt.NDArray[np.bool_], k: Array) -> set[tuple[int, int]]:
    """The 8-connected part of `mask` holding the most of `k`'s mass."""
    seen: set[tuple[int, int]] = set()
    best: tuple[float, set[tuple[int, int]]] = (-1.0, set())
    for start in zip(*np.nonzero(mask), strict=True):
        s = (int(start[0]), int(start[1]))
        if s in seen:
            continue
        part, todo = {s}, [s]
        while todo:
            y, x = todo.pop()
            for dy, dx in _NEIGHBOURS:
                n = (y + dy, x + dx)
                if (
                    0 <= n[0] < mask.shape[0] and 0 <= n[1] < mask.shape[1]
                    and mask[n] and n not in part
                ):  # fmt: skip
                    part.add(n)
                    todo.append(n)
        seen |= part
        mass = float(sum(k[p] for p in part))
        if mass > best[0]:
            best = (mass, part)
    return best[1]


def _farthest(part: set[tuple[int, int]], start: tuple[int, int]) -> tuple[tuple[int, int], float]:
    """The pixel of `part` farthest from `start` along 8-neighbour steps, and how far."""
    dist = {start: 0.0}
    heap = [(0.0, start)]
    while heap:
        d, p = heapq.heappop(heap)
        if d > dist[p]:
            continue
        for dy, dx in _NEIGHBOURS:
            n = (p[0] + dy, p[1] + dx)
            if n in part:
                nd = d + (math.sqrt(2) if dy and dx else 1.0)
                if nd < dist.get(n, math.inf):
                    dist[n] = nd
                    heapq.heappush(heap, (nd, n))
    end = max(dist, key=lambda q: (dist[q], q))
    return end, dist[end]


def kernel_stats(k: Array) -> dict[str, float]:
    """The statistics of the module's docs, of kernel `k` (any scale)."""
    k = np.asarray(k, dtype=np.float64)
    part = _component(k >= SUPPORT_SHARE * k.max(), k)
    pts = np.array(sorted(part), dtype=np.float64)
    ext = extent(pts)
    # The longest shortest path: from any pixel to the farthest, then from there.
    a, _ = _farthest(part, min(part))
    b, length = _farthest(part, a)
    vals = np.sort(np.array([k[p] for p in part]))[::-1]
    top = max(1, math.ceil(DWELL_TOP * len(vals)))
    return {
        "extent_px": ext,
        "length_over_extent": length / ext if ext > 0 else 0.0,
        "ends_share": math.hypot(a[0] - b[0], a[1] - b[1]) / ext if ext > 0 else 0.0,
        "dwell_share": float(vals[:top].sum() / k.sum()),
        "width_px": len(part) / (length + 1.0),
    }


def path_stats(path: Array, kernel_extent_px: float) -> dict[str, float]:
    """A model path's kernel statistics, drawn at `kernel_extent_px`, and its own."""
    e = extent(path)
    own = {
        "drift_share": float(np.hypot(*(path[-1] - path[0])) / e) if e > 0 else 0.0,
        "path_over_extent": polyline_length(path) / e if e > 0 else 0.0,
    }
    return {**kernel_stats(rasterize(path, kernel_extent_px)), **own}


# -- MATLAB v5 files ---------------------------------------------------------------------

_MI = {1: "i1", 2: "u1", 3: "<i2", 4: "<u2", 5: "<i4", 6: "<u4", 7: "<f4", 9: "<f8",
       12: "<i8", 13: "<u8", 16: "u1"}  # fmt: skip
_MI_MATRIX, _MI_COMPRESSED, _MX_CELL = 14, 15, 1


def _elements(buf: bytes):
    """(type, payload) of each data element of a little-endian v5 stream."""
    i = 0
    while i + 8 <= len(buf):
        t, n = struct.unpack_from("<II", buf, i)
        if t >> 16:  # small element: type and size in one word, payload in the next
            yield t & 0xFFFF, buf[i + 4 : i + 4 + (t >> 16)]
            i += 8
            continue
        yield t, buf[i + 8 : i + 8 + n]
        i += 8 + n + ((-n) % 8 if t != _MI_COMPRESSED else 0)


def _matrix(buf: bytes) -> tuple[str, object]:
    subs = list(_elements(buf))
    cls = int(np.frombuffer(subs[0][1], "<u4")[0]) & 0xFF
    dims = tuple(int(d) for d in np.frombuffer(subs[1][1], "<i4"))
    name = bytes(subs[2][1]).decode("latin-1")
    if cls == _MX_CELL:
        cells = [_matrix(d)[1] for t, d in subs[3:] if t == _MI_MATRIX]
        arr = np.empty(len(cells), dtype=object)
        arr[:] = cells
        return name, arr.reshape(dims, order="F")
    t, data = subs[3]
    if t not in _MI:
        raise ValueError(f"{name!r}: MATLAB data type {t} is not read here")
    return name, np.frombuffer(data, _MI[t]).astype(np.float64).reshape(dims, order="F")


def read_mat(path: Path) -> dict[str, object]:
    """The numeric matrices and cell arrays of a MATLAB v5 `.mat` file (little-endian),
    by name. A v7.3 file (HDF5) is refused by name."""
    buf = Path(path).read_bytes()
    if buf[:19] == b"MATLAB 7.3 MAT-file":
        raise ValueError(f"{path}: a MATLAB 7.3 (HDF5) file; this reader reads v5 files")
    if buf[126:128] != b"IM":
        raise ValueError(f"{path}: not a little-endian MATLAB v5 file")
    out: dict[str, object] = {}
    for t, data in _elements(buf[128:]):
        if t == _MI_COMPRESSED:
            t, data = next(_elements(zlib.decompress(data)))
        if t == _MI_MATRIX:
            name, value = _matrix(data)
            out[name] = value
    return out


def recorded_kernels(path: Path) -> list[Array]:
    """The kernels of a `.mat` file holding them as the cell array `kernels` (the form
    Levin et al. 2009's eight recorded kernels are passed around in, `Levin09.mat`)."""
    cells = read_mat(path).get("kernels")
    if not isinstance(cells, np.ndarray) or cells.dtype != object:
        raise ValueError(f"{path}: no cell array 'kernels'")
    return [np.asarray(k, dtype=np.float64) for k in cells.ravel(order="F")]


# -- the shake model before issue 61 -----------------------------------------------------
# A port of `rust/core/src/plan/kinds/shake.rs` at 1c923e5^ (the commit before issue 61's
# hand shake): per view, per image axis, three sinusoids c_j sin(2π j t + φ_j), c_j uniform
# in [0, 1/j], φ_j uniform in [0, 2π); level l scales the path so the image centre's
# largest displacement is 2^(l+1) px at 512 px; the ghost gap is measured at the image
# centre; latents auto takes the fewest evenly spread frames (from 4) within the bound.

OLD_HARMONICS = 3
OLD_MIN_FRAMES = OLD_HARMONICS + 1
OLD_GRID = 512
MOTION_KEY_TOLERANCE_PX = 0.02  # degradation.rs
MOTION_STEPS_RANGE = (1, 7)  # degradation.rs


def key_midpoint_error(path: Array, times: Array, steps: int) -> float:
    """The largest distance (px) at the middle of each of 2^steps equal intervals between
    `path` (dense, at `times`; linear between them) and the straight line joining its
    ends: how far a motion-blur render along 2^steps + 1 keys strays from the path (the
    core's `motion_steps` check, measured on the path through dense frames)."""
    n = 1 << steps
    a = np.arange(n) / n
    b, mid = a + 1 / n, a + 0.5 / n

    def at(t: Array) -> Array:
        return np.stack([np.interp(t, times, path[:, 0]), np.interp(t, times, path[:, 1])], 1)

    return float(np.hypot(*(at(mid) - (at(a) + at(b)) / 2).T).max())


def old_draw(rng: np.random.Generator) -> Array:
    """One view's harmonics: (axis, j, (c_j, φ_j))."""
    out = np.empty((2, OLD_HARMONICS, 2))
    for a in range(2):
        for j in range(OLD_HARMONICS):
            out[a, j] = rng.uniform(0.0, 1.0 / (j + 1)), rng.uniform(0.0, 2 * math.pi)
    return out


def old_at(h: Array, t: npt.ArrayLike) -> Array:
    """d(t) (N, 2) before scaling, at the times `t` (a number is one time)."""
    t = np.atleast_1d(np.asarray(t, dtype=np.float64))
    j = np.arange(1, OLD_HARMONICS + 1)
    arg = 2 * math.pi * j * t[:, None, None] + h[None, :, :, 1]
    return (h[None, :, :, 0] * np.sin(arg)).sum(-1)


def old_level(h: Array, level: int, resolution: int) -> Callable[[npt.ArrayLike], Array]:
    """The image centre's path d(t) (px) of level `level`: largest |d| on the grid
    2^(l+1) px at 512 px, scaled with the resolution."""
    pts = old_at(h, np.linspace(0, 1, OLD_GRID + 1))
    largest = float(np.hypot(pts[:, 0], pts[:, 1]).max())
    amp = 2.0 ** (min(level, 7) + 1) * resolution / REFERENCE_PX
    scale = amp / largest if largest > 0 else 0.0
    return lambda t: old_at(h, t) * scale


def old_gap(d: Callable[[npt.ArrayLike], Array], times: Array) -> float:
    """The largest gap between consecutive frames at the image centre, the two uncovered
    ends of the exposure counting as one."""
    p = d(times)
    ends = float(np.hypot(*(d(0.0)[0] - p[0])) + np.hypot(*(p[-1] - d(1.0)[0])))
    inner = np.hypot(*np.diff(p, axis=0).T)
    return max(ends, float(inner.max())) if len(inner) else ends


def old_frames(d: Callable[[npt.ArrayLike], Array], bound: float, latents_max: int = 4096) -> int:
    """The old latents auto: the fewest m from ⌈length / bound⌉ (at least 4) whose evenly
    spread frames leave no gap over `bound`, at most `latents_max`."""
    length = polyline_length(d(np.linspace(0, 1, OLD_GRID + 1)))
    first = max(min(math.ceil(length / bound - 1e-9), latents_max), OLD_MIN_FRAMES)
    m = first
    for m in range(first, max(latents_max, first) + 1):
        if old_gap(d, (np.arange(m) + 0.5) / m) <= bound:
            break
    return m


def old_motion_steps(d: Callable[[npt.ArrayLike], Array]) -> int:
    """The fewest motion steps whose keys, joined linearly, stay within 0.02 px of d at
    the middle of every interval (the old `motion_steps`)."""
    lo, hi = MOTION_STEPS_RANGE
    for steps in range(lo, hi + 1):
        n = 1 << steps
        a, b = np.arange(n) / n, (np.arange(n) + 1) / n
        pa, pb, pm = d(a), d(b), d((a + b) / 2)
        if np.hypot(*(pm - (pa + pb) / 2).T).max() <= MOTION_KEY_TOLERANCE_PX:
            return steps
    return hi
