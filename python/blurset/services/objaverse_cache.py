"""Objaverse 1.0 objects by uid, through the `objaverse` package's cache (DESIGN §11).

The cache is the package's own layout, so objects a user already downloaded with
`objaverse.load_objects` are found, and ours are found by it:

    <dir>/hf-objaverse-v1/object-paths.json.gz       uid -> "glbs/<shard>/<uid>.glb"
    <dir>/hf-objaverse-v1/lvis-annotations.json.gz   LVIS category -> [uid, ...]
    <dir>/hf-objaverse-v1/glbs/<shard>/<uid>.glb

`<dir>` defaults to the package's `objaverse.BASE_PATH` (~/.objaverse). Offline, what is
in the cache builds and what is missing fails with a clear reason; online, missing files
are downloaded from the same Hugging Face paths the package uses (`HF_ENDPOINT` selects a
mirror, as for huggingface_hub), with retries, into the same places (temp file + rename, so a killed download leaves no half file). Our own
small downloader stands in for `objaverse.load_objects` because that one globs the
whole cache after every file, which does not scale to a cluster's shared cache.
"""

from __future__ import annotations

import gzip
import json
import os
import re
import time
import urllib.error
import urllib.request
from pathlib import Path

from blurset.exceptions import InputError

REPO = "datasets/allenai/objaverse/resolve/main"
VERSIONED = "hf-objaverse-v1"
PREFIX = "objaverse:"
# Objaverse 1.0 uids are 32 hex digits; anything path-like is refused before it can
# name a file outside the cache.
_UID = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
RETRIES = 3
TIMEOUT_S = 60


class FetchError(Exception):
    """An object could not be made local; the message is the one-line reason."""


def hf_base() -> str:
    endpoint = os.environ.get("HF_ENDPOINT", "https://huggingface.co").rstrip("/")
    return f"{endpoint}/{REPO}"


def default_dir() -> Path:
    try:
        import objaverse  # type: ignore[import-untyped]  # the package ships no types

        return Path(objaverse.BASE_PATH)
    except ImportError:
        return Path.home() / ".objaverse"


def is_entry(entry: str) -> bool:
    return entry.startswith(PREFIX)


class Cache:
    def __init__(self, root: Path | str | None = None, *, offline: bool = False) -> None:
        self.root = Path(root).expanduser() if root else default_dir()
        self.versioned = self.root / VERSIONED
        self.offline = offline
        self._paths: dict[str, str] | None = None
        self._lvis: dict[str, list[str]] | None = None

    # -- index files ---------------------------------------------------------------------

    def _index(self, name: str, what: str) -> object:
        local = self.versioned / name
        if not local.exists():
            if self.offline:
                raise InputError(
                    f"{what} needs {local} (the objaverse package's index); it is not in "
                    "the cache and --objaverse-offline forbids downloading it"
                )
            try:
                _download(f"{hf_base()}/{name}", local)
            except FetchError as e:
                raise InputError(f"{what}: cannot download {name}: {e}") from None
        try:
            with gzip.open(local, "rb") as f:
                return json.load(f)
        except (OSError, ValueError) as e:
            raise InputError(f"{what}: {local} is not a gzipped JSON index ({e})") from None

    def object_paths(self, what: str = "objaverse ids") -> dict[str, str]:
        if self._paths is None:
            data = self._index("object-paths.json.gz", what)
            if not isinstance(data, dict):
                raise InputError(f"{self.versioned / 'object-paths.json.gz'}: not a uid map")
            self._paths = data
        return self._paths

    def lvis(self, what: str) -> dict[str, list[str]]:
        if self._lvis is None:
            data = self._index("lvis-annotations.json.gz", what)
            if not isinstance(data, dict):
                raise InputError(f"{self.versioned / 'lvis-annotations.json.gz'}: not a map")
            self._lvis = data
        return self._lvis

    # -- entries -------------------------------------------------------------------------

    def uids(self, entry: str) -> list[str]:
        """The uids an `objaverse:` entry names: `objaverse:<uid>`, `objaverse:lvis=<cat>`
        (several categories separated by `+`), or `objaverse:all`."""
        body = entry[len(PREFIX) :].strip()
        if body == "all":
            return sorted(self.object_paths(entry))
        if body.startswith("lvis="):
            table = self.lvis(entry)
            out: set[str] = set()
            for cat in body[len("lvis=") :].split("+"):
                if cat not in table:
                    import difflib

                    close = difflib.get_close_matches(cat, list(table), n=3)
                    hint = f" (did you mean {', '.join(close)}?)" if close else ""
                    raise InputError(f"--objects {entry}: no LVIS category {cat!r}{hint}")
                out.update(table[cat])
            return sorted(out)
        if not _UID.match(body):
            raise InputError(f"--objects {entry}: {body!r} is not an objaverse uid")
        return [body]

    def path(self, uid: str) -> Path:
        """Where the package keeps (or would keep) this object's GLB."""
        if not _UID.match(uid):
            raise InputError(f"{uid!r} is not an objaverse uid")
        try:
            rel = self.object_paths()[uid]
        except InputError:
            # No index, offline: the object may still be cached under any shard.
            found = sorted(self.versioned.glob(f"glbs/*/{uid}.glb"))
            return found[0] if found else self.versioned / "glbs" / "unknown" / f"{uid}.glb"
        except KeyError:
            raise InputError(f"objaverse:{uid} is not in the Objaverse 1.0 index") from None
        p = (self.versioned / rel).resolve()
        if self.versioned.resolve() not in p.parents:
            raise InputError(f"objaverse:{uid}: the index points outside the cache ({rel!r})")
        return p

    # -- fetching ------------------------------------------------------------------------

    def ensure(self, uid: str, path: Path) -> Path:
        """The local GLB of `uid`, downloaded with retries when missing and allowed."""
        if path.is_file():
            return path
        if self.offline:
            raise FetchError(f"not in the objaverse cache {self.versioned} (offline)")
        rel = path.relative_to(self.versioned).as_posix()
        if rel.startswith("glbs/unknown/"):
            raise FetchError(f"not in the objaverse cache {self.versioned} and no index")
        _download(f"{hf_base()}/{rel}", path)
        return path


def _download(url: str, dest: Path) -> None:
    """url -> dest via a temp file and rename, with RETRIES attempts and backoff."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.with_name(f".{dest.name}.tmp{os.getpid()}")
    last = ""
    for attempt in range(RETRIES):
        if attempt:
            time.sleep(2.0**attempt)
        try:
            with urllib.request.urlopen(url, timeout=TIMEOUT_S) as r, open(tmp, "wb") as f:
                while chunk := r.read(1 << 20):
                    f.write(chunk)
            os.replace(tmp, dest)
            return
        except urllib.error.HTTPError as e:
            last = f"HTTP {e.code}"
            if 400 <= e.code < 500 and e.code != 429:
                break  # not found / forbidden: retrying cannot help
        except (urllib.error.URLError, OSError, TimeoutError) as e:
            last = str(getattr(e, "reason", e))
        finally:
            tmp.unlink(missing_ok=True)
    raise FetchError(f"download of {url} failed after {attempt + 1} attempt(s): {last}")
