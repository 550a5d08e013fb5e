"""The dataset card's loading recipe follows the build's test-view stride (a real build
by the stand-in worker: no rendering)."""

from __future__ import annotations

import pytest
from blurset.commands.card import make_card

from tests.conftest import standin_build


@pytest.mark.parametrize("stride", [8, 16])
def test_card_llffhold_is_the_builds_view_stride(tmp_path, standin_blender, stride):
    out = tmp_path / "build"
    standin_build(out, standin_blender, "--views", "17", "--test-view-stride", str(stride),
                  "--settings-per-object", "1")  # fmt: skip
    card = make_card(out)
    assert f"use `--llffhold {stride}`" in card
    assert card.count("--llffhold") == 1
