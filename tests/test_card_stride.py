"""The dataset card's loading recipe follows the build's test-view stride (no rendering:
a synthetic build in the schema `blurset build` writes)."""

from __future__ import annotations

import json

import pytest
from blurset.card import make_card

from tests.conftest import write_synthetic_build


@pytest.mark.parametrize("stride", [8, 16])
def test_card_llffhold_is_the_builds_view_stride(tmp_path, stride):
    out = tmp_path / "build"
    write_synthetic_build(out, 2, views=17, levels=(1,), latents=4, settings_per_object=1)
    splits = json.loads((out / "splits.json").read_text())
    splits["view_stride"] = stride
    (out / "splits.json").write_text(json.dumps(splits))
    config = {"view_stride": stride, "views": 17, "settings_per_object": 1, "levels": [1]}
    (out / "dataset.json").write_text(
        json.dumps({"config": config, "counts": {"objects": 2, "settings": 2, "images": 68}})
    )
    card = make_card(out)
    assert f"use `--llffhold {stride}`" in card
    assert card.count("--llffhold") == 1
