"""Build the SpecGen Blender extension zips with Blender's own builder, one per platform.

The zips are made by ``blender --command extension build --split-platforms``: the same code ships
in the bpy wheel (``bl_pkg/cli/blender_ext.py``), which this script runs with its own Python, or a
real Blender given with ``--blender``. Each zip is then checked by Blender's validator. The
onnxruntime wheels the manifest lists (one per platform, about 15–24 MB each) are not committed:
``--fetch-wheels`` downloads the missing ones with ``pip download`` into ``wheels/`` first.

The builder runs on a staged copy of the extension's files (the package, its weights, the
manifest and the listed wheels only), so nothing else lying in the working tree reaches a zip.

    .venv/bin/python scripts/build_extension.py --fetch-wheels            # dist/specgen-<ver>-<platform>.zip ×4
    .venv/bin/python scripts/build_extension.py --fetch-wheels --out X.zip    # this machine's platform only
    .venv/bin/python scripts/build_extension.py --no-wheels --out X.zip   # no wheels, every platform
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SIZE_LIMIT_BYTES = 60 * 2**20  # per platform (docs/blender.md)
#: What the extension is made of (the manifest's exclude patterns then apply inside these).
SOURCES = ("__init__.py", "ops", "specgen_addon", "weights", "configs")


def _manifest() -> tuple[str, dict]:
    text = (REPO / "blender_manifest.toml").read_text(encoding="utf-8")
    return text, tomllib.loads(text)


def wheel_platform(wheel: str) -> str:
    """The Blender platform of a wheel file name (``…-win_amd64.whl`` → ``windows-x64``)."""
    tag = Path(wheel).stem.split("-")[-1]
    system = {"win": "windows", "macosx": "macos", "manylinux": "linux", "musllinux": "linux"}
    head = next((b for w, b in system.items() if tag.startswith(w)), None)
    machine = "arm64" if tag.endswith(("arm64", "aarch64")) else "x64" if tag.endswith(("x86_64", "amd64")) else None
    if head is None or machine is None:
        raise SystemExit(f"cannot tell the platform of wheel {wheel}")
    return f"{head}-{machine}"


def host_platform() -> str:
    """This machine's Blender platform name (``linux-x64``, ``windows-x64``, ``macos-arm64`` …)."""
    import platform

    system = {"darwin": "macos"}.get(platform.system().lower(), platform.system().lower())
    machine = platform.machine().lower()
    return f"{system}-{'arm64' if machine in ('arm64', 'aarch64') else 'x64'}"


def fetch_wheels(wheels: list[str]) -> None:
    """pip-download each listed wheel for its own platform into ``wheels/`` unless present."""
    for entry in wheels:
        path = REPO / entry
        if path.is_file():
            continue
        parts = path.stem.split("-")
        if len(parts) < 5:
            raise SystemExit(f"cannot parse wheel name {path.name}")
        platforms = [a for p in parts[-1].split(".") for a in ("--platform", p)]
        path.parent.mkdir(parents=True, exist_ok=True)
        subprocess.run([sys.executable, "-m", "pip", "download", f"{parts[0]}=={parts[1]}",
                        "--only-binary=:all:", "--no-deps", "--python-version", "3.11", *platforms,
                        "-d", str(path.parent)], check=True)
        if not path.is_file():
            raise SystemExit(f"pip did not produce {path.name}")


def blender_ext_command(blender: str | None) -> list[str]:
    """The command that runs Blender's extension CLI: a real Blender or the bpy wheel's copy."""
    if blender:
        return [blender, "--factory-startup", "--command", "extension"]
    spec = importlib.util.find_spec("bpy")
    roots = list(spec.submodule_search_locations or []) if spec else []
    found = next((p for r in roots for p in Path(r).glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py")), None)
    if found is None:
        raise SystemExit("Blender's extension builder was not found: install the bpy wheel or pass --blender")
    return [sys.executable, str(found)]


def _set_list(text: str, key: str, values: list[str] | None) -> str:
    """The manifest with ``key = [...]`` replaced by ``values`` (removed when None)."""
    pattern = rf"(?ms)^{key}\s*=\s*\[.*?\]\s*\n"
    if values is None:
        return re.sub(pattern, "", text)
    body = f"{key} = [\n" + "".join(f'  "{v}",\n' for v in values) + "]\n"
    return re.sub(pattern, lambda m: body, text)


def stage(dest: Path, platforms: list[str] | None, with_wheels: bool) -> None:
    """Copy the extension's files into ``dest`` with a manifest for ``platforms`` (all when None)."""
    text, manifest = _manifest()
    wheels = list(manifest.get("wheels", []))
    if platforms is not None:
        wheels = [w for w in wheels if wheel_platform(w) in platforms]
        text = _set_list(text, "platforms", platforms)
    if not with_wheels:
        wheels = []
        text = _set_list(text, "wheels", None)
        if platforms is None:
            text = _set_list(text, "platforms", None)
    else:
        text = _set_list(text, "wheels", wheels)
        missing = [w for w in wheels if not (REPO / w).is_file()]
        if missing:
            raise SystemExit(f"missing wheel {missing[0]} (run with --fetch-wheels)")
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "blender_manifest.toml").write_text(text, encoding="utf-8")
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
    for name in SOURCES:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dest / name, ignore=ignore)
        elif src.is_file():
            shutil.copy2(src, dest / name)
    for w in wheels:
        (dest / w).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(REPO / w, dest / w)


def _run(cmd: list[str]) -> str:
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(cmd[-4:])} failed:\n{done.stdout}{done.stderr}")
    return done.stdout


def build(out: Path | None = None, out_dir: Path | None = None, platform: str | None = None,
          with_wheels: bool = True, blender: str | None = None) -> list[Path]:
    """Build and validate the zips; returns their paths.

    ``out`` names one zip: for ``platform`` (default this machine's) with wheels, or for every
    platform without them.
    Otherwise one zip per platform goes to ``out_dir`` (``<id>-<version>-<platform>.zip``)."""
    ext = blender_ext_command(blender)
    _, manifest = _manifest()
    with tempfile.TemporaryDirectory(prefix="specgen-build-") as tmp:
        src = Path(tmp) / "src"
        if out is not None:
            if with_wheels and platform is None:
                platform = host_platform()
            stage(src, [platform] if platform else None, with_wheels)
            out.parent.mkdir(parents=True, exist_ok=True)
            out.unlink(missing_ok=True)
            _run([*ext, "build", "--source-dir", str(src), "--output-filepath", str(out)])
            zips = [out]
        else:
            out_dir = out_dir or REPO / "dist"
            out_dir.mkdir(parents=True, exist_ok=True)
            platforms = [platform] if platform else list(manifest["platforms"])
            stage(src, platforms, with_wheels)
            stem = f"{manifest['id']}-{manifest['version']}"
            zips = [out_dir / f"{stem}-{p.replace('-', '_')}.zip" for p in platforms]
            for z in zips:
                z.unlink(missing_ok=True)
            _run([*ext, "build", "--source-dir", str(src), "--output-dir", str(out_dir), "--split-platforms"])
    for z in zips:
        if not z.is_file():
            raise SystemExit(f"Blender's builder did not write {z}")
        _run([*ext, "validate", str(z)])
    return zips


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=None,
                    help="one zip: --platform's (default this machine's) or a wheel-less one (--no-wheels)")
    ap.add_argument("--out-dir", type=Path, default=None, help="folder of the per-platform zips (default dist/)")
    ap.add_argument("--platform", default=None, help="build only this platform's zip (e.g. linux-x64)")
    ap.add_argument("--fetch-wheels", action="store_true", help="pip-download the manifest's missing wheels first")
    ap.add_argument("--no-wheels", action="store_true", help="leave the wheels out (and out of the manifest)")
    ap.add_argument("--blender", default=None, help="a Blender executable whose builder to use "
                                                    "(default: the bpy wheel's copy of it)")
    args = ap.parse_args(argv)
    _, manifest = _manifest()
    if args.platform and args.platform not in manifest["platforms"]:
        raise SystemExit(f"--platform {args.platform}: the manifest lists {', '.join(manifest['platforms'])}")
    if args.fetch_wheels and not args.no_wheels:
        wheels = list(manifest.get("wheels", []))
        only = args.platform or (host_platform() if args.out else None)
        fetch_wheels([w for w in wheels if only in (None, wheel_platform(w))])
    zips = build(args.out, args.out_dir, args.platform, not args.no_wheels, args.blender)
    for z in zips:
        size = z.stat().st_size
        print(f"wrote {z} ({size / 2**20:.1f} MiB = {size:,} bytes), validated")
        if size > SIZE_LIMIT_BYTES:
            print(f"warning: {z.name} is above the {SIZE_LIMIT_BYTES / 2**20:.0f} MiB per-platform budget",
                  file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
