"""The core package must work without Blender: import every module with bpy blocked."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]

SCRIPT = r"""
import importlib, pkgutil, sys
class Block:
    def find_spec(self, name, path=None, target=None):
        if name == "bpy" or name.startswith("bpy.") or name in ("mathutils", "bmesh"):
            raise ImportError("bpy is blocked in this test")
        return None
sys.meta_path.insert(0, Block())
import specgen_addon
failed = []
for mod in pkgutil.walk_packages(specgen_addon.__path__, "specgen_addon."):
    if mod.name.endswith("__main__"):
        continue
    try:
        importlib.import_module(mod.name)
    except ImportError as exc:
        failed.append(f"{mod.name}: {exc}")
print("\n".join(failed))
sys.exit(1 if failed else 0)
"""


def test_every_core_module_imports_with_bpy_blocked():
    res = subprocess.run([sys.executable, "-c", SCRIPT], cwd=REPO, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr


def test_core_sources_never_mention_import_bpy():
    offenders = [str(p) for p in (REPO / "specgen_addon").rglob("*.py")
                 if "import bpy" in p.read_text(encoding="utf-8")]
    assert not offenders
