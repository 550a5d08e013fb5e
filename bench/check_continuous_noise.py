"""How much of the continuous reference's detail energy is its own render noise, at 512 px
(bench_target_speed's reference: frames 0.5 px apart sharing 1,024 samples)?

The bench's reference of the panel's view 0 (same seeds) and a second one on other seeds,
levels 1 and 4: the noise of their mean is half either's, so the reference's noise-free
detail energy is E(signal) = 2 E(mean) - E(one), and `signal_share_of_ref` its share of
the reference's (1: no noise). A build's detail ratio against a reference whose share is
s reads about s where the build is noise-free: a ratio under 1 there is the reference's
noise, not texture smoothed away. Writes bench/check_continuous_noise.json (a few
minutes on 2 cores)."""

from __future__ import annotations

import json
import os
import sys
import tempfile
from pathlib import Path

os.environ["BLURSET_BENCH_SPEED_RES"] = "512"
os.environ["BLURSET_BENCH_SPEED_VIEWS"] = "1"
sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_target_speed as b  # noqa: E402
from blurset import image  # noqa: E402
from blurset.services.worker_client import Worker  # noqa: E402
from harness import plan_object, render_mean  # noqa: E402

HERE = Path(__file__).resolve().parent
GLB = HERE.parent.parent / "shared" / "data" / "glb" / "textured_panel_blender_reexport.glb"


def main() -> dict:
    out = {}
    with tempfile.TemporaryDirectory() as d:
        work = Path(d)
        cfg = b.continuous_config(GLB, work)
        with Worker(timeout=7200, workdir=work / "s", device="CPU") as w:
            plan = plan_object(cfg, GLB, w, work)
            for lvl in (1, 4):
                refs = []
                for salt in (b.CONT_SALT, 0x1234567):
                    frames = plan.level_renders(0, lvl, str(work / "c"))
                    for f in frames:
                        f["seed"] = (f["seed"] ^ salt) & 0x7FFFFFFF
                    refs.append(render_mean(w, frames, 1, b.RES, cfg.fov_deg))
                a, c = refs
                r_avg = image.image_error((a + c) / 2, a).detail_ratio  # E(mean) / E(one)
                out[lvl] = {
                    "E_avg_over_E_ref": round(r_avg, 4),
                    "signal_share_of_ref": round(2 * r_avg - 1, 4),
                    "ref_vs_ref_psnr": round(float(image.object_error(a, c).psnr), 2),
                }
    return out


if __name__ == "__main__":
    res = main()
    print(res)
    (HERE / "check_continuous_noise.json").write_text(json.dumps(res, indent=1) + "\n")
