"""bench/paired_families.py: the paired difference of two evaluate runs, against numpy and scipy."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

SPEC = importlib.util.spec_from_file_location("paired_families",
                                              Path(__file__).resolve().parents[2] / "bench" / "paired_families.py")
paired_families = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(paired_families)


def write(path: Path, scores: dict[str, float], rgl: float) -> Path:
    rows = [{"material": m, "family": "sheen" if m.startswith("s") else "classic", "kind": "x",
             "psnr_distant": v} for m, v in scores.items()]
    rows.append({"material": "real", "family": "rgl (real, RGB)", "kind": "measured", "psnr_distant": rgl})
    path.write_text(json.dumps({"by_family": {"materials": rows}}))
    return path


def test_the_paired_difference_and_its_standard_error_match_scipy(tmp_path):
    stats = pytest.importorskip("scipy.stats")
    rng = np.random.default_rng(0)
    base = {f"{'sc'[i % 2]}{i}": float(v) for i, v in enumerate(30 + 5 * rng.random(12))}
    cand = {k: v + float(d) for (k, v), d in zip(base.items(), 0.2 + 0.3 * rng.standard_normal(12))}
    a = paired_families.synthetic_scores(write(tmp_path / "a.json", base, 19.0), "distant")
    b = paired_families.synthetic_scores(write(tmp_path / "b.json", cand, 99.0), "distant")
    assert len(a) == 12                                           # the measured row is left out
    s = paired_families.paired(a, b)
    d = np.array([cand[k] - base[k] for k in sorted(base)])
    assert s["diff"] == pytest.approx(d.mean()) and s["se"] == pytest.approx(stats.sem(d))
    assert s["ratio"] == pytest.approx(stats.ttest_rel(list(b.values()), list(a.values())).statistic)
    assert s["better"] == int((d > 0).sum())


def test_files_without_rows_or_shared_materials_are_refused(tmp_path):
    (tmp_path / "empty.json").write_text(json.dumps({"means": {}}))
    with pytest.raises(SystemExit, match="no per-material rows"):
        paired_families.synthetic_scores(tmp_path / "empty.json", "distant")
    with pytest.raises(SystemExit, match="in common"):
        paired_families.paired({("a", "x"): 1.0, ("a", "y"): 2.0}, {("a", "z"): 1.0})


def test_halves_of_a_whole_split_pair_like_one_file(tmp_path, capsys):
    rng = np.random.default_rng(1)
    base = {f"{'sc'[i % 2]}{i}": float(v) for i, v in enumerate(30 + 5 * rng.random(10))}
    cand = {k: v + 0.1 * (i % 3) for i, (k, v) in enumerate(base.items())}
    half = lambda d, lo, hi: dict(list(d.items())[lo:hi])  # noqa: E731
    whole = [str(write(tmp_path / "b.json", base, 1.0)), str(write(tmp_path / "c.json", cand, 1.0))]
    assert paired_families.main(whole) == 0
    one = capsys.readouterr().out
    halves = [str(write(tmp_path / "b1.json", half(base, 0, 4), 1.0)), str(write(tmp_path / "c1.json", half(cand, 0, 4), 1.0)),
              "--also-baseline", str(write(tmp_path / "b2.json", half(base, 4, 10), 1.0)),
              "--also-candidate", str(write(tmp_path / "c2.json", half(cand, 4, 10), 1.0))]
    assert paired_families.main(halves) == 0
    assert capsys.readouterr().out == one and "10 materials" in one
