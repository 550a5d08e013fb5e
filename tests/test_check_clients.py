"""scripts/check_clients.py, the blurset side: it finds the build an export links into,
knows a sharp copy by its bytes, and judges what a client read (the client side needs
the clients' code and torch, and runs by hand: docs/training/index.md). Here the
client's reads are written as a client would make them, on a stand-in build."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_cli, standin_build

SCRIPT = ROOT / "scripts" / "check_clients.py"


@pytest.fixture(scope="module")
def cc():
    spec = importlib.util.spec_from_file_location("check_clients", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    sys.modules["check_clients"] = mod
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def geonerf_export(tmp_path_factory, standin_blender):
    tmp = tmp_path_factory.mktemp("cc")
    out = tmp / "b"
    standin_build(out, standin_blender, "--views", "17")
    run_cli("export", str(out), "--out", str(tmp / "g"), "--for", "geonerf")
    return out, tmp / "g"


def _result(root: Path, draw) -> dict:
    """What a GeoNeRF child reports: every test scene read, one target each."""
    scenes, draws = [], []
    for d in sorted((root / "geonerf" / "test").iterdir()):
        files = sorted(str(p) for p in (d / "images_4").iterdir())
        scenes.append({"dir": str(d), "images": 8, "poses": 8, "shape": [16, 16, 3],
                       "focal": 1.0, "held_out": [0]})  # fmt: skip
        target, sources = draw(files)
        draws.append({"dir": str(d), "target": target, "sources": sources, "target_index": 0})
    phase = {"name": "val", "draws": draws,
             "expect": {"targets_sharp": True, "sources_sharp": False}}  # fmt: skip
    return {"python": "py", "versions": [], "ran": ["x"], "scenes": scenes, "phases": [phase]}


def test_the_build_is_found_from_the_links_and_sharp_copies_are_told(cc, geonerf_export):
    build, root = geonerf_export
    doc = json.loads((root / "export.json").read_text())
    assert cc._find_build(root, doc) == build.resolve()
    # GeoNeRF with nb_views 6: the 6 nearest of the 7 degraded views, the target first.
    report, status = cc.analyse(
        "geonerf", root, doc, build, _result(root, lambda f: (f[0], f[1:7]))
    )
    assert status == 0 and "verdict: ok" in report, report
    assert "0 of them a sharp copy (expected none: ok)" in report
    n = sum(1 for k in doc["scenes"] if k.startswith("test/") and "__sharp" not in k)
    assert f"{n} targets, {n} of them sharp (expected {n}: ok)" in report
    # With nb_views 9 the target comes back among the sources: a sharp copy.
    report, status = cc.analyse(
        "geonerf", root, doc, build, _result(root, lambda f: (f[0], [*f[1:7], f[0]]))
    )
    assert status == 1 and "verdict: FAILED" in report, report
    assert f"{n * 7} sources, {n} of them a sharp copy" in report
    assert "the target itself is among the sources" in report


def test_a_client_given_the_wrong_export_or_failing_says_so(cc, geonerf_export, tmp_path, capsys):
    _, root = geonerf_export
    args = ["--checkout", str(tmp_path), "--python", sys.executable]
    assert cc.main(["ibrnet", str(root), *args]) == 2
    assert "reads an export --for llff" in capsys.readouterr().err
    # An empty checkout: the client's modules do not import, and the error is shown.
    assert cc.main(["geonerf", str(root), *args]) == 2
    assert "ModuleNotFoundError" in capsys.readouterr().out


def test_a_relative_python_and_checkout_are_the_ones_the_user_named(
    cc, geonerf_export, tmp_path, capsys, monkeypatch
):
    """The docs' form, `--python env/bin/python --checkout GeoNeRF` from the folder
    holding both: the child runs inside the checkout, where those relative paths would
    name nothing; the client's own code is reached (here an empty checkout, so its
    import fails and says so)."""
    _, root = geonerf_export
    (tmp_path / "env" / "bin").mkdir(parents=True)
    (tmp_path / "env" / "bin" / "python").symlink_to(sys.executable)
    (tmp_path / "GeoNeRF").mkdir()
    monkeypatch.chdir(tmp_path)
    args = ["--checkout", "GeoNeRF", "--python", "env/bin/python"]
    assert cc.main(["geonerf", str(root), *args]) == 2
    out = capsys.readouterr()
    assert "ModuleNotFoundError" in out.out, out


def test_json_never_replaces_a_file_it_did_not_write(cc, tmp_path, capsys):
    # Refused before anything runs (no export, checkout or Python is looked at): one line
    # naming --json and the file, its bytes unchanged; its own earlier report may go.
    mine = tmp_path / "meta.json"
    mine.write_text('{"build": "not a client report"}')
    before = mine.read_bytes()
    args = ["geonerf", str(tmp_path / "none"), "--checkout", str(tmp_path), "--python", "x"]
    assert cc.main([*args, "--json", str(mine)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--json" in err[0] and str(mine) in err[0], err
    assert mine.read_bytes() == before
    assert cc.main([*args, "--json", str(tmp_path)]) == 2  # a folder
    own = tmp_path / "read.json"
    own.write_text(
        json.dumps({"python": "py", "versions": [], "ran": [], "scenes": [], "phases": []})
    )
    capsys.readouterr()
    assert cc.main([*args, "--json", str(own)]) == 2  # past the claim: the export is absent
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert "export.json" in line and str(tmp_path / "none") in line, line


# -- the IBRNet/GNT noise recipe: blur + noise scenes in a second root ---------------------

# A stand-in of IBRNet's checkout, for CI (which has neither IBRNet nor torch): its
# reading rules as llff_test.py has them (every folder of <rootdir>/data/nerf_llff_data/
# a scene, images_4/, i_test = arange(N)[::llffhold], sources from the other views), and
# torch and imageio as far as check_clients uses them. The real loader's run is on the
# IBRNet page (docs/training/ibrnet.md).
FAKE_IBRNET = {
    "config.py": """
import argparse
def config_parser():
    p = argparse.ArgumentParser()
    for o in ("--config", "--rootdir", "--train_dataset", "--eval_dataset"):
        p.add_argument(o)
    p.add_argument("--train_scenes", nargs="+", default=[])
    p.add_argument("--eval_scenes", nargs="+", default=[])
    p.add_argument("--llffhold", type=int, default=8)
    p.add_argument("--num_source_views", type=int, default=4)
    return p
""",
    "torch.py": "__version__ = 'stand-in'\ndef manual_seed(i): pass\n",
    "imageio.py": """
import numpy as np
from PIL import Image
__version__ = 'stand-in'
def imread(path):
    return np.asarray(Image.open(path))
""",
    "ibrnet/__init__.py": "",
    "ibrnet/data_loaders/__init__.py": "",
    "ibrnet/data_loaders/llff_data_utils.py": """
import os
import numpy as np
def load_llff_data(basedir, load_imgs=False, factor=4):
    rows = np.load(os.path.join(basedir, 'poses_bounds.npy'))
    d = os.path.join(basedir, 'images_{}'.format(factor))
    files = [os.path.join(d, f) for f in sorted(os.listdir(d))]
    return None, rows[:, :15].reshape(-1, 3, 5), rows[:, 15:], None, None, files
def batch_parse_llff_poses(poses):
    intr = np.zeros((len(poses), 4, 4))
    intr[:, 0, 0] = poses[:, 2, 4] / 4
    return intr, poses
""",
    "ibrnet/data_loaders/llff_test.py": """
import os
import numpy as np
import imageio
from .llff_data_utils import load_llff_data
class LLFFTestDataset:
    def __init__(self, args, mode, scenes=()):
        root = os.path.join(args.rootdir, 'data/nerf_llff_data/')
        self.render_rgb_files, self.sources = [], []
        for scene in scenes or os.listdir(root):
            _, _, _, _, _, files = load_llff_data(os.path.join(root, scene), factor=4)
            test = list(range(len(files)))[::args.llffhold]
            train = [f for i, f in enumerate(files) if i not in test]
            render = train if mode == 'train' else [files[i] for i in test]
            self.render_rgb_files += render
            self.sources += [[f for f in train if f != r][:args.num_source_views]
                             for r in render]
    def __getitem__(self, i):
        rgb = imageio.imread(self.render_rgb_files[i])
        src = np.stack([imageio.imread(f) for f in self.sources[i]])
        return {'rgb': rgb, 'src_rgbs': src}
""",
}


def test_the_ibrnet_noise_recipe_reads_noisy_scenes_from_a_second_root(
    cc, tmp_path, standin_blender, capsys
):
    """The docs' recipe: the clean export in ROOT/data, the blur + noise export in a
    second root ROOTN/data, read with --rootdir ROOTN. IBRNet's dataset (here its
    stand-in) reads the gain scenes only, every image it draws noisy but the clean
    held-out targets; a noise-free image among them fails the check; an export beside
    ROOT/data, which --rootdir ROOT never reads, is refused by name."""
    b, noise = tmp_path / "b", tmp_path / "n"
    standin_build(b, standin_blender, "--views", "17")
    run_cli("noise", str(b), "--out", str(noise), "--gains", "4", "--levels", "blur_1",
            "--quiet")  # fmt: skip
    run_cli("export", str(b), "--out", str(tmp_path / "root" / "data"), "--levels", "blur_1")
    rootn = tmp_path / "rootn" / "data"
    run_cli("export", str(b), "--noise", str(noise), "--out", str(rootn))
    checkout = tmp_path / "IBRNet"
    for rel, text in FAKE_IBRNET.items():
        (checkout / rel).parent.mkdir(parents=True, exist_ok=True)
        (checkout / rel).write_text(text.lstrip())
    args = ["--checkout", str(checkout), "--python", sys.executable, "--build", str(b)]
    read = tmp_path / "read.json"
    assert cc.main(["ibrnet", str(rootn), *args, "--json", str(read)]) == 0, capsys.readouterr()
    out = capsys.readouterr().out
    assert f"rootdir {rootn.parent}" in out and "verdict: ok" in out, out
    n = len(json.loads((rootn / "export.json").read_text())["scenes"])
    dirs = {s["dir"] for s in json.loads(read.read_text())["scenes"]}
    assert len(dirs) == n and all(d.endswith("__blur_1__gain_4") for d in dirs), dirs
    assert all(Path(d).parent == rootn / "nerf_llff_data" for d in dirs), dirs
    # Validation (the held-out targets stay clean), then training: every image noisy.
    val, train = [line for line in out.splitlines() if "gain scenes:" in line]
    assert "sources, 0 of them noise-free (sources expected 0: ok)" in val, val
    assert "targets, 0 of them noise-free;" in train and "sources, 0 of them noise-free" in train
    assert "(targets expected 0: ok) (sources expected 0: ok)" in train, train
    # A source with the bytes of the build's own (noise-free) image: FAILED.
    setting = json.loads((b / "splits.json").read_text())["train"][0]
    noisy = sorted((noise / setting / "blur_1" / "gain_4" / "images_4").glob("*.png"))[1]
    clean = sorted((b / setting / "blur_1" / "images_4").glob("*.png"))[1]
    noisy.write_bytes(clean.read_bytes())
    assert cc.main(["ibrnet", str(rootn), *args]) == 1
    out = capsys.readouterr().out
    assert "verdict: FAILED" in out and "noise-free sources" in out, out
    # The noise beside the clean export (ROOT/data_noisy): IBRNet never reads it.
    beside = tmp_path / "root" / "data_noisy"
    run_cli("export", str(b), "--noise", str(noise), "--out", str(beside))
    assert cc.main(["ibrnet", str(beside), *args]) == 2
    err = capsys.readouterr().err
    assert "never read" in err and "ROOTN/data" in err and "--rootdir ROOTN" in err, err


# -- the client pages' commands, in the environments docs/training/index.md builds -----

TRAINING = ROOT / "docs" / "training"
CLIENT_PACKAGE = {"nerfstudio": "nerfstudio"}  # a client checked as an installed package


def _sh_lines(page: Path) -> list[str]:
    """Every command of the page's ```sh blocks, continuation lines joined."""
    import re

    lines = []
    for block in re.findall(r"```sh\n(.*?)```", page.read_text(), flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                lines.append(" ".join(line.split()))
    return lines


def _environments() -> dict[str, list[str]]:
    """The client environments index.md's recipe makes: path → what pip installs in it."""
    envs: dict[str, list[str]] = {}
    for line in _sh_lines(TRAINING / "index.md"):
        words = line.split()
        if words[1:3] == ["-m", "venv"]:
            envs[words[3]] = []
        elif len(words) > 2 and words[0].endswith("/bin/pip") and words[1] == "install":
            env = words[0].removesuffix("/bin/pip")
            assert env in envs, f"pip of {env}, which the recipe does not make"
            envs[env] += [w.strip('"') for w in words[2:]]
    return envs


def test_every_client_environment_pins_numpy_below_2():
    """Each pip install resolves on its own: one without the pin takes numpy 2, which the
    clients' binary dependencies (torch, OpenCV as Deblur-NeRF imports them) were not
    built against, also in an environment stacked on another's site-packages."""
    envs = _environments()
    assert {"clients/venv", "clients/venv-ns"} <= set(envs), envs
    for line in _sh_lines(TRAINING / "index.md"):
        if "/bin/pip install" in line:
            assert '"numpy<2"' in line, line


def test_the_client_pages_check_commands_run_in_environments_the_recipe_makes():
    """Every `check_clients.py` command of a client page names a --python the recipe
    makes, and a --checkout inside an environment's site-packages only where that
    environment installs the client (nerfstudio from PyPI)."""
    envs = _environments()
    commands = [
        (page, line.split())
        for page in sorted(TRAINING.glob("*.md"))
        for line in _sh_lines(page)
        if "scripts/check_clients.py" in line and page.name != "index.md"
    ]
    assert len(commands) >= 6, commands
    for page, words in commands:
        client = words[words.index("scripts/check_clients.py") + 1]
        python = words[words.index("--python") + 1]
        env = python.removesuffix("/bin/python")
        assert env in envs, (page.name, python)
        checkout = words[words.index("--checkout") + 1]
        if "/site-packages" in checkout:
            assert checkout == f"{env}/lib/python3.11/site-packages", (page.name, checkout)
            pkg = CLIENT_PACKAGE[client]
            assert any(w.split("=")[0].split("<")[0] == pkg for w in envs[env]), (
                page.name,
                f"{env} does not install {pkg}",
            )


def test_the_deblur_nerf_config_is_the_one_checked_and_runs_alone(cc):
    """docs/training/deblur-nerf.md's config is what check_clients feeds Deblur-NeRF's
    parser, and holds what run_nerf.py needs to train from it alone: its parser's
    required options (basedir, datadir, tbdir) and a kernel_type train() builds."""
    import re

    text = (TRAINING / "deblur-nerf.md").read_text()
    blocks = re.findall(r"```text\n(.*?)```", text, flags=re.S)
    scene = "<setting>__blur_4"
    want = cc.DEBLUR_NERF_CONFIG.format(
        scene=scene, root="ROOT", datadir=f"ROOT/data/nerf_llff_data/{scene}", llffhold=16
    )
    assert want in blocks, blocks[:1]
    keys = dict(line.split(" = ", 1) for line in want.splitlines())
    assert {"basedir", "datadir", "tbdir", "expname"} <= set(keys)
    assert keys["kernel_type"] in ("deformablesparsekernel", "none")
    assert f"python run_nerf.py --config {scene}.txt" in text
