"""The Hub shard format (issue 50), shared by `blurset export --for hub` (which writes
it: `commands/export/hub.py`), `blurset verify`, `blurset card` and `blurset.data`
(which read it): the columns and their `datasets` features, the Arrow schema and the key
a shard carries, config names, and reading an export's rows back."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

from blurset.exceptions import ConfigError, InputError
from blurset.services import outputs

if TYPE_CHECKING:
    import pyarrow as pa

    from blurset import _records

TARGET: _records.ExportTarget = "hub"
DATA_DIR = "data"
# The shard's schema metadata: `huggingface` (the `datasets` features: the image
# columns are Images) and ours, the key of what the shard was made from.
KEY = b"blurset"
# The row layout's version: a change of columns changes every key. 2: lists spelled
# `Sequence` (datasets 3.x reads no `List`); a moving camera's amplitude and path.
LAYOUT = 2


def pyarrow():
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise ConfigError(
            "--for hub needs pyarrow: pip install pyarrow (or, from blurset's checkout, pip install '.[hub]')"
        ) from None
    return pa, pq


def config_name(level: str, gain: str | None = None) -> str:
    """A config's name: the level, or `<level>_<gain>` (`blur_4_gain_4`)."""
    return level if gain is None else f"{level}_{gain}"


def columns(factors: list[int], passes: list[str], noise: bool) -> list[tuple[str, Any]]:
    """(name, `datasets` feature) of every column, in order."""
    f64 = {"dtype": "float64", "_type": "Value"}
    i32 = {"dtype": "int32", "_type": "Value"}
    s = {"dtype": "string", "_type": "Value"}
    # A list is spelled `Sequence`, which every `datasets` from 3.0 reads as a list of the
    # value: 4.0 renamed it `List` and still reads the old name so, 3.x knows no `List`.
    vec = {"feature": f64, "_type": "Sequence"}
    mat = {"feature": vec, "_type": "Sequence"}
    cols: list[tuple[str, Any]] = [("image", {"_type": "Image"})]
    cols += [(f"image_{f}", {"_type": "Image"}) for f in factors]
    cols += [
        ("setting", s),
        ("uid", s),
        ("theta0_deg", f64),
        ("level", s),
        ("gain", f64),
        ("view", i32),
        ("split", s),
        ("held_out", {"dtype": "bool", "_type": "Value"}),
        ("width", i32),
        ("height", i32),
        ("focal", f64),
        ("near", f64),
        ("far", f64),
        ("poses_bounds", vec),
        ("c2w", mat),
        ("mean_c2w", mat),
        ("w_l", f64),
        ("motion_px", f64),
        ("latents", i32),
        ("samples", i32),
        ("render_psnr_db", f64),
        ("coc_px", vec),
        ("amplitude_px", f64),
        ("path_px", f64),
        ("meta", s),
    ]
    if noise:
        cols += [("sigma_read", f64), ("sigma_shot", f64), ("noise", s)]
    for kind in passes:
        feature = {"_type": "Image"} if kind == "mask" else {"dtype": "binary", "_type": "Value"}
        cols += [(pass_column(kind, f), feature) for f in [1, *factors]]
    return cols


def pass_column(kind: str, factor: int) -> str:
    """The column of pass `kind` (`depth`, `normal`, `mask`) at 1/`factor` of the size."""
    return kind if factor == 1 else f"{kind}_{factor}"


def column_factor(column: str) -> int:
    """The factor of an image or pass column (`image_4`, `depth_4`: 4; `image`: 1), as
    `columns` and `pass_column` name them."""
    tail = column.rpartition("_")[2]
    return int(tail) if tail.isdigit() else 1


def _arrow_type(pa, feature: dict):
    t = feature["_type"]
    if t == "Image":
        return pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    if t == "Sequence":
        return pa.list_(_arrow_type(pa, feature["feature"]))
    return {
        "float64": pa.float64(),
        "int32": pa.int32(),
        "string": pa.string(),
        "bool": pa.bool_(),
        "binary": pa.binary(),
    }[feature["dtype"]]


def features(hp_factors: list[int], passes: list[str], noise: bool) -> dict[str, Any]:
    """The `datasets` features of a config's rows (what `huggingface` metadata holds)."""
    return dict(columns(hp_factors, passes, noise))


def schema(factors: list[int], passes: list[str], noise: bool, key: str) -> pa.Schema:
    pa, _ = pyarrow()
    cols = columns(factors, passes, noise)
    hf = {"info": {"features": dict(cols)}}
    meta = {b"huggingface": json.dumps(hf).encode(), KEY: key.encode()}
    return pa.schema([(n, _arrow_type(pa, f)) for n, f in cols], metadata=meta)


def read_key(path: Path) -> str | None:
    """The key a finished shard was made from, or None (no shard, or not ours)."""
    _, pq = pyarrow()
    try:
        meta = pq.read_schema(path).metadata or {}
    except (OSError, ValueError):
        return None
    key = meta.get(KEY)
    return key.decode() if key else None


# -- reading shards back -----------------------------------------------------------------


def hub_doc(path: Path) -> dict | None:
    """export.json of a `--for hub` export in `path`, or None when it is not one."""
    rec = Path(path) / outputs.OutputKind.EXPORT.record
    if not rec.is_file():
        return None
    doc = outputs.read_record(rec)
    return doc if isinstance(doc, dict) and doc.get("for") == TARGET else None


def iter_rows(path: Path, config: str, setting: str | None = None) -> Iterator[dict]:
    """The rows of `config` in a hub export (of one setting: only its shard is read,
    only its row group)."""
    _, pq = pyarrow()
    doc = hub_doc(path)
    if doc is None:
        raise InputError(f"not a `blurset export --for hub` output (export.json): {path}")
    if doc.get("state") == "replacing" or doc.get("shards") is None:
        raise InputError(f"the export is not finished (a run was stopped): {path}")
    for name, rec in sorted(doc["shards"].items()):
        if rec["config"] != config or (setting is not None and setting not in rec["settings"]):
            continue
        f = pq.ParquetFile(Path(path) / DATA_DIR / name)
        groups = list(range(f.num_row_groups))
        if setting is not None:
            groups = [rec["settings"].index(setting)]
        for g in groups:
            yield from f.read_row_group(g).to_pylist()
