"""Images in and out of blurset-core: the running mean of linear frames (Accumulator),
EXR/PNG/JPEG reading (and the depth EXRs of `build --passes`), the sRGB curve, render QA and the error against a reference.

The public face of these bindings for scripts, tests and benchmarks (blurset._core is
private to the package)."""

from __future__ import annotations

from blurset._core import (
    Accumulator,
    FrameQa,
    ImageMetrics,
    ObjectError,
    QaThresholds,
    circle_of_confusion,
    default_qa_thresholds,
    detail_kept,
    frame_qa,
    half_noise,
    half_noise_bound,
    image_error,
    image_info,
    object_error,
    pareto_front,
    read_depth,
    read_exr,
    read_image,
    spread,
    srgb_encode,
    thumbnail_qa,
)

__all__ = [
    "Accumulator",
    "circle_of_confusion",
    "FrameQa",
    "ImageMetrics",
    "ObjectError",
    "QaThresholds",
    "default_qa_thresholds",
    "detail_kept",
    "frame_qa",
    "half_noise",
    "half_noise_bound",
    "image_error",
    "image_info",
    "object_error",
    "pareto_front",
    "read_depth",
    "read_exr",
    "read_image",
    "spread",
    "srgb_encode",
    "thumbnail_qa",
]
