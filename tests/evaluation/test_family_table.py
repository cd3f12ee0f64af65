"""bench/family_table.py: per-family means, standard errors and counts under the floor of merged
evaluate results, against numpy and scipy."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from script_modules import load_script

family_table = load_script("bench/family_table.py")


def write(path: Path, rows: list[tuple[str, str, float]]) -> Path:
    data = [{"material": m, "family": f, "kind": "x", "psnr_distant": v} for m, f, v in rows]
    data.append({"material": "real", "family": "rgl (real, RGB)", "kind": "measured", "psnr_distant": 10.0})
    path.write_text(json.dumps({"by_family": {"materials": data}}))
    return path


def test_merged_halves_give_each_familys_mean_error_and_count_under_the_floor(tmp_path, capsys):
    stats = pytest.importorskip("scipy.stats")
    rng = np.random.default_rng(0)
    sheen = 28 + 8 * rng.random(9)
    lobes = 30 + 6 * rng.random(7)
    a = write(tmp_path / "a.json", [(f"s{i}", "sheen", float(v)) for i, v in enumerate(sheen)])
    b = write(tmp_path / "b.json", [(f"l{i}", "lobes", float(v)) for i, v in enumerate(lobes)])
    assert family_table.main([str(a), str(b)]) == 0
    lines = {ln.split()[0]: ln.split() for ln in capsys.readouterr().out.splitlines()[1:]}
    assert set(lines) == {"lobes", "sheen", "all"}                  # the measured RGL row is left out
    for name, vals in (("sheen", sheen), ("lobes", lobes), ("all", np.r_[lobes, sheen])):
        n, mean, se, under = lines[name][1:]
        assert int(n) == vals.size and float(mean) == pytest.approx(vals.mean(), abs=0.005)
        assert float(se) == pytest.approx(stats.sem(vals), abs=0.005)
        assert int(under) == int((vals < 32).sum())


def test_a_material_in_two_files_or_a_missing_file_is_refused(tmp_path):
    a = write(tmp_path / "a.json", [("m0", "sheen", 31.0), ("m1", "sheen", 33.0)])
    for argv in ([str(a), str(a)], [str(tmp_path / "missing.json")]):
        with pytest.raises(SystemExit) as e:
            family_table.main(argv)
        assert e.value.code == 2
