"""`blurset preview`: the dataset's own pictures (issue 9).

`blurset preview SETTING` draws one figure per setting: rows of views (test views
first), columns sharp, blur_1 … blur_4 and, with `--noise DIR --gain G`, the noisy
copy of every level `blurset noise BUILD --out DIR` wrote at gain G; labelled. That is
the paper's "examples at different blur levels" figure. `blurset build --previews`
writes one into every setting (`<setting>/preview.png`, before its marker).

`blurset preview BUILD` draws a contact sheet: the sharp first test view of every
complete setting, labelled with its name, so a black, empty or mis-framed object shows
at a glance; blurset-core's `thumbnail_qa` flags them in red (EMPTY: almost nothing
differs from the background; BLACK: the object is nearly black; EDGE: the object
touches the frame).

Layout (pixels): a title band of TITLE_H, then for a setting figure a header of
HEADER_H (column labels) and a left band of LABEL_W (row labels); cells of tile size
separated by GAP, with PAD around the grid. `grid_size` and `cell_origin` give the
geometry so tests and users can crop the tiles back out.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from blurset import _core, layout
from blurset.exceptions import ConfigError, InputError
from blurset.services import outputs, publish
from blurset.services.options import check_range

# The file types a figure is written as, by the suffix of --out.
IMAGE_FORMATS = {".png": "PNG", ".jpg": "JPEG", ".jpeg": "JPEG", ".webp": "WEBP"}
PAD = 8
GAP = 4
TITLE_H = 30
HEADER_H = 24
LABEL_W = 84
CAPTION_H = 34  # contact sheet: two lines under each thumbnail
SHEET_TITLE_H = 46  # contact sheet: title and a line of counts
SHEET_MIN_W = 380  # the counts line whole, even above one or two small thumbnails
MIN_TILE, MAX_TILE = 128, 256
BG = (255, 255, 255)
INK = (20, 20, 20)
FLAG = (200, 0, 0)
FRAME = (200, 200, 200)
# Contact-sheet flags (thumbnail_qa numbers computed in blurset-core).
EMPTY_COVERAGE = 0.002
BLACK_LUMA = 0.06
EDGE_BORDER = 0.02


def add_arguments(parser) -> None:
    parser.add_argument(
        "path", type=Path, help="a setting directory (one figure) or a build (contact sheet)"
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="PNG to write (default: SETTING/preview.png, BUILD/contact_sheet.png)",
    )
    parser.add_argument(
        "--noise",
        type=Path,
        default=None,
        help="output of `blurset noise BUILD` to show beside (default: none)",
    )
    parser.add_argument(
        "--gain",
        default=None,
        help="gain of --noise to show, e.g. 4 (required with --noise; default: none)",
    )
    parser.add_argument(
        "--rows", type=int, default=4, help="views per setting figure, test views first"
    )
    parser.add_argument(
        "--tile", type=int, default=None, help="thumbnail width in px (default: 128..256)"
    )
    parser.add_argument(
        "--columns",
        type=int,
        default=None,
        help="contact sheet columns (default: ceil(sqrt(settings)), about square)",
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace an image at --out that preview did not write (default: refuse)",
    )


# -- drawing helpers ---------------------------------------------------------------------


def _font(size: int, bold: bool = False) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """DejaVu Sans from matplotlib's data (always installed with blurset), else Pillow's."""
    try:
        import matplotlib

        name = "DejaVuSans-Bold.ttf" if bold else "DejaVuSans.ttf"
        return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts/ttf" / name), size)
    except (ImportError, OSError):
        return ImageFont.load_default(size=size)


def tile_size(width: int, height: int, tile: int | None = None) -> tuple[int, int]:
    """Thumbnail (w, h): the image size, scaled by an integer up to MIN_TILE or down
    to MAX_TILE, aspect kept; `tile` forces the width."""
    if tile is None:
        if width < MIN_TILE:
            tile = width * math.ceil(MIN_TILE / width)
        else:
            tile = min(width, MAX_TILE)
    return tile, max(1, round(tile * height / width))


def _thumb(img: Image.Image, size: tuple[int, int]) -> Image.Image:
    img = img.convert("RGB")
    if img.size == size:
        return img
    up = size[0] >= img.size[0] and size[0] % img.size[0] == 0
    return img.resize(size, Image.Resampling.NEAREST if up else Image.Resampling.LANCZOS)


def _fit(draw: ImageDraw.ImageDraw, text: str, font, width: int) -> str:
    """`text`, cut with an ellipsis to fit `width` pixels."""
    if draw.textlength(text, font=font) <= width:
        return text
    while text and draw.textlength(text + "…", font=font) > width:
        text = text[:-1]
    return text + "…"


def _frame(draw: ImageDraw.ImageDraw, x: int, y: int, tile: tuple[int, int]) -> None:
    """A light one-pixel frame just outside a tile (inside the gap), so an empty
    white tile still reads as a tile."""
    draw.rectangle([x - 1, y - 1, x + tile[0], y + tile[1]], outline=FRAME, width=1)


# Every figure says who wrote it (a PNG text chunk, a JPEG comment): a later run tells
# its own figure from a user's image at --out, which it does not replace unasked.
MARK = "blurset preview"


def _save(img: Image.Image, out: Path) -> None:
    out.parent.mkdir(parents=True, exist_ok=True)
    fmt = IMAGE_FORMATS.get(out.suffix.lower(), "PNG")
    rgb = img.convert("RGB") if fmt == "JPEG" else img
    extra: dict = {}
    if fmt == "PNG":
        from PIL.PngImagePlugin import PngInfo

        info = PngInfo()
        info.add_text("Software", MARK)
        extra["pnginfo"] = info
    elif fmt == "JPEG":
        extra["comment"] = MARK.encode()
    layout.write_figure(out, lambda f: rgb.save(f, format=fmt, **extra))


def is_our_figure(path: Path) -> bool:
    """Whether the image at `path` is a figure `blurset preview` wrote."""
    try:
        with Image.open(path) as im:
            said = im.info.get("Software") or im.info.get("comment") or b""
    except (OSError, ValueError):
        return False
    return (said.decode("utf-8", "replace") if isinstance(said, bytes) else str(said)) == MARK


# -- setting figure ------------------------------------------------------------------------


def grid_size(rows: int, cols: int, tile: tuple[int, int]) -> tuple[int, int]:
    """(width, height) of a setting figure."""
    tw, th = tile
    return (
        PAD + LABEL_W + cols * tw + (cols - 1) * GAP + PAD,
        TITLE_H + HEADER_H + rows * th + (rows - 1) * GAP + PAD,
    )


def cell_origin(row: int, col: int, tile: tuple[int, int]) -> tuple[int, int]:
    """Top-left pixel of the tile at (row, col) of a setting figure."""
    tw, th = tile
    return PAD + LABEL_W + col * (tw + GAP), TITLE_H + HEADER_H + row * (th + GAP)


@dataclass
class Figure:
    path: Path
    rows: list[int]  # view indices, top to bottom
    columns: list[str]  # labels, left to right
    tile: tuple[int, int]
    size: tuple[int, int]
    flagged: list[tuple[str, str]] = field(default_factory=list)


def _read_meta(setting: Path) -> dict:
    p = setting / layout.META
    if not p.is_file():
        raise InputError(f"not a setting or a build (no meta.json or dataset.json): {setting}")
    return outputs.read_record(p)


def choose_views(n: int, test_views: list[int], rows: int) -> list[int]:
    """Test views first, then train views spread evenly over the rest."""
    test = [v for v in test_views if 0 <= v < n][:rows]
    rest = [v for v in range(n) if v not in test]
    k = min(rows - len(test), len(rest))
    if k > 0:
        picks = sorted({rest[round(i * (len(rest) - 1) / max(1, k - 1))] for i in range(k)})
        for v in rest:  # rounding may merge picks on tiny settings
            if len(picks) >= k:
                break
            if v not in picks:
                picks.append(v)
        test += sorted(picks)
    return test


def _noise_columns(
    noise_dir: Path, setting: str, levels: list[str], gain: str
) -> list[tuple[str, Path]]:
    """(label, gain dir) for every level of `setting` that `noise_dir` holds at `gain`."""
    try:
        g = _core.NoiseConfig(gains=[gain], any_gain=True).gain_values[0]
    except _core.ConfigValueError as e:
        raise ConfigError(f"--gain {e.detail}") from None
    gname = layout.gain_name(g)
    if not noise_dir.is_dir():
        raise InputError(f"--noise directory not found: {noise_dir}")
    cols = []
    for lvl in levels:
        for d in (noise_dir / setting / lvl / gname, noise_dir / lvl / gname):
            try:
                there = (d / layout.NOISE).is_file()
            except OSError:  # a name no folder can have (--gain 1e308): not there
                there = False
            if there:
                cols.append((f"{lvl} · gain {g:g}", d))
                break
    if not cols:
        raise InputError(f"--gain {gain}: no {gname} of setting {setting!r} in --noise {noise_dir}")
    return cols


def _noisy_files(gain_dir: Path) -> dict[int, Path]:
    meta = outputs.read_record(gain_dir / layout.NOISE)
    return {f["view"]: gain_dir / f["image"] for f in meta["files"] if f.get("frame", 0) == 0}


def setting_figure(
    setting: Path,
    out: Path,
    *,
    rows: int = 4,
    tile: int | None = None,
    noise: Path | None = None,
    gain: str | None = None,
) -> Figure:
    """Write the figure of one setting to `out`."""
    setting = Path(setting)
    meta = _read_meta(setting)
    n = len(meta.get("views", []))
    levels = _shown_levels(setting, meta)
    if not n or not levels:
        raise InputError(f"setting has no views or no level directories: {setting}")
    check_range("--rows", rows, 1)
    name = setting.name.removesuffix(".partial")
    views = choose_views(n, list(meta.get("test_views", [])), rows)
    columns = [
        (lvl, {v: setting / lvl / layout.IMAGES / _core.image_name(v, n) for v in views})
        for lvl in levels
    ]
    if noise is not None or gain is not None:
        columns += _noise_columns_of(setting, Path(noise) if noise else None, name, levels, gain)
    for _, files in columns:
        for v in views:
            if v not in files or not files[v].is_file():
                raise InputError(f"image of view {v} not found: {files.get(v, setting)}")
    w0, h0 = Image.open(columns[0][1][views[0]]).size
    ts = tile_size(w0, h0, tile)
    size = grid_size(len(views), len(columns), ts)
    res = meta.get("resolution", [w0, h0])
    title = f"{name}   {n} views, {res[0]}x{res[1]} px"
    fig = _draw_grid(title, columns, views, set(meta.get("test_views", [])), ts, size)
    _save(fig, out)
    return Figure(out, views, [c[0] for c in columns], ts, size)


def _shown_levels(setting: Path, meta: dict) -> list[str]:
    """The setting's levels that have their images/ folder: a finished setting without one
    is damaged (refused); a setting still being written shows those it has."""
    levels = list(meta["levels"])
    gone = [lvl for lvl in levels if not (setting / lvl / layout.IMAGES).is_dir()]
    if gone and not setting.name.endswith(layout.PARTIAL_SUFFIX):
        raise InputError(
            f"level {gone[0]} has no images/ folder (a damaged setting: `blurset verify` "
            f"lists what is wrong): {setting / gone[0]}"
        )
    return [lvl for lvl in levels if lvl not in gone]


def _noise_columns_of(
    setting: Path, noise: Path | None, name: str, levels: list[str], gain: str | None
) -> list[tuple[str, dict[int, Path]]]:
    """The columns of one gain of a noise output shown beside the setting it was made from."""
    if noise is None or gain is None:
        raise ConfigError("--noise and --gain go together (a noise output and one of its gains)")
    kind = outputs.kind_of(noise) if noise.is_dir() else None
    if kind is outputs.OutputKind.NOISE:
        # Only noise made from this setting's build is shown beside it.
        outputs.noise_of_build(noise, setting.parent)
    elif kind is not outputs.OutputKind.NOISE_SCENE:
        raise InputError(f"--noise is not a blurset noise output: {noise}")
    return [(label, _noisy_files(d)) for label, d in _noise_columns(noise, name, levels, gain)]


def _draw_grid(
    title: str,
    columns: list[tuple[str, dict[int, Path]]],
    views: list[int],
    test: set[int],
    ts: tuple[int, int],
    size: tuple[int, int],
) -> Image.Image:
    """The figure: a title, a labelled column per level or gain, a row per view."""
    fig = Image.new("RGB", size, BG)
    draw = ImageDraw.Draw(fig)
    f_title, f_label, f_small = _font(16, bold=True), _font(13), _font(11)
    draw.text((PAD, 7), _fit(draw, title, f_title, size[0] - 2 * PAD), fill=INK, font=f_title)
    for c, (label, files) in enumerate(columns):
        x, y = cell_origin(0, c, ts)
        draw.text(
            (x + 2, TITLE_H + 3), _fit(draw, label, f_label, ts[0] - 2), fill=INK, font=f_label
        )
        for r, v in enumerate(views):
            x, y = cell_origin(r, c, ts)
            with Image.open(files[v]) as im:
                fig.paste(_thumb(im, ts), (x, y))
            _frame(draw, x, y, ts)
    for r, v in enumerate(views):
        x, y = cell_origin(r, 0, ts)
        draw.text((PAD, y + 2), f"view {v:03d}", fill=INK, font=f_label)
        draw.text((PAD, y + 20), "test" if v in test else "train", fill=INK, font=f_small)
    return fig


def write_build_preview(setting_dir: Path, warn=print) -> None:
    """`blurset build --previews`: `<setting>/preview.png`; a failure only warns (a
    figure must never cost the rendered setting)."""
    try:
        setting_figure(setting_dir, Path(setting_dir) / "preview.png")
    except Exception as e:  # reported; the setting stays
        warn(f"warning: preview of {Path(setting_dir).name} not written: {e}")


# -- contact sheet -----------------------------------------------------------------------


def sheet_size(n: int, cols: int, tile: tuple[int, int]) -> tuple[int, int]:
    """(width, height) of a contact sheet of `n` thumbnails in `cols` columns."""
    tw, th = tile
    rows = max(1, math.ceil(n / cols))
    return (
        max(SHEET_MIN_W, PAD + cols * tw + (cols - 1) * GAP + PAD),
        SHEET_TITLE_H + rows * (th + CAPTION_H) + (rows - 1) * GAP + PAD,
    )


def sheet_origin(k: int, cols: int, tile: tuple[int, int]) -> tuple[int, int]:
    """Top-left pixel of thumbnail `k` (row-major) of a contact sheet."""
    tw, th = tile
    r, c = divmod(k, cols)
    return PAD + c * (tw + GAP), SHEET_TITLE_H + r * (th + CAPTION_H + GAP)


def qa_flags(rgb: np.ndarray, background) -> tuple[list[str], tuple[float, float, float]]:
    cov, luma, border = _core.thumbnail_qa(np.ascontiguousarray(rgb), background=background)
    flags = []
    if cov < EMPTY_COVERAGE:
        flags.append("EMPTY")
    elif luma < BLACK_LUMA:
        flags.append("BLACK")
    if border > EDGE_BORDER:
        flags.append("EDGE")
    return flags, (cov, luma, border)


def contact_sheet(
    build: Path, out: Path, *, columns: int | None = None, tile: int | None = None
) -> Figure:
    """Write the contact sheet of a build to `out`."""
    build = Path(build)
    settings = layout.complete_settings(build)
    if not settings:
        raise InputError(f"no complete setting (<setting>/{layout.MARKER}) in build: {build}")
    if columns is not None:
        check_range("--columns", columns, 1)
    cols = columns or math.ceil(math.sqrt(len(settings)))
    cols = min(cols, len(settings))
    cells = []
    for s in settings:
        meta = _read_meta(s)
        n = len(meta["views"])
        view = (meta.get("test_views") or [0])[0]
        path = s / "sharp" / layout.IMAGES / _core.image_name(view, n)
        if not path.is_file():
            raise InputError(f"sharp image not found: {path}")
        bg = tuple(meta.get("render", {}).get("background", [1.0, 1.0, 1.0]))
        cells.append((s.name, view, path, bg))
    with Image.open(cells[0][2]) as im:
        ts = tile_size(*im.size, tile)
    failed = _failed_objects(build)
    f_title, f_label, f_small = _font(16, bold=True), _font(12), _font(11)
    plural = "" if len(cells) == 1 else "s"
    title = f"{build.resolve().name}: {len(cells)} setting{plural}"
    size = sheet_size(len(cells), cols, ts)
    fig = Image.new("RGB", size, BG)
    draw = ImageDraw.Draw(fig)
    flagged = []
    for k, (name, view, path, bg) in enumerate(cells):
        x, y = sheet_origin(k, cols, ts)
        with Image.open(path) as im:
            rgb = np.asarray(im.convert("RGB"))
            fig.paste(_thumb(im, ts), (x, y))
        _frame(draw, x, y, ts)
        flags, _ = qa_flags(rgb, bg)
        ink = FLAG if flags else INK
        if flags:
            flagged.append((name, " ".join(flags)))
            draw.rectangle([x - 2, y - 2, x + ts[0] + 1, y + ts[1] + 1], outline=FLAG, width=2)
        draw.text((x, y + ts[1] + 2), _fit(draw, name, f_label, ts[0]), fill=ink, font=f_label)
        sub = f"view {view:03d}" + (f"  {' '.join(flags)}" if flags else "")
        draw.text((x, y + ts[1] + 18), _fit(draw, sub, f_small, ts[0]), fill=ink, font=f_small)
    counts = f"sharp, first test view; {failed} objects failed; {len(flagged)} flagged"
    draw.text((PAD, 5), _fit(draw, title, f_title, size[0] - 2 * PAD), fill=INK, font=f_title)
    draw.text(
        (PAD, 26),
        _fit(draw, counts, f_small, size[0] - 2 * PAD),
        fill=FLAG if flagged else INK,
        font=f_small,
    )
    _save(fig, out)
    return Figure(out, [c[1] for c in cells], [c[0] for c in cells], ts, size, flagged)


def _failed_objects(build: Path) -> int:
    """Objects failing now, as the build counted them in dataset.json (failures.jsonl keeps
    every attempt, also of objects a later run built)."""
    counts = outputs.read_record(build / layout.DATASET).get("counts") or {}
    return int(counts.get("objects_failed", 0))


# -- command ---------------------------------------------------------------------------------


def run(args) -> int:
    path: Path = args.path
    if not path.is_dir():
        raise InputError(f"setting or build directory not found: {path}")
    if args.tile is not None:
        check_range("--tile", args.tile, 16, 2048)
    if args.out is not None:
        if args.out.suffix.lower() not in IMAGE_FORMATS:
            raise ConfigError(f"--out {args.out}: the figure is an image: .png, .jpg or .webp")
        # A figure never replaces a dataset image or lands in a level folder.
        outputs.refuse_inside_settings(args.out, allow=("preview.png",))
        # Only the build the figure shows may hold it: never another build or a noise
        # output (their manifests would list it and `verify` certify it).
        own = path if outputs.kind_of(path) is outputs.OutputKind.BUILD else path.parent
        outputs.refuse_inside_output(args.out, "--out", within=own)
        if args.out.is_dir():
            raise ConfigError(f"--out is a folder, not an image file: {args.out}")
        if args.out.exists() and not args.force and not is_our_figure(args.out):
            raise ConfigError(
                f"--out {args.out.name} is an image blurset preview did not write: keep it "
                f"(give another --out), or --force to replace it: {args.out}"
            )
    if outputs.kind_of(path) is outputs.OutputKind.BUILD:
        if args.noise is not None or args.gain is not None:
            raise ConfigError("--noise/--gain apply to a setting figure, not to a contact sheet")
        fig = contact_sheet(
            path, args.out or path / "contact_sheet.png", columns=args.columns, tile=args.tile
        )
        publish.refresh_manifest([fig.path])
        for name, flags in fig.flagged:
            print(f"flagged: {name}: {flags}", file=sys.stderr)
        print(
            f"blurset preview: contact sheet of {len(fig.columns)} "
            f"setting{'' if len(fig.columns) == 1 else 's'} "
            f"({len(fig.flagged)} flagged) -> {fig.path}"
        )
        return 0
    fig = setting_figure(
        path,
        args.out or path / "preview.png",
        rows=args.rows,
        tile=args.tile,
        noise=args.noise,
        gain=args.gain,
    )
    publish.refresh_manifest([fig.path])
    print(
        f"blurset preview: {len(fig.rows)} views x {len(fig.columns)} columns "
        f"({', '.join(fig.columns)}) -> {fig.path}"
    )
    return 0
