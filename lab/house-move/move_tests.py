#!/usr/bin/env python3
"""Move the flat tests/test_*.py files into folders that mirror the product, and fix what a move breaks.

Run from a repository root (deterministic, re-runnable: on a tree where it already ran it moves only
the flat test files that appeared since, e.g. from a merged branch):

    python lab/house-move/move_tests.py            # git mv + rewrite, prints what it did
    python lab/house-move/move_tests.py --dry-run  # only print the plan (and what the rule placed)

Folders: ``tests/<package>/`` for the unit tests of one package of specgen_addon (common, spectral,
brdf, photo, render, corpus, model, generate, bake, train, evaluation, scale, cli), ``tests/ops/``
for the Blender tier, ``tests/batch/`` for batch.py end to end, ``tests/extension/`` for the zip,
its manifest and the stock Blender, ``tests/house/`` for checks on the whole product (layers,
installability, docs, the one bad-input suite).

1. Each flat ``tests/test_*.py`` goes where :data:`PLACES` says; a file it does not know goes by
   :func:`place_by_rule` (the specgen_addon package it imports most; bpy or the add-on's modules:
   ops), and is printed so its line can be added to :data:`PLACES`.
2. Helper modules (``conftest.py``, ``tiny_model.py``, ...) stay in tests/: pytest's ``pythonpath``
   gets ``tests`` so they import by name from every folder, and ``--import-mode=importlib`` lets two
   folders hold files of the same name (a test module is ``tests.<folder>.test_x``).
3. In a moved file ``Path(__file__)...parents[N]`` / ``.parent`` gain the new depth.
4. Imports between test modules (``from test_x import y``) become ``from tests.<folder>.test_x import y``.
5. Every path ``tests/test_x.py`` in the tracked text files (docs/, scripts/, .ci/, lab/, tests/,
   docstrings and comments) becomes its new path.
"""
from __future__ import annotations

import argparse
import ast
import re
import subprocess
import sys
import tomllib
from collections import Counter
from pathlib import Path

TESTS = Path("tests")
#: The product packages in layer order (lowest first): the rule's tie-break takes the highest.
PACKAGES = ("common", "spectral", "brdf", "render", "corpus", "photo", "model", "bake", "generate",
            "train", "evaluation", "scale", "cli")
OTHER_FOLDERS = ("ops", "batch", "extension", "house")

#: Test file -> folder under tests/. Files not listed are placed by :func:`place_by_rule`.
PLACES: dict[str, str] = {
    # common: errors, atomic writes and locks, clean stops, worker processes
    "test_io_utils.py": "common",
    "test_faults.py": "common",
    "test_interrupts.py": "common",
    "test_spawn_workers.py": "common",
    # spectral: spectra, colour tables, RGB -> spectrum
    "test_spectra.py": "spectral",
    "test_colour_tables.py": "spectral",
    "test_spectral_recovery.py": "spectral",
    # brdf: the table, coordinates, file formats
    "test_table.py": "brdf",
    "test_rusinkiewicz.py": "brdf",
    "test_rgl.py": "brdf",
    "test_merl.py": "brdf",
    "test_lookup_reach.py": "brdf",
    "test_material_file.py": "brdf",
    "test_exports.py": "brdf",
    # render: the reference renderer, environment maps, outputs, metrics
    "test_render.py": "render",
    "test_metrics.py": "render",
    "test_spectral_exr.py": "render",
    "test_lighting_layouts.py": "render",
    "test_lighting_inner_bpy.py": "render",
    # corpus
    "test_corpus.py": "corpus",
    "test_corpus_families.py": "corpus",
    "test_colour_twin.py": "corpus",
    # photo: decode, find and crop the sphere, the photo's lighting
    "test_photo_decode.py": "photo",
    "test_input_image.py": "photo",
    "test_sphere_edge.py": "photo",
    "test_ndimage_np.py": "photo",
    "test_real_photos.py": "photo",
    "test_light_probe_and_estimate.py": "photo",
    "test_room_lights.py": "photo",
    # model: the network, its runtime and ONNX export
    "test_model.py": "model",
    "test_model_average.py": "model",
    "test_model_grow.py": "model",
    "test_dormant_units.py": "model",
    "test_onnx.py": "model",
    "test_infer.py": "model",
    "test_infer_without_torch.py": "model",
    # bake: what Blender reads, computed without bpy
    "test_bake.py": "bake",
    "test_fit_closures.py": "bake",
    "test_uplift.py": "bake",
    # generate: network -> refinement / latent fit / thin film
    "test_refine.py": "generate",
    "test_refine_excludes_saturated.py": "generate",
    "test_refine_relax.py": "generate",
    "test_latent_fit.py": "generate",
    "test_thin_film_fit.py": "generate",
    "test_shipped_networks.py": "generate",
    # train
    "test_train.py": "train",
    "test_train_distributed.py": "train",
    "test_balanced_loss.py": "train",
    "test_config_extends.py": "train",
    "test_input_jitter.py": "train",
    "test_rendered_scale_loss.py": "train",
    "test_real_rgb_training.py": "train",
    "test_real_cv.py": "train",
    "test_recolour.py": "train",
    # evaluation: baselines, the paper's tables, ablations (and the bench's statistics it feeds)
    "test_photo_fit.py": "evaluation",
    "test_evaluation.py": "evaluation",
    "test_evaluate_families.py": "evaluation",
    "test_family_table.py": "evaluation",
    "test_paired_families.py": "evaluation",
    "test_ablation_study.py": "evaluation",
    "test_ablate_workers.py": "evaluation",
    # scale: batch-many
    "test_batch_many.py": "scale",
    "test_batch_many_faults.py": "scale",
    # cli
    "test_cli.py": "cli",
    "test_scene_args.py": "cli",
    # ops: the Blender tier, headless with the bpy module
    "test_blender_addon.py": "ops",
    "test_apply_undo.py": "ops",
    "test_generate_undo.py": "ops",
    "test_blend_travel.py": "ops",
    "test_exact_mode.py": "ops",
    "test_export_brdf_panel.py": "ops",
    "test_fullscene.py": "ops",
    "test_fullscene_fidelity.py": "ops",
    "test_materials.py": "ops",
    "test_principled_exports.py": "ops",
    "test_render_settings.py": "ops",
    "test_result_view.py": "ops",
    # batch: batch.py end to end
    "test_batch_blender.py": "batch",
    "test_batch_outputs.py": "batch",
    "test_batch_scene_apply.py": "batch",
    # extension: the zip, its manifest, the stock Blender
    "test_platform_zips.py": "extension",
    "test_stock_blender.py": "extension",
    # house: the whole product (layers, one import scheme, installable, docs, bad input everywhere)
    "test_layers.py": "house",
    "test_core_no_bpy.py": "house",
    "test_one_import_scheme.py": "house",
    "test_installable.py": "house",
    "test_docs_links.py": "house",
    "test_bad_input.py": "house",
}

#: Names other test modules imported from a test module, now in a helper module of tests/:
#: (test module, name) -> "helper.name". A branch written before the move keeps working.
MOVED_NAMES: dict[tuple[str, str], str] = {
    ("test_train", "FAST"): "tiny_training.FAST_TRAIN",
    ("test_train", "SMALL"): "tiny_training.TRAIN_MODEL",
    ("test_train", "sets"): "tiny_training.material_sets",
    ("test_train", "twice_and_without"): "tiny_training.twice_and_without",
    ("test_interrupts", "FAKE_BLENDER"): "stop_stand_ins.FAKE_BLENDER",
}

TEXT_SUFFIXES = {".py", ".sh", ".toml", ".cfg", ".ini", ".txt", ".md", ".yml", ".yaml"}
#: Extension-less text files that may name test paths.
TEXT_NAMES = {".ci/run"}
#: The add-on's Blender tier, seen from a test.
BLENDER_IMPORTS = {"bpy", "addon_modules", "mathutils", "bpy_extras"}


def git(*cmd: str) -> str:
    return subprocess.run(["git", *cmd], check=True, capture_output=True, text=True).stdout


def imported_modules(src: str) -> list[str]:
    """Modules a file imports, one per statement (``import a.b``, ``from a.b import c``: ``a.b``;
    ``from specgen_addon import x``: ``specgen_addon.x``), and ``import_module("…")`` /
    ``addon_module("…")`` calls."""
    names: list[str] = []
    try:
        tree = ast.parse(src)
    except SyntaxError:
        return names
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            if node.module == "specgen_addon":
                names += [f"specgen_addon.{a.name}" for a in node.names]
            else:
                names.append(node.module)
        elif (isinstance(node, ast.Call) and node.args and isinstance(node.args[0], ast.Constant)
              and isinstance(node.args[0].value, str) and getattr(node.func, "id", getattr(node.func, "attr", ""))
              in ("import_module", "addon_module")):
            names.append(node.args[0].value)
    return names


def place_by_rule(path: Path) -> tuple[str, str]:
    """(folder, why) for a test file :data:`PLACES` does not know."""
    src = path.read_text()
    mods = imported_modules(src)
    tops = {m.split(".")[0] for m in mods}
    if tops & BLENDER_IMPORTS or any(m.startswith("ops.") or m == "ops" for m in mods):
        return "ops", "imports bpy or the add-on's Blender tier"
    if "batch" in tops:
        return "batch", "imports batch.py"
    counts = Counter(m.split(".")[1] for m in mods
                     if m.startswith("specgen_addon.") and m.split(".")[1] in PACKAGES)
    if not counts:
        return "house", "imports no package of specgen_addon"
    best = max(counts.values())
    top = max((p for p, n in counts.items() if n == best), key=PACKAGES.index)
    return top, "imports specgen_addon." + ", ".join(f"{p} ×{n}" for p, n in counts.most_common())


def plan() -> list[tuple[Path, Path, str]]:
    """(source, destination, why) for every flat test file."""
    moves = []
    for src in sorted(TESTS.glob("test_*.py")):
        if src.name in PLACES:
            folder, why = PLACES[src.name], "table"
        else:
            folder, why = place_by_rule(src)
        dst = TESTS / folder / src.name
        there = sorted(TESTS.glob(f"*/{src.name}"))
        if there:
            sys.exit(f"{src}: {there[0]} has that name already; rename one of them (a test file's name "
                     "is how docs and other tests refer to it)")
        moves.append((src, dst, why))
    return moves


def where_tests_are() -> dict[str, Path]:
    """Test module name -> its file, for the files already in folders."""
    return {p.stem: p for p in sorted(TESTS.glob("*/test_*.py"))}


DEPTH = re.compile(r"(Path\(__file__\)(?:\.resolve\(\)|\.absolute\(\))?)\.(?:parent(?!s)|parents\[(\d+)\])")


def fix_depth(src: str, delta: int) -> str:
    """Paths built from ``__file__`` in a file moved ``delta`` folders deeper: ``Path(__file__).parent``
    / ``.parents[N]``, ``Path(__file__).with_name(x)`` (a helper left in tests/) and
    ``os.path.dirname(__file__)`` still name the folders they named."""
    if delta <= 0:
        return src

    def deeper(m: re.Match) -> str:
        n = int(m.group(2)) if m.group(2) is not None else 0
        return f"{m.group(1)}.parents[{n + delta}]"
    src = DEPTH.sub(deeper, src)
    src = re.sub(r"(Path\(__file__\)(?:\.resolve\(\)|\.absolute\(\))?)\.with_name\(",
                 lambda m: f"{m.group(1)}.parents[{delta}].joinpath(", src)
    up = "os.path.dirname(" * delta
    return re.sub(r"os\.path\.dirname\((os\.path\.(?:abspath|realpath)\(__file__\)|__file__)\)",
                  lambda m: f"os.path.dirname({up}{m.group(1)}{')' * delta})", src)


def fix_test_imports(src: str, where: dict[str, Path]) -> str:
    """``from test_x import y`` / ``import test_x`` of a test module now in a folder: from the helper
    module that holds ``y`` now (:data:`MOVED_NAMES`), else from ``tests.<folder>.test_x``."""
    def dotted(name: str) -> str:
        return ".".join(where[name].with_suffix("").parts)

    def from_import(m: re.Match) -> str:
        indent, module, names = m.group(1), m.group(2), m.group(3)
        comment = m.group(4) or ""
        items = [n.strip() for n in names.strip("()").replace("\n", " ").split(",") if n.strip()]
        pairs = [(i.split(" as ")[0].strip(), i.split(" as ")[-1].strip()) for i in items]
        if pairs and all((module, n) in MOVED_NAMES for n, _ in pairs):
            lines = []
            for n, alias in pairs:
                helper, new = MOVED_NAMES[(module, n)].rsplit(".", 1)
                lines.append(f"{indent}from {helper} import {new}" + (f" as {alias}" if alias != new else ""))
            return "\n".join(lines) + comment
        if module not in where:
            return m.group(0)
        return f"{indent}from {dotted(module)} import {names}{comment}"

    def plain_import(m: re.Match) -> str:
        name = m.group(2)
        if name not in where:
            return m.group(0)
        pkg, mod = dotted(name).rsplit(".", 1)
        return f"{m.group(1)}from {pkg} import {mod}"

    src = re.sub(r"(?m)^([ \t]*)from (test_\w+) import (\([^)]*\)|[^\n#]*?)([ \t]*#.*)?$", from_import, src)
    return re.sub(r"(?m)^([ \t]*)import (test_\w+)\b(?=[ \t]*(?:#.*)?$)", plain_import, src)


def fix_paths(src: str, where: dict[str, Path]) -> str:
    """Every ``tests/test_x.py`` of a moved file becomes its new path."""
    def repl(m: re.Match) -> str:
        return where[m.group(1)].as_posix() if m.group(1) in where else m.group(0)
    return re.sub(r"(?<![\w-])(?<![\w-]/)tests/(test_\w+)\.py", repl, src)


def fix_pytest_config(path: Path = Path("pyproject.toml")) -> bool:
    """pytest's config: helpers in tests/ importable by name, same-named files in two folders."""
    text = path.read_text()
    conf = tomllib.loads(text).get("tool", {}).get("pytest", {}).get("ini_options")
    if conf is None:
        sys.exit(f"no [tool.pytest.ini_options] in {path}: add it, then run this again")
    new = text
    if "tests" not in conf.get("pythonpath", []):
        paths = [*conf.get("pythonpath", []), "tests"]
        line = "pythonpath = [" + ", ".join(f'"{p}"' for p in paths) + "]"
        if "pythonpath" in conf:
            new = re.sub(r"(?m)^pythonpath\s*=.*$", line, new, count=1)
        else:
            new = re.sub(r"(?m)^(testpaths\s*=.*)$", r"\1\n" + line, new, count=1)
    addopts = conf.get("addopts", "")
    if "--import-mode" not in addopts:
        if "addopts" in conf:
            new = re.sub(r'(?m)^addopts\s*=\s*"([^"]*)"', lambda m: f'addopts = "{m.group(1)} --import-mode=importlib"',
                         new, count=1)
        else:
            new = re.sub(r"(?m)^(testpaths\s*=.*)$", r'\1\naddopts = "--import-mode=importlib"', new, count=1)
    if new != text:
        path.write_text(new)
    return new != text


def text_files() -> list[Path]:
    names = git("ls-files").splitlines() + git("ls-files", "--others", "--exclude-standard").splitlines()
    return [Path(n) for n in names
            if (Path(n).suffix in TEXT_SUFFIXES or n in TEXT_NAMES) and Path(n).is_file()]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dry-run", action="store_true", help="print the plan, change nothing")
    args = ap.parse_args()
    if not (Path("specgen_addon") / "__init__.py").is_file() or not TESTS.is_dir():
        sys.exit("run from the repository root")
    moves = plan()
    for src, dst, why in moves:
        if why != "table":
            print(f"placed by rule: {src} -> {dst.parent}/  ({why}); add it to PLACES to keep it there")
    stale = sorted(n for n in PLACES if not (TESTS / n).exists() and not any(TESTS.glob(f"*/{n}")))
    print(f"{len(moves)} flat test files to move; already in folders: {len(where_tests_are())}"
          + (f"; listed but absent: {', '.join(stale)}" if stale else ""))
    if args.dry_run:
        for src, dst, _ in moves:
            print(f"  {src} -> {dst}")
        return 0
    for src, dst, _ in moves:
        dst.parent.mkdir(parents=True, exist_ok=True)
        if git("ls-files", str(src)).strip():
            git("mv", str(src), str(dst))
        else:                                   # not tracked yet (a new file): a plain move
            src.rename(dst)
        dst.write_text(fix_depth(dst.read_text(), len(dst.parts) - len(src.parts)))
    where = where_tests_are()
    changed = []
    for f in text_files():
        if f.parts[:2] == ("lab", "house-move"):   # this tool and its record stay as written
            continue
        s = f.read_text()
        s2 = fix_paths(s, where)
        if f.suffix == ".py" and f.parts[0] in ("tests", "lab", "bench", "scripts"):
            s2 = fix_test_imports(s2, where)
        if s2 != s:
            f.write_text(s2)
            changed.append(str(f))
    if fix_pytest_config():
        changed.append("pyproject.toml (pytest: pythonpath tests, --import-mode=importlib)")
    print(f"moved {len(moves)} files; rewrote {len(changed)} files:", *changed, sep="\n  ")
    return 0


if __name__ == "__main__":
    sys.exit(main())
