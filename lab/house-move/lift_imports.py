"""Lift ``specgen_addon`` imports placed inside functions to module level where that is safe.

Safe means: the imported module's module-level import closure adds no third-party package (beyond
numpy) that the importing module does not already import at module level (so a lazy import of an
optional dependency such as torch, scipy or OpenImageIO stays lazy), and the new module-level edge
closes no import circle. Imports under ``try`` stay where they are, as do imports whose name a
function rebinds or another module-level name already holds. ``--skip PREFIX`` leaves files alone.

Usage: ``python3 lab/house-move/lift_imports.py [--dry-run] [--skip specgen_addon/photo/ ...]``
"""

from __future__ import annotations

import argparse
import ast
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
CORE = REPO / "specgen_addon"
STDLIB = set(sys.stdlib_module_names) | {"__future__"}
FREE = {"numpy", "specgen_addon"}


def dotted(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> dict[str, Path]:
    return {dotted(p): p for p in sorted(CORE.rglob("*.py")) if "__pycache__" not in p.parts}


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or \
        (isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING")


def lazy_names(mods: dict[str, Path]) -> dict[str, tuple[set[str], set[str]]]:
    """Packages with a module ``__getattr__`` (PEP 562): (names bound at load, modules its
    ``__getattr__`` imports): ``from package import name`` of an unbound name loads those."""
    out = {}
    for m, p in mods.items():
        tree = ast.parse(p.read_text(encoding="utf-8"))
        for node in tree.body:
            if isinstance(node, ast.FunctionDef) and node.name == "__getattr__":
                loads = {f"{n.module}.{a.name}" if f"{n.module}.{a.name}" in mods else n.module
                         for n in ast.walk(node) if isinstance(n, ast.ImportFrom) and n.module
                         for a in n.names}
                out[m] = (set(module_names(tree)), loads)
    return out


def module_level_imports(tree: ast.Module, mods: dict[str, Path],
                         lazy: dict[str, tuple[set[str], set[str]]] | None = None) -> tuple[set[str], set[str]]:
    """(specgen_addon modules, third-party top-level packages) imported when the module loads."""
    ours, third = set(), set()
    lazy = lazy or {}

    def visit(nodes):
        for node in nodes:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(node, ast.If) and _is_type_checking(node):
                visit(node.orelse)
                continue
            if isinstance(node, ast.Import):
                for a in node.names:
                    add(a.name)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                add(node.module)
                for a in node.names:
                    if f"{node.module}.{a.name}" in mods:
                        add(f"{node.module}.{a.name}")
                    elif node.module in lazy and a.name not in lazy[node.module][0]:
                        for loaded in lazy[node.module][1]:
                            add(loaded)
            for field in ("body", "orelse", "finalbody", "handlers"):
                sub = getattr(node, field, None)
                if isinstance(sub, list) and not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    visit(sub)

    def add(name: str):
        top = name.split(".")[0]
        if top == "specgen_addon":
            parts = name.split(".")
            for i in range(1, len(parts) + 1):
                if ".".join(parts[:i]) in mods:
                    ours.add(".".join(parts[:i]))
        elif top not in STDLIB and top not in FREE:
            third.add(top)

    visit(tree.body)
    return ours, third


class Graph:
    def __init__(self):
        self.mods = modules()
        self.trees = {m: ast.parse(p.read_text(encoding="utf-8")) for m, p in self.mods.items()}
        self.edges, self.third = {}, {}
        self.lazy = lazy_names(self.mods)
        for m, t in self.trees.items():
            self.edges[m], self.third[m] = module_level_imports(t, self.mods, self.lazy)
            parent = m.rsplit(".", 1)[0]       # loading a module loads its package first
            if parent != m and parent in self.mods:
                self.edges[m].add(parent)

    def closure(self, m: str) -> set[str]:
        seen, todo = set(), [m]
        while todo:
            x = todo.pop()
            if x in seen:
                continue
            seen.add(x)
            todo += [y for y in self.edges.get(x, ()) if y not in seen]
        return seen

    def deps(self, m: str) -> set[str]:
        return set().union(*(self.third[x] for x in self.closure(m)))

    def target(self, module: str, names: list[str]) -> list[str]:
        """The modules ``from module import names`` loads."""
        out = [module] if module in self.mods else []
        if module in self.lazy:
            out += [x for n in names if n not in self.lazy[module][0] for x in self.lazy[module][1]]
        return out + [f"{module}.{n}" for n in names if f"{module}.{n}" in self.mods]

    def lazy_for_a_dependency(self, m: str, node: ast.ImportFrom) -> bool:
        """True when the import brings a third-party package that ``m`` does not load itself."""
        mine = self.deps(m)
        return any(not self.deps(t) <= mine for t in self.target(node.module, [a.name for a in node.names]))


def in_function_imports(tree: ast.Module):
    """``(function, import node, parent statement list, inside try)`` of every ``from
    specgen_addon… import`` inside a function body."""
    out = []

    def visit(body, fn, in_try):
        for node in body:
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                visit(node.body, node, False)
                continue
            if isinstance(node, ast.ClassDef):
                visit(node.body, fn, in_try)
                continue
            if fn is not None and isinstance(node, ast.ImportFrom) and node.level == 0 \
                    and (node.module or "").startswith("specgen_addon"):
                out.append((fn, node, body, in_try))
            for field in ("body", "orelse", "finalbody"):
                sub = getattr(node, field, None)
                if isinstance(sub, list):
                    visit(sub, fn, in_try or isinstance(node, ast.Try))
            for h in getattr(node, "handlers", []) or []:
                visit(h.body, fn, True)

    visit(tree.body, None, False)
    return out


def _rebound(fn, name: str) -> bool:
    """``name`` is a parameter of ``fn`` or assigned in it (other than by the import)."""
    args = fn.args
    params = {a.arg for a in args.args + args.kwonlyargs + args.posonlyargs}
    params |= {a.arg for a in (args.vararg, args.kwarg) if a is not None}
    if name in params:
        return True
    for n in ast.walk(fn):
        if isinstance(n, ast.Name) and n.id == name and isinstance(n.ctx, ast.Store):
            return True
        if isinstance(n, (ast.FunctionDef, ast.ClassDef)) and n is not fn and n.name == name:
            return True
    return False


def module_names(tree: ast.Module) -> dict[str, str]:
    """Module-level names → what binds them (``"module:name"`` for imports, ``""`` otherwise)."""
    out = {}
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            for a in node.names:
                out[a.asname or a.name] = f"{node.module}:{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                out[(a.asname or a.name).split(".")[0]] = f"import:{a.name}"
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out[node.name] = ""
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for t in (node.targets if isinstance(node, ast.Assign) else [node.target]):
                for n in ast.walk(t):
                    if isinstance(n, ast.Name):
                        out[n.id] = ""
    return out


def plan(skip: list[str]):
    g = Graph()
    moves: dict[str, list] = {}
    kept = []
    for m, tree in g.trees.items():
        rel = str(g.mods[m].relative_to(REPO))
        names = module_names(tree)
        for fn, node, body, in_try in in_function_imports(tree):
            why = None
            if any(rel.startswith(s) for s in skip):
                why = "skipped"
            elif in_try:
                why = "inside try"
            elif g.lazy_for_a_dependency(m, node):
                why = "lazy for an optional dependency"
            elif any(_rebound(fn, a.asname or a.name) for a in node.names):
                why = "name rebound in the function"
            elif any(names.get(a.asname or a.name, f"{node.module}:{a.name}") != f"{node.module}:{a.name}"
                      for a in node.names):
                why = "another module-level name"
            elif sum(1 for s in body if s is not node and s not in [x[1] for x in moves.get(m, [])]) == 0:
                why = "only statement of its block"
            else:
                targets = g.target(node.module, [a.name for a in node.names])
                if any(m in g.closure(t) for t in targets):
                    why = "would close an import circle"
            if why is None:
                moves.setdefault(m, []).append((fn, node, body))
                g.edges[m] |= set(targets)
                for a in node.names:
                    names[a.asname or a.name] = f"{node.module}:{a.name}"
            else:
                kept.append((rel, node.lineno, node.module, why))
    return g, moves, kept


def apply(g: Graph, moves: dict[str, list]) -> None:
    for m, items in moves.items():
        path = g.mods[m]
        lines = path.read_text(encoding="utf-8").splitlines(keepends=True)
        tree = g.trees[m]
        drop = set()
        for _, node, _ in items:
            drop |= set(range(node.lineno - 1, node.end_lineno))
        # one statement per module at module level, without the names it already binds
        bound = module_names(tree)
        wanted: dict[str, list[str]] = {}
        for _, node, _ in items:
            for a in node.names:
                local = a.asname or a.name
                if bound.get(local) == f"{node.module}:{a.name}":
                    continue
                text = a.name if a.asname is None else f"{a.name} as {a.asname}"
                if text not in wanted.setdefault(node.module, []):
                    wanted[node.module].append(text)
        add = []
        for module, names in wanted.items():
            if not names:
                continue
            head = f"from {module} import "
            one = head + ", ".join(sorted(names)) + "\n"
            if len(one) <= 111:
                add.append(one)
                continue
            body, line = [], head + "("
            for i, n in enumerate(sorted(names)):
                piece = n + (", " if i < len(names) - 1 else ")")
                if len(line) + len(piece.rstrip()) > 110:
                    body.append(line.rstrip() + "\n")
                    line = " " * len(head + "(")
                line += piece
            add.append("".join(body) + line + "\n")
        # where: after the last import of the leading block
        last = 0
        for node in tree.body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                last = node.end_lineno
            elif not ((isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant))
                      or (isinstance(node, ast.If) and _is_type_checking(node))):
                break
        # a blank line that a lifted import left first in a body, or doubled, goes too
        docstring_ends = {n.body[0].end_lineno - 1 for n in ast.walk(tree)
                          if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.body
                          and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)
                          and isinstance(n.body[0].value.value, str)}
        for start in [i for i in sorted(drop) if i - 1 not in drop]:
            end = start
            while end + 1 in drop:
                end += 1
            nxt, prev = end + 1, start - 1
            if nxt < len(lines) and lines[nxt].strip() == "" and prev >= 0 and \
                    (lines[prev].rstrip().endswith(":") or prev in docstring_ends or lines[prev].strip() == ""):
                drop.add(nxt)
        add.sort(key=lambda stmt: stmt.split()[1])
        out = []
        for i, line in enumerate(lines):
            if i in drop:
                continue
            out.append(line)
            if i == last - 1:
                out += add
        if last == 0:
            out = add + ["\n"] + out
        cleaned = out
        path.write_text("".join(cleaned), encoding="utf-8")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--skip", action="append", default=[])
    args = ap.parse_args()
    g, moves, kept = plan(args.skip)
    n = sum(len(v) for v in moves.values())
    print(f"{n} in-function imports lifted in {len(moves)} modules; {len(kept)} kept:")
    reasons = {}
    for k in kept:
        reasons[k[3]] = reasons.get(k[3], 0) + 1
    for r, c in sorted(reasons.items(), key=lambda x: -x[1]):
        print(f"  {c:4d} {r}")
    if not args.dry_run:
        apply(g, moves)
    return 0


if __name__ == "__main__":
    sys.exit(main())
