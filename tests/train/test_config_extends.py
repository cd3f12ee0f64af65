"""A training config may name a base (``"extends"``) and state only what changes."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from specgen_addon.train.config_schema import read_config_dict
from specgen_addon.train.loop import validate_train_config
from specgen_addon.common.errors import SpecGenError
from specgen_addon.train.loop import load_config

BASE = {"model": {"spectral_code_knots": 6},
        "train": {"seed": 1, "steps": 100, "lr": 1e-4, "families": {"classic": 0.5, "sheen": 0.5}}}


def _write(path: Path, data: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(data))
    return path


def test_a_continuation_overrides_only_the_keys_it_names(tmp_path):
    _write(tmp_path / "base.json", BASE)
    child = _write(tmp_path / "child.json", {"extends": "base.json", "train": {"seed": 7, "steps": 50}})
    mcfg, tcfg = load_config(child)
    assert (tcfg.seed, tcfg.steps, tcfg.lr) == (7, 50, 1e-4)
    assert mcfg.spectral_code_knots == 6                      # the section it did not name is kept
    assert "extends" not in read_config_dict(child)


def test_an_object_value_replaces_the_bases_whole_object(tmp_path):
    _write(tmp_path / "base.json", BASE)
    child = _write(tmp_path / "child.json", {"extends": "base.json", "train": {"families": {"lobes": 1.0}}})
    assert read_config_dict(child)["train"]["families"] == {"lobes": 1.0}   # not merged with classic, sheen


def test_bases_chain_and_the_nearest_file_wins(tmp_path):
    _write(tmp_path / "a.json", BASE)
    _write(tmp_path / "b.json", {"extends": "a.json", "train": {"seed": 2, "lr": 5e-5}})
    c = _write(tmp_path / "c.json", {"extends": "b.json", "train": {"seed": 3}})
    _, tcfg = load_config(c)
    assert (tcfg.seed, tcfg.lr, tcfg.steps) == (3, 5e-5, 100)


def test_a_relative_init_weights_is_taken_against_the_file_that_names_it(tmp_path):
    weights = tmp_path / "weights" / "w.pt"
    weights.parent.mkdir()
    weights.write_bytes(b"")
    _write(tmp_path / "configs" / "base.json",
           {**BASE, "train": {**BASE["train"], "init_weights": "../weights/w.pt"}})
    child = _write(tmp_path / "elsewhere" / "deeper" / "child.json",
                   {"extends": "../../configs/base.json", "train": {"seed": 9}})
    assert Path(read_config_dict(child)["train"]["init_weights"]) == weights.resolve()


@pytest.mark.parametrize("files, match", [
    ({"child.json": {"extends": "gone.json"}}, "extends gone.json: config file not found"),
    ({"child.json": {"extends": 3}}, "extends must be the path of a base config file"),
    ({"child.json": {"extends": "b.json"}, "b.json": {"extends": "child.json"}},
     r"makes a cycle \(child.json → b.json → child.json\)"),
    ({"child.json": {"extends": "child.json"}}, "makes a cycle"),
    ({"child.json": {"extends": "base.json", "train": {"stepz": 3}}, "base.json": BASE}, "stepz"),
    ({"child.json": {"extends": "base.json", "train": {"steps": "ten"}}, "base.json": BASE}, "whole number"),
])
def test_a_bad_extends_is_refused_in_one_sentence(tmp_path, files, match):
    for name, data in files.items():
        _write(tmp_path / name, data)
    with pytest.raises(SpecGenError, match=match):
        validate_train_config(tmp_path / "child.json")


def test_an_overlong_chain_is_refused(tmp_path):
    _write(tmp_path / "c0.json", BASE)
    for i in range(1, 20):
        _write(tmp_path / f"c{i}.json", {"extends": f"c{i - 1}.json"})
    with pytest.raises(SpecGenError, match="longer than 16"):
        read_config_dict(tmp_path / "c19.json")


def test_the_shipped_recipe_is_one_flat_config(repo_dir):
    path = repo_dir / "configs" / "shipped.json"
    assert "extends" not in json.loads(path.read_text())
    data = read_config_dict(path)
    assert data["train"]["material_balance"] == "log" and data["train"]["balance_floor"] == 0.03


def test_the_cli_refuses_a_missing_base_before_any_work(tmp_path, repo_dir):
    child = _write(tmp_path / "child.json", {"extends": "nowhere.json"})
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "train", "--config", str(child),
                        "--out", str(tmp_path / "run")], capture_output=True, text=True, timeout=120, cwd=repo_dir)
    assert r.returncode != 0
    assert "extends nowhere.json: config file not found" in r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "run").exists()


def test_show_config_prints_the_resolved_configuration_and_exits(repo_dir, tmp_path):
    child = _write(tmp_path / "child.json", {"extends": str(repo_dir / "configs" / "shipped.json"),
                                              "train": {"seed": 7}})
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "train", "--show-config", "--config",
                        str(child), "--steps", "12"],
                       capture_output=True, text=True, timeout=120, cwd=repo_dir)
    assert r.returncode == 0, r.stderr
    shown = json.loads(r.stdout)
    assert shown["train"]["seed"] == 7 and shown["train"]["steps"] == 12            # file, then --steps
    assert shown["train"]["balance_floor"] == 0.03                                   # from the base
    assert shown["train"]["lr_decay_every"] == 4000
    assert Path(shown["train"]["init_weights"]) == (repo_dir / "weights" / "specgen_default.pt").resolve()
    assert shown["model"]["spectral_code_knots"] == 6 and "feature_dim" in shown["model"]  # defaults filled
    assert "extends" not in shown


def test_train_without_out_asks_for_it_in_one_sentence(repo_dir):
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "train"], capture_output=True, text=True,
                       timeout=120, cwd=repo_dir)
    assert r.returncode != 0 and "train needs --out" in r.stderr and "Traceback" not in r.stderr
