"""A `blurset export --for hub` output as a researcher loads it (issue 60): as exported
(the export writes its card, one config per level), by every route docs/guide/hub.md
shows, with the oldest and the newest `datasets` that `blurset[hub]` allows; and a shake
row carries its level's numbers as a blur row does.

The oldest `datasets` is installed once (`pip install --target`, what of its
requirements the venv lacks; numpy and pyarrow stay the venv's) under .venv/, and the
loads run in a subprocess with it first on PYTHONPATH (tests/hub_client_probe.py). Under
CI=true a failed install fails the test."""

from __future__ import annotations

import importlib.metadata as md
import json
import os
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.version import Version

from tests.conftest import ROOT, run_cli, standin_build

pq = pytest.importorskip("pyarrow.parquet")

PROBE = ROOT / "tests" / "hub_client_probe.py"
CACHE = ROOT / ".venv" / "blurset-test-datasets"


def _allowed() -> Requirement:
    """The `datasets` requirement of the `hub` extra."""
    doc = tomllib.loads((ROOT / "pyproject.toml").read_text())
    reqs = [Requirement(r) for r in doc["project"]["optional-dependencies"]["hub"]]
    return next(r for r in reqs if r.name == "datasets")


def _oldest(req: Requirement) -> str:
    lower = [s.version for s in req.specifier if s.operator == ">="]
    assert len(lower) == 1, f"the hub extra's datasets has no single lower bound: {req}"
    return lower[0]


def _unavailable(why: str) -> None:
    if os.environ.get("CI") == "true":
        pytest.fail(why)
    pytest.skip(why)


def _datasets_dir(version: str) -> Path:
    """A folder holding `datasets==version` and the requirements of it that the venv
    does not meet, installed once (complete, or not there: renamed into place)."""
    d = CACHE / version
    if (d / ".complete").is_file():
        return d
    CACHE.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=CACHE, prefix=f".{version}.tmp"))
    try:
        pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q", "install"]
        pins = [f"{n}=={md.version(n)}" for n in ("numpy", "pyarrow")]
        report = tmp / "report.json"
        cmd = [*pip, "--dry-run", "--report", str(report), f"datasets=={version}", *pins]
        proc = subprocess.run(cmd, capture_output=True, text=True)
        if proc.returncode != 0:
            _unavailable(f"pip cannot resolve datasets=={version}: {proc.stderr[-2000:]}")
        items = json.loads(report.read_text())["install"]
        need = [f"{i['metadata']['name']}=={i['metadata']['version']}" for i in items]
        site = tmp / "site"
        proc = subprocess.run([*pip, "--no-deps", "--target", str(site), *need],
                              capture_output=True, text=True)  # fmt: skip
        if proc.returncode != 0:
            _unavailable(f"pip cannot install datasets=={version}: {proc.stderr[-2000:]}")
        (site / ".complete").write_text(" ".join(need) + "\n")
        try:
            os.rename(site, d)
        except OSError:
            if not (d / ".complete").is_file():  # (another run's finished copy is as good)
                raise
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return d


@pytest.fixture(scope="module")
def shake_hub(tmp_path_factory, standin_blender) -> tuple[Path, Path]:
    """A build with blur, defocus, shake and rolling shutter levels, exported --for hub (no `blurset
    card`: the export is loadable as it is)."""
    root = tmp_path_factory.mktemp("hub_clients")
    b, hub = root / "b", root / "hub"
    standin_build(b, standin_blender, "--shake", "1", "--latents", "4", "--defocus", "1",
                  "--rolling-shutter", "3")  # fmt: skip
    run_cli("export", str(b), "--for", "hub", "--out", str(hub), "--shard-size", "0.02")
    return b, hub


def _probe(hub: Path, pythonpath: Path | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath is not None:
        env["PYTHONPATH"] = str(pythonpath)
    proc = subprocess.run([sys.executable, str(PROBE), str(hub)], capture_output=True,
                          text=True, env=env)  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-4000:]
    return json.loads(proc.stdout.splitlines()[-1])


def _expected(hub: Path) -> dict[str, dict[str, str]]:
    """config -> split -> the digest of its rows as the shards hold them (pyarrow)."""
    sys.path.insert(0, str(PROBE.parent))
    try:
        import hub_client_probe as probe
    finally:
        sys.path.remove(str(PROBE.parent))
    out: dict[str, dict[str, str]] = {}
    for config, splits in probe.configs(str(hub)).items():
        for split, files in splits.items():
            rows = [r for f in files for r in pq.read_table(f).to_pylist()]
            out.setdefault(config, {})[split] = probe.row_digest(rows)
    return out


@pytest.mark.parametrize("which", ["oldest", "newest"])
def test_every_documented_route_loads_every_config_with_the_allowed_datasets(shake_hub, which):
    """load_dataset(HUB, config) (whole and streamed: the card the export wrote),
    load_dataset("parquet", data_files=...) and Dataset.from_parquet give each config's
    rows exactly as the shards hold them, with the oldest and the newest `datasets` the
    hub extra allows (the venv's is the newest: requirements.lock)."""
    _, hub = shake_hub
    req = _allowed()
    if which == "oldest":
        version = _oldest(req)
        path: Path | None = _datasets_dir(version)
    else:
        version, path = md.version("datasets"), None
        assert req.specifier.contains(version), f"the venv's datasets {version} is not {req}"
    got = _probe(hub, path)
    assert Version(got["version"]) == Version(version)
    want = _expected(hub)
    assert set(want) == {"sharp", "blur_1", "blur_2", "defocus_1", "shake_1", "rolling_shutter_3"}
    for route, configs in got["routes"].items():
        assert configs == want, f"{route} with datasets {got['version']}"


def test_the_export_writes_its_card_and_a_rerun_leaves_it(shake_hub, tmp_path):
    """HUB/README.md is `blurset card BUILD --hub HUB`'s card; an up-to-date rerun does not
    touch it; a README the user edited is kept, and the line says how to replace it."""
    b, hub = shake_hub
    card = hub / "README.md"
    text = card.read_text()
    assert 'config_name: "shake_1"' in text and "default: true" in text
    other = tmp_path / "other"
    shutil.copytree(hub, other)
    (other / "README.md").unlink()
    run_cli("card", str(b), "--hub", str(other))
    assert (other / "README.md").read_text() == text
    before = card.stat().st_mtime_ns
    run_cli("export", str(b), "--for", "hub", "--out", str(hub), "--shard-size", "0.02")
    assert card.stat().st_mtime_ns == before
    (other / "README.md").write_text(text + "\nMy notes.\n")
    proc = run_cli("export", str(b), "--for", "hub", "--out", str(other), "--shard-size", "0.02")
    assert (other / "README.md").read_text() == text + "\nMy notes.\n"
    assert "README.md" in proc.stderr and "--force" in proc.stderr


def test_a_shake_row_carries_its_levels_numbers(shake_hub):
    """A shake row has latents, samples, mean_c2w and its amplitude and path, from the
    level's meta.json record; a blur row has no shake numbers."""
    b, hub = shake_hub
    doc = json.loads((hub / "export.json").read_text())
    seen = 0
    for name, rec in doc["shards"].items():
        if rec["config"] not in ("shake_1", "blur_1"):
            continue
        for row in pq.read_table(hub / "data" / name).to_pylist():
            meta = json.loads((b / row["setting"] / "meta.json").read_text())
            if row["held_out"] or row["level"] == "blur_1":
                assert row["amplitude_px"] is None and row["path_px"] is None
                assert row["mean_c2w"] is not None  # (a held-out view's: the written pose)
                continue
            sh = meta["views"][row["view"]]["shake"]["1"]
            assert row["amplitude_px"] == sh["amplitude_px"]
            assert row["path_px"] == sh["path_px"]
            assert row["latents"] == len(sh["poses"]) and sh["method"] == "average"
            assert row["samples"] == sh["samples_per_frame"] * len(sh["seeds"])
            assert row["mean_c2w"] == row["c2w"]  # the path averages to zero
            seen += 1
    assert seen > 0


def test_every_row_says_its_samples(shake_hub):
    """Defocus and rolling shutter images render at the sharp image's samples (one
    render, or bands that tile the image): their rows say so, as blur and shake rows say
    theirs; no row of a fixed-count build leaves its samples empty."""
    b, hub = shake_hub
    doc = json.loads((hub / "export.json").read_text())
    kinds = set()
    for name, rec in doc["shards"].items():
        for row in pq.read_table(hub / "data" / name).to_pylist():
            assert row["samples"] is not None, (rec["config"], row["view"])
            if rec["config"].startswith(("defocus_", "rolling_shutter_")):
                meta = json.loads((b / row["setting"] / "meta.json").read_text())
                assert row["samples"] == meta["render"]["sharp_samples"]
                kinds.add(rec["config"])
    assert kinds == {"defocus_1", "rolling_shutter_3"}


def test_the_probes_digest_sees_every_image_byte(shake_hub, tmp_path):
    """The check above can fail: one image byte changed changes its config's digest."""
    _, hub = shake_hub
    want = _expected(hub)
    copy = tmp_path / "hub"
    shutil.copytree(hub, copy)
    doc = json.loads((copy / "export.json").read_text())
    name = next(n for n, r in doc["shards"].items() if r["config"] == "shake_1")
    t = pq.read_table(copy / "data" / name)
    rows = t.to_pylist()
    img = rows[0]["image"]
    img["bytes"] = img["bytes"][:-1] + bytes([img["bytes"][-1] ^ 1])
    pq.write_table(type(t).from_pylist(rows, schema=t.schema), copy / "data" / name)
    got = _expected(copy)
    assert got["shake_1"] != want["shake_1"] and got["blur_1"] == want["blur_1"]


def test_a_card_made_with_other_options_survives_an_up_to_date_rerun(shake_hub, tmp_path):
    """`blurset card --hub --pretty-name` replaces the export's card (blurset's own file);
    an export rerun that changes no shard leaves that card as it is."""
    b, hub = shake_hub
    other = tmp_path / "named"
    shutil.copytree(hub, other)
    run_cli("card", str(b), "--hub", str(other), "--pretty-name", "My blur set")
    named = (other / "README.md").read_text()
    assert "My blur set" in named
    proc = run_cli("export", str(b), "--for", "hub", "--out", str(other), "--shard-size", "0.02")
    assert "up to date" in proc.stdout
    assert (other / "README.md").read_text() == named
