"""The seeded ablation study's statistics and its command's up-front checks."""

from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from specgen_addon.evaluation.ablation_study import format_markdown, paired_effect, summarise, wilcoxon_p


def test_paired_effect_is_the_mean_and_sample_std_of_per_seed_differences():
    e = paired_effect([30.0, 31.0, 33.0], [29.0, 29.5, 30.0])
    d = np.array([1.0, 1.5, 3.0])
    assert e["mean"] == pytest.approx(d.mean())
    assert e["std"] == pytest.approx(d.std(ddof=1))
    assert e["se"] == pytest.approx(d.std(ddof=1) / math.sqrt(3))
    assert e["sign"] == "positive"


def test_paired_effect_reports_the_median_and_how_often_the_first_arm_is_ahead():
    e = paired_effect([30.0, 28.0, 29.0, 25.0], [29.0, 28.5, 28.9, 30.0])  # differences 1, −0.5, 0.1, −5
    assert e["median"] == pytest.approx(-0.2)
    assert e["ahead"] == 2 and e["n"] == 4
    assert "| -0.20 | 2 of 4 |" in format_markdown({"steps": 1, "seeds": [0, 1, 2, 3], "by_arm": {},
                                                     "effects": {"x": e}})


def test_an_effect_within_two_standard_errors_is_not_called():
    e = paired_effect([30.0, 31.0, 29.0], [30.5, 30.0, 29.2])
    assert e["sign"].startswith("not resolved")
    assert paired_effect([20.0, 21.0, 20.5], [25.0, 26.0, 25.2])["sign"] == "negative"


def test_a_higher_sign_bar_leaves_an_effect_the_two_standard_error_rule_would_call_unresolved():
    d = np.array([1.0, 0.2, 1.5, -0.3, 0.9, 1.1, -0.4, 0.8])  # mean / SE ≈ 2.7
    z = d.mean() / (d.std(ddof=1) / math.sqrt(d.size))
    assert 2.36 < z < 3.0
    assert paired_effect(d, np.zeros_like(d))["sign"] == "positive"
    strict = paired_effect(d, np.zeros_like(d), sign_bar=3.0)
    assert strict["sign"] == "not resolved (mean within 3 standard errors of zero)"
    assert strict["passes_two_se"] and strict["z"] == pytest.approx(z)


def _wilcoxon_p_by_enumeration(d):
    """Exact two-sided signed-rank p by enumerating every sign pattern (no ties, no zeros)."""
    import itertools

    ranks = np.argsort(np.argsort(np.abs(d))) + 1.0
    w_plus = ranks[d > 0].sum()
    null = np.array([ranks[list(signs)].sum() for signs in itertools.product([False, True], repeat=d.size)])
    centre = ranks.sum() / 2
    return float(np.mean(np.abs(null - centre) >= abs(w_plus - centre) - 1e-9))


def test_the_wilcoxon_p_value_matches_an_exact_enumeration_of_sign_patterns():
    d = np.array([1.27, 0.21, 4.91, -1.45, -0.83, 2.05, 2.73, -1.92, 0.18, -1.38])
    assert wilcoxon_p(d) == pytest.approx(_wilcoxon_p_by_enumeration(d), abs=1e-12)
    assert wilcoxon_p(np.array([1.0, 2.0, 3.0, 4.0, 5.0, 6.0])) == pytest.approx(2 / 64)
    assert math.isnan(wilcoxon_p(np.array([0.0, 0.0, 1.0])))


def test_a_few_large_differences_carry_the_mean_but_not_the_signed_rank_test():
    d = np.array([6.0, 5.0, 0.2, -0.3, 0.1, -0.2, 0.3, -0.1, 0.25, -0.15])
    e = paired_effect(d, np.zeros_like(d), sign_bar=1.0)
    assert e["sign"] == "positive" and e["wilcoxon_p"] > 0.2


def test_the_summary_counts_each_arms_failed_runs_under_the_threshold():
    recs = [{"arm": a, "seed": s, "psnr_distant": v} for a, s, v in [
        ("joint-aff", 0, 27.0), ("joint-aff", 1, 26.5), ("joint-hadamard", 0, 23.4), ("joint-hadamard", 1, 28.0)]]
    s = summarise(recs, failure_below=26.0)
    assert s["by_arm"]["joint-aff"]["failures"]["seeds"] == []
    assert s["by_arm"]["joint-hadamard"]["failures"] == {"below_db": 26.0, "seeds": [0]}
    text = format_markdown({"seeds": [0, 1], **s})
    assert "Failed runs (under 26 dB): joint-aff 0 of 2; joint-hadamard 1 of 2 (seeds 0)." in text
    assert "failures" not in summarise(recs)["by_arm"]["joint-aff"]


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
    (["--sign-bar", "0.5"], "--sign-bar must be between"),
    (["--failure-below", "nan"], "--failure-below must be between"),
])
def test_ablate_refuses_bad_arguments_before_any_work(args, needle, tmp_path):
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "ablate", *args], capture_output=True, text=True,
                       cwd=tmp_path, env={"PYTHONPATH": str(__import__("pathlib").Path(__file__).resolve().parents[2]),
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
    marked = plot_study({"steps": 10, "seeds": [0, 1, 2], **summarise(recs, failure_below=29.5)}, tmp_path / "g.png")
    assert marked.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_figure_titles_write_consecutive_seeds_as_ranges():
    from specgen_addon.evaluation.ablation_study import seed_ranges

    assert seed_ranges([5, 6, 7, 8, 9, 10, 11, 13]) == "5–11, 13"
    assert seed_ranges([19, 5, 6, 5]) == "5–6, 19"
    assert seed_ranges([3]) == "3"


def _records_file(path, steps, recs):
    import json

    path.write_text(json.dumps({"steps": steps, "records": [
        {"arm": a, "seed": s, "psnr_distant": v} for a, s, v in recs]}), encoding="utf-8")
    return path


def test_pooled_records_keep_every_seed_and_recompute_the_paired_effect(tmp_path):
    from specgen_addon.evaluation.ablation_study import load_records, pool_records

    earlier = load_records(_records_file(tmp_path / "old.json", 3000, [
        ("joint-aff", 0, 28.27), ("joint-hadamard", 0, 26.40), ("joint-aff", 1, 28.03), ("joint-hadamard", 1, 27.96)]),
        3000)
    new = [{"arm": "joint-aff", "seed": 0, "psnr_distant": 28.2712},  # a retrained arm: agrees to the table's 0.01
           {"arm": "joint-aff", "seed": 5, "psnr_distant": 29.0}, {"arm": "joint-hadamard", "seed": 5, "psnr_distant": 28.0}]
    pooled = pool_records(new, earlier)
    assert [(r["arm"], r["seed"]) for r in pooled] == [
        ("joint-aff", 0), ("joint-hadamard", 0), ("joint-aff", 1), ("joint-hadamard", 1),
        ("joint-aff", 5), ("joint-hadamard", 5)]
    assert pooled[0]["psnr_distant"] == 28.2712  # this run's figure is kept
    e = summarise(pooled)["effects"]["AFF − Hadamard (joint training)"]
    d = np.array([28.2712 - 26.40, 28.03 - 27.96, 1.0])
    assert e["n"] == 3 and e["mean"] == pytest.approx(d.mean()) and e["std"] == pytest.approx(d.std(ddof=1))


def test_pooling_refuses_a_retrained_arm_that_disagrees_with_its_earlier_score(tmp_path):
    from specgen_addon.common.errors import SpecGenError
    from specgen_addon.evaluation.ablation_study import pool_records

    with pytest.raises(SpecGenError, match="joint-aff seed 0 scores 28.300 dB now but 28.270"):
        pool_records([{"arm": "joint-aff", "seed": 0, "psnr_distant": 28.30}],
                     [{"arm": "joint-aff", "seed": 0, "psnr_distant": 28.27}])


@pytest.mark.parametrize("content, needle", [
    ('{"steps": 3000, "records": []}', "trained 3000 steps, this study 4000"),
    ('{"steps": 4000}', "has no list of 'records'"),
    ('{"steps": 4000, "records": [{"arm": "nope", "seed": 0, "psnr_distant": 1.0}]}', "unknown arm"),
    ('{"steps": 4000, "records": [{"arm": "joint-aff"}]}', "lacks an arm, a seed or a psnr_distant"),
    ("not json", "not a readable JSON file"),
])
def test_ablate_refuses_bad_records_files_before_any_work(content, needle, tmp_path):
    (tmp_path / "r.json").write_text(content, encoding="utf-8")
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "ablate", "--steps", "4000", "--with-records", "r.json",
                        "--out", "study.md"], capture_output=True, text=True, cwd=tmp_path,
                       env={"PYTHONPATH": str(__import__("pathlib").Path(__file__).resolve().parents[2]),
                            "PATH": "/usr/bin:/bin"})
    assert r.returncode == 2
    assert needle in r.stderr and "Traceback" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_arms_cached_before_newer_config_fields_keep_their_keys():
    """Fields added to the configs later, at their defaults, leave an arm's cache key unchanged.

    The keys are those a recorded study holds (lab/runs/ablation_3000_six_knots.json), so the
    documented command still finds its trained arms instead of training them again."""
    import json
    from pathlib import Path

    from specgen_addon.evaluation.ablation import ARMS_BY_NAME, ablation_settings

    doc = Path(__file__).resolve().parents[2] / "lab" / "runs" / "ablation_3000_six_knots.json"
    records = json.loads(doc.read_text())["records"]
    settings = ablation_settings(steps=3000, log=lambda m: None)
    for r in (records[0], records[-1]):
        assert settings.key(ARMS_BY_NAME[r["arm"]], r["seed"]) == r["key"]


def test_a_newer_config_field_away_from_its_default_changes_the_key():
    import dataclasses

    from specgen_addon.evaluation.ablation import ARMS_BY_NAME, ablation_settings

    settings = ablation_settings(steps=3000, log=lambda m: None)
    leaky = dataclasses.replace(settings, model={**settings.model, "encoder_negative_slope": 0.01})
    arm = ARMS_BY_NAME["joint-aff"]
    assert leaky.key(arm, 5) != settings.key(arm, 5)


def test_a_one_seed_study_prints_dashes_where_the_spread_is_undefined():
    recs = [{"arm": "joint-aff", "seed": 7, "psnr_distant": 29.4}, {"arm": "joint-hadamard", "seed": 7,
                                                                      "psnr_distant": 26.25}]
    text = format_markdown({"seeds": [7], **summarise(recs)})
    assert "nan" not in text
    assert "| joint-aff | 29.40 | 29.40 |" in text
    assert "| AFF − Hadamard (joint training) | +3.15 | — |" in text


def test_a_single_stratum_reduces_to_the_one_sample_t_interval():
    from scipy import stats

    from specgen_addon.evaluation.ablation_study import stratified_effect

    d = [0.23, -0.4, 1.1, 0.7]
    r = stratified_effect({"all": (1.0, d)})
    se = np.std(d, ddof=1) / math.sqrt(4)
    assert r["estimate"] == pytest.approx(np.mean(d)) and r["se"] == pytest.approx(se)
    assert r["df"] == pytest.approx(3.0)
    assert r["ci95"] == pytest.approx(list(stats.t.interval(0.95, 3, loc=np.mean(d), scale=se)))


def test_the_stratified_estimate_weighs_each_stratum_by_its_share_hand_computed():
    """Shares 1/4 and 3/4; strata [1, 2, 3] (mean 2, s 1) and [0, 0, 3, 1] (mean 1, s √2):
    d̂ = 0.5 + 0.75, SE² = (1/16)·1/3 + (9/16)·2/4, ν = SE⁴ / (v₁²/2 + v₂²/3)."""
    from specgen_addon.evaluation.ablation_study import stratified_effect

    r = stratified_effect({"fail": (0.25, [1, 2, 3]), "ctrl": (0.75, [0, 0, 3, 1])})
    v1, v2 = 1 / 48, 9 / 32
    assert r["estimate"] == pytest.approx(1.25)
    assert r["se"] == pytest.approx(math.sqrt(v1 + v2))
    assert r["df"] == pytest.approx((v1 + v2) ** 2 / (v1 ** 2 / 2 + v2 ** 2 / 3))
    assert r["sign"] == "positive"  # 1.25 ≥ 2 × 0.55
    from scipy.stats import t

    half = t.ppf(0.975, r["df"]) * r["se"]  # ν ≈ 3.4: wider than 2 SE, reported, deciding nothing
    assert r["ci95"] == pytest.approx([1.25 - half, 1.25 + half]) and half > 2 * r["se"]
    assert r["strata"]["ctrl"]["std"] == pytest.approx(math.sqrt(2))


def test_the_stratified_estimate_waits_for_three_seeds_in_every_stratum_and_checks_shares():
    from specgen_addon.evaluation.ablation_study import stratified_effect

    r = stratified_effect({"fail": (5 / 23, [1.3, 3.2, 1.4]), "ctrl": (18 / 23, [0.2, 0.1])})
    assert math.isnan(r["estimate"]) and r["sign"].startswith("not computed")
    with pytest.raises(ValueError, match="sum to 1"):
        stratified_effect({"a": (0.5, [1, 2, 3]), "b": (0.6, [1, 2, 3])})
