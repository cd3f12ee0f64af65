"""Every command says what it wrote and how big it is, and leaves only what was asked for: batch.py
whose render fails halfway leaves no ``lookup/`` folder (and keeps what was in its output folder
before); batch-many's items record their bytes and its summary says the total."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from specgen_addon.scale import items as items_mod
from specgen_addon.scale.batch_many import format_summary
from specgen_addon.scale.worker import PYTHON, run_item

REPO = Path(__file__).resolve().parents[2]

#: batch.py whose spectral render fails after its first step (as a Cycles crash would).
FAILING_RENDER = r"""
import importlib, sys
sys.path.insert(0, {repo!r})
import batch
render = importlib.import_module(batch.load_package().__name__ + ".ops.render")
steps = render.SpectralRenderJob.steps
def failing(self):
    for i, f in enumerate(steps(self)):
        if i == 1:
            raise RuntimeError("simulated render failure")
        yield f
render.SpectralRenderJob.steps = failing
sys.exit(batch.main(sys.argv[1:]))
"""

#: A batch.py stand-in that writes two outputs of known sizes.
FAKE_BATCH = """
import argparse, pathlib
ap = argparse.ArgumentParser()
ap.add_argument("--image"); ap.add_argument("--brdf"); ap.add_argument("--out")
ap.add_argument("--overwrite", action="store_true")
a = ap.parse_args()
out = pathlib.Path(a.out)
(out / "ball_sphere_studio.exr").write_bytes(b"x" * 250_000)
(out / "ball_sphere_studio_preview.png").write_bytes(b"x" * 50_000)
"""


def test_batch_many_records_each_items_bytes_and_its_summary_says_the_total(tmp_path):
    script = tmp_path / "fake_batch.py"
    script.write_text(FAKE_BATCH)
    (tmp_path / "in").mkdir()
    (tmp_path / "in" / "ball.png").write_bytes(b"x")
    out = tmp_path / "out"
    out.mkdir()
    [it] = items_mod.make_items([tmp_path / "in" / "ball.png"])
    rec = run_item(it.to_dict(), str(out), "r1", [PYTHON, str(script)], [], str(REPO), it.fingerprint([]))
    on_disk = sum(p.stat().st_size for p in (out / "ball").iterdir() if p.name != "item.json")
    assert rec["status"] == "done" and rec["bytes"] == on_disk >= 300_000
    report = {"out": str(out), "items": [rec], "counts": {"done": 1, "skipped": 0, "failed": 0},
              "wall_seconds": 1.0, "workers": 1}
    text = format_summary(report)
    assert f"wrote {len(rec['outputs'])} files in 1 item folders under {out} ({on_disk / 1e6:.1f} MB)" in text, text


@pytest.mark.slow
@pytest.mark.blender
def test_batch_py_whose_render_fails_halfway_leaves_no_lookup_folder(tmp_path):
    pytest.importorskip("bpy")
    from blend_reopen import small_table

    table = tmp_path / "ball.npz"
    small_table().save(table, compact=True)
    out = tmp_path / "out"
    out.mkdir()
    (out / "notes.txt").write_text("the user's")
    args = ["--brdf", str(table), "--env", "studio", "--out", str(out), "--bands", "3", "--wl-min", "450",
            "--wl-max", "650", "--resolution", "16", "--samples", "1"]
    done = subprocess.run([sys.executable, "-c", FAILING_RENDER.format(repo=str(REPO)), *args],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode != 0 and "simulated render failure" in done.stderr, done.stderr[-2000:]
    assert "Traceback" not in done.stderr
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]
    assert not re.search(r"^wrote ", done.stdout, re.MULTILINE)
