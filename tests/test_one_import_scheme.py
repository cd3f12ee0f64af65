"""One import scheme: a class of the core is the same object in every entry.

The CLI, batch.py, the Blender tier loaded as a package (tests, batch.py) and the installed
extension (``bl_ext.user_default.specgen``) all reach the core as the top-level ``specgen_addon``,
so a ``Cancelled`` raised on one side is caught by the other side's ``except``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from importlib import import_module
from pathlib import Path

import pytest

from specgen_addon import errors
from specgen_addon.cli import run_guarded
from specgen_addon.interrupts import EXIT_ERROR

REPO = Path(__file__).resolve().parents[1]


def _raise(exc: BaseException):
    raise exc


def test_batch_catches_a_cancel_raised_by_the_core(monkeypatch, tmp_path, capsys):
    import batch

    monkeypatch.setattr(batch, "run", lambda args: _raise(errors.Cancelled("stopped by the test")))
    code = batch.main(["--image", str(tmp_path / "a.png"), "--out", str(tmp_path / "out")])
    assert code == EXIT_ERROR
    assert capsys.readouterr().err.strip() == "batch.py: error: stopped by the test"


def test_the_blender_tier_uses_the_core_classes_themselves(capsys):
    pytest.importorskip("bpy")
    import batch

    reporting = import_module(f"{batch.load_package().__name__}.ops.reporting")
    assert reporting.Cancelled is errors.Cancelled and reporting.SpecGenError is errors.SpecGenError
    code = run_guarded("the test", lambda: _raise(reporting.Cancelled("stopped in ops")))
    assert code == EXIT_ERROR and capsys.readouterr().err.strip() == "error: stopped in ops"
    assert not [m for m in sys.modules if m.endswith(".specgen_addon") or ".specgen_addon." in m]


@pytest.mark.slow
@pytest.mark.blender
def test_the_installed_extension_catches_the_core_cancel_in_the_cli_guard(tmp_path):
    pytest.importorskip("bpy")
    zip_path = tmp_path / "specgen.zip"
    subprocess.run([sys.executable, str(REPO / "scripts" / "build_extension.py"), "--no-wheels",
                    "--out", str(zip_path)], check=True, capture_output=True)
    script = (
        "import sys, bpy\n"
        f"r = bpy.ops.extensions.package_install_files(filepath={str(zip_path)!r}, repo='user_default', "
        "enable_on_install=True)\n"
        "assert r == {'FINISHED'}, r\n"
        "from bl_ext.user_default.specgen.ops import reporting\n"
        "from specgen_addon import errors\n"
        "from specgen_addon.cli import run_guarded\n"
        "assert reporting.Cancelled is errors.Cancelled\n"
        "def work():\n"
        "    raise reporting.Cancelled('stopped in the extension')\n"
        "print('SPECGEN-GUARD', run_guarded('the test', work), errors.__file__)\n")
    (tmp_path / "home").mkdir()
    done = subprocess.run([sys.executable, "-c", script], env={**os.environ, "HOME": str(tmp_path / "home")},
                          capture_output=True, text=True, timeout=240, cwd=tmp_path, check=False)
    assert f"SPECGEN-GUARD {EXIT_ERROR} {tmp_path / 'home'}" in done.stdout, done.stdout[-2000:] + done.stderr[-2000:]
    assert "error: stopped in the extension" in done.stderr
