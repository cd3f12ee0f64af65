"""batch.py as Blender runs it: ``blender --background --python batch.py -- ARGS``.

Blender hands the script its whole command line in ``sys.argv``; the script's own arguments are the
ones after ``--``. The test runs batch.py's ``__main__`` with exactly that argv (the bpy module
stands in for the Blender binary, which is not available here) and checks that Blender's own log
lines stay out of stdout unless ``--verbose``.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("bpy")

REPO = Path(__file__).resolve().parents[2]
RUN_AS_BLENDER = (
    "import runpy, sys\n"
    "sys.argv = ['blender', '--background', '--python', sys.argv[1], '--', *sys.argv[2:]]\n"
    "runpy.run_path(sys.argv[3], run_name='__main__')\n")


def _table(path: Path) -> Path:
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable

    rho = np.array([0.2, 0.5, 0.7])

    def f(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return np.where(((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None], rho[None] / np.pi, 0.0)

    BRDFTable.tabulate(f, np.array([450.0, 550.0, 650.0])).save(path)
    return path


@pytest.mark.slow
def test_batch_under_blender_argv_renders_and_keeps_blender_logs_out_of_stdout(tmp_path):
    table = _table(tmp_path / "lambert.npz")
    args = ["--brdf", str(table), "--env", "studio", "--out", str(tmp_path / "out"), "--bands", "3",
            "--wl-min", "450", "--wl-max", "650", "--resolution", "16", "--samples", "1"]
    done = subprocess.run([sys.executable, "-c", RUN_AS_BLENDER, str(REPO / "batch.py"), *args],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "out" / "lambert_sphere_studio.exr").is_file()
    assert "Saved:" not in done.stdout, done.stdout
    assert done.stdout.strip().splitlines()[-2].startswith("wrote ")
    verbose = subprocess.run([sys.executable, "-c", RUN_AS_BLENDER, str(REPO / "batch.py"), *args,
                              "--overwrite", "--verbose"], capture_output=True, text=True, timeout=300)
    assert verbose.returncode == 0, verbose.stderr[-2000:]
    assert "Saved:" in verbose.stdout


def test_batch_under_blender_argv_reports_bad_input_in_one_line(tmp_path):
    done = subprocess.run([sys.executable, "-c", RUN_AS_BLENDER, str(REPO / "batch.py"), "--image",
                           str(tmp_path / "missing.png"), "--out", str(tmp_path / "o")],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2
    lines = [l for l in done.stderr.splitlines() if l.strip()]
    assert len(lines) == 1 and "not found" in lines[0], done.stderr
