"""One import scheme: a class of the core is the same object in every entry.

The CLI, batch.py, the Blender tier loaded as a package (tests, batch.py) and the installed
extension (``bl_ext.user_default.specgen``) all reach the core as the top-level ``specgen_addon``,
so a ``Cancelled`` raised on one side is caught by the other side's ``except``. The installed
extension's side is checked in tests/ops/test_blender_addon.py (test_extension_zip_installs_and_registers).
"""

from __future__ import annotations

import sys
from importlib import import_module

import pytest

from specgen_addon.common import errors
from specgen_addon.cli.app import run_guarded
from specgen_addon.common.interrupts import EXIT_ERROR


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
