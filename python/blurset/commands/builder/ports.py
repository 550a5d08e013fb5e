"""What the builder asks of a worker (issue 49): the one port between the build's
orchestration and a renderer. `worker_client.Worker` (the Blender worker, or the tests'
stand-in it starts in Blender's place) is its implementation; the messages behind it are
typed in the core (dataset/wire.rs, schemas/worker/)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

from blurset.services.worker_client import Worker

if TYPE_CHECKING:
    from blurset import _records

# A frame on disk: its index in the request, its EXR, and where a cropped EXR's pixels
# sit in the image (None: a whole image).
OnFrame = Callable[[int, str, "tuple[int, int] | None"], None]


class RenderWorker(Protocol):
    """Loads one object at a time and renders frames of it, each reported once on disk."""

    @property
    def info(self) -> _records.Ready:
        """The worker's ready line (Blender version, device, CUDA archs)."""
        ...

    def load(
        self,
        glb: Path,
        vertices_out: Path,
        *,
        unlit: _records.Unlit = "lit",
        light_paths: _records.LightPaths = "auto",
    ) -> _records.Loaded:
        """Import, normalize and light one GLB, its QA views judged."""
        ...

    def render(
        self,
        frames: Sequence[Mapping[str, object]],
        *,
        resolution: int,
        fov_deg: float,
        samples: int | None = None,
        on_frame: OnFrame | None = None,
        exr_codec: str | None = None,
        noise_threshold: float | None = None,
        batch: bool = True,
        crop: bool = False,
        guides: bool = False,
        geometry: bool = False,
    ) -> _records.Rendered:
        """Render `frames` in order; `on_frame` as each one is on disk."""
        ...


def _conforms(worker: Worker) -> RenderWorker:
    """mypy holds Worker to the port here (an error names the method that drifted)."""
    return worker
