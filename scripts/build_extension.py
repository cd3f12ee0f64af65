"""Build the SpecGen Blender extension zip (what ``blender --command extension build`` makes).

The zip holds the repository root as the extension package (``blender_manifest.toml``,
``__init__.py``, ``ops/``, ``specgen_addon/``, the shipped weights), minus the paths the manifest's
``[build] paths_exclude_pattern`` excludes. The onnxruntime wheel the manifest lists is 23.7 MB, so
it is not committed: ``--fetch-wheels`` downloads it with ``pip download`` into ``wheels/`` first.
``--no-wheels`` builds a zip without the ``wheels`` entry (for tests and Blenders that already have
onnxruntime).

    .venv/bin/python scripts/build_extension.py --fetch-wheels          # dist/specgen-<ver>.zip
    .venv/bin/python scripts/build_extension.py --no-wheels --out X.zip
"""

from __future__ import annotations

import argparse
import fnmatch
import re
import subprocess
import sys
import zipfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SIZE_LIMIT_BYTES = 60 * 2**20  # per platform (docs/blender.md)


def _manifest() -> tuple[str, dict]:
    text = (REPO / "blender_manifest.toml").read_text()
    try:
        import tomllib
    except ImportError:  # Python < 3.11
        import tomli as tomllib  # type: ignore[no-redef]
    return text, tomllib.loads(text)


def _excluded(rel: str, is_dir: bool, patterns: list[str]) -> bool:
    """gitignore-style subset used by Blender's builder: '/x' anchors at the root, 'x/' = dirs."""
    name = rel.rsplit("/", 1)[-1]
    for pat in patterns:
        anchored = pat.startswith("/")
        p = pat.strip("/")
        dir_only = pat.endswith("/")
        if dir_only and not is_dir:
            continue
        if anchored:
            if fnmatch.fnmatch(rel, p):
                return True
        elif fnmatch.fnmatch(name, p) or fnmatch.fnmatch(rel, p):
            return True
    return False


def fetch_wheels(wheels: list[str]) -> None:
    """pip-download each listed wheel (cp311, manylinux x86_64) into wheels/ unless present."""
    for entry in wheels:
        path = REPO / entry
        if path.is_file():
            continue
        m = re.match(r"([A-Za-z0-9_.]+)-([0-9][^-]*)-", path.name)
        if not m:
            raise SystemExit(f"cannot parse wheel name {path.name}")
        path.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-m", "pip", "download", f"{m.group(1)}=={m.group(2)}",
                        "--only-binary=:all:", "--no-deps", "--python-version", "3.11",
                        "--platform", "manylinux_2_28_x86_64", "-d", str(path.parent)], check=True)
        if not path.is_file():
            raise SystemExit(f"pip did not produce {path.name}")


def build(out: Path, with_wheels: bool = True) -> Path:
    """Write the extension zip to ``out``; returns it."""
    text, manifest = _manifest()
    patterns = list(manifest.get("build", {}).get("paths_exclude_pattern", []))
    wheels = list(manifest.get("wheels", []))
    if with_wheels:
        missing = [w for w in wheels if not (REPO / w).is_file()]
        if missing:
            raise SystemExit(f"missing wheel {missing[0]} (run with --fetch-wheels)")
    else:
        text = re.sub(r"(?ms)^wheels\s*=\s*\[.*?\]\s*\n", "", text)
    out.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("blender_manifest.toml", text)
        for path in sorted(REPO.rglob("*")):
            rel = path.relative_to(REPO).as_posix()
            parts = rel.split("/")
            if rel == "blender_manifest.toml" or path.resolve() == out.resolve():
                continue
            if any(_excluded("/".join(parts[:i + 1]), True, patterns) for i in range(len(parts) - 1)):
                continue
            if path.is_dir() or _excluded(rel, False, patterns):
                continue
            if parts[0] == "wheels" and (not with_wheels or rel not in {w.lstrip("./") for w in wheels}):
                continue
            zf.write(path, rel)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None, help="zip path (default dist/specgen-<version>.zip)")
    ap.add_argument("--fetch-wheels", action="store_true", help="pip-download the manifest's wheels first")
    ap.add_argument("--no-wheels", action="store_true", help="leave the wheels out (and out of the manifest)")
    args = ap.parse_args(argv)
    _, manifest = _manifest()
    out = args.out or REPO / "dist" / f"{manifest['id']}-{manifest['version']}.zip"
    if args.fetch_wheels and not args.no_wheels:
        fetch_wheels(list(manifest.get("wheels", [])))
    zip_path = build(out, with_wheels=not args.no_wheels)
    size = zip_path.stat().st_size
    print(f"{zip_path} ({size / 2**20:.1f} MiB = {size:,} bytes)")
    if size > SIZE_LIMIT_BYTES:
        print(f"warning: the zip is above the {SIZE_LIMIT_BYTES / 2**20:.0f} MiB per-platform budget",
              file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
