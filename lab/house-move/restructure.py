#!/usr/bin/env python3
"""Move the flat specgen_addon/ modules into concept sub-packages and rewrite every reference.

Run from a repository root (deterministic, re-runnable on a fresh checkout of main):

    python lab/house-move/restructure.py            # git mv + rewrite, prints what it did
    python lab/house-move/restructure.py --dry-run  # only print the plan and unknown modules

1. ``git mv`` each module/package in MAPPING (old dotted name -> new dotted name).
2. Rewrites in every tracked .py file (specgen_addon/, ops/, tests/, bench/, lab/, scripts/,
   batch.py, __init__.py): relative imports inside specgen_addon/ become absolute
   (``specgen_addon.x``, the one import scheme), then every dotted name ``specgen_addon.a.b`` in code
   and strings (imports, ``import_module("…")``, ``mock.patch("…")``, ``python -m …``) and every path
   ``specgen_addon/a/b.py`` is mapped by longest prefix. Also .sh/.toml/.txt/.md (docs/ and lab/
   included unless ``--no-docs``).
3. ``Path(__file__)`` depth in moved modules is corrected (``parents[N]``).
4. Modules it does not know (created later) stay where they are and are printed for the lead.
"""
from __future__ import annotations

import argparse
import ast
import re
import subprocess
import sys
from pathlib import Path

P = "specgen_addon"
SENT = P + "\x00"  # marks a name already rewritten
#: old module or package (dotted, under specgen_addon) -> new dotted name. Packages move whole.
MAPPING: dict[str, str] = {
    # common: errors, limits, atomic writes, progress, quiet, clean stops
    "errors": "common.errors",
    "limits": "common.limits",
    "io_utils": "common.atomic_io",
    "progress": "common.progress",
    "quiet": "common.quiet",
    "interrupts": "common.interrupts",
    "processes": "common.processes",
    "image_io": "common.image_io",
    "evaluation.cache": "common.cache",
    # spectral: spectra, colour tables, RGB -> spectrum
    "spectra": "spectral.spectra",
    "colour_tables": "spectral.colour_tables",
    "spectral_recovery": "spectral.recovery",
    # brdf: the table, Rusinkiewicz coordinates, file formats
    "table": "brdf.table",
    "rusinkiewicz": "brdf.rusinkiewicz",
    "lookup_reach": "brdf.lookup_reach",
    "material_file": "brdf.material_file",
    "formats": "brdf.formats",
    # photo: decode, checks, find and crop the sphere, the photo's lighting
    "image_checks": "photo.image_checks",
    "input_image": "photo.sphere_image",
    "sphere_edge": "photo.sphere_edge",
    "ndimage_np": "photo.ndimage_np",
    "input_lighting": "photo.photo_lighting",
    "photo_read": "photo.read",
    "sphere_detect": "photo.sphere_detect",
    "resample": "photo.resample",
    "light_probe": "photo.light_probe",
    "light_estimate": "photo.light_estimate",
    # render: the reference renderer (existing package) + environment maps, meshes, outputs
    "lighting": "render.environment_maps",
    "mesh_checks": "render.mesh_checks",
    "spectral_exr": "render.spectral_exr",
    "metrics": "render.metrics",
    "view_transform": "render.view_transform",
    "render_estimate": "render.cycles_time_estimate",
    # model: the network; inference runtime and ONNX export below it
    "infer": "model.runtime.inference",
    "model.export_onnx": "model.runtime.export_onnx",
    "model.gather": "model.runtime.gather",
    "model.gather_kernels": "model.runtime.gather_kernels",
    "model._gather_loops": "model.runtime._gather_loops",
    "model.fast": "model.runtime.fast",
    # generate: the one front door (network -> refinement / latent fit / thin film)
    "pipeline": "generate.pipeline",
    "latent_fit": "generate.latent_fit",
    "refine.report": "render.photo_reproduction",
    "refine": "generate.refine",
    "fit.thin_film": "generate.thin_film",
    "bake": "generate.lookup",
    # bake: everything Blender reads, computed without bpy
    "fit": "bake.closure_fit",
    "uplift": "bake.scene_uplift",
    "preview": "bake.preview",
    # train / evaluation
    "config_schema": "train.config_schema",
    "train.evaluate": "evaluation.trained_network",
    # cli
    "cli": "cli.app",
    "cli_brdf": "cli.brdf",
    "cli_corpus": "cli.corpus",
    "cli_eval": "cli.evaluate",
    "cli_model": "cli.model",
    "cli_render": "cli.render",
    "cli_scale": "cli.scale",
    "preflight": "scale.preflight",
    "scene_args": "cli.scene_args",
}
#: data files that move with their module
DATA_MOVES = {"data": "spectral/data"}
#: new packages and what their __init__ re-exports (only re-exports)
NEW_PACKAGES = {
    "common": "", "spectral": "", "brdf": "", "photo": "", "model/runtime": "", "generate": "",
    "bake": "", "cli": "from specgen_addon\x00.cli.app import main\n\n__all__ = [\"main\"]\n",
}
#: modules that stay where they are (already in their concept package or a package root)
KNOWN_STAYING = {"__init__", "__main__", "corpus", "evaluation", "model", "render", "scale", "train"}
TEXT_SUFFIXES = {".py", ".sh", ".toml", ".cfg", ".txt", ".md"}


def run(*cmd: str) -> str:
    return subprocess.run(cmd, check=True, capture_output=True, text=True).stdout


def new_name(dotted: str) -> str:
    """``specgen_addon.a.b.c`` -> mapped by the longest known prefix (unchanged if none)."""
    parts = dotted.split(".")
    assert parts[0] == P
    for n in range(len(parts), 1, -1):
        key = ".".join(parts[1:n])
        if key in MAPPING:
            return ".".join([P, MAPPING[key]] + parts[n:])
    return dotted


def old_file(key: str) -> Path:
    base = Path(P, *key.split("."))
    return base if (base / "__init__.py").is_file() else base.with_suffix(".py")


def unknown_modules() -> list[str]:
    out = []
    for p in sorted(Path(P).iterdir()):
        name = p.stem if p.suffix == ".py" else p.name
        if p.name == "__pycache__" or (p.is_file() and p.suffix != ".py"):
            continue
        if name not in MAPPING and name not in KNOWN_STAYING and name not in DATA_MOVES:
            out.append(str(p))
    return out


def absolutise_relative(src: str, module: str, is_pkg: bool) -> str:
    """Rewrite ``from .x import y`` inside specgen_addon to ``from specgen_addon.x import y``
    (old names; the dotted pass maps them afterwards)."""
    try:
        tree = ast.parse(src)
    except SyntaxError:
        return src
    lines = src.splitlines(keepends=True)
    pkg_parts = module.split(".") if is_pkg else module.split(".")[:-1]
    edits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = pkg_parts[:len(pkg_parts) - (node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
            edits.append((node.lineno, node.col_offset, node.level, node.module, target))
    for lineno, col, level, mod, target in sorted(edits, reverse=True):
        line = lines[lineno - 1]
        m = re.compile(r"from\s+" + r"\." * level + (re.escape(mod) if mod else "") + r"(?=\s+import)").match(line, col)
        if not m:
            print(f"  ! could not rewrite relative import at {module}:{lineno}")
            continue
        lines[lineno - 1] = line[:m.start()] + f"from {target}" + line[m.end():]
    return "".join(lines)


SYS_PATH = re.compile(r"(?m)^sys\.path\.insert\(0, str\((?:REPO|Path\(__file__\)\.resolve\(\)\.parents\[\d\])\)\)[ \t]*(?:#.*)?\n")
DOTTED = re.compile(r"(?<![\w.])specgen_addon(?:\.[A-Za-z_]\w*)+")
PATHS = re.compile(r"(?<![\w.])specgen_addon(?:/[A-Za-z_]\w*)+(?:\.py)?")


def map_path(m: re.Match) -> str:
    text = m.group(0)
    for old, new in DATA_MOVES.items():
        if text == f"{P}/{old}" or text.startswith(f"{P}/{old}/"):
            return f"{P}/{new}" + text[len(f"{P}/{old}"):]
    suffix = ".py" if text.endswith(".py") else ""
    dotted = text[:-3].replace("/", ".") if suffix else text.replace("/", ".")
    mapped = new_name(dotted)
    return mapped.replace(".", "/") + suffix if mapped != dotted else text


FROM_IMPORT = re.compile(
    r"(?m)(?P<pre>^[ \t]*|(?<=[\"'])|(?<=; ))from (?P<parent>specgen_addon(?:\.\w+)*) import "
    r"(?P<names>\w+(?: as \w+)?(?:, *\w+(?: as \w+)?)*)(?P<post>[ \t]*(?:#[^\n]*)?$|(?=\\n|;|\"|'))")


def split_from_import(src: str) -> str:
    """``from specgen_addon.X import mod`` where X.mod moved elsewhere than under X: import the
    moved module by its new parent, keeping the local name (in code and in code held in strings)."""
    def fix(m: re.Match) -> str:
        pre, parent, names, post = m.group("pre"), m.group("parent"), m.group("names"), m.group("post")
        at_line_start = m.start() == 0 or src[m.start() - 1] == "\n" or pre.strip(" \t") == "" and pre
        out, rest = [], []
        for item in [n.strip() for n in names.split(",") if n.strip()]:
            name, _, alias = item.partition(" as ")
            full = f"{parent}.{name.strip()}"
            mapped = new_name(full)
            if mapped != full and mapped.rsplit(".", 1)[0] != new_name(parent):
                newp, newn = mapped.rsplit(".", 1)
                newp = newp.replace(P, SENT, 1)  # already new: the dotted pass must not map it again
                local = alias.strip() or name.strip()
                out.append(f"from {newp} import {newn}" + (f" as {local}" if local != newn else ""))
            else:
                rest.append(item)
        if not out:
            return m.group(0)
        if rest:
            out.insert(0, f"from {parent} import {', '.join(rest)}")
        if at_line_start and (not post or post.strip().startswith("#") or post.strip() == ""):
            indent = pre
            return indent + (post + "\n" + indent).join(out) + post
        return pre + "; ".join(out) + post
    return FROM_IMPORT.sub(fix, src)


def map_dynamic_helpers(src: str) -> str:
    """Map the literal arguments of local helpers that import ``f"specgen_addon.{name}"``."""
    try:
        tree = ast.parse(src)
    except SyntaxError:
        return src
    helpers = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.Lambda)) and len(node.args.args) == 1:
            param = node.args.args[0].arg
            for sub in ast.walk(node):
                if (isinstance(sub, ast.JoinedStr) and len(sub.values) == 2
                        and isinstance(sub.values[0], ast.Constant) and sub.values[0].value == P + "."
                        and isinstance(sub.values[1], ast.FormattedValue)
                        and isinstance(sub.values[1].value, ast.Name) and sub.values[1].value.id == param):
                    if isinstance(node, ast.FunctionDef):
                        helpers.add(node.name)
    for name in helpers:
        src = re.sub(rf'\b{re.escape(name)}\("([\w.]+)"\)',
                     lambda m: f'{name}("{new_name(P + "." + m.group(1))[len(P) + 1:]}")', src)
    return src


def rewrite_text(src: str) -> str:
    src = split_from_import(src)
    src = DOTTED.sub(lambda m: new_name(m.group(0)), src)
    return PATHS.sub(map_path, src).replace(SENT, P)


def fix_depth(path: Path, delta: int) -> None:
    s = path.read_text()
    s2 = re.sub(r"(Path\(__file__\)\.resolve\(\)\.parents\[)(\d+)\]",
                lambda m: f"{m.group(1)}{int(m.group(2)) + delta}]", s)
    if path.name == "errors.py":
        s2 = s2.replace("package = os.path.dirname(os.path.abspath(__file__))",
                        "package = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))")
    if s2 != s:
        path.write_text(s2)
        print(f"  depth +{delta}: {path}")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dry-run", action="store_true")
    ap.add_argument("--no-docs", action="store_true", help="leave the .md files of docs/ and lab/ alone")
    args = ap.parse_args()
    if not Path(P, "__init__.py").is_file():
        sys.exit("run from the repository root")
    unknown = unknown_modules()
    moves = [(k, v, old_file(k)) for k, v in MAPPING.items() if old_file(k).exists()]
    missing = [k for k in MAPPING if not old_file(k).exists()]
    print(f"{len(moves)} moves; already moved or absent: {missing or 'none'}")
    print("modules left where they are (place them by hand):", *unknown or ["none"], sep="\n  ")
    if args.dry_run:
        return 0
    files = [Path(f) for f in run("git", "ls-files").split() if Path(f).suffix in TEXT_SUFFIXES]
    files += [Path(f) for f in run("git", "ls-files", "--others", "--exclude-standard").split()
              if Path(f).suffix in TEXT_SUFFIXES]
    # 1. relative imports inside the core become absolute (old names)
    for f in files:
        if f.parts[0] == P and f.suffix == ".py" and f.is_file():
            mod = ".".join(f.with_suffix("").parts)
            is_pkg = f.name == "__init__.py"
            if is_pkg:
                mod = mod[: -len(".__init__")]
            s = f.read_text()
            s2 = absolutise_relative(s, mod, is_pkg)
            if s2 != s:
                f.write_text(s2)
    # 2. the moves
    for pkg, init in NEW_PACKAGES.items():
        d = Path(P, pkg)
        d.mkdir(parents=True, exist_ok=True)
        i = d / "__init__.py"
        if not i.exists():
            doc = f'"""SpecGen core: {pkg.replace("/", " ")} (see docs/dev/architecture.md)."""\n'
            i.write_text(doc + ("\n" + init if init else ""))
            run("git", "add", str(i))
    for key, new, src in moves:
        dst = Path(P, *new.split("."))
        dst = dst if src.is_dir() else dst.with_suffix(".py")
        dst.parent.mkdir(parents=True, exist_ok=True)
        run("git", "mv", str(src), str(dst))
        delta = len(dst.parts) - len(src.parts)
        if delta:
            for f in ([dst] if dst.is_file() else sorted(dst.rglob("*.py"))):
                fix_depth(f, delta)
    for old, new in DATA_MOVES.items():
        if Path(P, old).exists():
            Path(P, new).parent.mkdir(parents=True, exist_ok=True)
            run("git", "mv", str(Path(P, old)), str(Path(P, new)))
    # 3. every reference, by longest prefix
    files = [Path(f) for f in run("git", "ls-files").split() if Path(f).suffix in TEXT_SUFFIXES]
    files += [Path(f) for f in run("git", "ls-files", "--others", "--exclude-standard").split()
              if Path(f).suffix in TEXT_SUFFIXES]
    changed = 0
    for f in files:
        if not f.is_file() or (args.no_docs and f.suffix == ".md" and f.parts[0] in ("docs", "lab")):
            continue
        if f.parts[:2] == ("lab", "house-move"):  # this tool and its mapping stay as written
            continue
        s = f.read_text()
        s2 = rewrite_text(s)
        if s2 != s:
            f.write_text(s2)
            changed += 1
    print(f"rewrote references in {changed} files")
    # names built at run time: helpers such as ``core("errors")`` / ``_api("input_image")`` that
    # import f"specgen_addon.{name}": their string arguments are mapped
    for f in files:
        if f.suffix == ".py" and f.is_file():
            t = f.read_text()
            t2 = map_dynamic_helpers(t)
            if t2 != t:
                f.write_text(t2)
                print(f"  run-time module names mapped in {f}")
    # names built at run time: the command modules the CLI imports by name
    cli_main = Path(P, "cli", "app.py")
    if cli_main.is_file():
        t = cli_main.read_text()
        t2 = re.sub(r'"(cli_\w+)"', lambda m: '"%s"' % MAPPING.get(m.group(1), "cli." + m.group(1)).split(".", 1)[1], t)
        if t2 != t:
            cli_main.write_text(t2)
            print("  command modules renamed in", cli_main)
    # scripts outside the package: the editable install (scripts/setup.sh) makes the core importable
    kept, cleaned = [], []
    for f in files:
        if f.suffix != ".py" or f.parts[0] not in ("bench", "scripts", "lab") or not f.is_file():
            continue
        t = f.read_text()
        if not SYS_PATH.search(t):
            continue
        if re.search(r"(?m)^\s*import batch\b|^\s*from batch import", t):
            kept.append(str(f))
            continue
        t = SYS_PATH.sub("", t)
        if not re.search(r"\bsys\.", t):
            t = re.sub(r"(?m)^import sys\n", "", t, count=1)
        f.write_text(t)
        cleaned.append(str(f))
        print(f"  sys.path.insert removed: {f}")
    ruff = Path(".venv/bin/ruff")
    if cleaned and ruff.exists():  # imports that only served the path set-up (e.g. pathlib.Path)
        subprocess.run([str(ruff), "check", "-q", "--select", "F401", "--fix", *cleaned], check=False)
    if kept:
        print("sys.path.insert kept (the script imports batch.py from the repository root):", *kept,
              sep="\n  ")
    print("modules left where they are (place them by hand):", *unknown or ["none"], sep="\n  ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
