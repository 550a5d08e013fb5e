"""Build configuration: defaults < `--demo` defaults < TOML file (`--config`) < flags.

The sampling defaults (the paper's numbers) come from blurset-core, so they are defined
once; this module adds what only orchestration needs and validates everything with a
message that names the option (and the file, for TOML values).
"""

from __future__ import annotations

import dataclasses
import json
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from blurset import _core
from blurset.exceptions import ConfigError

SAMPLING_DEFAULTS: dict[str, Any] = json.loads(_core.default_sampling_config())


@dataclass
class BuildConfig:
    objects: list[str] = field(default_factory=list)
    out: Path | None = None
    demo: bool = False
    settings_per_object: int = 4
    views: int = SAMPLING_DEFAULTS["views"]
    levels: list[int] = field(default_factory=lambda: list(SAMPLING_DEFAULTS["levels"]))
    latents: int = SAMPLING_DEFAULTS["latents"]
    # `--latents auto`: m per view and level from the screen motion (issue 6, DESIGN §8):
    # the smallest m leaving no gap > max_ghost_px between latent frames, ≤ latents_max.
    latents_auto: bool = False
    latents_max: int = SAMPLING_DEFAULTS["latents_max"]
    max_ghost_px: float = SAMPLING_DEFAULTS["max_ghost_px"]
    # `average` (m latent renders, the paper) or `motion_blur` (one Cycles render).
    blur_method: str = SAMPLING_DEFAULTS["blur_method"]
    # Cycles samples per rendered latent frame.
    samples: int = SAMPLING_DEFAULTS["samples"]
    # Sample budget S of one blurry image: ⌈S / m⌉ samples per latent frame.
    samples_total: int | None = None
    # Samples of the sharp render; None = the blurry image's budget (samples_total, or
    # samples × latents), so ground truth is at least as clean as the blurry images
    # (m frames at s samples ≈ one frame at m·s).
    sharp_samples: int | None = None
    resolution: int = SAMPLING_DEFAULTS["resolution"]
    seed: int = 0
    fov_deg: float = SAMPLING_DEFAULTS["fov_deg"]
    phi0_deg: float = SAMPLING_DEFAULTS["phi0_deg"]
    window_deg: float = SAMPLING_DEFAULTS["window_deg"]
    delta0: float = SAMPLING_DEFAULTS["delta0"]
    radius_margin: float = SAMPLING_DEFAULTS["radius_margin"]
    level_spread: float = SAMPLING_DEFAULTS["level_spread"]
    latent_positions: str = SAMPLING_DEFAULTS["latent_positions"]
    # `start`: latent positions on [p, p + w_l·δ] (the paper); `centered`: on
    # [p − w_l·δ/2, p + w_l·δ/2], so the written pose is the middle of the exposure.
    trajectory: str = SAMPLING_DEFAULTS["trajectory"]
    orientation_max: float = SAMPLING_DEFAULTS["guards"]["orientation_max"]
    near_floor: float = SAMPLING_DEFAULTS["guards"]["near_floor"]
    background: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    # `--keep-linear` (alias `--write-linear`): linear/<view>.exr beside images/ per level.
    write_linear: bool = False
    # `--previews`: <setting>/preview.png (blurset.preview), written before the marker.
    previews: bool = False
    view_stride: int = 16
    test_fraction: float = 0.2
    test_objects: list[str] | None = None
    workers: int = 1
    threads: int = 0
    executor: str = "local"
    # Ray cluster address (ray://host:10001, or "auto"); None starts a local Ray.
    ray_address: str | None = None
    shard: str | None = None
    # Objaverse: the package's cache directory (None = objaverse.BASE_PATH), no
    # downloads when offline, and a seeded random subset of this many objaverse objects.
    objaverse_dir: str | None = None
    objaverse_offline: bool = False
    objaverse_count: int | None = None
    # Seconds without a reply from the worker before it counts as hung and is killed.
    timeout: float = 600.0
    # Wall-clock budget of one object (load + all its settings); 0 = no budget.
    object_timeout: float = 0.0
    # Extra attempts after a transient failure (worker crash or hang).
    retries: int = 1
    # The build fails (exit 1) when more than this fraction of its objects failed.
    max_failure_rate: float = 1.0
    # Pre-flight budgets: bigger objects fail before Blender is started.
    max_triangles: int = 5_000_000
    max_texture_pixels: int = 256 * 2**20
    blender: str | None = None
    check_poses: bool = False
    # A rerun into an OUT made with other output-shaping options is refused unless this
    # is set (the dataset would mix settings that dataset.json cannot describe).
    allow_mixed: bool = False

    def sampling_json(self) -> str:
        """The blurset-core SamplingConfig of this build."""
        return json.dumps(
            {
                "views": self.views,
                "phi0_deg": self.phi0_deg,
                "window_deg": self.window_deg,
                "fov_deg": self.fov_deg,
                "radius_margin": self.radius_margin,
                "delta0": self.delta0,
                "levels": self.levels,
                "level_spread": self.level_spread,
                "latents": self.latents,
                "latent_positions": self.latent_positions,
                "trajectory": self.trajectory,
                "resolution": self.resolution,
                "guards": {"orientation_max": self.orientation_max, "near_floor": self.near_floor},
                "latents_auto": self.latents_auto,
                "latents_max": self.latents_max,
                "max_ghost_px": self.max_ghost_px,
                "blur_method": self.blur_method,
                "samples": self.samples,
                **({"samples_total": self.samples_total} if self.samples_total else {}),
            }
        )

    @property
    def max_latents(self) -> int:
        """The most renders one blurry image can take under this config."""
        if self.blur_method == "motion_blur":
            return 1
        return self.latents_max if self.latents_auto else self.latents

    @property
    def blur_samples_total(self) -> int:
        """Samples one blurry image gets at most (the budget, or samples × its frames)."""
        if self.samples_total:
            return self.samples_total
        m = self.latents if self.blur_method == "motion_blur" else self.max_latents
        return self.samples * m

    @property
    def effective_sharp_samples(self) -> int:
        return self.sharp_samples or self.blur_samples_total

    @property
    def theta0s(self) -> list[float]:
        return _core.theta0s(self.settings_per_object)

    @property
    def level_dirs(self) -> list[str]:
        return ["sharp"] + [f"blur_{lvl}" for lvl in self.levels]

    def to_json(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d["out"] = str(self.out) if self.out else None
        d["effective_sharp_samples"] = self.effective_sharp_samples
        if self.latents_auto:
            d["latents"] = "auto"
        return d


# Small enough for about two minutes on 2 cores, rich enough for SfM.
DEMO_DEFAULTS: dict[str, Any] = {
    "settings_per_object": 1,
    "views": 17,
    "latents": 6,
    "samples": 4,
    "resolution": 96,
}

FIELDS = {f.name: f for f in dataclasses.fields(BuildConfig)}
# Other spellings of option names in TOML files (the name → the field).
ALIASES = {"keep_linear": "write_linear"}


def parse_levels(value: Any, where: str = "--levels") -> list[int]:
    """`1,2,3,4`, a list, or `none`/`` for sharp only."""
    if isinstance(value, list):
        items = value
    elif isinstance(value, int):
        items = [value]
    else:
        text = str(value).strip().lower()
        items = [] if text in ("", "none", "sharp") else [s for s in text.split(",") if s.strip()]
    try:
        levels = [int(x) for x in items]
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: expected levels like 1,2,3,4 or none, got {value!r}") from None
    if any(lvl < 1 or lvl > 64 for lvl in levels) or len(set(levels)) != len(levels):
        raise ConfigError(f"{where}: levels must be distinct integers in 1..64, got {value!r}")
    return sorted(levels)


def _coerce(name: str, value: Any, where: str) -> Any:
    if name == "levels":
        return parse_levels(value, where)
    if name == "latents" and isinstance(value, str):
        if value.strip().lower() == "auto":
            return "auto"
        try:
            return int(value)
        except ValueError:
            raise ConfigError(
                f"{where}: expected a number of frames or auto, got {value!r}"
            ) from None
    default = getattr(BuildConfig(), name)
    try:
        if name == "out":
            return Path(value)
        if name in ("objects", "test_objects"):
            if isinstance(value, str):
                return [value]
            return [str(v) for v in value]
        if name == "background":
            bg = [float(v) for v in value]
            if len(bg) != 3:
                raise ValueError
            return bg
        nullable = (
            "sharp_samples",
            "samples_total",
            "shard",
            "blender",
            "ray_address",
            "objaverse_dir",
        )
        if name in (*nullable, "objaverse_count") and value is None:
            return None
        if name in ("sharp_samples", "samples_total", "objaverse_count"):
            if isinstance(value, bool) or int(value) != value:
                raise ValueError
            return int(value)
        if isinstance(default, bool):
            if not isinstance(value, bool):
                raise ValueError
            return value
        if isinstance(default, int):
            if isinstance(value, bool) or int(value) != value:
                raise ValueError
            return int(value)
        if isinstance(default, float):
            return float(value)
        return str(value) if value is not None else None
    except (TypeError, ValueError):
        raise ConfigError(f"{where}: bad value {value!r} for {name}") from None


def load_toml(path: Path) -> dict[str, Any]:
    """Read a TOML config. Keys are option names (`latents`, `settings-per-object` …),
    at top level or under a `[build]` table."""
    try:
        data = tomllib.loads(Path(path).read_text())
    except FileNotFoundError:
        raise ConfigError(f"--config: no such file {str(path)!r}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"--config: {str(path)!r} is not valid TOML: {e}") from None
    table = data.get("build", data)
    out: dict[str, Any] = {}
    for key, value in table.items():
        name = ALIASES.get(key.replace("-", "_"), key.replace("-", "_"))
        if name not in FIELDS or name == "demo" and not isinstance(value, bool):
            raise ConfigError(f"{path}: unknown option {key!r}")
        out[name] = _coerce(name, value, f"{path}: {key}")
    return out


def _latents_layer(layer: dict[str, Any], where: str) -> dict[str, Any]:
    """`latents = auto` in one layer → latents_auto; a number there turns auto off."""
    layer = {k: v for k, v in layer.items() if v is not None}
    if "latents" in layer:
        value = _coerce("latents", layer.pop("latents"), where)
        if value == "auto":
            layer["latents_auto"] = True
        else:
            layer["latents"], layer["latents_auto"] = value, False
    return layer


# Options that only mean something with `--latents auto` / the average method.
AUTO_ONLY = ("latents_max", "max_ghost_px")


def make_config(file_values: dict[str, Any], flag_values: dict[str, Any]) -> BuildConfig:
    """Combine the layers and validate."""
    demo = bool(flag_values.get("demo") or file_values.get("demo"))
    values: dict[str, Any] = dict(DEMO_DEFAULTS) if demo else {}
    given = _latents_layer(file_values, "--config: latents")
    given.update(_latents_layer(flag_values, "--latents"))
    values.update(given)
    values["demo"] = demo
    cfg = BuildConfig(**{k: _coerce(k, v, f"--{k.replace('_', '-')}") for k, v in values.items()})
    for name in AUTO_ONLY:
        if name in given and not cfg.latents_auto:
            raise ConfigError(f"--{name.replace('_', '-')}: only used with --latents auto")
    if cfg.blur_method == "motion_blur":
        for name, what in (
            ("latents_auto", "--latents auto"),
            ("latent_positions", "--latent-positions"),
        ):
            if given.get(name) not in (None, False):
                raise ConfigError(
                    f"{what}: the motion_blur method has no latent frames (one render per "
                    "blurry image); use --blur-method average"
                )
    validate(cfg)
    return cfg


def validate(cfg: BuildConfig) -> None:
    def need(ok: bool, option: str, msg: str) -> None:
        if not ok:
            raise ConfigError(f"--{option.replace('_', '-')}: {msg}")

    need(cfg.out is not None, "out", "an output directory is required")
    need(bool(cfg.objects) or cfg.demo, "objects", "give GLB files/folders/lists, or --demo")
    need(1 <= cfg.settings_per_object <= 360, "settings_per_object", "must be in 1..360")
    need(1 <= cfg.samples <= 65536, "samples", "must be in 1..65536")
    need(
        cfg.sharp_samples is None or 1 <= cfg.sharp_samples <= 65536,
        "sharp_samples",
        "must be in 1..65536",
    )
    need(cfg.workers >= 1, "workers", "must be at least 1")
    need(cfg.threads >= 0, "threads", "must be ≥ 0 (0 = all cores)")
    need(cfg.timeout > 0, "timeout", "must be positive seconds")
    need(cfg.object_timeout >= 0, "object_timeout", "must be ≥ 0 seconds (0 = no budget)")
    need(0 <= cfg.retries <= 100, "retries", "must be in 0..100")
    need(0.0 <= cfg.max_failure_rate <= 1.0, "max_failure_rate", "must be in [0, 1]")
    need(cfg.max_triangles >= 1, "max_triangles", "must be at least 1")
    need(cfg.max_texture_pixels >= 0, "max_texture_pixels", "must be ≥ 0")
    need(cfg.view_stride >= 1, "view_stride", "must be at least 1")
    need(0.0 <= cfg.test_fraction <= 1.0, "test_fraction", "must be in [0, 1]")
    need(cfg.executor in ("local", "ray"), "executor", "must be local or ray")
    need(
        cfg.ray_address is None or cfg.executor == "ray",
        "ray_address",
        "only with --executor ray",
    )
    need(
        cfg.objaverse_count is None or cfg.objaverse_count >= 1,
        "objaverse_count",
        "must be at least 1",
    )
    need(
        cfg.latent_positions in ("random", "stratified"), "latent_positions", "random or stratified"
    )
    need(cfg.blur_method in ("average", "motion_blur"), "blur_method", "average or motion_blur")
    need(cfg.trajectory in ("start", "centered"), "trajectory", "start or centered")
    need(1 <= cfg.latents_max <= 4096, "latents_max", "must be in 1..4096")
    need(
        math.isfinite(cfg.max_ghost_px) and cfg.max_ghost_px >= 0.01,
        "max_ghost_px",
        "must be a number of pixels ≥ 0.01",
    )
    need(
        cfg.samples_total is None or 1 <= cfg.samples_total <= 2**20,
        "samples_total",
        "must be in 1..1048576",
    )
    need(all(0.0 <= c <= 1.0 for c in cfg.background), "background", "RGB values in [0, 1]")
    if cfg.shard is not None:
        try:
            i, n = (int(x) for x in cfg.shard.split("/"))
            ok = 0 <= i < n
        except ValueError:
            ok = False
        need(ok, "shard", f"expected i/N with 0 ≤ i < N, got {cfg.shard!r}")
    try:
        _core.validate_sampling_config(cfg.sampling_json())
    except ValueError as e:
        raise ConfigError(str(e).replace("invalid value: ", "")) from None
