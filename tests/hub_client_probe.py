"""Loads a `blurset export --for hub` output by every route docs/guide/hub.md shows, with
whichever `datasets` is importable (tests/test_hub_clients.py runs it with the oldest and
the newest that `blurset[hub]` allows), and prints what each route read as JSON:
`{"version": ..., "routes": {route: {config: {split: digest of its rows}}}}`.

Usage: python hub_client_probe.py HUB. Offline, its cache in a temp folder."""

from __future__ import annotations

import atexit
import glob
import hashlib
import json
import os
import shutil
import sys
import tempfile

os.environ["HF_DATASETS_OFFLINE"] = "1"
os.environ["HF_HUB_OFFLINE"] = "1"
os.environ["HF_HOME"] = tempfile.mkdtemp(prefix="blurset-hf-")
atexit.register(shutil.rmtree, os.environ["HF_HOME"], True)
os.environ["HF_DATASETS_DISABLE_PROGRESS_BARS"] = "1"

import datasets  # noqa: E402

# The columns a digest covers: the camera, the records and the image's bytes.
COLUMNS = ("setting", "view", "level", "held_out", "c2w", "mean_c2w", "poses_bounds",
           "latents", "samples", "amplitude", "meta")  # fmt: skip


def row_digest(rows) -> str:
    """sha256 over every row's COLUMNS and its image's bytes, in order."""
    h = hashlib.sha256()
    for r in rows:
        image = r["image"]["bytes"]
        h.update(json.dumps([r.get(c) for c in COLUMNS]).encode())
        h.update(hashlib.sha256(image).digest())
    return h.hexdigest()


def undecoded(ds):
    return ds.cast_column("image", datasets.Image(decode=False))


def configs(hub: str) -> dict[str, dict[str, list[str]]]:
    """config -> split -> its shards, from export.json."""
    with open(os.path.join(hub, "export.json")) as f:
        doc = json.load(f)
    out: dict[str, dict[str, list[str]]] = {}
    for name, rec in sorted(doc["shards"].items()):
        out.setdefault(rec["config"], {}).setdefault(rec["split"], []).append(
            os.path.join(hub, "data", name)
        )
    return out


def main(hub: str) -> None:
    routes: dict[str, dict] = {}
    for config, splits in configs(hub).items():
        for split, files in splits.items():
            # The card's configs (a local folder, as from the Hub), whole and streamed.
            ds = load = datasets.load_dataset(hub, config, split=split)
            got = {"card": row_digest(undecoded(load))}
            stream = datasets.load_dataset(hub, config, split=split, streaming=True)
            got["card_streaming"] = row_digest(undecoded(stream))
            # The shards without the card.
            ds = datasets.load_dataset("parquet", data_files={split: files}, split=split)
            got["data_files"] = row_digest(undecoded(ds))
            got["from_parquet"] = row_digest(undecoded(datasets.Dataset.from_parquet(files)))
            # A decoded row is an image; c2w a 4 x 4 list.
            row = load[0]
            assert row["image"].size == (row["width"], row["height"]), row["image"].size
            assert len(row["c2w"]) == 4 and all(len(r) == 4 for r in row["c2w"])
            for route, digest in got.items():
                routes.setdefault(route, {}).setdefault(config, {})[split] = digest
    assert glob.glob(os.path.join(hub, "README.md"))
    print(json.dumps({"version": datasets.__version__, "routes": routes}))


if __name__ == "__main__":
    main(sys.argv[1])
