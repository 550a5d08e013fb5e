"""A training loader of the IBRNet / NAN / GNT family on a blurset build, with pairs.

IBRNet's LLFF datasets give a target view and its nearest source views; the paper's
restoration head also needs the clean version of every source (and of the target).
`blurset.data.open_scene` returns both, so a batch here is IBRNet's dict plus
`src_rgbs_clean` and `rgb_clean`:

    rgb, rgb_clean          (H, W, 3)     degraded target and its sharp version
    camera                  (34,)         H, W, K (4x4), c2w (4x4, OpenCV) flattened
    src_rgbs, src_rgbs_clean (n, H, W, 3) degraded sources and their sharp versions
    src_cameras             (n, 34)
    depth_range             (2,)          IBRNet's [0.9 near, 1.6 far]

Run `python examples/gnerf_loader.py BUILD` to print one batch's shapes. PyTorch is
imported only to wrap the batches (`BlursetPairs`); `sample` is plain NumPy.
"""

from __future__ import annotations

import sys

import numpy as np
from blurset.data import Scene, list_scenes, open_scene


def camera_vector(scene: Scene, view: int) -> np.ndarray:
    """IBRNet's 34-vector: image size, 4x4 intrinsics, 4x4 OpenCV camera-to-world."""
    k = np.eye(4)
    k[:3, :3] = scene.intrinsics
    h, w = scene.size
    return np.concatenate(([h, w], k.ravel(), scene.c2w_opencv[view].ravel())).astype(np.float32)


def nearest_sources(scene: Scene, target: int, n: int) -> np.ndarray:
    """The n train views nearest to the target's camera centre (IBRNet's 'dist')."""
    centres = scene.c2w_opencv[:, :3, 3]
    pool = np.array([v for v in scene.train_views if v != target])
    d = np.linalg.norm(centres[pool] - centres[target], axis=1)
    return pool[np.argsort(d, kind="stable")[:n]]


def sample(scene: Scene, target: int, n_sources: int = 8) -> dict[str, np.ndarray]:
    """One batch of NumPy arrays for `target` (a test view to evaluate, or a train
    view to train on): the target, its clean version and its nearest sources."""
    src = nearest_sources(scene, target, n_sources)
    return {
        "rgb": scene.images[target],
        "rgb_clean": scene.clean[target],
        "camera": camera_vector(scene, target),
        "src_rgbs": scene.images[src],
        "src_rgbs_clean": scene.clean[src],
        "src_cameras": np.stack([camera_vector(scene, v) for v in src]),
        "depth_range": np.array([scene.near.min() * 0.9, scene.far.max() * 1.6], dtype=np.float32),
    }


def make_dataset(build, level: str, *, split: str = "train", downsample: int = 4, **scene_kw):
    """A torch Dataset of every (setting, target view): train views of the build's train
    settings for `split="train"`, test views of its test settings otherwise."""
    import json
    from pathlib import Path

    import torch

    splits = json.loads((Path(build) / "splits.json").read_text())
    settings = sorted({s for s, lvl in list_scenes(build) if lvl == level} & set(splits[split]))
    scenes = [open_scene(build, s, level, downsample=downsample, **scene_kw) for s in settings]
    items = [
        (i, int(v))
        for i, sc in enumerate(scenes)
        for v in (sc.train_views if split == "train" else sc.test_views)
    ]

    class BlursetPairs(torch.utils.data.Dataset):
        def __len__(self) -> int:
            return len(items)

        def __getitem__(self, k: int) -> dict:
            i, view = items[k]
            return {key: torch.from_numpy(v) for key, v in sample(scenes[i], view).items()}

    return BlursetPairs()


if __name__ == "__main__":
    build = sys.argv[1]
    setting, _ = list_scenes(build)[0]
    scene = open_scene(build, setting, "blur_4" if len(sys.argv) < 3 else sys.argv[2])
    batch = sample(scene, int(scene.test_views[0]))
    for key, value in batch.items():
        print(f"{key:16s} {value.shape} {value.dtype}")
