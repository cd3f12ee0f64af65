"""lab/studies/ablation_strata.py: strata from the short study, paired differences from the long ones."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "lab" / "studies" / "ablation_strata.py"


def _study(path: Path, steps: int, scores: dict[int, tuple[float, float]]) -> Path:
    recs = [{"arm": arm, "seed": seed, "psnr_distant": v} for seed, pair in scores.items()
            for arm, v in zip(("joint-aff", "joint-hadamard"), pair)]
    path.write_text(json.dumps({"steps": steps, "records": recs}))
    return path


def _run(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(SCRIPT), *argv], capture_output=True, text=True, cwd=REPO)


def test_strata_come_from_the_short_study_and_shares_weigh_the_long_differences(tmp_path):
    # short: seeds 1-2 failed (Hadamard under 26), 3-8 did not: shares 2/8 and 6/8
    short = {1: (28, 23), 2: (28, 24), **{s: (28, 27.5) for s in range(3, 9)}}
    long_a = {1: (30, 28), 2: (30, 27), 3: (29, 29)}      # failure diffs 2, 3
    long_b = {4: (29, 28.5), 5: (29, 29.5)}               # control diffs 0, 0.5, -0.5
    out = tmp_path / "r.json"
    r = _run("--short", str(_study(tmp_path / "s.json", 3000, short)), "--failure-below", "26",
             "--long", str(_study(tmp_path / "a.json", 6000, long_a)), str(_study(tmp_path / "b.json", 6000, long_b)),
             "--json", str(out))
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert res["strata_of_seeds"]["1"] == "failure" and res["strata_of_seeds"]["3"] == "control"
    assert res["strata"]["failure"]["share"] == pytest.approx(2 / 8)
    assert res["strata"]["control"]["n"] == 3
    # the failure stratum has two seeds, so the plan's estimate waits
    assert res["sign"].startswith("not computed") and "failure 2" in res["sign"]
    r = _run("--short", str(tmp_path / "s.json"), "--failure-below", "26", "--long", str(tmp_path / "a.json"),
             str(tmp_path / "b.json"), str(_study(tmp_path / "c.json", 6000, {6: (29, 28), 7: (31, 28)})),
             "--json", str(out))
    assert r.returncode == 0, r.stderr
    res = json.loads(out.read_text())
    assert res["strata"]["failure"]["n"] == 2  # seed 7 did not fail at the short budget: control
    assert res["strata"]["control"]["n"] == 5


def test_a_long_seed_missing_from_the_short_study_or_a_mixed_budget_is_refused(tmp_path):
    short = _study(tmp_path / "s.json", 3000, {1: (28, 23), 2: (28, 27)})
    r = _run("--short", str(short), "--failure-below", "26", "--long",
             str(_study(tmp_path / "a.json", 6000, {9: (29, 28)})))
    assert r.returncode != 0 and "not in the short study" in r.stderr and "Traceback" not in r.stderr
    r = _run("--short", str(short), "--failure-below", "26", "--long",
             str(_study(tmp_path / "a.json", 6000, {1: (29, 28)})), str(_study(tmp_path / "b.json", 5000, {2: (1, 1)})))
    assert r.returncode != 0 and "5000 steps" in r.stderr and "Traceback" not in r.stderr
