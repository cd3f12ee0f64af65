import subprocess
import sys
from pathlib import Path

import numpy as np

from specgen_addon.brdf.formats.merl import MERLData, write_merl

REPO = Path(__file__).resolve().parents[2]


def _run(*args):
    return subprocess.run([sys.executable, "-m", "specgen_addon", *args], cwd=REPO,
                          capture_output=True, text=True, timeout=600)


def test_help_lists_commands():
    res = _run("--help")
    assert res.returncode == 0
    for cmd in ("info", "tabulate"):
        assert cmd in res.stdout


def test_info_prints_merl_metadata(tmp_path):
    p = write_merl(tmp_path / "m.binary", MERLData(np.ones((3, 90, 90, 180))))
    res = _run("info", str(p))
    assert res.returncode == 0 and "merl" in res.stdout


def test_info_json_of_a_spectral_table_lists_its_wavelengths_and_their_range(tmp_path, ramp_table):
    import json

    ramp_table.save(tmp_path / "t.npz")
    res = _run("info", "--json", str(tmp_path / "t.npz"))
    info = json.loads(res.stdout)
    assert info["wavelengths_nm"] == [float(w) for w in ramp_table.wavelengths]   # every band, in nm
    assert info["bands"] == len(ramp_table.wavelengths) and info["wavelength_range_nm"] == [380.0, 780.0]


def test_tabulate_merl_writes_table_and_refuses_overwrite(tmp_path):
    p = write_merl(tmp_path / "m.binary", MERLData(np.ones((3, 90, 90, 180))))
    out = tmp_path / "t.npz"
    assert _run("tabulate", str(p), "-o", str(out), "--quiet").returncode == 0
    assert out.is_file()
    res = _run("tabulate", str(p), "-o", str(out), "--quiet")
    assert res.returncode != 0 and "exists" in res.stderr


def test_bad_file_gives_one_line_error_and_nonzero_exit(tmp_path):
    bad = tmp_path / "broken.binary"
    bad.write_bytes(b"\x00" * 40)
    res = _run("tabulate", str(bad), "-o", str(tmp_path / "o.npz"), "--quiet")
    assert res.returncode == 2
    assert res.stderr.strip().count("\n") == 0 and "broken.binary" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "o.npz").exists()
