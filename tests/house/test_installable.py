"""The package installs as ``specgen`` and its command line runs from any folder."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from setuptools import find_packages

REPO = Path(__file__).resolve().parents[2]


def _clean_env() -> dict[str, str]:
    env = dict(os.environ)
    env.pop("PYTHONPATH", None)
    return env


def test_package_discovery_ships_the_core_and_nothing_else():
    cfg = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    found = set(find_packages(where=str(REPO), include=cfg["include"]))
    core = {".".join(p.parent.relative_to(REPO).parts) for p in (REPO / "specgen_addon").rglob("__init__.py")}
    assert found == core
    assert not {p.split(".")[0] for p in found} - {"specgen_addon"}


def test_module_help_runs_from_another_folder(tmp_path):
    if subprocess.run([sys.executable, "-c", "import specgen_addon"], cwd=tmp_path, env=_clean_env(),
                      capture_output=True).returncode:
        pytest.skip("specgen is not installed in this environment (scripts/setup.sh installs it)")
    r = subprocess.run([sys.executable, "-m", "specgen_addon", "--help"], cwd=tmp_path, env=_clean_env(),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "usage:" in r.stdout and "generate" in r.stdout


def test_console_script_help_runs_from_another_folder(tmp_path):
    script = Path(sys.executable).with_name("specgen")
    if not script.is_file():
        pytest.skip(f"no console script at {script} (scripts/setup.sh installs it)")
    r = subprocess.run([str(script), "--help"], cwd=tmp_path, env=_clean_env(),
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "usage:" in r.stdout and "generate" in r.stdout
