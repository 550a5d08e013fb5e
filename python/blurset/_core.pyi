"""Type stubs of the native module `blurset._core` (built from rust/py).

One section per binding file; keep each section next to its Rust counterpart's name.
"""

from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path
from typing import Any, Literal, TypeAlias, TypedDict, final

import numpy as np
import numpy.typing as npt

# The dicts that cross the FFI, typed from the core's serde types (blurset.services.stubgen).
from blurset import _records as rec

__version__: str

class BlursetError(Exception): ...
class PoseFormatError(BlursetError): ...
class ImageError(BlursetError): ...

class InputError(BlursetError):
    """Bad input data (missing file, wrong shape, mismatched sizes); the message names the file."""

class ConfigValueError(ValueError):
    """An option out of its range; `option` names it, `detail` holds the value and the range."""

    option: str
    detail: str

# --- build config (rust/py/src/config.rs) ---------------------------------------------

def check_downsample(factors: list[int]) -> None:
    """ConfigValueError unless the factors are distinct integers in 2..=64."""

def check_range(
    option: str,
    value: object,
    lo: float,
    hi: float = ...,
    *,
    lo_open: bool = False,
    integer: bool = True,
) -> None:
    """ConfigValueError naming `option` unless `value` is in lo..=hi (above lo with
    lo_open; hi 2^32 - 1 unless given), an integer unless `integer` is false: the words
    of every declared range."""

def preset_values(name: str) -> dict[str, bool | int | float | str]:
    """What preset `name` sets, option name -> value (ValueError: no such preset)."""

def target_next_round(
    config: BuildConfig,
    *,
    frames: int,
    spent_per_frame: int,
    rounds: int,
    mse: float | None = None,
    previous: tuple[int, float] | None = None,
) -> int | None:
    """Samples per frame and half of an image's next round under the config's target, or
    None when it is done (`mse`: the last estimate, None before the pilot; `previous`:
    samples per frame and half and the MSE of the estimate before it)."""

# The kinds of what is wrong with a file (layout.rs Fault, manifest.rs ManifestProblem).
SettingFault: TypeAlias = Literal[
    "missing",
    "unreadable",
    "level_missing",
    "count",
    "size",
    "not_png",
    "png_truncated",
    "empty",
    "truncated",
    "undecodable",
]
ManifestFault: TypeAlias = Literal["missing", "mismatch", "unlisted"]

_OptionKind: TypeAlias = Literal[
    "switch",
    "int",
    "float",
    "text",
    "choice",
    "words",
    "levels",
    "factors",
    "indices",
    "rgb",
    "count_or_auto",
    "fraction_or_ids",
]

@final
class OptionDecl:
    """One option as its declaration in the core states it: the flags, help, TOML keys,
    range, defaults and whether it shapes the outputs (python/blurset/services/options.py makes the
    parsers and the CLI reference from these)."""

    @property
    def name(self) -> str: ...
    @property
    def rust_type(self) -> str:
        """The field's Rust type as the core's table writes it (`Option<Vec<String>>`)."""
    @property
    def flags(self) -> list[str]:
        """Its flags, the first the one errors name (none: set through `via`, or TOML only)."""
    @property
    def via(self) -> str | None:
        """The option whose flag sets this one."""
    @property
    def keys(self) -> list[str]:
        """The keys a TOML file may name it by (dashes or underscores alike)."""
    @property
    def kind(self) -> _OptionKind:
        """How it reads on the command line: switch, int, float, text, choice, words,
        levels, factors, indices, rgb, count_or_auto, fraction_or_ids."""
    @property
    def optional(self) -> bool:
        """None is a value of it."""
    @property
    def choices(self) -> list[str]: ...
    @property
    def range(self) -> str:
        """The accepted values, as an error states them."""
    @property
    def default(self) -> object:
        """The default, as dataset.json records it."""
    @property
    def unset(self) -> str | None:
        """What a None default means, in words."""
    @property
    def demo(self) -> object:
        """The default under --demo, when it has its own."""
    @property
    def before(self) -> object:
        """The value a recorded config without this option was made with."""
    @property
    def help(self) -> str: ...
    @property
    def shapes_outputs(self) -> bool:
        """Whether it shapes the files written (a rerun into the same output must keep it)."""
    @property
    def group(self) -> str | None:
        """Options whose flags exclude each other share a group."""
    @property
    def metavar(self) -> str | None: ...
    @property
    def section(self) -> str | None:
        """The titled section of the help its flag is listed under (None: the command's)."""

# dataset.json's config record, generated from the declarations (`make stub`):
class BuildConfigRecord(TypedDict):
    """dataset.json's `config`: every option as `BuildConfig.record()` writes it."""

    objects: list[str]
    out: str | None
    demo: bool
    settings_per_object: int
    views: int
    levels: list[int]
    latents: int | Literal["auto"]
    latents_auto: bool
    latents_max: int
    max_ghost_px: float
    blur_method: Literal["average", "motion_blur", "auto"]
    samples: int
    samples_total: int | None
    sharp_samples: int | None
    latent_sampling: Literal["subsets", "independent"]
    blur_budget: Literal["parity", "flat", "need"]
    denoise: Literal["none", "oidn"]
    preset: Literal["paper", "balanced", "floor", "fast"] | None
    target_psnr: float | None
    target_pilot_samples: int
    target_max_samples: int
    light_paths: Literal["auto", "fixed"]
    device: Literal["auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal"]
    gpus: list[int] | None
    gpus_per_task: float | None
    resolution: int
    seed: int
    fov_deg: float
    phi0_deg: float
    window_deg: float
    delta0: float
    radius_margin: float
    level_spread: float
    latent_positions: Literal["random", "stratified"]
    trajectory: Literal["start", "centered"]
    orientation_max: float
    near_floor: float
    background: list[float]
    write_linear: bool
    previews: bool
    view_stride: int
    test_fraction: float
    test_objects: list[str] | None
    test_settings: int | None
    blurry_test_views: bool
    downsample: list[int]
    defocus: list[int]
    shake: list[int]
    rolling_shutter: list[int]
    passes: list[str]
    workers: int
    workers_per_gpu: int | None
    threads: int
    executor: Literal["local", "ray"]
    ray_address: str | None
    shard: str | None
    objaverse_dir: str | None
    objaverse_offline: bool
    objaverse_count: int | None
    timeout: float
    object_timeout: float
    retries: int
    max_failure_rate: float
    max_triangles: int
    max_texture_pixels: int
    blender: str | None
    check_poses: bool
    allow_mixed: bool
    licenses: list[str] | None
    effective_sharp_samples: int

# (end of the generated record)

@final
class BuildConfig:
    """Every option of `blurset build`, validated (frozen: `replace` makes a new one).

    `BuildConfig(**values)` takes option names (`views=8`, `levels=[1, 4]` …) over the
    defaults; a value out of range raises ConfigValueError naming the option and range.
    """

    def __new__(cls, **values: object) -> BuildConfig: ...
    def replace(self, **values: object) -> BuildConfig:
        """A copy with these options replaced, validated."""
    def require_target(self) -> None:
        """ConfigValueError unless the config names an output and objects (or demo)."""
    @property
    def shard_index(self) -> tuple[int, int] | None:
        """This job's share of the objects, `(i, N)` of `shard` (None: every object)."""
    def check_test_objects(self, uids: list[str]) -> None:
        """ConfigValueError (option test_objects) naming the listed test objects that are
        not among `uids`, every object of the build."""
    @staticmethod
    def options() -> list[str]:
        """The option names, in declaration order."""
    @staticmethod
    def declarations() -> list[OptionDecl]:
        """Every option as the core declares it, in declaration order."""
    def record(self) -> BuildConfigRecord:
        """dataset.json's `config` record: every option, `latents` = "auto" under latents
        auto, and `effective_sharp_samples`."""
    def sampling(self) -> SamplingConfig:
        """The sampling sub-config every setting's plan is made with."""
    def __reduce__(self) -> tuple[Any, tuple[str]]: ...
    @staticmethod
    def _from_json(text: str) -> BuildConfig:
        """The config a `__reduce__` wrote (pickling, e.g. to Ray tasks)."""
    @property
    def max_latents(self) -> int:
        """The most renders one blurry image can take."""
    @property
    def blur_samples_total(self) -> int:
        """Samples one blurry image gets at most (the budget, or samples × its frames)."""
    @property
    def effective_sharp_samples(self) -> int:
        """Samples of the sharp render (`sharp_samples`, or the blurry image's budget)."""
    @property
    def cycles_samples(self) -> int | None:
        """The Cycles `samples` every render of a subsets build is pinned to (None: each
        render its own), so a pixel never depends on what the worker rendered before it."""
    @property
    def frames_per_setting(self) -> int:
        """Renders of one setting (an upper bound with latents auto)."""
    @property
    def level_dirs(self) -> list[str]:
        """`sharp`, then `blur_<l>` of every level."""
    @property
    def theta0s(self) -> list[float]:
        """The θ0 of each setting of an object."""
    def sharp_views(self, n_views: int) -> list[int]:
        """The views whose blur levels hold a copy of the sharp image (none with
        blurry_test_views)."""
    @property
    def test_view_images(self) -> str:
        """What the blur levels hold at the test views: "sharp" or "blurry"."""
    # The options, generated from the core's declarations (`make stub`):
    @property
    def objects(self) -> list[str]: ...
    @property
    def out(self) -> str | None: ...
    @property
    def demo(self) -> bool: ...
    @property
    def settings_per_object(self) -> int: ...
    @property
    def views(self) -> int: ...
    @property
    def levels(self) -> list[int]: ...
    @property
    def latents(self) -> int: ...
    @property
    def latents_auto(self) -> bool: ...
    @property
    def latents_max(self) -> int: ...
    @property
    def max_ghost_px(self) -> float: ...
    @property
    def blur_method(self) -> Literal["average", "motion_blur", "auto"]: ...
    @property
    def samples(self) -> int: ...
    @property
    def samples_total(self) -> int | None: ...
    @property
    def sharp_samples(self) -> int | None: ...
    @property
    def latent_sampling(self) -> Literal["subsets", "independent"]: ...
    @property
    def blur_budget(self) -> Literal["parity", "flat", "need"]: ...
    @property
    def denoise(self) -> Literal["none", "oidn"]: ...
    @property
    def preset(self) -> Literal["paper", "balanced", "floor", "fast"] | None: ...
    @property
    def target_psnr(self) -> float | None: ...
    @property
    def target_pilot_samples(self) -> int: ...
    @property
    def target_max_samples(self) -> int: ...
    @property
    def light_paths(self) -> Literal["auto", "fixed"]: ...
    @property
    def device(self) -> Literal["auto", "cpu", "optix", "cuda", "hip", "oneapi", "metal"]: ...
    @property
    def gpus(self) -> list[int] | None: ...
    @property
    def gpus_per_task(self) -> float | None: ...
    @property
    def resolution(self) -> int: ...
    @property
    def seed(self) -> int: ...
    @property
    def fov_deg(self) -> float: ...
    @property
    def phi0_deg(self) -> float: ...
    @property
    def window_deg(self) -> float: ...
    @property
    def delta0(self) -> float: ...
    @property
    def radius_margin(self) -> float: ...
    @property
    def level_spread(self) -> float: ...
    @property
    def latent_positions(self) -> Literal["random", "stratified"]: ...
    @property
    def trajectory(self) -> Literal["start", "centered"]: ...
    @property
    def orientation_max(self) -> float: ...
    @property
    def near_floor(self) -> float: ...
    @property
    def background(self) -> tuple[float, float, float]: ...
    @property
    def write_linear(self) -> bool: ...
    @property
    def previews(self) -> bool: ...
    @property
    def view_stride(self) -> int: ...
    @property
    def test_fraction(self) -> float: ...
    @property
    def test_objects(self) -> list[str] | None: ...
    @property
    def test_settings(self) -> int | None: ...
    @property
    def blurry_test_views(self) -> bool: ...
    @property
    def downsample(self) -> list[int]: ...
    @property
    def defocus(self) -> list[int]: ...
    @property
    def shake(self) -> list[int]: ...
    @property
    def rolling_shutter(self) -> list[int]: ...
    @property
    def passes(self) -> list[str]: ...
    @property
    def workers(self) -> int: ...
    @property
    def workers_per_gpu(self) -> int | None: ...
    @property
    def threads(self) -> int: ...
    @property
    def executor(self) -> Literal["local", "ray"]: ...
    @property
    def ray_address(self) -> str | None: ...
    @property
    def shard(self) -> str | None: ...
    @property
    def objaverse_dir(self) -> str | None: ...
    @property
    def objaverse_offline(self) -> bool: ...
    @property
    def objaverse_count(self) -> int | None: ...
    @property
    def timeout(self) -> float: ...
    @property
    def object_timeout(self) -> float: ...
    @property
    def retries(self) -> int: ...
    @property
    def max_failure_rate(self) -> float: ...
    @property
    def max_triangles(self) -> int: ...
    @property
    def max_texture_pixels(self) -> int: ...
    @property
    def blender(self) -> str | None: ...
    @property
    def check_poses(self) -> bool: ...
    @property
    def allow_mixed(self) -> bool: ...
    @property
    def licenses(self) -> list[str] | None: ...
    # (end of the generated options)

@final
class NoiseConfig:
    """Every option of `blurset noise`, validated (frozen).

    `NoiseConfig(**values)` takes option names (`gains=["1", "4"]`, `frames=2` …) over
    the defaults; a bad value raises ConfigValueError naming the option.
    """

    def __new__(cls, **values: object) -> NoiseConfig: ...
    @property
    def gain_values(self) -> list[float]:
        """The gains as numbers, in the order given."""
    @staticmethod
    def options() -> list[str]:
        """The option names, in declaration order."""
    @staticmethod
    def declarations() -> list[OptionDecl]:
        """Every option as the core declares it, in declaration order."""
    # The options, generated from the core's declarations (`make stub`):
    @property
    def out(self) -> str | None: ...
    @property
    def gains(self) -> list[str]: ...
    @property
    def factor(self) -> int | None: ...
    @property
    def seed(self) -> int: ...
    @property
    def profile(self) -> Literal["paper", "nan"]: ...
    @property
    def model(self) -> str: ...
    @property
    def frames(self) -> int: ...
    @property
    def kpn_levels(self) -> str | None: ...
    @property
    def gamma(self) -> Literal["2.2", "srgb"] | None: ...
    @property
    def white_level(self) -> float: ...
    @property
    def any_gain(self) -> bool: ...
    @property
    def downsample(self) -> list[int] | None: ...
    @property
    def clean_views(self) -> int | None: ...
    @property
    def no_linear(self) -> bool: ...
    @property
    def overwrite(self) -> bool: ...
    @property
    def levels(self) -> str | None: ...
    @property
    def source(self) -> Literal["auto", "linear", "png"]: ...
    @property
    def noisy_test_views(self) -> bool: ...
    @property
    def quiet(self) -> bool: ...
    # (end of the generated options)

# --- layout (rust/py/src/layout.rs) --------------------------------------------------

MARKER: str
PARTIAL_SUFFIX: str
SHARP: str
META: str
DATASET: str
SPLITS: str
FAILURES: str
POSES_BOUNDS: str
TRANSFORMS: str
NOISE: str
NOISE_DATASET: str
NOISE_SCENE: str
EXPORT: str
STATS: str
IMAGES: str
LINEAR: str
DEMO_OBJECTS: str

def work_dir(uid: str) -> str:
    """The private folder an object's worker writes its scratch in (`.work-<uid>`)."""

def object_lock(uid: str) -> str:
    """The lock a build holds while it builds one object (`.lock-<uid>`)."""

def linear_name(image: str) -> str:
    """The linear EXR of an image (`007.png` → `007.exr`)."""

def images_dir(factor: int) -> str:
    """The image folder at downsampling factor `factor` (`images`, `images_4`)."""

def linear_dir(factor: int) -> str:
    """The linear EXR folder at downsampling factor `factor` (`linear`, `linear_4`)."""

PASSES: list[str]
# A worker's start and one object's load, on a CPU (plan/cost.rs): the dry run's estimate.
OBJECT_LOAD_S: float
"""The per-view outputs besides colour (`--passes`), in order: depth, normal, mask."""

def pass_dir(kind: str, factor: int) -> str:
    """The sharp level's folder of a pass at downsampling factor `factor` (`depth`,
    `normals_4`, `masks`)."""

def nerfstudio_depth_dir(factor: int) -> str:
    """nerfstudio's depth folder in an exported scene at downsampling factor `factor`
    (`depths`, `depths_4`)."""

def pass_file(kind: str, image: str) -> str:
    """The file of an image's view in a pass's folder (`007.exr`; masks `007.png`)."""

def pass_level(kind: str, level: str, level_masks: bool) -> str:
    """The level folder that holds `level`'s files of pass `kind`: a blur or shake
    level's own masks (`blur_4`, `shake_2`) where the setting records them (meta.json
    `render.level_masks`), everything else the sharp level's (`sharp`)."""

def setting_name(uid: str, theta0_deg: float) -> str:
    """`<uid>_<theta0>`, the directory name of one setting (θ0 rounded, 3 digits)."""

def theta0s(n: int) -> list[float]:
    """The θ0 of each of an object's `n` settings, evenly spaced from 0°."""

def image_name(index: int, n: int) -> str:
    """The image file name of view `index` of `n` (sorted order is view order)."""

def level_dir(level: int) -> str:
    """Directory of a blur level (`blur_<l>`); level 0 is `sharp`."""

def level_dirs(levels: list[int]) -> list[str]:
    """`sharp`, then `blur_<l>` of every level."""

def parse_level_dir(name: str) -> int | None:
    """The level of a level directory name (`sharp` -> 0, `blur_<l>` -> l), or None."""

def level_kind(name: str) -> str | None:
    """The kind of a level directory (sharp, blur, defocus …), or None."""

def level_means(name: str) -> tuple[str, str] | None:
    """What a level directory's kind is, as a dataset card says it: (its directories'
    pattern, `blur_<l>`, and its sentence); None for `sharp` and a non-level name."""

def is_level_dir(name: str) -> bool:
    """Whether a name is a level directory a build writes (sharp, blur_<l>, defocus_<l>)."""

def level_record(name: str) -> tuple[str, str] | None:
    """Where meta.json records a level directory's image in each view: (the key of its
    kind's map, its level's key), `("levels", "2")` for `blur_2`; None for `sharp` and
    for a name that is no level directory."""

def written_pose(name: str) -> bool:
    """Whether a level directory's images are seen from the written poses (sharp, defocus)
    rather than being means whose mean latent poses meta.json records; False for a name
    that is no level directory."""

def sort_level_dirs(names: list[str]) -> list[str]:
    """Level directory names in level order; other names are dropped."""

def setting_levels(setting: str | PathLike[str]) -> list[str]:
    """The level directories a setting holds, in level order."""

def read_mean_poses(meta: str | PathLike[str], level: int) -> list[list[list[float]]] | None:
    """The mean latent pose (OpenGL c2w rows) of blur level `level` of every view of a
    setting's meta.json, or None for a meta.json from before mean poses."""

def read_exposure_ends(
    meta: str | PathLike[str], level: int
) -> list[tuple[list[list[float]], list[list[float]]] | None] | None:
    """The first and last latent camera (OpenGL c2w rows, in time) of each view's exposure
    in blur level `level`: None for a view whose image is a sharp copy or that has under
    two frames; None overall for a meta.json from before mean poses."""

def gain_name(gain: float) -> str:
    """Directory name of a noise gain (`gain_4`, `gain_2.5`)."""

def partial_dir(final_dir: str | PathLike[str]) -> Path:
    """Where a setting or noise unit is written before it is published."""

def is_complete(dir: str | PathLike[str]) -> bool:
    """A final (not `*.partial`) directory holding its marker."""

def is_image_folder(name: str) -> bool:
    """Whether a level's folder `name` holds per-view files: images, linear, depth,
    normals, masks, each also at a factor (`images_4`)."""

def setting_problem(setting: str | PathLike[str]) -> str | None:
    """What is missing or damaged in a complete setting (checked cheaply), or None."""

def setting_problems(setting: str | PathLike[str]) -> list[tuple[str, SettingFault, str]]:
    """Every problem of a complete setting the cheap check finds: (path relative to
    the setting, its kind, what is wrong in words), in the order the check meets them."""

def png_problem(path: str | PathLike[str]) -> str | None:
    """What is wrong with a PNG read without decoding (signature, end chunk), or None."""

def complete_settings(build: str | PathLike[str]) -> list[str]:
    """The complete setting directory names of a build, sorted."""

def publish(partial: str | PathLike[str], final_dir: str | PathLike[str], stamp: str) -> None:
    """Write the marker (holding `stamp`) into `partial` and put it at `final_dir`."""

def replace_dir(new: str | PathLike[str], dst: str | PathLike[str]) -> None:
    """Put the folder `new` at `dst`, the old one renamed aside, then removed."""

def temp_path(path: str | PathLike[str]) -> Path:
    """The temp path an atomic write of `path` goes through (`.<name>.tmp<pid>`)."""

def parse_temp_name(name: str) -> tuple[str, int] | None:
    """(target name, pid) of a temp file name `.<name>.tmp<pid>`, or None."""

def write_atomic(path: str | PathLike[str], data: bytes) -> None:
    """Write `data` through a synced temp file and a rename (parents created)."""

def write_build_tail(
    out: str | PathLike[str],
    config: BuildConfig,
    *,
    name: str,
    blurset_version: str,
    python_version: str,
    created: str,
    seconds: float,
) -> tuple[int, list[rec.Failure], int, list[tuple[str, str]]]:
    """Write failures.jsonl (the failures now), splits.json and dataset.json of the build
    at `out` made with `config`, from its complete settings' meta.json (call under the
    build's lock). Returns (settings complete, the failures now, test settings, the
    settings left out because their meta.json does not read: (name, why))."""

def write_dataset_json(path: str | PathLike[str], doc: rec.DatasetDoc) -> None:
    """Write a build's dataset.json; `doc` must match the core's DatasetDoc (unknown or
    missing fields are errors)."""

# --- accumulate (rust/py/src/accumulate.rs) -----------------------------------------

@final
class Accumulator:
    """Running mean of premultiplied linear RGBA frames of one size.

    Memory is one float64 frame whatever the number of frames; the mean is taken in
    linear light, then composited over a background, sRGB-encoded and quantized.
    """

    def __new__(cls, width: int, height: int, *, guides: bool = False) -> Accumulator:
        """With `guides`, it also averages the frames' denoising guides (albedo and
        normal passes of a multi-layer EXR) for `denoise`."""
    @property
    def guides(self) -> bool:
        """Whether the denoising guides are averaged."""
    @property
    def denoised(self) -> bool:
        """Whether the mean has been denoised (no frame can be added after)."""
    def denoise(self, denoiser: Denoiser) -> None:
        """Denoise the mean once: the denoiser sees the mean colour with the mean albedo
        and normal; its output replaces the RGB of the mean (alpha stays). ValueError
        without guides or frames."""
    def guide_means(self) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.float32]]:
        """The mean albedo and normal, float32 (H, W, 3) each."""
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def count(self) -> int:
        """Number of frames added so far."""
    def merge(self, other: Accumulator) -> None:
        """Add the frames of `other` (same size, plain, undenoised): the other half of an
        image rendered to a target, each frame keeping its weight."""
    def add_exr(
        self,
        path: str | PathLike[str],
        origin: tuple[int, int] | None = None,
        *,
        weight: float = 1.0,
    ) -> None:
        """Read an RGBA float EXR (alpha 1 when absent) and add it, counted `weight` times
        in the mean (positive, finite: its samples, where an image's frames render
        different counts).

        With `origin` = (x0, y0) the file is a render cropped to its region: its pixel
        (0, 0) is pixel (x0, y0) of the image (rows from the top), it must fit inside, and
        every pixel outside adds 0 (what a full render holds there).

        Raises ValueError when its size differs (or it does not fit at `origin`),
        ImageError (naming the file) when it holds NaN/inf or cannot be decoded,
        FileNotFoundError when it is missing.
        """
    def add(self, frame: npt.NDArray[np.float32]) -> None:
        """Add a float32 (H, W, 4) C-contiguous premultiplied linear RGBA frame."""
    def mean(self) -> npt.NDArray[np.float32]:
        """The mean so far, float32 (H, W, 4); ValueError when no frame was added."""
    def qa(self, *, thresholds: QaThresholds | None = None) -> FrameQa:
        """Render QA of the mean under `thresholds` (default: the core's); its pixels
        stay in the core."""
    def write_png(
        self,
        path: str | PathLike[str],
        background: tuple[float, float, float] = ...,
        *,
        downsample: int = 1,
    ) -> None:
        """Write the mean as 8-bit sRGB PNG over `background` (linear RGB), atomically;
        area-averaged over `downsample` x `downsample` blocks in linear light first."""
    def write_mask(self, path: str | PathLike[str], *, downsample: int = 1) -> None:
        """Write the object mask of the mean (8-bit PNG: 255 where coverage, area-averaged
        over `downsample` x `downsample` blocks, is at least one half; else 0)."""
    def write_exposure_mask(
        self,
        path: str | PathLike[str],
        *,
        blur_method: Literal["average", "motion_blur"],
        downsample: int = 1,
        sharp: str | PathLike[str] | None = None,
    ) -> None:
        """Write a blurry image's mask (8-bit PNG): 255 where its exposure covered the
        pixel, each frame one render of `blur_method` (`average`: some frame's alpha at
        least one half; `motion_blur`: the render's alpha above 0), area-averaged over
        `downsample` x `downsample` blocks to at least one half; every pixel of the mask
        PNG `sharp` (the view's sharp mask at that size) added."""
    def write_exr(self, path: str | PathLike[str]) -> None:
        """Write the linear mean as a ZIP-compressed RGBA float32 EXR, atomically."""

@final
class Denoiser:
    """Open Image Denoise loaded from `library` (the bpy wheel's
    libOpenImageDenoise.so.2) with one device: `auto` (OIDN's fastest, a GPU when there is
    one) or `cpu`. InputError naming the file when it cannot be loaded."""

    def __new__(cls, library: str | PathLike[str], device: str = "auto") -> Denoiser: ...
    @property
    def library(self) -> str: ...
    @property
    def version(self) -> str:
        """OIDN's version, e.g. 2.3.3."""
    @property
    def device_type(self) -> str:
        """CPU, CUDA, HIP, SYCL or METAL."""
    def record(self) -> rec.DenoiserRecord:
        """What meta.json records: the library, its version and the device type."""
    def denoise(
        self,
        color: npt.NDArray[np.float32],
        albedo: npt.NDArray[np.float32],
        normal: npt.NDArray[np.float32],
    ) -> npt.NDArray[np.float32]:
        """Denoise a float32 (H, W, 3) scene-linear colour image with its (H, W, 3)
        guides (C-contiguous); returns the denoised colour."""

def srgb_encode(linear: npt.NDArray[np.float32]) -> npt.NDArray[np.float32]:
    """Exact IEC 61966-2-1 encoding, clamped to [0, 1] (NaN -> 0); same shape."""

def read_exr(
    path: str | PathLike[str], *, size: tuple[int, int] | None = None
) -> npt.NDArray[np.float32]:
    """The first RGB(A) layer of an EXR as float32 (H, W, 4), values as stored; with
    `size` (width, height), a file of another size is refused from its header first."""

# --- geometry (rust/py/src/geometry.rs) --------------------------------------------------

def write_geometry(
    render: str | PathLike[str],
    *,
    depth: str | PathLike[str] | None = None,
    normal: str | PathLike[str] | None = None,
) -> None:
    """From a geometry render (Cycles' Depth and Normal passes) write the view's depth
    EXR (one channel Y, world units along the viewing axis, 0: no surface) and/or normal
    EXR (world-frame x, y, z in R, G, B; 0: no surface)."""

def read_depth(
    path: str | PathLike[str], *, size: tuple[int, int] | None = None
) -> npt.NDArray[np.float32]:
    """A depth EXR as float32 (H, W); with `size` (width, height), a file of another size
    is refused from its header first."""

def circle_of_confusion(
    depth: npt.NDArray[np.float32], focus: float, aperture_radius: float, focal_px: float
) -> npt.NDArray[np.float64]:
    """The circle of confusion (diameter, px) of each depth (0: no surface, gives 0) for a
    thin lens focused at `focus` with an aperture of `aperture_radius` (world units) and a
    focal length of `focal_px` pixels: meta.json's defocus levels' model."""

def write_depth_millimetres(depth_exr: str | PathLike[str], png: str | PathLike[str]) -> None:
    """A depth EXR as a 16-bit PNG in millimetres (0: no surface), nerfstudio's default
    unit; a depth past 65.535 units is refused."""

# --- noise (rust/py/src/noise.rs) ---------------------------------------------------

_NoiseLevelTable: TypeAlias = tuple[float, float, float, float]
"""(log10 sigma_read(1), read step, log10 sigma_shot(1), shot step) per log2 gain."""

def noise_default_levels() -> _NoiseLevelTable:
    """blurset's default gain table (derived from KPN's training ranges; not NAN's)."""

def noise_levels_from_kpn(
    sig_read: npt.NDArray[np.float64], sig_shot: npt.NDArray[np.float64]
) -> _NoiseLevelTable:
    """NAN's mapping: sorted unique values, two lowest dropped, first two used (1-D arrays)."""

def noise_sigmas(gain: float, levels: _NoiseLevelTable) -> tuple[float, float]:
    """(sigma_read, sigma_shot) at `gain`: log10 sigma(g) = log10 sigma(1) + step * log2 g."""

def noise_white_balance(seed: int) -> tuple[float, float]:
    """The scene's (red, blue) gains, red U[1.9, 2.4], blue U[1.5, 1.9], from `seed`."""

def noise_key(seed: int, gain: float) -> int:
    """The Philox key of one gain of one seed (what `blurset noise` uses)."""

def image_info(path: str | PathLike[str]) -> tuple[int, int, int, int]:
    """(width, height, channels, bits per sample) from the header; ImageError names the file."""

def read_image(path: str | PathLike[str]) -> npt.NDArray[np.uint8] | npt.NDArray[np.uint16]:
    """Decode PNG (8/16-bit) or JPEG to (H, W, C), C in 1..4, in the file's own depth."""

def noise_image_model(
    image: npt.NDArray[np.float32],
    *,
    model: str,
    gain: float,
    seed: int,
    key: int,
    view: int = 0,
    frame: int = 0,
    gamma: str = "srgb",
    white_balance: tuple[float, float] | None = None,
    white_level: float = 1.0,
    clean: bool = False,
) -> tuple[npt.NDArray[np.float32], npt.NDArray[np.uint8], str]:
    """One noisy frame of a camera model (`unprocess`, `eld:<camera>`) from linear
    float32 (H, W, 3): (linear float32 (H, W, 3), processed uint8 (H, W, 3), the model's
    noise.json `raw_model` as JSON text), as `blurset noise --model` writes it for view
    `view`, frame `frame`, key `noise_key(seed, gain)` (seed the scene's)."""

def noise_image(
    image: npt.NDArray[np.uint8] | npt.NDArray[np.uint16] | npt.NDArray[np.float32],
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
    view `view`, frame `frame` with key `noise_key(seed, gain)`. A float32 (H, W, 3)
    image is composited linear light (a build's EXR), processed to uint8."""

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
    background: tuple[float, float, float] | None = None,
    downsample: list[int] = ...,
    clean_views: list[int] = ...,
) -> None:
    """Write images/<name>.png and linear/<name>.exr of every (out_dir, sigma_read,
    sigma_shot, key) variant; `names` holds len(sources) * frames stems, view-major;
    images_<f>/ and linear_<f>/ for each `downsample` factor (noise drawn at that size);
    the views in `clean_views` stay clean (sigma 0). With a `background` the sources
    are a build's linear EXRs, composited over it."""

# --- the noise plan (rust/py/src/noise_plan.rs) ----------------------------------------

@final
class NoiseGain:
    """One gain of a unit: its folder, key, sigmas and noise.json."""

    @property
    def gain(self) -> float: ...
    @property
    def dir(self) -> str:
        """`gain_<g>`."""
    @property
    def key(self) -> int: ...
    @property
    def sigma_read(self) -> float: ...
    @property
    def sigma_shot(self) -> float: ...
    @property
    def record(self) -> rec.NoiseDoc:
        """The gain's noise.json, as written."""

@final
class NoiseUnit:
    """One scene to noise (a scene, or a level of a build's setting)."""

    @property
    def setting(self) -> str | None: ...
    @property
    def level(self) -> str | None: ...
    @property
    def dst(self) -> Path:
        """Where its gain folders go: OUT/<setting>/<level> of a build, OUT of a scene."""
    @property
    def seed(self) -> int: ...
    @property
    def images(self) -> int:
        """Images each gain writes (views x frames)."""
    @property
    def clean_views(self) -> list[int]: ...
    @property
    def gains(self) -> list[NoiseGain]: ...
    def pending(self) -> list[int]:
        """The gains not yet complete in `dst` (indices into `gains`)."""
    def write_images(self, dirs: list[tuple[int, str | PathLike[str]]]) -> None:
        """The noisy images of the gains `dirs` names, as (gain index, folder)."""
    def write_gain_files(self, gain: int, dir: str | PathLike[str]) -> None:
        """The clean views' files, the poses, a build's transforms.json and noise.json of
        gain `gain` in `dir`."""

@final
class NoisePlan:
    """The plan of one `blurset noise` run (rust/core/src/dataset/noise_plan.rs)."""

    @property
    def source(self) -> Literal["linear", "png"]: ...
    @property
    def gamma(self) -> Literal["2.2", "srgb"]: ...
    @property
    def downsample(self) -> list[int]: ...
    @property
    def levels(self) -> list[str]: ...
    @property
    def units(self) -> list[NoiseUnit]: ...
    @property
    def params(self) -> rec.NoiseParams:
        """The options the run is made with (noise_dataset.json `params`): a rerun into
        the same output must match them."""
    def write_dataset_start(self, out: str | PathLike[str]) -> None:
        """noise_dataset.json in `out` before any unit: the build and the options."""
    def write_dataset(self, out: str | PathLike[str], created: str) -> rec.NoiseDatasetDoc:
        """noise_dataset.json in `out` over its complete units (earlier runs' too),
        stamped `created`; returned."""
    def write_scene_record(self, out: str | PathLike[str]) -> rec.NoiseSceneRecord:
        """noise_scene.json in `out`: the scene, its gain folders, seed and profile;
        returned."""

def plan_noise_scene(
    scene: str | PathLike[str],
    out: str | PathLike[str],
    config: NoiseConfig,
    levels: _NoiseLevelTable,
) -> NoisePlan:
    """The plan of `blurset noise SCENE` (one unit, its gain folders in `out`) under the
    sigma table `levels`; InputError names a bad file, ConfigValueError the option."""

def plan_noise_build(
    build: str | PathLike[str],
    out: str | PathLike[str],
    settings: list[str],
    config: NoiseConfig,
    levels: _NoiseLevelTable,
) -> NoisePlan:
    """The plan of `blurset noise BUILD` over its complete `settings`, gains under
    `out/<setting>/<level>/`; every unit is checked before any is written."""

# --- noise on a build, from linear light (rust/py/src/noise_linear.rs) ---------------

def noise_scene_seed(seed: int, setting: str, level: str) -> int:
    """The noise seed of one level of one setting of a build (plays `--seed`'s role)."""

def read_linear_composited(
    path: str | PathLike[str], *, background: tuple[float, float, float] = ...
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

def thumbnail_qa(
    image: npt.NDArray[np.uint8], *, background: tuple[float, float, float] = ...
) -> tuple[float, float, float]:
    """(object coverage, mean object luma in [0, 1], fraction of the border touched) of an
    RGB8 image over `background` (linear RGB)."""

# --- tradeoff (rust/py/src/tradeoff.rs) ---------------------------------------------

@final
class ImageMetrics:
    """Error of an image against a reference (DESIGN §8): PSNR and MSE, sRGB and linear."""

    @property
    def psnr(self) -> float:
        """PSNR (dB, peak 1) of the sRGB image composited over the background (≤ 200)."""
    @property
    def psnr_linear(self) -> float:
        """PSNR (dB, peak 1) of the linear premultiplied RGBA."""
    @property
    def mse(self) -> float: ...
    @property
    def mse_linear(self) -> float: ...
    @property
    def detail_ratio(self) -> float:
        """High-frequency energy (squared Laplacian of sRGB luma over the background) of
        the image over the reference's: < 1 smoothed, > 1 noisier (issue 28)."""

def image_error(
    image: npt.NDArray[np.float32],
    reference: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = ...,
) -> ImageMetrics:
    """{psnr, psnr_linear, mse, mse_linear} of `image` against `reference`, both
    float32 (H, W, 4) premultiplied linear RGBA; `psnr` is of the sRGB image composited
    over `background` (peak 1), capped at 200 dB for identical images."""

def detail_kept(
    image: npt.NDArray[np.float32],
    r1: npt.NDArray[np.float32],
    r2: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = ...,
) -> float:
    """The share of the reference's texture `image` keeps (core `detail_kept`): `reference`
    rendered twice on independent seeds, `r1` and `r2`; all float32 (H, W, 4)
    premultiplied linear RGBA. Render noise on either side does not read as detail."""

@final
class ObjectError:
    """Error on the object's pixels (alpha over 1e-6, Cycles' rounding, in either image;
    DESIGN §8)."""

    @property
    def psnr(self) -> float:
        """PSNR (dB, peak 1) of the sRGB image over the background, on object pixels."""
    @property
    def mse(self) -> float: ...
    @property
    def coverage(self) -> float:
        """Fraction of the frame that is object pixels."""
    @property
    def object_px(self) -> int: ...

def object_error(
    image: npt.NDArray[np.float32],
    reference: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = ...,
) -> ObjectError:
    """Error of `image` against `reference` (float32 (H, W, 4) premultiplied linear RGBA)
    on the pixels covered in either: a whole-frame PSNR reads 10·log10(1/coverage) high."""

def half_noise(
    half_a: npt.NDArray[np.float32],
    half_b: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = ...,
) -> ObjectError:
    """The render noise of the mean of two independent halves of an image, estimated from
    them on object pixels: MSE(half_a, half_b) / 4 where sRGB is straight over their
    spread, each half's distance from their merged image where it bends."""

def half_noise_bound(
    half_a: npt.NDArray[np.float32],
    half_b: npt.NDArray[np.float32],
    *,
    background: tuple[float, float, float] = ...,
) -> rec.HalfNoise:
    """half_noise with its upper bound where the noise is heavy-tailed: `estimate` (psnr,
    mse, coverage, object_px), `mse_bound`, `psnr_bound` (the PSNR reached at least) and
    `n_eff` (how many pixels the estimate effectively rests on)."""

def spread(values: list[float]) -> rec.Spread:
    """The worst value, the 5th percentile (nearest rank) and the mean of per-image
    figures."""

def pareto_front(seconds: list[float], psnr: list[float]) -> list[bool]:
    """Which (seconds, psnr) points no other point beats in both (ties count as beaten
    only when the other is strictly better in one)."""

# -- LLFF -------------------------------------------------------------------------------

def read_poses_bounds(path: str | PathLike[str]) -> npt.NDArray[np.float64]:
    """`poses_bounds.npy` as (N, 17) float64; PoseFormatError names the file and reason."""

def write_poses_bounds(path: str | PathLike[str], rows: npt.NDArray[np.float64]) -> None:
    """Write (N, 17) rows atomically; non-finite values are refused."""

# -- sampling and the plan (rust/py/src/sampling.rs) ---------------------------------

@final
class SamplingConfig:
    """The sampling of a setting's plan (views, trajectory, levels, latents, samples).

    `SamplingConfig(**values)` takes the fields of `to_dict()` over the paper's defaults;
    ConfigValueError names an option out of range.
    """

    def __new__(cls, **values: object) -> SamplingConfig: ...
    def to_dict(self) -> rec.SamplingConfig:
        """The fields as a dict (what meta.json records as `sampling`)."""
    @property
    def max_latents(self) -> int:
        """The most latent frames one blurry image can have."""

def default_sampling_config() -> SamplingConfig:
    """The paper's sampling settings."""

def seed_for(seed: int, uid: str, index: int) -> int:
    """The seed of setting `index` of object `uid` under the build seed."""

def check_theta0_deg(theta0_deg: float) -> None:
    """ConfigValueError unless θ0 is a finite number of degrees."""

@final
class Plan:
    """The plan of one setting: every view, trajectory, level, latent frame and seed."""

    @property
    def uid(self) -> str: ...
    @property
    def n_views(self) -> int: ...
    @property
    def resolution(self) -> list[int]: ...
    @property
    def fov_deg(self) -> float: ...
    def ghost_overruns(self) -> list[tuple[int, str, float]]:
        """The blurry images latents auto left above its ghost bound (`latents_max`
        stopped it): (view, level, largest gap px); none without latents auto."""
    def to_dict(self) -> rec.SettingPlan:
        """The whole plan as a dict (views[].levels["<l>"].latent_frames …), for reading."""
    def level(self, view: int, level: int) -> rec.LevelPlan:
        """One view's plan of one blur level as a dict (w_l, latents, motion_px, …)."""
    def cost(
        self,
        pin: int | None,
        *,
        sharp_views: list[int],
        sharp_samples: int,
        backend: str,
        cores: int,
    ) -> tuple[int, int, float]:
        """What `renders` (with the same arguments) cost on `backend` with `cores` cores:
        (renders, samples, seconds), `blurset build --dry-run`'s estimate."""
    def renders(
        self,
        exr_dir: str | PathLike[str],
        pin: int | None = None,
        *,
        sharp_views: list[int] = ...,
        sharp_samples: int | None = None,
    ) -> list[rec.Render]:
        """Every render of the setting in stream order (per view: sharp, then each level),
        as the worker takes them: {view, level, kind, phase, c2w, seed, samples?,
        sample_offset?, sample_sequence?, out, motion?}; `pin`: BuildConfig.cycles_samples.
        The blur renders of `sharp_views` are left out (their levels get the sharp image).
        With `sharp_samples` (BuildConfig.effective_sharp_samples) every render carries its
        samples."""
    def level_renders(
        self, view: int, level: int, prefix: str, pin: int | None = None
    ) -> list[rec.Render]:
        """The renders of one blurry image (view, level), EXRs named `<prefix>_…`."""
    def write_poses(
        self,
        setting_dir: str | PathLike[str],
        level_dirs: list[str],
        *,
        test_views: list[int] = ...,
        sharp_test_views: bool = True,
    ) -> None:
        """Write `<level>/poses_bounds.npy` and `<level>/transforms.json` for each level dir
        and the setting's transforms.json; `test_views` hold sharp images in the blur
        levels when `sharp_test_views`."""
    def write_meta(
        self,
        path: str | PathLike[str],
        *,
        config: BuildConfig,
        object: rec.ObjectRecord,
        timings: rec.Timings,
        qa: list[FrameQa],
        pose_check: rec.PoseCheck | None = None,
        light_paths: rec.LightPathsRecord | None = None,
        device: rec.DeviceRecord | None = None,
        denoiser: rec.DenoiserRecord | None = None,
        images: list[tuple[int, str, rec.ImageRender]] | None = None,
    ) -> None:
        """Write the setting's meta.json: this plan, the build config, the object as the
        worker reported it, the timings, the QA of every view and, with --check-poses, the
        COLMAP verdict; `light_paths` and `device` as the worker reported them, `denoiser`
        as the driver's Denoiser describes itself."""

def plan_setting(
    config: SamplingConfig | BuildConfig,
    *,
    uid: str,
    theta0_deg: float,
    seed: int,
    bbox_dims: list[float] | tuple[float, float, float],
    vertices: npt.NDArray[np.float32],
    backend: str | None = None,
) -> Plan:
    """Plan one setting (views, near/far from the vertices, weights, latent frames, seeds).
    `backend`: the Cycles backend the worker reported, on which `blur_method auto` (a
    BuildConfig's) prices each blurry image's method; auto without it is refused."""

def write_scene_transforms(
    path: str | PathLike[str],
    setting: str | PathLike[str],
    files: list[tuple[int, str]],
    *,
    test_views: list[int],
    level: str,
    gain: float | None = None,
    test_view_images: str | None = None,
) -> None:
    """The transforms.json of one scene of a setting (a noisy copy of a level): the
    cameras of the setting's transforms.json at `setting` (InputError naming it when it
    cannot be read or lacks a field), a frame per (view, file path),
    train/val/test_filenames, its level, gain (an integer when integral) and what its
    held-out views hold."""

def test_views(views: int, stride: int) -> list[int]:
    """Every `stride`-th view index below `views`."""

@final
class Splits:
    """The train/test splits of a build (the `splits.json` document)."""

    @property
    def train(self) -> list[str]: ...
    @property
    def test(self) -> list[str]: ...
    @property
    def test_objects(self) -> list[str]: ...
    @property
    def view_stride(self) -> int: ...
    @property
    def test_views(self) -> dict[str, list[int]]:
        """Held-out view indices per test setting."""
    def write(self, path: str | PathLike[str]) -> None:
        """Write splits.json atomically."""
    def to_dict(self) -> rec.Splits:
        """The document as a dict."""

def make_splits(
    entries: list[tuple[str, str, int]],
    *,
    view_stride: int,
    test_fraction: float,
    test_objects: list[str] | None,
    seed: int,
    test_settings: int | None = None,
    sharp_test_views: bool = True,
) -> Splits:
    """Splits of setting entries (setting dir, object uid, views): whole objects held
    out, or `test_settings` random settings."""

def seeded_subset(ids: list[str], k: int, seed: int) -> list[str]:
    """A seeded random subset of `k` ids, sorted; independent of the ids' order."""

# -- render QA (rust/py/src/qa.rs) ---------------------------------------------------

@final
class QaThresholds:
    """When a view fails render QA (the core's defaults unless given)."""

    def __new__(
        cls,
        *,
        min_coverage: float | None = None,
        min_luminance: float | None = None,
        max_saturated: float | None = None,
    ) -> QaThresholds: ...
    @property
    def min_coverage(self) -> float:
        """Least mean alpha (fraction of the image the object covers)."""
    @property
    def min_luminance(self) -> float:
        """Least mean unpremultiplied luminance of the object."""
    @property
    def max_saturated(self) -> float:
        """Largest fraction of the object's pixels clipped in sRGB."""

@final
class FrameQa:
    """What one view looks like in numbers, and its verdict under the thresholds."""

    @property
    def coverage(self) -> float:
        """Mean alpha: the fraction of the image the object covers."""
    @property
    def luminance(self) -> float:
        """Mean unpremultiplied luminance of the object (Σ premultiplied Y / Σ alpha)."""
    @property
    def saturated(self) -> float:
        """Fraction of covered pixels with a colour channel at or above 1."""
    @property
    def border_coverage(self) -> float:
        """Fraction of the border pixels the object covers."""
    @property
    def failure(self) -> str | None:
        """The reason the view fails, or None when it passes."""

def frame_qa(rgba_: npt.NDArray[np.float32], *, thresholds: QaThresholds | None = None) -> FrameQa:
    """QA of a premultiplied linear RGBA image (H, W, 4) under `thresholds`."""

def frame_qa_exr(path: str | PathLike[str], *, thresholds: QaThresholds | None = None) -> FrameQa:
    """QA of an EXR (premultiplied linear RGBA), read and judged in the core."""

def default_qa_thresholds() -> QaThresholds:
    """The default QA thresholds (one place for the numbers)."""

OBJECT_QA_RESOLUTION: int
OBJECT_QA_SAMPLES: int
OBJECT_QA_FOV_DEG: float

def object_qa_cameras(
    bbox_dims: list[float] | tuple[float, float, float],
) -> list[list[list[float]]]:
    """OpenGL camera-to-world (row-major) of each load-time QA view of an object of this box."""

def object_qa_verdict(
    views: list[FrameQa], *, thresholds: QaThresholds | None = None
) -> str | None:
    """The reason an object fails its load-time QA (invisible or black in every view), or None."""

# --- the render session (rust/py/src/session.rs) -------------------------------------

@final
class Session:
    """One setting's images, rendered phase by phase (the sharp images, their render QA,
    then each kind's) at fixed counts or to the config's target, and written under its
    partial folder: every image's state stays in the core (`dataset/session.rs`)."""

    def __new__(
        cls,
        plan: Plan,
        config: BuildConfig,
        *,
        partial: str | PathLike[str],
        exr_dir: str | PathLike[str],
        sharp_views: list[int],
        denoiser: Denoiser | None = None,
    ) -> Session:
        """The images of `plan` under `config`, written under `partial` (whose image
        folders it makes), their frames' EXRs in `exr_dir`; `sharp_views` as for
        `Plan.renders`; `denoiser`: --denoise oidn's."""
    def next_renders(self) -> list[rec.Render]:
        """The renders to make next, after taking in the last ones; an empty list: every
        image is written, or the sharp images failed render QA (`failure`)."""
    def add_exr(
        self, i: int, path: str | PathLike[str], origin: tuple[int, int] | None = None
    ) -> None:
        """The EXR of render `i` of the last `next_renders` into its image (deleted once
        read); an image that holds all its frames is written."""
    @property
    def failure(self) -> str | None:
        """Why the setting failed render QA, or None."""
    @property
    def phases_started(self) -> int:
        """Render phases started so far: 1 while the sharp images render."""
    def qa(self) -> list[FrameQa]:
        """The render QA of every view's sharp image, in view order."""
    def records(self) -> list[tuple[int, str, rec.ImageRender]]:
        """Under a render target, each image's record (meta.json `views[].images`)."""

# --- stats (rust/py/src/stats.rs) ---------------------------------------------------

@final
class BuildStats:
    """The statistics of a build (the `stats.json` document, schema "blurset-stats/1")."""

    @property
    def counts(self) -> dict[str, int | None]:
        """Objects, settings, views, images, test counts, failures, skipped settings."""
    @property
    def settings(self) -> list[rec.SettingInfo]:
        """The complete settings read (name, uid, θ0, views, level dirs, images …)."""
    def to_dict(self) -> rec.BuildStats:
        """The whole document as a dict (per-level maps keyed "1" … as in stats.json)."""
    def write(self, path: str | PathLike[str], generated: str) -> None:
        """Write stats.json (compact), `generated` and `blurset_version` first, atomically."""

def build_stats(out: str | PathLike[str]) -> BuildStats:
    """The statistics of the build at `out`: per-view and per-setting numbers of every
    complete setting's meta.json, min/median/max/mean summaries and counts.

    Raises InputError naming the file: no such directory, not a build, unreadable or
    corrupt meta.json of a complete setting, corrupt splits.json or failures.jsonl.
    """

def kind_figures() -> list[tuple[str, str, str, str]]:
    """Each degradation kind beside motion blur, in level order, as its histogram shows
    it: (kind, its statistic's name in stats.json, figure title, x axis label)."""

# -- failures.jsonl ---------------------------------------------------------------------

def current_failures(
    path: str | PathLike[str], *, complete: list[str], theta0s: list[float] | None = None
) -> tuple[list[rec.Failure], int]:
    """(the failures now, torn lines skipped): the latest record per (uid, setting)
    whose work is still not complete."""

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

def check_manifest(root: str | PathLike[str]) -> list[tuple[str, ManifestFault, str]]:
    """(relative path, kind, what is wrong) of each file that does not match
    root/MANIFEST.sha256: `missing`, `mismatch` (checksum mismatch) or `unlisted` (not in
    MANIFEST.sha256), sorted by path.
    Raises FileNotFoundError without a manifest, InputError naming a bad line."""

def rewrite_manifest(root: str | PathLike[str], vouched: list[str], keep_old: bool = True) -> int:
    """Write root/MANIFEST.sha256 at the end of a run that vouches for `vouched`
    (relative files or folders it wrote, or checked before reusing them): those hashed;
    with `keep_old`, every other file the existing manifest lists kept at its line;
    nothing else listed. The number of files listed."""

def manifest_mismatches(
    root: str | PathLike[str], dir: str
) -> list[tuple[str, ManifestFault, str]]:
    """(relative path, kind, what is wrong) of each file root/MANIFEST.sha256 lists under
    the folder `dir` that is gone (`missing`) or holds other bytes (`mismatch`), sorted
    by path; empty without a manifest. InputError naming a bad line."""

def check_images(items: list[tuple[str | PathLike[str], int, int]]) -> list[str | None]:
    """For each (path, width, height): None when the image (PNG/JPEG, or a linear EXR
    by its extension) decodes whole at that size, else the problem. In parallel."""

def spdx_of(text: str | None) -> str:
    """The SPDX id a licence text names, `other` when it maps to none, `unknown` for
    no text."""

def canonical_license(id: str) -> str | None:
    """The canonical spelling of a licence id (SPDX, `other`, `unknown`), or None."""

def license_allowed(id: str, licenses: list[str] | None) -> bool:
    """Whether an object under licence `id` passes a `--licenses` filter (None: all)."""

SPDX_IDS: list[str]

# -- what blurset writes and what a command may touch (dataset::outputs, dataset::read) --

@final
class OutputKind:
    """The kinds of output blurset writes into a folder of their own."""

    BUILD: OutputKind
    NOISE: OutputKind
    NOISE_SCENE: OutputKind
    EXPORT: OutputKind
    STATS: OutputKind
    @property
    def label(self) -> str:
        """How messages name the kind (`build`, `noise output`, `export` …)."""
    @property
    def record(self) -> str:
        """The file name of the record that says what the folder is."""
    @property
    def lock_name(self) -> str:
        """The lock file a writer of this kind holds in its folder."""
    def __eq__(self, value: object, /) -> bool: ...
    def __int__(self) -> int: ...

@final
class BuildState:
    """A build as its readers see it."""

    @property
    def complete(self) -> list[str]:
        """Complete setting directory names, sorted."""
    @property
    def provisional(self) -> list[str]:
        """Why the build is provisional; empty when it is finished."""

def output_kind(dir: str | PathLike[str]) -> OutputKind | None:
    """The kind of blurset output `dir` is, from its record; None for none."""

def claim(dir: str | PathLike[str], kind: OutputKind, option: str) -> str:
    """`new`, `empty`, `same` or `beside`: what a command writing `kind` may do with
    `dir`; ConfigValueError naming `option` when it may not write there."""

def owned_entries(dir: str | PathLike[str], kind: OutputKind) -> list[str]:
    """The entries (relative paths) an output of `kind` in `dir` wrote."""

def not_written(dir: str | PathLike[str], kind: OutputKind, rel: str) -> list[str]:
    """The entries inside the owned entry `rel` of the output in `dir` that no command of
    `kind` writes (paths relative to `dir`)."""

def linked_entry(dir: str | PathLike[str], rels: list[str]) -> str | None:
    """The first entry on the way to one of `rels` in `dir` that is a link, or None."""

def remove_owned(dir: str | PathLike[str], kind: OutputKind) -> list[str]:
    """Remove what `owned_entries` lists; returns it. An entry holding a file the command
    did not write is refused by name (InputError) before anything is removed."""

def build_state(out: str | PathLike[str]) -> BuildState:
    """Whether `out` is a finished build, and its complete settings."""

def superseded_settings(
    out: str | PathLike[str], current: list[tuple[str, str]]
) -> list[tuple[str, str, str]]:
    """(setting, source path, the source's id now) of complete settings whose source
    file now has another id; `current` holds (uid, source path) of every object."""

def mark_text(text: str, command: str) -> str:
    """`text` with its last line marking it as written by `command` (and its checksum)."""

def text_owner(path: str | PathLike[str], command: str) -> str:
    """`absent`, `ours`, `edited` or `foreign`: who the text file at `path` belongs to."""

def read_record(path: str | PathLike[str], record: str | None = None) -> Any:
    """A record blurset wrote, checked against its shape: the parsed JSON. InputError
    naming the file and the field when the shape is wrong."""

def write_record(path: str | PathLike[str], record: str, value: Any) -> None:
    """Write a record assembled in Python (`record` its file name) through the core's
    type: an unknown, missing or wrongly typed field is a ValueError, nothing written."""

def record_schemas() -> list[tuple[str, Any]]:
    """(schema file name, JSON Schema) of every record blurset writes."""

def value_schemas() -> list[tuple[str, Any]]:
    """(type name, JSON Schema) of every value the bindings hand across as a dict (what
    blurset/_records.pyi is generated from)."""

def render_request(
    frames: Sequence[Mapping[str, Any]],
    *,
    resolution: int,
    fov_deg: float,
    samples: int,
    exr_codec: str | None = None,
    noise_threshold: float | None = None,
    batch: bool = True,
    crop: bool = False,
    guides: bool = False,
    geometry: bool = False,
) -> str:
    """The JSON line of a render request of `frames` (the plan's renders, or a caller's
    frames of `c2w`, `seed` and `out`): each frame typed as the core's Render and checked,
    its EXR path made absolute; ValueError naming what is wrong."""

def load_request(
    glb: str, vertices_out: str, *, unlit: rec.Unlit, light_paths: rec.LightPaths
) -> str:
    """The JSON line of a load request: import, normalize and light the GLB at `glb` (an
    absolute path), its vertices to `vertices_out`; ValueError for an `unlit` or
    `light_paths` the contract lacks."""

def quit_request() -> str:
    """The JSON line that asks the worker to exit."""

def worker_reply(msg: object) -> rec.WorkerReply:
    """A reply the worker sent (its JSON line parsed), checked against the contract's
    reply types and given back as sent (every field, a null kept); ValueError naming the
    reply and the field that does not fit."""

def worker_schemas() -> list[tuple[str, Any]]:
    """(file stem, JSON Schema) of the worker's requests and replies."""
