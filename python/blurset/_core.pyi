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

class InputError(BlursetError):
    """Bad input data (missing file, wrong shape, mismatched sizes); the message names the file."""

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

# --- noise (rust/py/src/noise.rs) ---------------------------------------------------

NoiseLevelTable = tuple[float, float, float, float]
"""(log10 sigma_read(1), read step, log10 sigma_shot(1), shot step) per log2 gain."""

def noise_default_levels() -> NoiseLevelTable:
    """blurset's default gain table (derived from KPN's training ranges; not NAN's)."""

def noise_levels_from_kpn(
    sig_read: npt.NDArray[np.float64], sig_shot: npt.NDArray[np.float64]
) -> NoiseLevelTable:
    """NAN's mapping: sorted unique values, two lowest dropped, first two used (1-D arrays)."""

def noise_sigmas(gain: float, levels: NoiseLevelTable) -> tuple[float, float]:
    """(sigma_read, sigma_shot) at `gain`: log10 sigma(g) = log10 sigma(1) + step * log2 g."""

def noise_white_balance(seed: int) -> tuple[float, float]:
    """The scene's (red, blue) gains, red U[1.9, 2.4], blue U[1.5, 1.9], from `seed`."""

def noise_key(seed: int, gain: float) -> int:
    """The Philox key of one gain of one seed (what `blurset noise` uses)."""

def image_info(path: str | PathLike[str]) -> tuple[int, int, int, int]:
    """(width, height, channels, bits per sample) from the header; ImageError names the file."""

def read_image(path: str | PathLike[str]) -> npt.NDArray[np.uint8] | npt.NDArray[np.uint16]:
    """Decode PNG (8/16-bit) or JPEG to (H, W, C), C in 1..4, in the file's own depth."""

def noise_image(
    image: npt.NDArray[np.uint8] | npt.NDArray[np.uint16],
    *,
    sigma_read: float,
    sigma_shot: float,
    key: int,
    view: int = 0,
    frame: int = 0,
    gamma: str = "2.2",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8] | npt.NDArray[np.uint16]]:
    """One noisy frame: (linear float32 (H, W, 3|4), processed image of the input's
    dtype and shape, alpha copied). Bit-identical to what `blurset noise` writes for
    view `view`, frame `frame` with key `noise_key(seed, gain)`."""

def noise_clean_linear(
    image: npt.NDArray[np.uint8] | npt.NDArray[np.uint16],
    *,
    gamma: str = "2.2",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
) -> npt.NDArray[np.float32]:
    """The clean linear values y the noise is added to, float32 (H, W, 1|3)."""

def noise_write_variants(
    sources: list[str | PathLike[str]],
    names: list[str],
    variants: list[tuple[str | PathLike[str], float, float, int]],
    *,
    frames: int = 1,
    gamma: str = "2.2",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
) -> None:
    """Write images/<name>.png and linear/<name>.exr of every (out_dir, sigma_read,
    sigma_shot, key) variant; `names` holds len(sources) * frames stems, view-major."""

# --- noise on a build, from linear light (rust/py/src/noise_linear.rs) ---------------

def noise_scene_seed(seed: int, setting: str, level: str) -> int:
    """The noise seed of one level of one setting of a build (plays `--seed`'s role)."""

def read_linear_composited(
    path: str | PathLike[str], *, background: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> npt.NDArray[np.float32]:
    """A build's linear RGBA EXR composited over `background`: float32 (H, W, 3), unclipped;
    ImageError names the file on NaN/inf."""

def noise_clean_from_linear(
    image: npt.NDArray[np.float32],
    *,
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
) -> npt.NDArray[np.float32]:
    """The clean values y = white_level * clip(L, 0, 1) / wb of the linear path."""

def noise_image_linear(
    image: npt.NDArray[np.float32],
    *,
    sigma_read: float,
    sigma_shot: float,
    key: int,
    view: int = 0,
    frame: int = 0,
    gamma: str = "2.2",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8]]:
    """One noisy frame from composited linear RGB (H, W, 3): (linear float32, processed
    uint8), with the same standard normals as `noise_image` for the same key/view/frame."""

def noise_write_variants_linear(
    sources: list[str | PathLike[str]],
    names: list[str],
    variants: list[tuple[str | PathLike[str], float, float, int]],
    *,
    frames: int = 1,
    gamma: str = "2.2",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
    background: tuple[float, float, float] = (1.0, 1.0, 1.0),
) -> None:
    """`noise_write_variants` from a build's linear EXRs (composited over `background`)."""

def thumbnail_qa(
    image: npt.NDArray[np.uint8], *, background: tuple[float, float, float] = (1.0, 1.0, 1.0)
) -> tuple[float, float, float]:
    """(object coverage, mean object luma in [0, 1], fraction of the border touched) of an
    RGB8 image over `background` (linear RGB)."""

# --- tradeoff (rust/py/src/tradeoff.rs) ---------------------------------------------

def image_error(
    image: npt.NDArray[np.float32],
    reference: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = (1.0, 1.0, 1.0),
) -> str:
    """JSON {psnr, psnr_linear, mse, mse_linear} of `image` against `reference`, both
    float32 (H, W, 4) premultiplied linear RGBA; `psnr` is of the sRGB image composited
    over `background` (peak 1), capped at 200 dB for identical images."""

def pareto_front(seconds: list[float], psnr: list[float]) -> list[bool]:
    """Which (seconds, psnr) points no other point beats in both (ties count as beaten
    only when the other is strictly better in one)."""

# -- LLFF -------------------------------------------------------------------------------

def read_poses_bounds(path: str | PathLike[str]) -> npt.NDArray[np.float64]:
    """`poses_bounds.npy` as (N, 17) float64; PoseFormatError names the file and reason."""

def write_poses_bounds(path: str | PathLike[str], rows: npt.NDArray[np.float64]) -> None:
    """Write (N, 17) rows atomically; non-finite values are refused."""

# -- sampling ---------------------------------------------------------------------------

def default_sampling_config() -> str:
    """The paper's sampling settings as SamplingConfig JSON."""

def validate_sampling_config(config_json: str) -> None:
    """ValueError naming the option when a SamplingConfig is out of range."""

def seed_for(seed: int, uid: str, index: int) -> int:
    """The seed of setting `index` of object `uid` under the build seed."""

def plan_setting(
    config_json: str,
    *,
    uid: str,
    theta0_deg: float,
    seed: int,
    bbox_dims: list[float] | tuple[float, float, float],
    vertices: npt.NDArray[np.float32],
) -> str:
    """A setting's plan (views, trajectories, weights, latent frames, seeds) as JSON."""

def write_setting_poses(
    plan_json: str, setting_dir: str | PathLike[str], level_dirs: list[str]
) -> None:
    """`<level>/poses_bounds.npy` for each level and `transforms.json` of a setting."""

def test_views(views: int, stride: int) -> list[int]:
    """Every `stride`-th view index below `views`."""

def image_name(index: int, n: int) -> str:
    """The image file name of view `index` of `n` (sorted order is view order)."""

def make_splits(
    entries_json: str,
    *,
    view_stride: int,
    test_fraction: float,
    test_objects: list[str] | None,
    seed: int,
) -> str:
    """splits.json (by object) for setting entries `[{setting, object, views}]`."""

def seeded_subset(ids: list[str], k: int, seed: int) -> list[str]:
    """A seeded random subset of `k` ids, sorted; independent of the ids' order."""

# -- render QA --------------------------------------------------------------------------

def frame_qa(rgba: npt.NDArray[np.float32], *, thresholds: str | None = None) -> str:
    """QA of a premultiplied linear (H, W, 4) image as JSON: coverage, luminance,
    saturated, border_coverage and failure (the reason, or null)."""

def default_qa_thresholds() -> str:
    """The default QA thresholds (QaThresholds) as JSON."""

# --- stats (rust/py/src/stats.rs) ---------------------------------------------------

def build_stats(out: str | PathLike[str]) -> str:
    """The statistics of the build at `out` as JSON text (the `stats.json` document,
    schema "blurset-stats/1"): per-view and per-setting numbers of every complete
    setting's meta.json, min/median/max/mean summaries and counts.

    Raises InputError naming the file: no such directory, not a build, unreadable or
    corrupt meta.json of a complete setting, corrupt splits.json or failures.jsonl.
    """

# -- failures.jsonl ---------------------------------------------------------------------

def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, the directory name of one setting (θ0 rounded, 3 digits)."""

def theta0s(n: int) -> list[float]:
    """The θ0 of each of an object's `n` settings, evenly spaced from 0°."""

def current_failures(
    path: str | PathLike[str], *, complete: list[str], theta0s: list[float] | None = None
) -> tuple[str, int]:
    """(JSON list of the failures now, torn lines skipped): the latest record per
    (uid, setting) whose work is still not complete."""

# -- publishing: checksums, the image check of verify (rust/py/src/publish.rs) ----------

MANIFEST: str

def sha256_file(path: str | PathLike[str]) -> str:
    """sha256 of a file's bytes, lowercase hex."""

def manifest_files(root: str | PathLike[str]) -> list[str]:
    """The files MANIFEST.sha256 of `root` lists: relative, '/'-separated, sorted
    bytewise; not the manifest, dot files, dot folders or `*.partial` folders."""

def write_manifest(root: str | PathLike[str]) -> int:
    """Hash every listed file (in parallel) into root/MANIFEST.sha256 (sha256sum
    format, atomic); returns the number of files."""

def update_manifest(root: str | PathLike[str], rels: list[str]) -> int:
    """Rehash these files (relative to `root`) into its existing manifest, dropping
    those no longer there; returns the number of files listed."""

def check_manifest(root: str | PathLike[str]) -> list[tuple[str, str]]:
    """(relative path, problem) of each file that does not match root/MANIFEST.sha256:
    `missing`, `checksum mismatch` or `not in MANIFEST.sha256`, sorted by path.
    Raises FileNotFoundError without a manifest, InputError naming a bad line."""

def check_images(items: list[tuple[str | PathLike[str], int, int]]) -> list[str | None]:
    """For each (path, width, height): None when the image (PNG/JPEG, or a linear EXR
    by its extension) decodes whole at that size, else the problem. In parallel."""
