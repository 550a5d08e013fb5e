"""Rendering each image of a setting to a render-noise target (`--target-psnr`, DESIGN §8).

The core decides everything numeric (`plan/target.rs`: the rounds, the sample blocks, the
seeds of the two halves, when an image is done; `metrics::half_noise`: the estimate on
the object's pixels); this module schedules the rounds on the worker and keeps the two
halves of each image in flight, a few images at a time so memory stays bounded at any
resolution.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from blurset import _core
from blurset.config import BuildConfig

if TYPE_CHECKING:
    from blurset._records import ImageRender, ImageRound

# Images whose halves are in flight at once (two accumulators each): 8 MB a half at 512 px.
GROUP = 8


@dataclass
class _Image:
    view: int
    level: str
    frames: int
    halves: tuple[Any, Any]
    spent: int = 0
    rounds: int = 0
    # _core.half_noise_bound of the last round: the estimate and the bound the rounds
    # stop on (a few fireflies on a specular surface make one round's estimate scatter).
    estimate: dict[str, Any] | None = None
    previous: tuple[int, float] | None = None  # (spent, mse bound) of the round before
    pilot_db: float = 0.0

    @classmethod
    def new(cls, key: tuple[int, str], frames: int, res: int) -> _Image:
        return cls(
            key[0], key[1], frames, (_core.Accumulator(res, res), _core.Accumulator(res, res))
        )

    def next_round(self, cfg: BuildConfig) -> int | None:
        """Samples per frame and half this image renders next (None: it is done)."""
        return _core.target_next_round(
            cfg,
            frames=self.frames,
            spent_per_frame=self.spent,
            rounds=self.rounds,
            mse=None if self.estimate is None else self.estimate["mse_bound"],
            previous=self.previous,
        )

    def rendered(self, add: int, background: tuple[float, float, float]) -> None:
        """A round of `add` samples per frame and half is in both halves: estimate anew."""
        if self.estimate is not None:
            self.previous = (self.spent, float(self.estimate["mse_bound"]))
        self.spent += add
        self.rounds += 1
        a, b = self.halves
        self.estimate = _core.half_noise_bound(a.mean(), b.mean(), background=background)
        if self.rounds == 1:
            self.pilot_db = float(self.estimate["psnr_bound"])  # what the rest follows from

    def record(self, cfg: BuildConfig) -> ImageRender:
        assert self.estimate is not None  # a record is made after a round
        e = self.estimate["estimate"]
        return {
            "samples": 2 * self.frames * self.spent,
            "rounds": self.rounds,
            "render_psnr_db": round(float(e["psnr"]), 3),
            "render_psnr_bound_db": round(float(self.estimate["psnr_bound"]), 3),
            "pilot_psnr_db": round(self.pilot_db, 3),
            "coverage": round(float(e["coverage"]), 6),
            "reached": _core.target_reached(cfg, float(self.estimate["mse_bound"])),
        }


def _adder(
    renders: list[dict],
    group: dict[tuple[int, str], _Image],
    adds: dict[tuple[int, str], int],
    on_render: Callable[[], None],
) -> Callable[[int, str, tuple[int, int] | None], None]:
    """The worker's on_frame of one round: each EXR into its image's half, weighted by
    the samples each of its frames rendered this round, then deleted."""

    def on_frame(i: int, path: str, origin: tuple[int, int] | None) -> None:
        r = renders[i]
        key = (r["view"], r["level"])
        group[key].halves[r["half"]].add_exr(path, origin, weight=float(adds[key]))
        Path(path).unlink()
        on_render()

    return on_frame


def frame_counts(renders: Iterable[dict]) -> dict[tuple[int, str], int]:
    """Latent frames of each image (view, level) in the plan's render list."""
    out: dict[tuple[int, str], int] = {}
    for r in renders:
        key = (r["view"], r["level"])
        out[key] = out.get(key, 0) + 1
    return out


def render_to_target(
    plan: Any,
    cfg: BuildConfig,
    worker: Any,
    exr_dir: Path,
    sharp_views: list[int],
    keys: list[tuple[int, str]],
    frames: dict[tuple[int, str], int],
    finish: Callable[[tuple[int, str], Any], None],
    on_render: Callable[[], None],
    common: dict[str, Any],
) -> tuple[dict[tuple[int, str], ImageRender], int]:
    """Render the images `keys` (each of `frames[key]` latent frames) to the config's
    target, a group at a time; `finish(key, accumulator)` gets each finished image (its
    halves merged) as soon as it is done. Returns each image's record and the renders."""
    if cfg.target_psnr is None or cfg.cycles_samples is None:
        raise ValueError("render_to_target needs a config with target_psnr")
    pin = int(cfg.cycles_samples)
    bg = (cfg.background[0], cfg.background[1], cfg.background[2])
    records: dict[tuple[int, str], ImageRender] = {}
    n_renders = 0
    for start in range(0, len(keys), GROUP):
        group = {k: _Image.new(k, frames[k], cfg.resolution) for k in keys[start : start + GROUP]}
        while rounds := _next_rounds(group, cfg, records, finish):
            renders = plan.round_renders(exr_dir, pin, sharp_views, rounds)
            adds = {(r["view"], r["level"]): r["add_per_frame"] for r in rounds}
            worker.render(renders, on_frame=_adder(renders, group, adds, on_render), **common)
            n_renders += len(renders)
            for key, add in adds.items():
                group[key].rendered(add, bg)
    return records, n_renders


def _next_rounds(
    group: dict[tuple[int, str], _Image],
    cfg: BuildConfig,
    records: dict[tuple[int, str], ImageRender],
    finish: Callable[[tuple[int, str], Any], None],
) -> list[ImageRound]:
    """The next round of every image of `group` that needs one; an image that is done
    leaves the group: its halves merged go to `finish`, its record to `records`."""
    rounds: list[ImageRound] = []
    for key, im in list(group.items()):
        add = im.next_round(cfg)
        if add is None:
            a, b = im.halves
            a.merge(b)
            records[key] = im.record(cfg)
            finish(key, a)
            del group[key]
            continue
        rounds.append({"view": im.view, "level": im.level, "spent_per_frame": im.spent,
                       "add_per_frame": add, "round": im.rounds + 1})  # fmt: skip
    return rounds
