"""batch.py leaves what the user asked for: the spectral EXR and its preview, each printed with its
size; the baked lookups stay only with ``--keep-lookups``, reported with their total size."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]


def _lambert(path: Path) -> Path:
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable

    rho = np.array([0.2, 0.5, 0.7])

    def f(th, td, pd):
        wi, wo = io_from_half_diff(th, td, pd)
        return np.where(((wi[:, 2] > 0) & (wo[:, 2] > 0))[:, None], rho[None] / np.pi, 0.0)

    BRDFTable.tabulate(f, np.array([450.0, 550.0, 650.0])).save(path, compact=True)
    return path


@pytest.mark.slow
@pytest.mark.blender
def test_batch_keeps_only_the_renders_unless_asked_to_keep_the_lookups(tmp_path):
    table = _lambert(tmp_path / "lambert.npz")
    out = tmp_path / "out"
    args = [sys.executable, str(REPO / "batch.py"), "--brdf", str(table), "--env", "studio", "--out", str(out),
            "--bands", "3", "--wl-min", "450", "--wl-max", "650", "--resolution", "16", "--samples", "1"]
    done = subprocess.run(args, capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert sorted(p.name for p in out.iterdir()) == ["lambert_sphere_studio.exr",
                                                     "lambert_sphere_studio_preview.png"]
    for name in ("lambert_sphere_studio.exr", "lambert_sphere_studio_preview.png"):
        assert re.search(rf"wrote .*{re.escape(name)} \(\d+\.\d (kB|MB)\)", done.stdout), done.stdout
    kept = subprocess.run([*args, "--overwrite", "--keep-lookups"], capture_output=True, text=True,
                          timeout=300, check=False)
    assert kept.returncode == 0, kept.stderr[-2000:]
    lookups = sorted(p.name for p in (out / "lookup").iterdir())
    assert "env_studio.exr" in lookups and any(n.startswith("lambert_lookup.g") for n in lookups)
    assert re.search(rf"kept {len(lookups)} lookup files in .*lookup \(\d+\.\d (kB|MB)\)", kept.stdout), kept.stdout
    # again over the kept set: the rewritten files are counted as this run's, and a group file of
    # the replaced set that this run does not write (an earlier, larger basis) is removed
    (out / "lookup" / "lambert_lookup.g07.exr").write_bytes(b"an earlier run's extra group")
    again = subprocess.run([*args, "--overwrite", "--keep-lookups"], capture_output=True, text=True,
                           timeout=300, check=False)
    assert again.returncode == 0, again.stderr[-2000:]
    assert sorted(p.name for p in (out / "lookup").iterdir()) == lookups
    assert re.search(rf"kept {len(lookups)} lookup files in .*lookup \(\d+\.\d (kB|MB)\)", again.stdout), \
        again.stdout
    assert not [p for p in out.rglob(".*")], "hidden copies of the replaced files were left"
