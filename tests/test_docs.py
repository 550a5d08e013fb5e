"""The docs: every `DESIGN §n` the code cites exists in docs/design.md, the README stays a
short first read, user pages carry no project history, every benchmark figure README.md
and docs/guide/*.md quote is a marker filled from bench/results.json, and the generators
of the CLI reference, the file-format pages and the benchmark pages work on the real
parser, schemas/ and bench/results.json (`make docs` runs them, then `mkdocs build
--strict`)."""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import pytest

from tests.conftest import gen_module as _gen

ROOT = Path(__file__).resolve().parents[1]
GEN = ROOT / "docs" / "gen"


def test_every_cited_design_section_exists() -> None:
    check = _gen("check")
    cited = check.cited_sections()
    assert len(cited) >= 10, "the code cites the design: the scan found too little"
    assert check.missing_sections() == []


def test_a_citation_of_a_missing_section_is_found(tmp_path, monkeypatch) -> None:
    check = _gen("check")
    assert [m.group(1) for m in check.CITE.finditer("DESIGN §2, §12 and DESIGN §1–4")] == [
        "§2, §12",
        "§1–4",
    ]
    design = tmp_path / "design.md"
    design.write_text("# d\n\n## 1. One\n\n## 2. Two\n")
    monkeypatch.setattr(check, "DESIGN", design)
    monkeypatch.setattr(check, "cited_sections", lambda: {1: ["a.py:1"], 3: ["b.rs:7"]})
    assert check.missing_sections() == [
        "DESIGN §3 (cited at b.rs:7) is not a section of docs/design.md"
    ]


def test_readme_is_short_and_its_links_resolve() -> None:
    assert _gen("check").readme_problems() == []


def test_user_pages_name_no_issue_date_load_or_commit() -> None:
    check = _gen("check")
    assert check.history_problems() == []
    common = _gen("common")
    text = "one render call per frame (before issue 16), measured 2026-11-30 (issue 19: x)"
    clean = common.sanitize(text)
    assert not [p for p, _ in common.FORBIDDEN if p.search(clean)], clean


def test_cli_reference_covers_every_command_and_option(tmp_path, monkeypatch) -> None:
    cli_gen = _gen("cli")
    monkeypatch.setattr(cli_gen, "OUT", tmp_path / "cli.md")
    monkeypatch.setattr(cli_gen, "GUIDES", [])
    assert cli_gen.main() == 0
    page = (tmp_path / "cli.md").read_text()
    from blurset.cli import subcommands

    for name, p in subcommands().items():
        assert f"## `blurset {name}`" in page
        for action in p._actions:
            if isinstance(action, argparse._HelpAction) or "--debug" in action.option_strings:
                continue
            for flag in action.option_strings:
                assert f"`{flag}`" in page, (name, flag)
    # The keys only a --config file sets, from the core's declarations.
    from blurset.services.config import BUILD

    for d in BUILD.decls:
        if not d.flags and not d.via:
            assert f"| `{d.name}` |" in page, d.name


def test_build_guide_synopsis_is_the_generated_one() -> None:
    """docs/guide/build.md's synopsis is what docs/gen/cli.py makes from the parser and the
    option declarations (`make docs` rewrites it), and names every option of `blurset build`."""
    cli_gen = _gen("cli")
    page = ROOT / "docs" / "guide" / "build.md"
    text = page.read_text()
    blocks = list(cli_gen.SYNOPSIS.finditer(text))
    assert [m["name"] for m in blocks] == ["build"], "build.md holds no generated synopsis"
    assert blocks[0]["body"] == cli_gen.synopsis("build"), "stale synopsis: run make docs"
    assert cli_gen.rewrite_synopses(text) == text
    from blurset.cli import subcommands

    for action in subcommands()["build"]._actions:
        if isinstance(action, argparse._HelpAction) or "--debug" in action.option_strings:
            continue
        assert f"[{action.option_strings[0]}" in blocks[0]["body"] or (
            f"| {action.option_strings[0]}" in blocks[0]["body"]
        ), action.option_strings
    # A hand edit of the block is found.
    edited = text.replace("[--quiet]", "")
    assert cli_gen.rewrite_synopses(edited) == text


def test_a_page_per_schema_listing_every_field(tmp_path, monkeypatch) -> None:
    formats = _gen("formats")
    monkeypatch.setattr(formats, "OUT", tmp_path / "records")
    assert formats.main() == 0
    for path in sorted((ROOT / "schemas").glob("*.schema.json")):
        stem = path.name.removesuffix(".schema.json")
        page = (tmp_path / "records" / f"{stem}.md").read_text()
        schema = json.loads(path.read_text())
        nodes = [schema, *(schema.get("$defs") or {}).values()]
        for node in nodes:
            for field in node.get("properties") or {}:
                assert f"| `{field}` |" in page, (stem, field)
        assert (tmp_path / "records" / path.name).exists()


def test_benchmark_pages_plot_every_result(tmp_path, monkeypatch) -> None:
    pytest.importorskip("matplotlib")
    bench = _gen("bench")
    monkeypatch.setattr(bench, "OUT", tmp_path / "bench")
    assert bench.main(figures_too=False) == 0
    pages = "".join(p.read_text() for p in (tmp_path / "bench").glob("*.md"))
    for r in json.loads((ROOT / "bench" / "results.json").read_text()):
        light = bench.LIGHT.match(r["name"])
        gain = bench.GAIN.match(r["name"])
        target = bench.TARGET.match(r["name"])
        kinds = bench.KINDS.match(r["name"])
        model = kinds and bench.model_label(kinds["model"])
        half = bench.HALF_NOISE.match(r["name"])
        half_row = half and (
            ("**every model**" if half["model"] == "all" else f"`{half['model']}`")
            + f" | {bench.ESTIMATORS[half['estimator']].split(': ')[1]} | {r['images']} |"
        )
        shown = (
            r["name"] in pages
            or (light and f"| {light['glb']} |" in pages)
            or (gain and f"| `{gain['glb']}` | {gain['res']} |" in pages)
            or (target and f"| `{target['model']}` |" in pages)
            or (kinds and f"| {kinds['kind']} | {model} |" in pages)
            or (half_row and f"| {half_row}" in pages)
        )
        assert shown or bench.PRESETS.match(r["name"]), r["name"]
    assert list((tmp_path / "bench").glob("*.png"))


def test_gpu_page_shows_every_gpu_result_or_says_there_is_none(tmp_path, monkeypatch) -> None:
    """docs/benchmarks/gpu.md comes from bench/results_gpu.json: each of its results on the
    page; without the file, a page that says nothing was measured on a GPU."""
    pytest.importorskip("matplotlib")
    bench = _gen("bench")
    monkeypatch.setattr(bench, "OUT", tmp_path / "bench")
    monkeypatch.setattr(bench, "RESULTS_GPU", tmp_path / "absent.json")
    assert bench.main(figures_too=False) == 0
    assert "No GPU results yet" in (tmp_path / "bench" / "gpu.md").read_text()
    # The CPU's results stand in for a GPU run's: the page is generated the same way.
    results = json.loads((ROOT / "bench" / "results.json").read_text())
    page = "\n".join(bench.device_page(results))
    assert "No GPU results yet" not in page
    shown = [r["name"] for r in results if f"`{r['name']}`" in page]
    speed = [r["name"] for r in results if bench.SPEED.match(r["name"])]
    assert speed and set(speed) <= set(shown)
    others = [r["name"] for r in results if not bench.SPEED.match(r["name"])]
    assert set(others) <= set(shown)


def test_every_quoted_benchmark_figure_is_a_marker_filled_from_results() -> None:
    """README.md and docs/guide/*.md: each marker shows what bench/results.json gives, and
    no benchmark-looking number stands outside a marker but the allowed definitions."""
    figures = _gen("figures")
    assert figures.problems() == []
    texts = [p.read_text() for p in figures.pages()]
    assert sum(len(figures.MARKER.findall(t)) for t in texts) >= 20, "the scan found too few"
    assert figures.unused_allowed(texts) == []


def test_a_hand_typed_or_stale_figure_fails(tmp_path) -> None:
    """Plant figures in temp copies of the real pages: the check must name each."""
    figures = _gen("figures")
    results = figures.load()
    readme = tmp_path / "README.md"
    speed = tmp_path / "speed.md"
    readme.write_text(
        (ROOT / "README.md").read_text()
        + "\nThe floor preset is 7.3× faster, at 61.2 dB, 12 settings per hour, 95 %.\n"
    )
    text = (ROOT / "docs" / "guide" / "speed.md").read_text()
    m = next(figures.MARKER.finditer(text))
    wrong = "99.9" if m["value"] != "99.9" else "11.1"
    speed.write_text(
        text[: m.start("value")]
        + wrong
        + text[m.end("value") :]
        + "\n<!-- fig no_such_result ratio .1f -->3.0<!-- /fig -->×\n"
        + "<!-- fig settings_per_hour_paper no_such_field .1f -->3.0<!-- /fig -->×\n"
    )
    assert figures.problems([readme, speed], results) != []
    found = "\n".join(figures.problems([readme, speed], results))
    for planted in ("'7.3×'", "'61.2 dB'", "'12 settings per hour'", "'95 %'"):
        assert planted in found, planted
    assert f"the page says {wrong!r}" in found
    assert "no result 'no_such_result'" in found
    assert "has no field 'no_such_field'" in found
    # In code, in a marker or as an allowed definition a number is not a stray.
    assert figures.strays("`--target-psnr 45`\n```sh\n3 dB\n```\nthe floor, 58.92 dB") == []
    # make docs rewrites the stale marker from the results; the missing ones stay named.
    bad = figures.update([speed], results)
    assert len(bad) == 2
    assert "the page says" not in "\n".join(figures.problems([speed], results))
    assert figures.rewrite(speed.read_text(), results)[0] == speed.read_text()


def test_no_absolute_machine_path_in_docs_or_readme() -> None:
    """README.md, ARCHITECTURE.md, docs/**/*.md and the page generators in docs/gen spell no
    path of the machine they were made on (a transcript shows relative paths)."""
    check = _gen("check")
    pages = check.machine_path_pages()
    assert ROOT / "README.md" in pages and ROOT / "ARCHITECTURE.md" in pages
    assert len([p for p in pages if p.suffix == ".md"]) >= 20, "the scan found too few pages"
    assert check.machine_path_problems() == []


def test_a_planted_machine_path_fails(tmp_path, monkeypatch) -> None:
    check = _gen("check")
    page = ROOT / "docs" / "training" / "ibrnet.md"
    text = page.read_text()
    planted = tmp_path / "ibrnet.md"
    planted.write_text(text + "\n```sh\npython train.py --rootdir /work/main/foo\n```\n")
    monkeypatch.setattr(check, "machine_path_pages", lambda: [planted])
    assert any("'/work/main/foo'" in p for p in check.machine_path_problems())
    for bad in (
        "/home/alice/ibrnet",
        "/Users/bob/data",
        "/tmp/pytest-of-x/p0/out",
        "/tmp/tmpab12cd/x",
        "flock /tmp/blurset-blender.lock",
    ):
        assert check.machine_paths(f"see `{bad}` here"), bad
    # Examples a reader adapts, relative and home-relative paths are fine.
    for fine in (
        "/path/to/IBRNet",
        "~/IBRNet",
        "ROOT/data/tmp/x",
        "flock ~/.blurset-blender.lock",
        "/usr/bin/python3",
        "$HOME/work/x",
    ):
        assert check.machine_paths(fine) == [], fine


def test_the_generated_pages_are_committed_and_current(tmp_path, monkeypatch) -> None:
    """The pages `make docs` generates are committed (a link to them resolves on GitHub,
    not only on the built site), and each is what its generator makes today."""
    pytest.importorskip("matplotlib")
    cli_gen, formats, bench = _gen("cli"), _gen("formats"), _gen("bench")
    monkeypatch.setattr(cli_gen, "OUT", tmp_path / "reference" / "cli.md")
    monkeypatch.setattr(cli_gen, "GUIDES", [])
    monkeypatch.setattr(formats, "OUT", tmp_path / "records")
    monkeypatch.setattr(bench, "OUT", tmp_path / "benchmarks")
    assert cli_gen.main() == 0 and formats.main() == 0 and bench.main(figures_too=False) == 0
    pairs = [(tmp_path / "reference", ROOT / "docs" / "reference")]
    pairs += [(tmp_path / "records", ROOT / "docs" / "formats" / "records")]
    pairs += [(tmp_path / "benchmarks", ROOT / "docs" / "benchmarks")]
    for made, committed in pairs:
        names = sorted(p.name for p in made.iterdir())
        assert names == sorted(p.name for p in committed.iterdir()), committed
        for name in names:
            if name.endswith(".png"):  # a figure: its renderer's bytes vary by platform
                continue
            stale = (made / name).read_bytes() != (committed / name).read_bytes()
            assert not stale, f"{committed / name} is stale: run make docs"


def test_no_relative_link_of_the_readme_or_docs_is_dead() -> None:
    """Every relative link in README.md and docs/ names a file of the checkout, as
    GitHub shows them (no page only the docs build makes)."""
    dead = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for m in re.finditer(r"\]\(([^)\s#]+)(?:#[^)\s]*)?\)", page.read_text()):
            link = m.group(1)
            if not re.match(r"[a-z]+:", link) and not (page.parent / link).exists():
                dead.append(f"{page.relative_to(ROOT)}: {link}")
    assert dead == [], dead
