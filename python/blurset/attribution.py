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
that maps to none is `other` (the raw text is always kept in `license_text`).
"""

from __future__ import annotations

import functools
import gzip
import json
import re
from pathlib import Path
from typing import Any

from blurset.exceptions import ConfigError

UNKNOWN = "unknown"
OTHER = "other"

# The Creative Commons licences Sketchfab and Objaverse use, as SPDX ids.
_CC = ("by", "by-sa", "by-nd", "by-nc", "by-nc-sa", "by-nc-nd")
SPDX_IDS = (
    *(f"CC-{k.upper()}-{v}" for k in _CC for v in ("4.0", "3.0", "2.5", "2.0")),
    "CC0-1.0",
    "CC-PDDC",
)
_BY_LOWER = {s.lower(): s for s in SPDX_IDS}
# Objaverse 1.0 annotations name licences by Sketchfab's short codes.
_OBJAVERSE_CODES = {
    **{k: f"CC-{k.upper()}-4.0" for k in _CC},
    "cc0": "CC0-1.0",
}
_CC_URL = re.compile(r"creativecommons\.org/licenses/([a-z-]+)/(\d\.\d)", re.I)
_CC0_URL = re.compile(r"creativecommons\.org/publicdomain/zero/1\.0", re.I)
_NAME_URL = re.compile(r"^(.*?)\s*\((https?://[^\s)]+)\)\s*$")

# The fields of meta.json `object` this module fills.
FIELDS = ("title", "author", "author_url", "license", "license_text", "source_url")


def spdx(text: str | None) -> str:
    """The SPDX id a licence text names, `other` for text that maps to none, `unknown`
    for no text."""
    if text is None or not str(text).strip():
        return UNKNOWN
    t = " ".join(str(text).split())
    head = t.split(" ", 1)[0].strip("(),;")
    if head.lower() in _BY_LOWER:
        return _BY_LOWER[head.lower()]
    if t.lower() in _OBJAVERSE_CODES:
        return _OBJAVERSE_CODES[t.lower()]
    if _CC0_URL.search(t) or re.fullmatch(r"cc0(\s*1\.0)?", t, re.I):
        return "CC0-1.0"
    m = _CC_URL.search(t)
    if m and m.group(1).lower() in _CC:
        return f"CC-{m.group(1).upper()}-{m.group(2)}"
    return OTHER


def _split_name_url(text: str) -> tuple[str, str | None]:
    """`Name (https://…)` (Sketchfab's author field) → name and URL."""
    m = _NAME_URL.match(text)
    return (m.group(1), m.group(2)) if m and m.group(1) else (text, None)


def _text(v: Any) -> str | None:
    return " ".join(v.split()) if isinstance(v, str) and v.strip() else None


def from_asset(asset: Any) -> dict[str, Any]:
    """The attribution a glTF `asset` object carries (only the fields it has)."""
    if not isinstance(asset, dict):
        return {}
    out: dict[str, Any] = {}
    extras = asset.get("extras") if isinstance(asset.get("extras"), dict) else {}
    if title := _text(extras.get("title")):
        out["title"] = title
    if author := _text(extras.get("author")):
        out["author"], url = _split_name_url(author)
        if url:
            out["author_url"] = url
    if lic := _text(extras.get("license")):
        out["license_text"] = lic
    if src := _text(extras.get("source")):
        out["source_url"] = src
    if copyright_ := _text(asset.get("copyright")):
        out["copyright"] = copyright_
    return out


def from_objaverse_annotation(ann: Any) -> dict[str, Any]:
    """The attribution of one Objaverse 1.0 annotation record (Sketchfab's API fields)."""
    if not isinstance(ann, dict):
        return {}
    out: dict[str, Any] = {}
    if title := _text(ann.get("name")):
        out["title"] = title
    user = ann.get("user") if isinstance(ann.get("user"), dict) else {}
    if author := _text(user.get("displayName")) or _text(user.get("username")):
        out["author"] = author
    if url := _text(user.get("profileUrl")):
        out["author_url"] = url
    if lic := _text(ann.get("license")):
        out["license_text"] = lic
    if src := _text(ann.get("viewerUrl")):
        out["source_url"] = src
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


# -- the --licenses filter ---------------------------------------------------------------


def parse_licenses(value: Any, where: str = "--licenses") -> list[str] | None:
    """`cc-by-4.0,cc0-1.0,unknown` (or a TOML list) → canonical ids; None = no filter.
    Ids are case-insensitive; anything but a known SPDX id, `other` or `unknown` is an
    error (a typo would otherwise skip every object)."""
    if value is None:
        return None
    items = value if isinstance(value, list) else str(value).split(",")
    out: list[str] = []
    for raw in items:
        if not isinstance(raw, str):
            raise ConfigError(f"{where}: expected licence ids, got {raw!r}")
        s = raw.strip()
        if not s:
            continue
        low = s.lower()
        if low in (UNKNOWN, OTHER):
            canon = low
        elif low in _BY_LOWER:
            canon = _BY_LOWER[low]
        else:
            raise ConfigError(
                f"{where}: unknown licence {s!r} (SPDX ids such as cc-by-4.0, cc-by-sa-4.0, "
                "cc-by-nc-4.0, cc0-1.0, or other / unknown)"
            )
        if canon not in out:
            out.append(canon)
    if not out:
        raise ConfigError(f"{where}: give at least one licence id (e.g. cc-by-4.0,cc0-1.0)")
    return out


def allowed(license_id: str, licenses: list[str] | None) -> bool:
    """Whether an object under `license_id` passes the filter (None lets all pass)."""
    if licenses is None:
        return True
    return license_id.lower() in {x.lower() for x in licenses}


def hf_license(license_id: str) -> str:
    """The Hugging Face card id of a licence (lowercase SPDX; `other`, `unknown`)."""
    return license_id.lower()
