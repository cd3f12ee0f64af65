"""The seeded ablation study's statistics and its command's up-front checks."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from specgen_addon.evaluation.ablation_study import format_markdown, paired_effect, summarise


def test_paired_effect_is_the_mean_and_sample_std_of_per_seed_differences():
    e = paired_effect([30.0, 31.0, 33.0], [29.0, 29.5, 30.0])
    d = np.array([1.0, 1.5, 3.0])
    assert e["mean"] == pytest.approx(d.mean())
    assert e["std"] == pytest.approx(d.std(ddof=1))
    assert e["se"] == pytest.approx(d.std(ddof=1) / math.sqrt(3))
    assert e["sign"] == "positive"


def test_an_effect_within_two_standard_errors_is_not_called():
    e = paired_effect([30.0, 31.0, 29.0], [30.5, 30.0, 29.2])
    assert e["sign"].startswith("not resolved")
    assert paired_effect([20.0, 21.0, 20.5], [25.0, 26.0, 25.2])["sign"] == "negative"


def test_summary_pairs_arms_by_seed_and_reports_both_effects():
    recs = [{"arm": a, "seed": s, "psnr_distant": v} for a, s, v in [
        ("joint-aff", 0, 30.0), ("joint-aff", 1, 31.0), ("joint-aff", 2, 32.0),
        ("joint-hadamard", 0, 29.0), ("joint-hadamard", 1, 30.0), ("joint-hadamard", 2, 31.5),
        ("spectral-aff", 0, 30.5), ("spectral-aff", 2, 32.5)]]  # seed 1 missing: pairs on 0 and 2
    s = summarise(recs)
    assert s["by_arm"]["joint-aff"]["mean"] == pytest.approx(31.0)
    assert s["by_arm"]["joint-aff"]["std"] == pytest.approx(1.0)
    fusion = s["effects"]["AFF − Hadamard (joint training)"]
    assert fusion["mean"] == pytest.approx((1.0 + 1.0 + 0.5) / 3)
    data = s["effects"]["joint − spectral-only (AFF)"]
    assert data["n"] == 2 and data["mean"] == pytest.approx(-0.5)
    text = format_markdown({"seeds": [0, 1, 2], **s})
    assert "| spectral-aff | 30.50 | — | 32.50 |" in text
    assert "+0.83 ± 0.29" in text


@pytest.mark.parametrize("args, needle", [
    (["--seeds", "1", "1"], "--seeds must be distinct"),
    (["--arms", "nope"], "unknown arm 'nope'"),
    (["--steps", "0"], "--steps must be between"),
    (["--workers", "0"], "--workers must be between"),
])
def test_ablate_refuses_bad_arguments_before_any_work(args, needle, tmp_path):
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "ablate", *args], capture_output=True, text=True,
                       cwd=tmp_path, env={"PYTHONPATH": str(__import__("pathlib").Path(__file__).resolve().parents[1]),
                                          "PATH": "/usr/bin:/bin"})
    assert r.returncode == 2
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert list(tmp_path.iterdir()) == []


def test_the_study_figure_is_a_png(tmp_path):
    from specgen_addon.evaluation.ablation_study import plot_study

    recs = [{"arm": a, "seed": s, "psnr_distant": 28.0 + s + (a == "joint-aff")} for a in ("joint-aff", "spectral-aff")
            for s in (0, 1, 2)]
    out = plot_study({"steps": 10, "seeds": [0, 1, 2], **summarise(recs)}, tmp_path / "f.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
