"""One extension zip per platform, made by Blender's own builder: each carries the onnxruntime
wheel of its platform (the last Intel-mac release where the newest has none), names that
platform alone, and passes Blender's validator; the Intel-mac release loads the shipped graphs."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
from script_modules import load_script

REPO = Path(__file__).resolve().parents[2]
BUILD = REPO / "scripts" / "build_extension.py"
build_extension = load_script("scripts/build_extension.py")

#: Platform → (wheel platform tag start, onnxruntime version) every zip must carry.
EXPECTED = {"windows-x64": ("win_amd64", "1.31.1"), "macos-arm64": ("macosx_14_0_arm64", "1.31.1"),
            "macos-x64": ("macosx_13_0_x86_64", "1.23.2"), "linux-x64": ("manylinux_2_28_x86_64", "1.31.1")}
ZIP_LIMIT_BYTES = 60 * 2**20


def _run_builder(*args: str) -> subprocess.CompletedProcess:
    done = subprocess.run([sys.executable, str(BUILD), *args], capture_output=True, text=True, timeout=600, check=False)
    if done.returncode != 0 and "pip" in done.stdout + done.stderr and "download" in done.stdout + done.stderr:
        pytest.skip(f"the platform wheels could not be fetched: {done.stderr.strip()[-300:]}")
    assert done.returncode == 0, done.stdout + done.stderr
    return done


@pytest.fixture(scope="module")
def platform_zips(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("dist")
    done = _run_builder("--fetch-wheels", "--out-dir", str(out))
    zips = {p: out / f"specgen-0.1.0-{p.replace('-', '_')}.zip" for p in EXPECTED}
    for z in zips.values():
        assert f"wrote {z}" in done.stdout
    return zips


def test_the_manifest_lists_every_platform_with_one_wheel_each():
    manifest = tomllib.loads((REPO / "blender_manifest.toml").read_text())
    assert sorted(manifest["platforms"]) == sorted(EXPECTED)
    assert sorted(build_extension.wheel_platform(w) for w in manifest["wheels"]) == sorted(EXPECTED)


@pytest.mark.slow
@pytest.mark.parametrize("platform", sorted(EXPECTED))
def test_each_platform_zip_carries_its_own_wheel_and_passes_blenders_validator(platform, platform_zips):
    zip_path = platform_zips[platform]
    tag, version = EXPECTED[platform]
    with zipfile.ZipFile(zip_path) as zf:
        names = zf.namelist()
        manifest = tomllib.loads(zf.read("blender_manifest.toml").decode())
    wheels = [n for n in names if n.endswith(".whl")]
    assert len(wheels) == 1, wheels
    assert wheels[0].startswith(f"wheels/onnxruntime-{version}-cp311-") and tag in wheels[0]
    assert manifest["build"]["generated"]["platforms"] == [platform]
    assert manifest["build"]["generated"]["wheels"] == [f"./{wheels[0]}"]
    assert "weights/specgen_default.tables.onnx" in names and "specgen_addon/__init__.py" in names
    assert not any(n.startswith(("tests/", "bench/", "docs/", ".git")) or n.endswith(".pt") for n in names)
    assert zip_path.stat().st_size <= ZIP_LIMIT_BYTES
    validate = build_extension.blender_ext_command(None) + ["validate", str(zip_path)]
    done = subprocess.run(validate, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0 and "Success" in done.stdout, done.stdout + done.stderr


@pytest.mark.slow
def test_the_intel_mac_onnxruntime_release_runs_the_shipped_graphs_like_the_newest(tmp_path):
    """The macos-x64 zip carries onnxruntime 1.23.2: the same release for Linux loads every shipped
    graph and gives the newest release's outputs (the graphs' IR and opset stay within its reach)."""
    ort = pytest.importorskip("onnxruntime")
    dl = subprocess.run([sys.executable, "-m", "pip", "download", "onnxruntime==1.23.2", "--only-binary=:all:",
                         "--no-deps", "--python-version", "3.11", "--platform", "manylinux_2_27_x86_64",
                         "--platform", "manylinux_2_28_x86_64", "-d", str(tmp_path)],
                        capture_output=True, text=True, timeout=300, check=False)
    wheel = next(tmp_path.glob("onnxruntime-1.23.2-*.whl"), None)
    if dl.returncode != 0 or wheel is None:
        pytest.skip(f"onnxruntime 1.23.2 could not be fetched: {dl.stderr.strip()[-300:]}")
    site = tmp_path / "site"
    with zipfile.ZipFile(wheel) as zf:
        zf.extractall(site)
    script = (
        "import sys, numpy as np, onnxruntime as ort\n"
        f"sys.path.insert(0, {str(REPO)!r})\n"
        "from specgen_addon.model.runtime.inference import generate_brdf\n"
        "t = generate_brdf(sys.argv[1], backend='onnx', wavelengths_nm=[450.0, 550.0, 650.0])\n"
        "np.save(sys.argv[2], t.values)\n"
        "print(ort.__version__)\n")
    results = {}
    for name, extra in (("old", str(site)), ("new", "")):
        env = {**os.environ, "PYTHONPATH": extra}
        done = subprocess.run([sys.executable, "-c", script, str(REPO / "examples" / "sphere.png"),
                               str(tmp_path / f"{name}.npy")], capture_output=True, text=True, timeout=600, env=env, check=False)
        assert done.returncode == 0, done.stderr[-2000:]
        results[name] = (done.stdout.split()[-1], np.load(tmp_path / f"{name}.npy"))
    assert results["old"][0] == "1.23.2" and results["new"][0] == ort.__version__
    np.testing.assert_allclose(results["old"][1], results["new"][1], rtol=1e-4, atol=1e-6)
