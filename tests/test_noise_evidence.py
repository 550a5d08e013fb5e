"""The camera noise models' evidence and its page: bench/bench_noise_evidence.py (the
statistics read back through the binding), bench/bench_noise.py's model rows and figure
row, and docs/gen/noise_guide.py (the noise guide's generated tables). Statistics are
checked at small size against the model; no timing is asserted."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import bench_module as _bench
from tests.conftest import gen_module as _gen

ROOT = Path(__file__).resolve().parents[1]
BENCH = ROOT / "bench"
GEN = ROOT / "docs" / "gen"


@pytest.fixture(scope="module")
def ev():
    return _bench("bench_noise_evidence")


# --- the Tukey lambda distribution and the estimators -------------------------------


@pytest.mark.parametrize("lam", [-0.14, 0.0, 0.11, 1.0])
def test_tukey_variance_and_quantile_agree(ev, lam):
    u = np.random.default_rng(1).random(400_000)
    samples = ev.tukey_quantile(u, lam)
    assert np.var(samples) == pytest.approx(ev.tukey_variance(lam), rel=0.02)
    if lam == 1.0:  # Q(p) = 2p - 1: uniform on [-1, 1]
        assert ev.tukey_variance(lam) == pytest.approx(1 / 3)
    if lam == 0.0:  # the logistic
        assert ev.tukey_variance(lam) == pytest.approx(math.pi**2 / 3)


@pytest.mark.parametrize("lam", [-0.14, -0.03, 0.0, 0.11])
def test_fit_lambda_recovers_the_shape_of_tukey_samples(ev, lam):
    u = np.random.default_rng(2).random(300_000)
    fit, r = ev.fit_lambda(7.5 * ev.tukey_quantile(u, lam) + 3.0)
    assert fit == pytest.approx(lam, abs=0.01)
    assert r > 0.999
    # A normal is not a heavy-tailed Tukey: its lambda is near 0.14.
    normal, _ = ev.fit_lambda(np.random.default_rng(3).standard_normal(300_000))
    assert normal == pytest.approx(0.1349, abs=0.01)


def test_row_power_finds_a_planted_row_noise(ev):
    rng = np.random.default_rng(4)
    rows, width, sigma = 4000, 256, 1.5
    n = rng.normal(0, sigma, (rows, 1)) + rng.normal(0, 6.0, (rows, width))
    power, per_site = ev.row_power(n)
    assert power / sigma**2 == pytest.approx(1.0, abs=0.08)
    assert np.allclose(per_site.mean(axis=1), 0)
    # Without row noise, nothing: the read noise's share is taken out.
    none, _ = ev.row_power(rng.normal(0, 6.0, (rows, width)))
    assert abs(none) < 0.05 * sigma**2


def test_cfa_channel_is_rggb(ev):
    np.testing.assert_array_equal(ev.cfa_channel(2, 4), [[0, 1, 0, 1], [1, 2, 1, 2]])


# --- the statistics through the binding, at small size --------------------------------


def test_raw_noise_reads_back_whole_dn_and_the_clean_level(ev):
    """ELD's noisy raw comes back as whole DN (raw_noise asserts it) and the clean raw of
    a flat grey is level x (white - black) / white balance per CFA channel."""
    level = 0.2
    x, n, rec = ev.raw_noise("eld:SonyA7S2", ev.flat(64, level), 20.0)
    unit = rec["white_level_dn"] - rec["black_level_dn"]
    cfa = ev.cfa_channel(64, 64)
    for c in range(3):
        want = level * unit / rec["white_balance_gains"][c]
        assert x[cfa == c] == pytest.approx(want, rel=1e-5)
    assert np.abs(n).max() > 1


@pytest.mark.parametrize("model", ["unprocess", "eld:CanonEOS70D", "eld:NikonD850"])
def test_variance_per_cfa_channel_is_the_models(ev, monkeypatch, model):
    monkeypatch.setattr(ev, "VARIANCE_GAINS", (20.0,))
    rows = ev.variance_per_channel(model, size=256)
    assert len(rows) == len(ev.LEVELS) * 3
    for r in rows:
        assert r["ratio"] == pytest.approx(1.0, abs=0.05), r
    # The variance grows with the signal: shot noise.
    dark = [r["measured"] for r in rows if r["level"] == 0.0]
    bright = [r["measured"] for r in rows if r["level"] == 0.6]
    assert min(bright) > 2 * max(dark)


def test_dark_frames_carry_the_calibrated_row_power_and_lambda(ev):
    d = ev.dark_frame("eld:CanonEOS70D", 20.0, shape=(1024, 256), views=2)
    assert d["row_power_ratio"] == pytest.approx(1.0, abs=0.15)
    assert d["lambda_fit"] == pytest.approx(d["lambda_published"], abs=0.02)
    assert d["q_low_over_model"] == pytest.approx(1.0, abs=0.05)
    assert d["q_high_over_model"] == pytest.approx(1.0, abs=0.05)


def test_demosaicked_noise_is_correlated_and_the_papers_is_not(ev):
    paper = ev.correlation("paper")
    assert all(abs(v) < 0.02 for v in paper.values()), paper
    for model in ("unprocess", "eld:SonyA7S2"):
        c = ev.correlation(model)
        assert c["green_right_corr"] > 0.2 and c["green_down_corr"] > 0.2, c
        assert c["red_green_corr"] < -0.05, c


@pytest.mark.parametrize("model", ["paper", "unprocess", "eld:SonyA7S2"])
def test_black_saturated_and_largest_gain_stay_finite(ev, model):
    e = ev.extremes(model)
    assert e["all_finite"]
    assert len(e["cases"]) == len(ev.EXTREME_GAINS) * len(ev.EXTREME_LEVELS)
    if model.startswith("eld:"):
        # The raw clips at the white level: bounded whatever the gain.
        assert e["max_abs_linear"] < 10
        white = [c for c in e["cases"] if c["level"] >= 1.0 and c["gain"] == 1.0]
        assert all(c["png_min"] >= 250 for c in white), white


def test_an_evidence_row_names_its_model_and_fields(ev, monkeypatch):
    monkeypatch.setattr(ev, "VARIANCE_SIZE", 64)
    monkeypatch.setattr(ev, "DARK_SHAPE", (256, 64))
    monkeypatch.setattr(ev, "DARK_VIEWS", 1)
    row = ev.measure("eld:CanonEOS700D")
    assert row["name"] == "noise_evidence_eld_CanonEOS700D"
    assert row["ratio"] in (row["variance_ratio_min"], row["variance_ratio_max"])
    assert len(row["dark"]) == len(ev.DARK_GAINS)
    assert row["lambda_published_top"] == row["dark"][-1]["lambda_published"]
    json.dumps(row)  # a results row is JSON


# --- bench_noise: the models' rows and the figure's ------------------------------------


def test_model_rows_are_each_models_time_over_the_papers():
    bn = _bench("bench_noise")
    times = {"paper": [1.0, 2.0, 1.0], "eld:SonyA7S2": [3.0, 4.0, 3.5]}
    rows = {r["model"]: r for r in bn.model_rows(times, megapixels=0.5, images=2)}
    assert rows["paper"]["name"] == "noise_model_paper" and rows["paper"]["ratio"] == 1.0
    eld = rows["eld:SonyA7S2"]
    assert eld["name"] == "noise_model_eld_SonyA7S2"
    assert eld["s_per_megapixel"] == pytest.approx(7.0)
    assert eld["over_paper"] == pytest.approx(3.0)  # rounds: 3, 2, 3.5
    assert eld["over_paper_range"] == [2.0, 3.5]
    assert eld["over_paper_of_medians"] == pytest.approx(3.5)


@pytest.fixture(scope="module")
def crop_and_row():
    bn = _bench("bench_noise")
    y, x = np.mgrid[0:32, 0:32]
    crop = np.stack([x * 6 + 20, y * 5 + 40, 200 - x * 3], axis=-1).astype(np.uint8)
    return bn, crop, bn.figure_row(crop)


def test_figure_row_matches_the_noise_power_and_draws_from_results(crop_and_row, tmp_path):
    bn, crop, row = crop_and_row
    models = row["models"]
    assert [v["model"] for v in models.values()] == list(bn.FIGURE_MODELS)
    stds = [v["std"] for v in models.values()]
    assert max(stds) / min(stds) < 1.15 and row["ratio"] == max(stds) / min(stds)
    # The paper's residual is white; the camera models' is correlated and falls with
    # frequency (the demosaic's interpolation).
    assert abs(models["paper"]["neighbour_corr"]) < 0.2
    for key in ("unprocess", "eld_SonyA7S2"):
        assert models[key]["neighbour_corr"] > 0.2
        assert models[key]["power"][-1] < 0.5 * models[key]["power"][1]
    out = tmp_path / "fig.png"
    assert bn.draw_figure(row, crop, out) == []
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    # A row the code no longer makes is found.
    stale = json.loads(json.dumps(row))
    stale["models"]["eld_SonyA7S2"]["std"] += 0.5
    assert [s for s in bn.draw_figure(stale, crop, out) if s.startswith("eld:SonyA7S2")]


def test_radial_power_of_white_noise_is_its_variance():
    bn = _bench("bench_noise")
    res = np.random.default_rng(5).normal(0, 3.0, (128, 128, 3))
    f, power = bn.radial_power(res)
    assert f[0] > 0 and f[-1] < 0.5
    assert np.mean(power) == pytest.approx(9.0, rel=0.05)


# --- the guide's generated tables ---------------------------------------------------


def test_noise_guide_blocks_are_the_generated_ones():
    """docs/guide/noise.md's blocks are what noise_guide makes from bench/results.json
    (`make docs` rewrites them), and each row of the results shows there."""
    ng, figures = _gen("noise_guide"), _gen("figures")
    results = figures.load()
    text = ng.PAGE.read_text()
    assert ng.rewrite(text, results) == text, "stale noise guide tables: run make docs"
    names = [m["name"] for m in ng.BLOCK.finditer(text)]
    assert sorted(names) == sorted(ng.BLOCKS)
    for n, r in results.items():
        if n.startswith(("noise_model_", "noise_evidence_")):
            assert f"`{r['model']}`" in text and f"fig {n} " in text, n
    if ng.FIGURE_ROW in results:
        for v in results[ng.FIGURE_ROW]["models"].values():
            assert f"| `{v['model']}` |" in text
    # A hand edit of a block is found.
    edited = text.replace("| model | seconds per megapixel", "| model | s/MP", 1)
    assert edited != text and ng.rewrite(edited, results) == text


def test_noise_guide_blocks_without_results_say_how_to_measure():
    ng = _gen("noise_guide")
    page = (
        "a\n<!-- noise speed -->\nold\n<!-- /noise -->\n<!-- noise evidence -->\n<!-- /noise -->\n"
    )
    out = ng.rewrite(page, {})
    assert out.count("Not measured yet") == 2 and "old" not in out
    assert "bench/run.py bench_noise`" in out and "bench_noise_evidence" in out
    with pytest.raises(ValueError, match="no generator"):
        ng.rewrite("<!-- noise nosuch -->\n<!-- /noise -->", {})


def test_merge_into_results_replaces_its_own_rows_only(tmp_path, monkeypatch):
    harness = _bench("harness")
    monkeypatch.syspath_prepend(str(BENCH))  # harness names the machine through run.py
    out = tmp_path / "results.json"
    out.write_text(json.dumps([{"name": "a", "ratio": 1}, {"name": "b", "ratio": 2}]))
    harness.merge_into_results([{"name": "b", "ratio": 3}, {"name": "c", "ratio": 4}], out)
    rows = {r["name"]: r for r in json.loads(out.read_text())}
    assert [rows[n]["ratio"] for n in "abc"] == [1, 3, 4]
    assert "machine" not in rows["a"] and rows["c"]["machine"]


def test_interleaved_times_runs_every_thunk_each_round():
    harness = _bench("harness")
    calls: list[str] = []
    times = harness.interleaved_times({k: (lambda k=k: calls.append(k)) for k in "xyz"}, 3)
    assert calls == list("xyz") * 3
    assert {k: len(v) for k, v in times.items()} == {"x": 3, "y": 3, "z": 3}
