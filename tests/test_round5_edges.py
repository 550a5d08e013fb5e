"""Issue 60, the edges: a lock file that is a link is never followed, --workers-per-gpu
on a Ray cluster without GPUs is refused as the local executor refuses it, a GLB whose
vertex buffer holds NaN or Inf is that object's failure, and tradeoff's scratch folder
never takes a user's `work/`. Real commands; the builds are stand-in builds (no Blender
render)."""

from __future__ import annotations

import json

from blurset.services import outputs

from tests.conftest import run_cli

# -- tradeoff's scratch is its temp name, never a user's `work/` (a planted bug) ------------


def test_tradeoff_never_takes_a_users_work_folder_for_its_scratch(tmp_path):
    """A tradeoff folder of an earlier run may hold the user's own `work/notes.txt`: the
    run's scratch is `.work.tmp<pid>`, made and removed beside it, never `work/`."""
    glb = tmp_path / "obj.glb"
    glb.write_bytes(b"glTF")
    out = tmp_path / "out"
    (out / "work").mkdir(parents=True)
    (out / "work" / "notes.txt").write_text("keep")
    (out / outputs.TRADEOFF_RECORD).write_text(json.dumps({"kind": outputs.TRADEOFF_KIND}))
    # A Blender that does not exist: the run fails at the worker, after it has made its
    # scratch folder and the worker's log.
    proc = run_cli("tradeoff", "--object", str(glb), "--out", str(out), "--quick",
                   "--blender", str(tmp_path / "no-blender"), check=False)  # fmt: skip
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert "no-blender" in proc.stderr, proc.stderr  # it got as far as the worker
    assert (out / "work" / "notes.txt").read_text() == "keep"
    assert sorted(p.name for p in (out / "work").iterdir()) == ["notes.txt"]
    # The scratch it made (a failed run's, which the next run removes) is its own name.
    assert len(list(out.glob(".work.tmp*"))) == 1
