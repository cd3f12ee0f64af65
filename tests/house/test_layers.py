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

REPO = Path(__file__).resolve().parents[2]
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
        elif _imports_by_name(node):    # importlib.import_module("a.b"), __import__("a.b"): imports too
            out.append((node.lineno, node.args[0].value))
    return out


def _imports_by_name(node: ast.AST) -> bool:
    """Whether ``node`` is a call importing a module named by a string literal."""
    if not (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)):
        return False
    f = node.func
    name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) else ""
    return name in ("import_module", "__import__")


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


def test_the_blender_tier_stands_beside_the_commands_and_never_imports_the_lab():
    """``ops/`` sits beside ``cli/`` (both above ``scale``), so it takes nothing from the commands;
    no product entry (``ops/``, ``batch.py``, the extension's ``__init__.py``) imports ``lab/``,
    ``bench/`` or the tests, by statement or by name (``import_module("…")``)."""
    entries = [REPO / "batch.py", REPO / "__init__.py", *sorted((REPO / "ops").rglob("*.py"))]
    bad = [f"{p.relative_to(REPO)}:{line} {m}" for p in entries for line, m in _imports(p)
           if m.split(".")[0] in ("lab", "bench", "tests")
           or (p.relative_to(REPO).parts[0] == "ops" and m.startswith("specgen_addon.cli"))]
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


# ------------------------------------------------------------------------- imports inside functions
#: An import of a ``specgen_addon`` module inside a function is lazy for a reason: it brings an
#: optional package (torch, scipy, OpenImageIO, …: anything beyond numpy and the standard library)
#: that the importing module does not load itself, so the panel's path in a stock Blender and the
#: CLI's start stay light. Any other in-function import is listed here with its reason; new ones
#: fail. ``python3 lab/house-move/lift_imports.py`` lifts what is safe to lift.
IN_FUNCTION_ALLOWED: dict = {
    # the command line's entry loads the commands inside its own Ctrl-C guard (a stop while loading)
    ("specgen_addon/cli/entry.py", "specgen_addon.cli.app"): "loaded inside the entry's Ctrl-C guard",
}
_STDLIB = set(__import__("sys").stdlib_module_names) | {"__future__"}


def _load_time_imports(tree: ast.Module, getattr_loads: dict[str, tuple[set[str], set[str]]],
                       known: set[str]) -> tuple[set[str], set[str]]:
    """(``specgen_addon`` modules, optional packages) a module imports when it loads."""
    ours, optional = set(), set()

    def add(name: str) -> None:
        parts = name.split(".")
        if parts[0] == "specgen_addon":
            ours.update(".".join(parts[:i]) for i in range(1, len(parts) + 1) if ".".join(parts[:i]) in known)
        elif parts[0] not in _STDLIB and parts[0] != "numpy":
            optional.add(parts[0])

    def visit(nodes) -> None:
        for node in nodes:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            if isinstance(node, ast.If) and getattr(node.test, "id", getattr(node.test, "attr", "")) == "TYPE_CHECKING":
                visit(node.orelse)
                continue
            if isinstance(node, ast.Import):
                for a in node.names:
                    add(a.name)
            elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
                add(node.module)
                for a in node.names:
                    lazy = getattr_loads.get(node.module)
                    if f"{node.module}.{a.name}" in known:
                        add(f"{node.module}.{a.name}")
                    elif lazy and a.name not in lazy[0]:      # a PEP 562 name: what __getattr__ loads
                        for m in lazy[1]:
                            add(m)
            for field in ("body", "orelse", "finalbody"):
                visit(getattr(node, field, None) or [])
            for h in getattr(node, "handlers", None) or []:
                visit(h.body)

    visit(tree.body)
    return ours, optional


def _optional_closure() -> tuple[dict[str, set[str]], dict[str, tuple[set[str], set[str]]]]:
    """Module → every optional package it loads at import, through ``specgen_addon`` modules; and
    the packages with a PEP 562 ``__getattr__``: (names bound at load, modules it loads)."""
    trees = {_dotted(p): ast.parse(p.read_text(encoding="utf-8")) for p in _modules()}
    known = set(trees)
    getattr_loads = {}
    for m, tree in trees.items():
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
                bound = {a.asname or a.name for n in tree.body if isinstance(n, ast.ImportFrom) for a in n.names}
                bound |= {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
                loads = {n.module + (f".{a.name}" if f"{n.module}.{a.name}" in known else "")
                         for n in ast.walk(node) if isinstance(n, ast.ImportFrom) and n.module for a in n.names}
                getattr_loads[m] = (bound, loads)
    direct = {m: _load_time_imports(t, getattr_loads, known) for m, t in trees.items()}
    out = {}
    for m in trees:
        seen, todo = set(), [m]
        while todo:
            x = todo.pop()
            if x not in seen:
                seen.add(x)
                todo += list(direct[x][0]) + ([x.rsplit(".", 1)[0]] if "." in x else [])
        out[m] = set().union(*(direct[x][1] for x in seen if x in direct))
    return out, getattr_loads


def test_imports_inside_functions_are_lazy_for_an_optional_package_or_listed():
    optional, getattr_loads = _optional_closure()
    bad = []
    for p in _modules():
        rel, here = str(p.relative_to(REPO)), _dotted(p)
        if any(rel.startswith(k) for k in IN_FUNCTION_ALLOWED if isinstance(k, str)):
            continue
        tree = ast.parse(p.read_text(encoding="utf-8"))
        for fn in ast.walk(tree):
            if not isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            for node in ast.walk(fn):
                if not (isinstance(node, ast.ImportFrom) and (node.module or "").startswith("specgen_addon")):
                    continue
                lazy = getattr_loads.get(node.module, (set(), set()))
                targets = [node.module] + [f"{node.module}.{a.name}" for a in node.names
                                           if f"{node.module}.{a.name}" in optional]
                targets += [m for a in node.names if node.module in getattr_loads and a.name not in lazy[0]
                            for m in lazy[1]]
                if fn.name == "__getattr__" or (rel, node.module) in IN_FUNCTION_ALLOWED:
                    continue
                if any(not optional.get(t, set()) <= optional[here] for t in targets):
                    continue   # lazy for an optional package
                bad.append(f"{rel}:{node.lineno} imports {node.module} inside {fn.name}()")
    assert not bad, ("imports inside functions that could be at module level (or list them with a "
                     "reason in IN_FUNCTION_ALLOWED):\n" + "\n".join(sorted(set(bad))))


def _import_graph() -> dict[str, set[str]]:
    """Module → the ``specgen_addon`` modules it imports, at load or inside a function (with the
    packages above them, whose ``__init__`` runs first), its own enclosing packages left out: they
    are already loading when it runs."""
    known = {_dotted(p) for p in _modules()}
    graph = {}
    for p in _modules():
        m = _dotted(p)
        own = {".".join(m.split(".")[:i]) for i in range(1, m.count(".") + 2)}
        targets = set()
        for _, name in _imports(p):
            parts = name.split(".")
            targets |= {".".join(parts[:i]) for i in range(2, len(parts) + 1)} & known
        graph[m] = targets - own
    return graph


def _a_circle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import circle of ``graph`` (a list that starts and ends at the same module), or None."""
    state: dict[str, int] = {}      # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        path.append(m)
        for n in sorted(graph.get(m, ())):
            if state.get(n) == 1:
                return path[path.index(n):] + [n]
            if n not in state and (found := visit(n)):
                return found
        path.pop()
        state[m] = 2
        return None

    for m in sorted(graph):
        if m not in state and (found := visit(m)):
            return found
    return None


def test_the_circle_finder_finds_a_circle():
    assert _a_circle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _a_circle({"a": {"b"}, "b": {"c"}, "c": set()}) is None


def test_no_import_circle():
    circle = _a_circle(_import_graph())
    assert circle is None, "modules import each other: " + " → ".join(circle)


def test_no_module_imports_names_from_its_own_package_init():
    """A module that takes names from the ``__init__`` of a package it is in imports a package
    that is still loading: it works only in some import orders. It imports the defining module."""
    known = {_dotted(p) for p in _modules()}
    bad = []
    for p in _modules():
        m = _dotted(p)
        if p.name == "__init__.py":
            continue
        own = {".".join(m.split(".")[:i]) for i in range(2, m.count(".") + 1)}
        for node in ast.walk(ast.parse(p.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module in own:
                names = [a.name for a in node.names if f"{node.module}.{a.name}" not in known]
                if names:
                    bad.append(f"{p.relative_to(REPO)}:{node.lineno} takes {', '.join(names)} from {node.module}")
    assert not bad, "\n".join(bad)
