"""Who made each object and under which licence (issue 19): what a build needs to
attribute every object it publishes, and the `--licenses` filter.

Sources, first found wins per field, nothing guessed:
1. the model's own glTF `asset`: Sketchfab exports (every Objaverse 1.0 object) carry
   `asset.extras` {author, license, source, title}, e.g. license "CC-BY-4.0
   (http://creativecommons.org/licenses/by/4.0/)"; `asset.copyright` is kept as given;
2. for objaverse objects, the annotations the `objaverse` package caches beside the
   GLBs (`hf-objaverse-v1/metadata/<shard>.json.gz`, read offline, never fetched).
A field no source gives is "unknown".

Licences become SPDX ids where the text maps to one (`CC-BY-4.0`, `CC0-1.0` …); text
that maps to none is `other` (the raw text is always kept in `license_text`). The ids,
that mapping and the filter are blurset-core's (dataset/license.rs); `--licenses` is a
field of its BuildConfig.
"""

from __future__ import annotations

import functools
import gzip
import json
import re
from pathlib import Path
from typing import Any

from blurset import _core

UNKNOWN = "unknown"
OTHER = "other"
_NAME_URL = re.compile(r"^(.*?)\s*\((https?://[^\s)]+)\)\s*$")

# The fields of meta.json `object` this module fills.
FIELDS = ("title", "author", "author_url", "license", "license_text", "source_url")


def spdx(text: str | None) -> str:
    """The SPDX id a licence text names, `other` for text that maps to none, `unknown`
    for no text (the rule is blurset-core's dataset::license)."""
    return _core.spdx_of(None if text is None else str(text))


def _split_name_url(text: str) -> tuple[str, str | None]:
    """`Name (https://…)` (Sketchfab's author field) → name and URL."""
    m = _NAME_URL.match(text)
    return (m.group(1), m.group(2)) if m and m.group(1) else (text, None)


def _text(v: Any) -> str | None:
    return " ".join(v.split()) if isinstance(v, str) and v.strip() else None


def _texts(source: dict[str, Any], **fields: str) -> dict[str, str]:
    """Each of our fields (a keyword) whose key in `source` (its value) holds text."""
    return {ours: t for ours, key in fields.items() if (t := _text(source.get(key)))}


def from_asset(asset: Any) -> dict[str, Any]:
    """The attribution a glTF `asset` object carries (only the fields it has)."""
    if not isinstance(asset, dict):
        return {}
    extras = asset.get("extras")
    if not isinstance(extras, dict):
        extras = {}
    out: dict[str, Any] = _texts(extras, title="title")
    if author := _text(extras.get("author")):
        out["author"], url = _split_name_url(author)
        if url:
            out["author_url"] = url
    out |= _texts(extras, license_text="license", source_url="source")
    out |= _texts(asset, copyright="copyright")
    return out


def from_objaverse_annotation(ann: Any) -> dict[str, Any]:
    """The attribution of one Objaverse 1.0 annotation record (Sketchfab's API fields)."""
    if not isinstance(ann, dict):
        return {}
    user = ann.get("user")
    if not isinstance(user, dict):
        user = {}
    out: dict[str, Any] = _texts(ann, title="name")
    if author := _text(user.get("displayName")) or _text(user.get("username")):
        out["author"] = author
    out |= _texts(user, author_url="profileUrl")
    out |= _texts(ann, license_text="license", source_url="viewerUrl")
    return out


@functools.lru_cache(maxsize=8)
def _annotation_shard(path: Path) -> dict[str, Any]:
    try:
        with gzip.open(path, "rb") as f:
            data = json.load(f)
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def objaverse_annotation(versioned: Path, glb: Path, uid: str) -> dict[str, Any] | None:
    """The cached annotation of an objaverse object, or None. The package keeps the
    annotations of the GLBs in `glbs/<shard>/` in `metadata/<shard>.json.gz`."""
    shard = Path(versioned) / "metadata" / f"{Path(glb).parent.name}.json.gz"
    if not shard.is_file():
        return None
    ann = _annotation_shard(shard).get(uid)
    return ann if isinstance(ann, dict) else None


def attribution(*sources: dict[str, Any]) -> dict[str, Any]:
    """Merge sources (first wins per field) into the full record: every field present,
    `unknown` where no source says, `license` the SPDX id of `license_text`."""
    merged: dict[str, Any] = {}
    for s in sources:
        for k, v in s.items():
            merged.setdefault(k, v)
    out = {k: merged.get(k, UNKNOWN) for k in ("title", "author")}
    out["author_url"] = merged.get("author_url")
    out["license"] = spdx(merged.get("license_text"))
    out["license_text"] = merged.get("license_text", UNKNOWN)
    out["source_url"] = merged.get("source_url", UNKNOWN)
    if "copyright" in merged:
        out["copyright"] = merged["copyright"]
    return out


# -- the --licenses filter (an option of the core's BuildConfig) -----------------------


def allowed(license_id: str, licenses: list[str] | None) -> bool:
    """Whether an object under `license_id` passes the filter (None lets all pass)."""
    return _core.license_allowed(license_id, licenses)


def hf_license(license_id: str) -> str:
    """The Hugging Face card id of a licence (lowercase SPDX; `other`, `unknown`)."""
    return license_id.lower()
