"""The layers of the product, checked from the source (no import needed).

Only ``ops/``, ``batch.py`` and the extension's ``__init__.py`` import ``bpy``; inside
``specgen_addon`` every import, at module level or inside a function, goes down one order
(docs/dev/architecture.md)::

    cli > scale > evaluation > train > generate > bake | model > photo > render | corpus
        > brdf > spectral > common

so no two sub-packages import each other; every module lives in one of these packages; package
``__init__`` files only re-export.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
CORE = REPO / "specgen_addon"
#: rank of each sub-package: an import must go to a lower rank (or stay in its own package)
RANK = {"common": 0, "spectral": 1, "brdf": 2, "render": 3, "corpus": 3, "photo": 4, "model": 5,
        "bake": 5, "generate": 6, "train": 7, "evaluation": 8, "scale": 9, "cli": 10}
#: __init__ files that still define things (to be emptied into modules); new ones fail
INIT_WITH_DEFINITIONS: set[str] = set()
#: imports against the order that remain to be undone by moving one function down; new ones fail
KNOWN_UPWARD: set[tuple[str, str]] = set()


def _modules() -> list[Path]:
    return sorted(p for p in CORE.rglob("*.py") if "__pycache__" not in p.parts)


def _dotted(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports(path: Path) -> list[tuple[int, str]]:
    """``(line, absolute module)`` of every import in ``path``, relative ones resolved."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    here = _dotted(path).split(".")
    package = here if path.name == "__init__.py" else here[:-1]
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                base = ".".join(package[:len(package) - node.level + 1] + ([base] if base else []))
            out.append((node.lineno, base))
            out += [(node.lineno, f"{base}.{a.name}") for a in node.names if a.name != "*"]
    return out


def _layer(module: str) -> str | None:
    parts = module.split(".")
    return parts[1] if parts[0] == "specgen_addon" and len(parts) > 1 and parts[1] in RANK else None


def test_only_the_blender_tier_imports_bpy():
    allowed = {REPO / "batch.py", REPO / "__init__.py"} | set((REPO / "ops").rglob("*.py"))
    product = [p for p in [REPO / "batch.py", REPO / "__init__.py", *_modules(), *(REPO / "ops").rglob("*.py")]]
    bad = [f"{p.relative_to(REPO)}:{line}" for p in product if p not in allowed
           for line, m in _imports(p) if m.split(".")[0] in ("bpy", "mathutils", "bmesh")]
    assert not bad, "bpy outside ops/ and batch.py: " + ", ".join(bad)


def test_every_core_module_lives_in_a_layer():
    loose = [p.name for p in CORE.glob("*.py") if p.name not in ("__init__.py", "__main__.py")]
    unknown = [p.name for p in CORE.iterdir() if p.is_dir() and (p / "__init__.py").is_file()
               and p.name not in RANK]
    assert not loose and not unknown, f"modules outside the layer packages: {loose + unknown}"


def test_core_imports_go_down_the_layer_order():
    bad = []
    for p in _modules():
        src = _layer(_dotted(p))
        if src is None:
            continue
        for line, m in _imports(p):
            dst = _layer(m)
            known = (str(p.relative_to(REPO)), ".".join(m.split(".")[:3])) in KNOWN_UPWARD
            if dst is not None and dst != src and RANK[dst] >= RANK[src] and not known:
                bad.append(f"{p.relative_to(REPO)}:{line} ({src}) imports {m} ({dst})")
    assert not bad, "imports against the layer order:\n" + "\n".join(sorted(set(bad)))


def test_known_upward_imports_still_exist():
    """Each entry of KNOWN_UPWARD is a real import still to undo (drop it once undone)."""
    found = {(str(p.relative_to(REPO)), ".".join(m.split(".")[:3])) for p in _modules() for _, m in _imports(p)}
    assert KNOWN_UPWARD <= found, KNOWN_UPWARD - found


def test_the_core_never_imports_the_blender_tier_or_the_lab():
    bad = [f"{p.relative_to(REPO)}:{line} {m}" for p in _modules() for line, m in _imports(p)
           if m.split(".")[0] in ("ops", "batch", "lab", "bench", "tests")]
    assert not bad, bad


def _defines(tree: ast.Module) -> list[str]:
    names = []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            if not node.name.startswith("__"):   # a module __getattr__ (PEP 562) only re-exports lazily
                names.append(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            names += [t.id for t in targets if isinstance(t, ast.Name) and not t.id.startswith("__")]
    return names


@pytest.mark.parametrize("init", sorted(str(p.relative_to(REPO)) for p in CORE.rglob("__init__.py")))
def test_package_init_files_only_re_export(init):
    tree = ast.parse((REPO / init).read_text(encoding="utf-8"))
    defined = _defines(tree)
    if init in INIT_WITH_DEFINITIONS:
        assert defined, f"{init} re-exports only now: drop it from INIT_WITH_DEFINITIONS"
        return
    assert not defined, f"{init} defines {defined}; move them into a module and re-export"
