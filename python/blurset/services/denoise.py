"""Denoising with Open Image Denoise (issue 28): where the library is, and one denoiser
per process.

The driver denoises (blurset-core's `Denoiser`, an OIDN loaded at run time): a blurry
image is the mean of latent frames that only the driver holds (its Accumulator averages
their colour and their albedo and normal passes), so the driver calls OIDN once on that
mean, in memory, and the sharp image the same way. The library is the one the pinned bpy
wheel ships beside Cycles (`bpy/lib/libOpenImageDenoise.so.2`), i.e. the OIDN Cycles
itself denoises with; `BLURSET_OIDN_LIBRARY` names another file.
"""

from __future__ import annotations

import importlib.util
import os
import sys
import threading
from pathlib import Path

from blurset import _core
from blurset.exceptions import ConfigError

Denoiser = _core.Denoiser

_NAMES = {
    "linux": "libOpenImageDenoise.so.2",
    "darwin": "libOpenImageDenoise.2.dylib",
    "win32": "OpenImageDenoise.dll",
}
_LOCK = threading.Lock()
_CACHE: dict[str, Denoiser] = {}


def oidn_library() -> Path:
    """The OIDN library file: $BLURSET_OIDN_LIBRARY, else the bpy wheel's. ConfigError
    (naming --denoise) when there is none."""
    env = os.environ.get("BLURSET_OIDN_LIBRARY")
    if env:
        return Path(env)
    name = _NAMES.get(sys.platform, _NAMES["linux"])
    spec = importlib.util.find_spec("bpy")
    roots = list(spec.submodule_search_locations or []) if spec else []
    for root in roots:
        for sub in ("lib", "."):
            p = Path(root) / sub / name
            if p.exists():
                return p
    raise ConfigError(
        f"--denoise oidn: no Open Image Denoise library ({name}) in the bpy wheel; "
        "install the pinned bpy or set BLURSET_OIDN_LIBRARY to the file"
    )


def denoiser(device: str = "auto") -> Denoiser:
    """This process's denoiser on `device` (auto: OIDN's fastest, a GPU when there is one;
    cpu), opened once. ConfigError naming --denoise when OIDN cannot be loaded."""
    with _LOCK:
        d = _CACHE.get(device)
        if d is None:
            path = oidn_library()
            try:
                d = Denoiser(path, device)
            except _core.InputError as e:
                raise ConfigError(f"--denoise oidn: {e}") from None
            _CACHE[device] = d
        return d


def device_for(cycles_device: str) -> str:
    """The OIDN device of a build on a Cycles device: the CPU for a CPU build (OIDN
    would otherwise take a GPU the build was told not to use), else OIDN's choice."""
    return "cpu" if cycles_device.lower() == "cpu" else "auto"
