"""Type stubs of the native module `blurset._core` (built from rust/py).

One section per binding file; keep each section next to its Rust counterpart's name.
"""

from os import PathLike

import numpy as np
import numpy.typing as npt

__version__: str

class BlursetError(Exception): ...
class PoseFormatError(BlursetError): ...
class ImageError(BlursetError): ...

# --- accumulate (rust/py/src/accumulate.rs) -----------------------------------------

class Accumulator:
    """Running mean of premultiplied linear RGBA frames of one size.

    Memory is one float64 frame whatever the number of frames; the mean is taken in
    linear light, then composited over a background, sRGB-encoded and quantized.
    """

    def __new__(cls, width: int, height: int) -> Accumulator: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def count(self) -> int:
        """Number of frames added so far."""
    def add_exr(self, path: str | PathLike[str]) -> None:
        """Read an RGBA float EXR (alpha 1 when absent) and add it.

        Raises ValueError when its size differs, ImageError (naming the file) when it
        holds NaN/inf or cannot be decoded, FileNotFoundError when it is missing.
        """
    def add(self, frame: npt.NDArray[np.float32]) -> None:
        """Add a float32 (H, W, 4) C-contiguous premultiplied linear RGBA frame."""
    def mean(self) -> npt.NDArray[np.float32]:
        """The mean so far, float32 (H, W, 4); ValueError when no frame was added."""
    def write_png(
        self,
        path: str | PathLike[str],
        background: tuple[float, float, float] = (1.0, 1.0, 1.0),
    ) -> None:
        """Write the mean as 8-bit sRGB PNG over `background` (linear RGB), atomically."""
    def write_exr(self, path: str | PathLike[str]) -> None:
        """Write the linear mean as a ZIP-compressed RGBA float32 EXR, atomically."""

def srgb_encode(linear: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Exact IEC 61966-2-1 encoding, clamped to [0, 1] (NaN -> 0); same shape."""

def read_exr(path: str | PathLike[str]) -> npt.NDArray[np.float32]:
    """The first RGB(A) layer of an EXR as float32 (H, W, 4), values as stored."""
