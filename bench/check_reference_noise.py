"""Check the reference-noise correction of bench_settings_per_hour on one model: build one
preset, render its render reference at K = 32 (two halves of 16 on two seed sets) and
print, per image kind, the render PSNR as measured against that reference and with the
reference's own noise taken out. Compared with the same preset's K = 8 entry of a
settings_per_hour run (whose corrected scores this should match), it shows what the
correction does; not part of `make bench` (≈ 40 min for a model at 512 px on 2 cores).

    BLURSET_BENCH_SPH_RES=512 .venv/bin/python bench/check_reference_noise.py \\
        floor512_wide_oidn ../shared/data/glb/sketchfab_MazdaRX7Stylised.glb
"""

from __future__ import annotations

import importlib.util
import json
import os
import sys
import tempfile
from pathlib import Path

import numpy as np

os.environ.setdefault("BLURSET_BENCH_REF_CAP", "1000000")  # K = 32, uncapped
HERE = Path(__file__).resolve().parent
_spec = importlib.util.spec_from_file_location("sph", HERE / "bench_settings_per_hour.py")
assert _spec is not None and _spec.loader is not None  # a .py file: always a spec and a loader
sph = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(sph)
from sph_references import denoised_mse, render_reference  # noqa: E402


def main(preset_name: str, glb: Path) -> dict:
    from blurset.image import image_error, read_exr

    preset = sph.PRESETS[preset_name]
    with tempfile.TemporaryDirectory(prefix="blurset-refnoise-") as tmp:
        work = Path(tmp)
        built = sph._build(work / "b", glb, preset)
        plain = {k: v for k, v in preset.items() if k != "denoise"}
        ref, k, noise = render_reference(
            sph._config, glb, work, sph.RES, plain, built["samples"], True
        )
        mse: dict[str, list[float]] = {}
        for (view, level), r in ref.items():
            img = np.ascontiguousarray(
                read_exr(built["setting"] / level / "linear" / f"{view:03d}.exr")
            )
            kind = "sharp" if level == "sharp" else "blur"
            e = image_error(img, r).mse
            mse.setdefault(f"{kind}_measured", []).append(e)
            mse.setdefault(f"{kind}_corrected", []).append(denoised_mse(e, noise[(view, level)]))
            mse.setdefault(f"{kind}_reference_noise", []).append(noise[(view, level)])
    return {
        "preset": preset_name,
        "object": glb.stem,
        "resolution": sph.RES,
        "reference_factor": k,
        **{f"render_psnr_{key}_db": sph._db(float(np.mean(v))) for key, v in mse.items()},
    }


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit("usage: check_reference_noise.py PRESET MODEL.glb")
    json.dump(main(sys.argv[1], Path(sys.argv[2])), sys.stdout, indent=1)
    print()
