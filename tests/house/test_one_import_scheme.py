"""One import scheme: a class of the core is the same object in every entry.

The CLI, batch.py, the Blender tier loaded as a package (tests, batch.py) and the installed
extension (``bl_ext.user_default.specgen``) all reach the core as the top-level ``specgen_addon``,
so a ``Cancelled`` raised on one side is caught by the other side's ``except``. The installed
extension's side is checked in tests/ops/test_blender_addon.py (test_extension_zip_installs_and_registers).
"""

from __future__ import annotations

import ast
import sys
from importlib import import_module
from pathlib import Path

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


#: The code that changes ``sys.path`` (calls, not the source of child processes), each with its
#: reason; everything else imports the installed package (``pip install -e .``) normally.
PATH_CHANGES = {
    "__init__.py": "the extension entry: Blender loads it as bl_ext.<repo>.specgen",
    "batch.py": "the headless entry, which Blender runs as a script",
    "ops/render.py": "Blender's bundled site-packages (OpenImageIO, oslquery), kept off the path by the bpy module",
    "specgen_addon/render/view_transform.py": "Blender's bundled PyOpenColorIO, likewise",
    "tests/script_modules.py": "a bench/ or scripts/ file loaded in a test as it loads when run",
}


def _changes_sys_path(tree: ast.Module) -> list[int]:
    return [n.lineno for n in ast.walk(tree)
            if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
            and n.func.attr in ("insert", "append", "extend", "__setitem__")
            and isinstance(n.func.value, ast.Attribute) and n.func.value.attr == "path"
            and getattr(n.func.value.value, "id", "") == "sys"]


def test_only_the_entries_change_the_import_path():
    repo = Path(__file__).resolve().parents[2]
    bad = []
    for path in sorted(repo.rglob("*.py")):
        rel = path.relative_to(repo).as_posix()
        if rel.startswith(("lab/", ".venv/", ".cache/", "out/", "build/", "wheels/")) or "/." in "/" + rel:
            continue
        lines = _changes_sys_path(ast.parse(path.read_text(encoding="utf-8")))
        if lines and rel not in PATH_CHANGES:
            bad += [f"{rel}:{n}" for n in lines]
    assert not bad, "sys.path changed outside the entries (import the installed package): " + ", ".join(bad)


def test_the_path_check_sees_a_call_but_not_a_child_process_source():
    assert _changes_sys_path(ast.parse("import sys\nsys.path.insert(0, 'x')")) == [2]
    assert _changes_sys_path(ast.parse("code = 'import sys; sys.path.insert(0, \"x\")'")) == []
