"""Bad input across the CLI, batch.py, the operators (headless bpy) and the Python API.

Every case asserts: the exit status (2 for an error, 130/143 for SIGINT/SIGTERM), no "Traceback"
in the output, a message naming the problem, and that the test's whole folder (inputs, output
folder, existing outputs) is exactly as before: nothing new, existing files byte-identical.
CLI and batch.py cases run in-process through the same ``main`` functions the commands use; the
interrupt cases send real signals to real processes (marked slow).
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import struct
import subprocess
import sys
import time
import warnings
import zlib
from importlib import import_module
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.cli import app as cli
from specgen_addon.common.errors import BRDFFormatError, ImageInputError, SpecGenError, WeightsError
from specgen_addon.brdf.formats.merl import MERLData, write_merl
from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "sphere.png"
WEIGHTS = REPO / "weights" / "specgen_default.pt"


# ------------------------------------------------------------------------------------ fixtures
def snapshot(folder: Path) -> dict[str, bytes | None]:
    """Every file (with its bytes) and folder under ``folder``."""
    return {str(p.relative_to(folder)): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


def _table(values: np.ndarray) -> BRDFTable:
    return BRDFTable(values, np.linspace(400, 700, values.shape[-1]))


def _save_raw_table(path: Path, values: np.ndarray) -> Path:
    """A table file with arbitrary values (bypassing nothing: the loader is what is tested)."""
    _table(np.ones(GRID_SHAPE + (values.shape[-1],), np.float32)).save(path)
    header = {"format": "specgen-brdf-table", "version": 1,
              "channels": [f"{w:g}nm" for w in np.linspace(400, 700, values.shape[-1])], "metadata": {}}
    with open(path, "wb") as fh:
        np.savez(fh, values=values.astype(np.float32), wavelengths=np.linspace(400, 700, values.shape[-1]),
                 header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    return path


def _png_header_only(path: Path, width: int, height: int) -> Path:
    """A PNG whose header claims ``width × height`` (its data would take GBs to decode)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) +
                     chunk(b"IDAT", zlib.compress(b"\x00" * 1024)) + chunk(b"IEND", b""))
    return path


def _exr(path: Path, rgb: np.ndarray) -> Path:
    import OpenEXR

    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION},
                      {"RGB": np.ascontiguousarray(rgb, np.float32)}) as f:
        f.write(str(path))
    return path


def _sphere_rgb(size: int = 64) -> np.ndarray:
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * 2 - 1
    disc = x * x + y * y < 0.8
    return np.where(disc[..., None], 0.4 + 0.3 * np.clip(-y, 0, 1)[..., None], 0.0) * np.ones(3)


def _rgl_fields():
    from specgen_addon.brdf.formats.rgl import read_tensor_file, write_rgl

    m, s = 8, 3
    path = write_rgl(Path(os.environ["SPECGEN_TEST_TMP"]) / "good.bsdf", description="synthetic",
                     theta_i=np.linspace(0, np.pi / 2, s), ndf=np.full((2, 16), 3.0),
                     sigma=np.full((2, 16), 0.75), vndf=np.ones((1, s, 16, 16)),
                     luminance=np.ones((1, s, m, m)),
                     spectra=np.ones((1, s, 4, m, m)), wavelengths=np.linspace(400.0, 700.0, 4))
    fields = {k: np.array(v) for k, v in read_tensor_file(path).items()}
    path.unlink()
    return fields


def _rgl(path: Path, **changes) -> Path:
    from specgen_addon.brdf.formats.rgl import write_tensor_file

    fields = _rgl_fields()
    for key, value in changes.items():
        fields[key] = value
    write_tensor_file(path, fields)
    return path


class Workspace:
    """Input files made on demand inside the test's folder; ``out`` holds one existing file."""

    def __init__(self, root: Path):
        self.root = root
        self.out = root / "out"
        self.out.mkdir()
        (self.out / "keep.txt").write_text("an existing file that must stay byte-identical")
        self.blocker = root / "a_file"
        self.blocker.write_text("a file where a folder is expected")
        os.environ["SPECGEN_TEST_TMP"] = str(root)

    def __getattr__(self, name: str) -> Path:
        maker = MAKERS[name]
        path = maker(self.root)
        setattr(self, name, path)
        return path


def _merl(root: Path, name: str, fill) -> Path:
    raw = np.ones((3,) + GRID_SHAPE)
    fill(raw)
    return write_merl(root / name, MERLData(raw))


def _obj(root: Path, name: str, text: str) -> Path:
    (root / name).write_text(text)
    return root / name


def _cfg(root: Path, name: str, data) -> Path:
    (root / name).write_text(data if isinstance(data, str) else json.dumps(data))
    return root / name


TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
MAKERS = {
    "merl_inf": lambda r: _merl(r, "huge.binary", lambda a: a.__setitem__((0, 1, 1), 1e300)),
    "merl_nan": lambda r: _merl(r, "nan.binary", lambda a: a.__setitem__((1, 5, 5), np.nan)),
    "merl_invalid": lambda r: _merl(r, "invalid.binary", lambda a: a.__setitem__(Ellipsis, -1.0)),
    "merl_short": lambda r: ((r / "short.binary").write_bytes(b"Z\0\0\0Z\0\0\0\xb4\0\0\0" + b"\0" * 64),
                             r / "short.binary")[1],
    "npz_nan": lambda r: _save_raw_table(r / "nan.npz", np.where(
        np.arange(np.prod(GRID_SHAPE) * 3).reshape(GRID_SHAPE + (3,)) % 1000 == 0, np.nan, 0.1)),
    "npz_inf": lambda r: _save_raw_table(r / "inf.npz", np.full(GRID_SHAPE + (3,), np.inf)),
    "npz_neg": lambda r: _save_raw_table(r / "neg.npz", np.full(GRID_SHAPE + (3,), -0.2)),
    "npz_good": lambda r: _table(np.full(GRID_SHAPE + (4,), 0.1, np.float32)).save(r / "good.npz"),
    "rgl_lum_nan": lambda r: _rgl(r / "lum.bsdf", luminance=np.full((1, 3, 8, 8), np.nan)),
    "rgl_desc_float": lambda r: _rgl(r / "desc.bsdf", description=np.ones(4, np.float32)),
    "rgl_theta_int": lambda r: _rgl(r / "theta.bsdf", theta_i=np.arange(3, dtype=np.int32)),
    "rgl_version_nan": lambda r: _rgl(r / "ver.bsdf", version=np.array([np.nan, 0.0])),
    "rgl_spectra_inf": lambda r: _rgl(r / "inf.bsdf", spectra=np.full((1, 3, 4, 8, 8), np.inf)),
    "obj_vertices_only": lambda r: _obj(r, "verts.obj", TRI),
    "obj_truncated": lambda r: _obj(r, "trunc.obj", TRI + "f 1 2"),
    "obj_nan": lambda r: _obj(r, "nan.obj", TRI + "v nan 0 0\nf 1 2 4\n"),
    "obj_out_of_range": lambda r: _obj(r, "oor.obj", TRI + "f 1 2 7\n"),
    "obj_empty": lambda r: _obj(r, "empty.obj", ""),
    "png_huge": lambda r: _png_header_only(r / "huge.png", 20000, 20000),
    "png_flat": lambda r: _flat_png(r / "flat.png"),
    "exr_nan": lambda r: _exr(r / "nan.exr", np.where(_sphere_rgb() > 0.5, np.nan, _sphere_rgb())),
    "cfg_steps_zero": lambda r: _cfg(r, "steps0.json", {"train": {"steps": 0}}),
    "cfg_steps_ten": lambda r: _cfg(r, "steps10.json", {"train": {"steps": "ten"}}),
    "cfg_lr_nan": lambda r: _cfg(r, "lrnan.json", '{"train": {"lr": NaN}}'),
    "cfg_unknown": lambda r: _cfg(r, "unknown.json", {"train": {"stepz": 3}}),
    "cfg_bool_size": lambda r: _cfg(r, "bool.json", {"model": {"latent_dim": True}}),
    "cfg_broken": lambda r: _cfg(r, "broken.json", "{not json"),
    "run_dir": lambda r: _run_dir(r, b"not a checkpoint"),
    "weights_nan": lambda r: _nan_weights(r / "nan.pt"),
    # found by the campaign (tests/bad_input_cases.py)
    "npz_wl_nan": lambda r: _npz_wavelengths(r / "wlnan.npz", np.array([400.0, np.nan, 600.0, 700.0])),
    "rgl_version_fraction": lambda r: _rgl(r / "ver15.bsdf", version=np.array([1.5, 0.0], np.float32)),
    "cfg_train_null": lambda r: _cfg(r, "trainnull.json", {"train": None}),
    "png_over_libpng_limit": lambda r: _png_header_only(r / "huge100k.png", 100_000, 100_000),
    "blend_bad": lambda r: ((r / "bad.blend").write_bytes(b"BLENDER-v300" + bytes(50)), r / "bad.blend")[1],
    "fifo": lambda r: (os.mkfifo(r / "pipe.png"), r / "pipe.png")[1],   # reading it would block
    "weights_with_graphs": lambda r: _weights_with_graphs(r),
    # faults and limits: environment maps refused from their header like photos
    "env_huge": lambda r: _exr_declaring(r / "huge_env.exr", 20000, 10000),
    "env_square": lambda r: _exr(r / "square_env.exr", np.full((64, 64, 3), 0.5)),
    "env_tall": lambda r: _exr(r / "tall_env.exr", np.full((64, 1, 3), 0.5)),
    "env_wide": lambda r: _exr(r / "wide_env.exr", np.full((1, 64, 3), 0.5)),
    "lookup_link": lambda r: _lookup_link(r),
}


def _exr_declaring(path: Path, width: int, height: int) -> Path:
    """An EXR whose header declares width × height (its pixels would need gigabytes): a 2×1 file
    with its data and display windows rewritten."""
    import struct

    _exr(path, np.full((1, 2, 3), 0.5))
    data = bytearray(path.read_bytes())
    for name in (b"dataWindow", b"displayWindow"):
        at = data.index(name + b"\0box2i\0") + len(name) + 7 + 4
        data[at:at + 16] = struct.pack("<4i", 0, 0, width - 1, height - 1)
    path.write_bytes(bytes(data))
    return path


def _lookup_link(root: Path) -> Path:
    """An output folder whose ``lookup`` is a link to a folder outside it."""
    (root / "elsewhere").mkdir()
    (root / "linked_out").mkdir()
    (root / "linked_out" / "lookup").symlink_to(root / "elsewhere")
    return root / "linked_out"


def _weights_with_graphs(root: Path) -> Path:
    """A copy of the shipped weights with a ``.tables.onnx`` already beside it."""
    (root / "w.pt").write_bytes(WEIGHTS.read_bytes())
    _touch(root / "w.tables.onnx")
    return root / "w.pt"


def _npz_wavelengths(path: Path, wavelengths: np.ndarray) -> Path:
    """A table file whose wavelength axis is ``wavelengths`` (values fine)."""
    values = np.full(GRID_SHAPE + (wavelengths.size,), 0.1, np.float32)
    header = {"format": "specgen-brdf-table", "version": 1, "channels": ["c"] * wavelengths.size, "metadata": {}}
    with open(path, "wb") as fh:
        np.savez(fh, values=values, wavelengths=wavelengths,
                 header=np.frombuffer(json.dumps(header).encode(), dtype=np.uint8))
    return path


def _flat_png(path: Path) -> Path:
    from PIL import Image

    Image.fromarray(np.full((64, 64, 3), 128, np.uint8)).save(path)
    return path


def _run_dir(root: Path, checkpoint: bytes) -> Path:
    d = root / "out" / "run"
    d.mkdir()
    (d / "checkpoint.pt").write_bytes(checkpoint)
    return d


def _nan_weights(path: Path) -> Path:
    torch = pytest.importorskip("torch")
    from specgen_addon.model import load_weights, save_weights

    model = load_weights(WEIGHTS)
    with torch.no_grad():
        next(model.parameters())[...] = float("nan")
    return save_weights(model, path)


@pytest.fixture
def ws(tmp_path) -> Workspace:
    return Workspace(tmp_path)


def assert_clean_failure(code: int, text: str, expected_code: int, needle: str, before: dict,
                         root: Path) -> None:
    assert code == expected_code, text
    assert "Traceback" not in text, text
    assert needle.lower() in text.lower(), text
    assert snapshot(root) == before, "files were added, removed or changed"


# ------------------------------------------------------------------------------------ the CLI
Q = "--quiet"
CLI_CASES = {
    # name: (argv builder, message fragment)
    "tabulate-missing-file": (lambda w: ["tabulate", str(w.root / "nope.binary"), "-o", str(w.out / "t.npz")], "not found"),
    "tabulate-folder-as-file": (lambda w: ["tabulate", str(w.out), "-o", str(w.out / "t.npz")], "is a folder"),
    "tabulate-not-npz": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / "t.txt")], ".npz"),
    "tabulate-existing-output": (lambda w: ["tabulate", str(w.npz_good), "-o", str(_touch(w.out / "t.npz"))], "already exists"),
    "tabulate-bands-0": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / "t.npz"), "--bands", "0"], "--bands"),
    "tabulate-bands-10000": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / "t.npz"), "--bands", "10000"], "--bands"),
    "tabulate-wavelength-100": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / "t.npz"), "--wl-min", "100"], "between 360 and 1000 nm"),
    "tabulate-output-folder-missing": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.root / "no" / "t.npz")], "does not exist"),
    "tabulate-output-is-folder": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out)], "must end in .npz"),
    "tabulate-output-under-file": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.blocker / "t.npz")], "a_file is a file"),
    "tabulate-output-dotdot-missing": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / "x" / ".." / ".." / "no" / "t.npz")], "does not exist"),
    "info-merl-truncated": (lambda w: ["info", str(w.merl_short)], "truncated"),
    "info-merl-overflow": (lambda w: ["info", str(w.merl_inf)], "overflowing"),
    "info-merl-nan": (lambda w: ["info", str(w.merl_nan)], "180 NaN of 4,374,000"),
    "info-merl-all-invalid": (lambda w: ["info", str(w.merl_invalid)], "no valid measurement"),
    "info-npz-nan": (lambda w: ["info", str(w.npz_nan)], "NaN"),
    "info-npz-inf": (lambda w: ["info", str(w.npz_inf)], "infinite"),
    "info-npz-negative": (lambda w: ["info", str(w.npz_neg)], "negative"),
    "info-rgl-luminance-nan": (lambda w: ["info", str(w.rgl_lum_nan)], "luminance"),
    "info-rgl-description-float": (lambda w: ["info", str(w.rgl_desc_float)], "description"),
    "info-rgl-theta-int": (lambda w: ["info", str(w.rgl_theta_int)], "theta_i"),
    "info-rgl-version-nan": (lambda w: ["info", str(w.rgl_version_nan)], "version"),
    "info-rgl-spectra-inf": (lambda w: ["info", str(w.rgl_spectra_inf)], "infinite"),
    "info-folder": (lambda w: ["info", str(w.out)], "is a folder"),
    "corpus-n-0": (lambda w: ["corpus", "--n", "0", "--out", str(w.out / "c"), Q], "--n"),
    "corpus-bands-0": (lambda w: ["corpus", "--n", "3", "--bands", "0", "--out", str(w.out / "c"), Q], "--bands"),
    "corpus-out-under-file": (lambda w: ["corpus", "--n", "3", "--out", str(w.blocker / "c"), Q], "is a file"),
    "corpus-tabulate-dotdot": (lambda w: ["corpus", "--n", "3", "--tabulate", "../../x", "--out", str(w.out), Q], "plain file name"),
    "train-steps-0-flag": (lambda w: ["train", "--out", str(w.out / "t"), "--steps", "0", Q], "--steps"),
    "train-config-steps-0": (lambda w: ["train", "--config", str(w.cfg_steps_zero), "--out", str(w.out / "t"), Q], "train.steps"),
    "train-config-steps-ten": (lambda w: ["train", "--config", str(w.cfg_steps_ten), "--out", str(w.out / "t"), Q], "whole number"),
    "train-config-lr-nan": (lambda w: ["train", "--config", str(w.cfg_lr_nan), "--out", str(w.out / "t"), Q], "finite"),
    "train-config-unknown-key": (lambda w: ["train", "--config", str(w.cfg_unknown), "--out", str(w.out / "t"), Q], "stepz"),
    "train-config-bool-size": (lambda w: ["train", "--config", str(w.cfg_bool_size), "--out", str(w.out / "t"), Q], "latent_dim"),
    "train-config-unparsable": (lambda w: ["train", "--config", str(w.cfg_broken), "--out", str(w.out / "t"), Q], "cannot parse"),
    "train-config-folder": (lambda w: ["train", "--config", str(w.out), "--out", str(w.out / "t"), Q], "is a folder"),
    "train-out-under-file": (lambda w: ["train", "--out", str(w.blocker / "t"), Q], "is a file"),
    "train-resume-without-checkpoint": (lambda w: ["train", "--out", str(w.out), "--resume", Q], "no checkpoint"),
    "train-resume-corrupt-checkpoint": (lambda w: ["train", "--out", str(w.run_dir), "--resume", Q], "corrupt"),
    "train-existing-run": (lambda w: ["train", "--out", str(w.run_dir), Q], "--resume"),
    "infer-missing-image": (lambda w: ["infer", str(w.root / "nope.png"), "-o", str(w.out / "b.npz"), Q], "not found"),
    "infer-image-folder": (lambda w: ["infer", str(w.out), "-o", str(w.out / "b.npz"), Q], "is a folder"),
    "infer-image-over-pixel-limit": (lambda w: ["infer", str(w.png_huge), "-o", str(w.out / "b.npz"), Q], "megapixels"),
    "infer-bands-0": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--bands", "0", Q], "--bands"),
    "infer-bands-10000": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--bands", "10000", Q], "--bands"),
    "infer-range-reversed": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--range", "780", "380", Q], "increase"),
    "infer-existing-output": (lambda w: ["infer", str(EXAMPLE), "-o", str(_touch(w.out / "b.npz")), Q], "already exists"),
    "infer-existing-rgb-output": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--rgb", Q] if _touch(w.out / "b_rgb.npz") else [], "b_rgb.npz: already exists"),
    "infer-output-folder-missing": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.root / "no" / "b.npz"), Q], "does not exist"),
    "infer-weights-missing": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--weights", str(w.root / "w.pt"), Q], "not found"),
    "infer-weights-folder": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--weights", str(w.out), Q], "is a folder"),
    "evaluate-limit-0": (lambda w: ["evaluate", "--limit", "0", Q], "--limit"),
    "evaluate-input-env-without-families": (lambda w: ["evaluate", "--input-env", "courtyard", Q], "--families"),
    "evaluate-input-env-unknown": (lambda w: ["evaluate", "--families", "1", "--input-env", "moon", Q], "no environment map named 'moon'"),
    "evaluate-input-shift-without-families": (lambda w: ["evaluate", "--input-shift", "0.5", Q], "--families"),
    "evaluate-input-shift-9": (lambda w: ["evaluate", "--families", "1", "--input-shift", "9", Q], "--input-shift"),
    "evaluate-input-shift-nan": (lambda w: ["evaluate", "--families", "1", "--input-shift", "nan", Q], "--input-shift"),
    "evaluate-antialias-without-families": (lambda w: ["evaluate", "--input-antialias", Q], "--families"),
    "evaluate-antialias-with-env": (lambda w: ["evaluate", "--families", "1", "--input-antialias", "--input-env",
                                               "courtyard", Q], "--input-env"),
    "evaluate-family-without-families": (lambda w: ["evaluate", "--family", "sheen", Q], "--families"),
    "evaluate-family-unknown": (lambda w: ["evaluate", "--families", "1", "--family", "velvet", Q],
                                "unknown material family 'velvet'"),
    "evaluate-limit-negative": (lambda w: ["evaluate", "--limit", "-1", Q], "--limit"),
    "evaluate-json-folder": (lambda w: ["evaluate", "--json", str(w.out), Q], "is a folder"),
    "evaluate-json-existing": (lambda w: ["evaluate", "--json", str(_touch(w.out / "r.json")), Q], "already exists"),
    "evaluate-json-folder-missing": (lambda w: ["evaluate", "--json", str(w.root / "no" / "r.json"), Q], "does not exist"),
    "render-input-mat9999": (lambda w: ["render-input", "mat9999", "-o", str(w.out / "i.png"), Q], "standard corpus"),
    "render-input-mat99999999": (lambda w: ["render-input", "mat99999999", "-o", str(w.out / "i.png"), Q], "standard corpus"),
    "render-input-size-100000": (lambda w: ["render-input", "mat0001", "-o", str(w.out / "i.png"), "--size", "100000", Q], "--size"),
    "render-input-size-0": (lambda w: ["render-input", "mat0001", "-o", str(w.out / "i.png"), "--size", "0", Q], "--size"),
    "render-input-jpg-output": (lambda w: ["render-input", "mat0001", "-o", str(w.out / "i.jpg"), Q], ".exr or .png"),
    "render-input-existing-output": (lambda w: ["render-input", "mat0001", "-o", str(_touch(w.out / "i.png")), Q], "already exists"),
    "render-input-nan-table": (lambda w: ["render-input", str(w.npz_nan), "-o", str(w.out / "i.png"), Q], "NaN"),
    "render-input-negative-table": (lambda w: ["render-input", str(w.npz_neg), "-o", str(w.out / "i.png"), Q], "negative"),
    "paper-tables-resolution-0": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--resolution", "0", Q], "--resolution"),
    "paper-tables-materials-dotdot": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--materials", "../x", Q], "plain file name"),
    "paper-tables-unknown-material": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--materials", "mat9999", Q], "not test materials"),
    "paper-tables-out-folder-missing": (lambda w: ["paper-tables", "--out", str(w.root / "no" / "r.md"), Q], "does not exist"),
    "paper-tables-ablation-steps-0": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--ablation-steps", "0", Q], "--ablation-steps"),
    "export-onnx-missing-weights": (lambda w: ["export-onnx", "--weights", str(w.root / "w.pt")], "not found"),
    # found by the campaign (tests/bad_input_cases.py)
    "info-npz-nan-wavelengths": (lambda w: ["info", str(w.npz_wl_nan)], "finite and increasing"),
    "info-rgl-version-fraction": (lambda w: ["info", str(w.rgl_version_fraction)], "whole numbers"),
    "train-config-train-null": (lambda w: ["train", "--config", str(w.cfg_train_null), "--out", str(w.out / "t"), Q], "train must be an object"),
    "corpus-workers-100000": (lambda w: ["corpus", "--n", "3", "--inputs", "--workers", "100000", "--out", str(w.out / "c"), Q], "--workers"),
    "infer-image-over-libpng-limit": (lambda w: ["infer", str(w.png_over_libpng_limit), "-o", str(w.out / "b.npz"), Q], "megapixels"),
    "paper-tables-materials-0": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--materials", "0", Q], "--materials"),
    "paper-tables-report-only-empty-cache": (lambda w: ["paper-tables", "--out", str(w.out / "r.md"), "--report-only", Q], "nothing is cached"),
    "batch-many-timeout-nan": (lambda w: ["batch-many", "--out", str(w.out / "bm"), "--timeout", "nan", str(EXAMPLE), Q], "--timeout"),
    "batch-many-workers-100000": (lambda w: ["batch-many", "--out", str(w.out / "bm"), "--workers", "100000", str(EXAMPLE), Q], "--workers"),
    "info-named-pipe": (lambda w: ["info", str(w.fifo)], "not a regular file"),
    "infer-image-named-pipe": (lambda w: ["infer", str(w.fifo), "-o", str(w.out / "b.npz"), Q], "not a regular file"),
    "train-config-named-pipe": (lambda w: ["train", "--config", str(w.fifo), "--out", str(w.out / "t"), Q], "not a regular file"),
    "export-onnx-existing-graphs": (lambda w: ["export-onnx", "--weights", str(w.weights_with_graphs)], "already exists"),
    "batch-many-batch-args-resolution-0": (lambda w: ["batch-many", "--out", str(w.out / "bm"), "--batch-args=--resolution 0", str(EXAMPLE), Q], "--resolution"),
    # faults and limits: refused before any work
    "infer-input-env-over-pixel-limit": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--input-env", str(w.env_huge), Q], "megapixels"),
    "infer-input-env-square": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--input-env", str(w.env_square), Q], "twice as wide"),
    "infer-input-env-1-to-64": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--input-env", str(w.env_tall), Q], "twice as wide"),
    "infer-input-env-64-to-1": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / "b.npz"), "--input-env", str(w.env_wide), Q], "twice as wide"),
    "infer-output-name-256-bytes": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / ("n" * 252 + ".npz")), Q], "256 bytes long"),
    "infer-rgb-output-name-too-long": (lambda w: ["infer", str(EXAMPLE), "-o", str(w.out / ("n" * 250 + ".npz")), "--rgb", Q], "bytes long"),
    "tabulate-output-name-256-bytes": (lambda w: ["tabulate", str(w.npz_good), "-o", str(w.out / ("t" * 252 + ".npz"))], "256 bytes long"),
}


def _touch(path: Path) -> Path:
    path.write_bytes(b"an existing output")
    return path


def run_cli(argv: list[str], capsys) -> tuple[int, str]:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    return code, out + err


@pytest.mark.parametrize("name", sorted(CLI_CASES))
def test_cli_refuses_bad_input_cleanly(name, ws, capsys):
    build, needle = CLI_CASES[name]
    argv = build(ws)
    before = snapshot(ws.root)
    code, text = run_cli(argv, capsys)
    assert_clean_failure(code, text, 2, needle, before, ws.root)
    assert len([l for l in text.splitlines() if l.startswith("error:")]) == 1, text


NEEDS_WEIGHTS = pytest.mark.skipif(not WEIGHTS.is_file(), reason=f"no shipped weights at {WEIGHTS}")


@NEEDS_WEIGHTS
@pytest.mark.parametrize("name, needle", [("png_flat", "no sphere"), ("exr_nan", "NaN or Inf")])
def test_infer_refuses_an_image_without_a_usable_sphere(name, needle, ws, capsys):
    image = getattr(ws, name)
    before = snapshot(ws.root)
    code, text = run_cli(["infer", str(image), "-o", str(ws.out / "b.npz"), Q], capsys)
    assert_clean_failure(code, text, 2, needle, before, ws.root)


@NEEDS_WEIGHTS
def test_infer_refuses_weights_holding_nan(ws, capsys):
    weights = ws.weights_nan
    before = snapshot(ws.root)
    code, text = run_cli(["infer", str(EXAMPLE), "-o", str(ws.out / "b.npz"), "--weights",
                          str(weights), Q], capsys)
    assert_clean_failure(code, text, 2, "NaN or infinite values in the weights", before, ws.root)


@pytest.mark.skipif(os.geteuid() == 0, reason="root reads files whatever their permissions")
@pytest.mark.parametrize("kind", ["merl", "config"])
def test_unreadable_files_are_named_as_unreadable(kind, ws, capsys):
    path = ws.merl_nan if kind == "merl" else ws.cfg_unknown
    path.chmod(0)
    before = snapshot_names = sorted(p.name for p in ws.root.rglob("*"))
    argv = ["info", str(path)] if kind == "merl" else ["train", "--config", str(path), "--out", str(ws.out / "t")]
    code, text = run_cli(argv, capsys)
    assert code == 2 and "Traceback" not in text and ("permission" in text.lower() or "not readable" in text)
    assert sorted(p.name for p in ws.root.rglob("*")) == before == snapshot_names


SETPRIV = shutil.which("setpriv")


@pytest.mark.skipif(os.geteuid() != 0 or SETPRIV is None, reason="needs root and setpriv to drop to 'nobody'")
@pytest.mark.parametrize("kind", ["merl", "rgl", "config"])
def test_unreadable_files_are_named_as_unreadable_for_an_unprivileged_user(kind, ws):
    """The permission cases where CI runs as root: the CLI runs as 'nobody' (setpriv) on a file
    only root may read (the repository and .venv are world-readable)."""
    import tempfile

    src = {"merl": ws.merl_nan, "rgl": ws.rgl_lum_nan, "config": ws.cfg_unknown}[kind]
    shared = Path(tempfile.mkdtemp(prefix="specgen_perm_", dir="/tmp"))
    try:
        shared.chmod(0o777)
        path = shared / src.name
        shutil.copyfile(src, path)
        path.chmod(0)
        argv = ["info", str(path)] if kind != "config" else \
            ["train", "--config", str(path), "--out", str(shared / "t"), "--quiet"]
        env = {**os.environ, "HOME": str(shared), "SPECGEN_CACHE_DIR": str(shared / "cache"),
               "TMPDIR": str(shared), "PYTHONDONTWRITEBYTECODE": "1"}
        done = subprocess.run([SETPRIV, "--reuid=65534", "--regid=65534", "--clear-groups",
                               sys.executable, "-m", "specgen_addon", *argv],
                              cwd=REPO, env=env, capture_output=True, text=True, timeout=300)
        text = done.stdout + done.stderr
        assert done.returncode == 2 and "Traceback" not in text, text
        assert "permission" in text.lower() or "not readable" in text, text
        assert sorted(p.name for p in shared.iterdir()) == [path.name]
    finally:
        shutil.rmtree(shared, ignore_errors=True)


# ------------------------------------------------------------------------------------ batch.py
def _batch_args(w: Workspace, **over) -> list[str]:
    args = {"--image": str(EXAMPLE), "--out": str(w.out), "--resolution": "16", "--samples": "1"}
    args.update({k if k.startswith("--") else f"--{k.replace('_', '-')}": v for k, v in over.items()})
    out = []
    for k, v in args.items():
        if v is not None:
            out += [k, v]
    return out


BATCH_CASES = {
    "resolution-0": (lambda w: _batch_args(w, resolution="0"), "--resolution"),
    "resolution-negative": (lambda w: _batch_args(w, resolution="-1"), "--resolution"),
    "resolution-100000": (lambda w: _batch_args(w, resolution="100000"), "--resolution"),
    "bands-10000": (lambda w: _batch_args(w, bands="10000"), "--bands"),
    "bands-0": (lambda w: _batch_args(w, bands="0"), "--bands"),
    "samples-0": (lambda w: _batch_args(w, samples="0"), "--samples"),
    "samples-negative": (lambda w: _batch_args(w, samples="-5"), "--samples"),
    "env-samples-0": (lambda w: _batch_args(w, env_samples="0"), "--env-samples"),
    "wavelengths-reversed": (lambda w: _batch_args(w, wl_min="700", wl_max="400"), "increase"),
    "env-with-path": (lambda w: _batch_args(w, env="../world/studio"), "plain file name"),
    "env-unknown": (lambda w: _batch_args(w, env="moon"), "moon"),
    "mesh-missing": (lambda w: _batch_args(w, mesh=str(w.root / "none.obj")), "not found"),
    "mesh-vertices-only": (lambda w: _batch_args(w, mesh=str(w.obj_vertices_only)), "no faces"),
    "mesh-truncated": (lambda w: _batch_args(w, mesh=str(w.obj_truncated)), "truncated"),
    "mesh-nan-vertex": (lambda w: _batch_args(w, mesh=str(w.obj_nan)), "NaN"),
    "mesh-face-out-of-range": (lambda w: _batch_args(w, mesh=str(w.obj_out_of_range)), "out of range"),
    "mesh-empty": (lambda w: _batch_args(w, mesh=str(w.obj_empty)), "0 vertices"),
    "out-under-file": (lambda w: _batch_args(w, out=str(w.blocker / "o")), "output folder"),
    "out-is-file": (lambda w: _batch_args(w, out=str(w.blocker)), "output folder"),
    "image-missing": (lambda w: _batch_args(w, image=str(w.root / "nope.png")), "not found"),
    "image-folder": (lambda w: _batch_args(w, image=str(w.out)), "is a folder"),
    "image-over-pixel-limit": (lambda w: _batch_args(w, image=str(w.png_huge)), "megapixels"),
    "image-without-sphere": (lambda w: _batch_args(w, image=str(w.png_flat)), "no sphere"),
    "brdf-nan-table": (lambda w: _batch_args(w, image=None, brdf=str(w.npz_nan)), "NaN"),
    "brdf-negative-table": (lambda w: _batch_args(w, image=None, brdf=str(w.npz_neg)), "negative"),
    "weights-missing": (lambda w: _batch_args(w, weights=str(w.root / "w.pt")), "not found"),
    "existing-lookup-folder": (lambda w: _batch_args(w) if _touch_lookup(w) else [], "--overwrite"),
    "existing-output": (lambda w: _batch_args(w) if _touch(w.out / "sphere_sphere_studio.exr") else [], "already exists"),
    "existing-preview": (lambda w: _batch_args(w) if _touch(w.out / "sphere_sphere_studio_preview.png") else [], "already exists"),
    "scene-not-a-blend": (lambda w: ["--scene", str(w.blend_bad), "--out", str(w.out)], "cannot open the .blend"),
    # faults and limits: refused before any work
    "lookup-is-a-link-out-of-the-folder": (lambda w: _batch_args(w, out=str(w.lookup_link)), "is a link"),
    "target-is-a-folder-with-overwrite": (lambda w: _batch_args(w, overwrite=None) + ["--overwrite"]
                                          if (w.out / "sphere_sphere_studio.exr").mkdir() is None else [], "is a folder"),
    "input-env-over-pixel-limit": (lambda w: _batch_args(w, input_env=str(w.env_huge)), "megapixels"),
    "input-env-not-2-to-1": (lambda w: _batch_args(w, input_env=str(w.env_square)), "twice as wide"),
    "image-name-too-long": (lambda w: _batch_args(w, image=str(_long_named_copy(w))), "bytes long"),
}


def _long_named_copy(w: Workspace) -> Path:
    """The example photo under a 240-byte name: batch.py's outputs add to it past 255 bytes."""
    path = w.root / ("p" * 236 + ".png")
    path.write_bytes(EXAMPLE.read_bytes())
    return path


def _touch_lookup(w: Workspace) -> Path:
    (w.out / "lookup").mkdir()
    return _touch(w.out / "lookup" / "sphere.npz")


@pytest.fixture(scope="module")
def batch_module():
    pytest.importorskip("bpy")
    import batch

    return batch


@pytest.mark.parametrize("name", sorted(BATCH_CASES))
def test_batch_refuses_bad_input_before_any_work(name, ws, capsys, batch_module):
    build, needle = BATCH_CASES[name]
    argv = build(ws)
    before = snapshot(ws.root)
    t0 = time.perf_counter()
    code = batch_module.main(argv)
    out, err = capsys.readouterr()
    assert_clean_failure(code, out + err, 2, needle, before, ws.root)
    lines = [l for l in err.splitlines() if l.strip()]
    assert len(lines) == 1 and lines[0].startswith("batch.py: error:"), err
    assert "generate:" not in out  # refused before the network ran
    assert time.perf_counter() - t0 < 30


# ------------------------------------------------------------------------------------ Python API
API_CASES = {
    "load-brdf-folder": (lambda w: __import__("specgen_addon.brdf.formats", fromlist=["x"]).load_brdf(w.out), BRDFFormatError, "is a folder"),
    "table-load-nan": (lambda w: BRDFTable.load(w.npz_nan), BRDFFormatError, "NaN"),
    "table-load-inf": (lambda w: BRDFTable.load(w.npz_inf), BRDFFormatError, "infinite"),
    "merl-read-overflow": (lambda w: __import__("specgen_addon.brdf.formats.merl", fromlist=["x"]).read_merl(w.merl_inf), BRDFFormatError, "overflowing"),
    "rgl-read-luminance-nan": (lambda w: __import__("specgen_addon.brdf.formats.rgl", fromlist=["x"]).read_rgl(w.rgl_lum_nan), BRDFFormatError, "luminance"),
    "image-over-limit": (lambda w: __import__("specgen_addon.photo.sphere_image", fromlist=["x"]).load_sphere_image(w.png_huge), ImageInputError, "megapixels"),
    "image-exr-nan": (lambda w: __import__("specgen_addon.photo.sphere_image", fromlist=["x"]).load_sphere_image(w.exr_nan), ImageInputError, "NaN"),
    "obj-out-of-range": (lambda w: __import__("specgen_addon.render.mesh_checks", fromlist=["x"]).check_obj(w.obj_out_of_range), SpecGenError, "out of range"),
    "safe-name-dotdot": (lambda w: __import__("specgen_addon.common.limits", fromlist=["x"]).safe_name("../x.exr"), SpecGenError, "plain file name"),
    "safe-name-absolute": (lambda w: __import__("specgen_addon.common.limits", fromlist=["x"]).safe_name("/tmp/x.exr"), SpecGenError, "plain file name"),
    "config-lr-nan": (lambda w: __import__("specgen_addon.train.loop", fromlist=["x"]).validate_train_config(w.cfg_lr_nan), SpecGenError, "finite"),
    # found by the campaign (tests/bad_input_cases.py)
    "table-load-nan-wavelengths": (lambda w: BRDFTable.load(w.npz_wl_nan), SpecGenError, "finite"),
    "refine-not-a-table": (lambda w: _api("generate.refine").refine_brdf("t.npz", np.full((64, 64, 3), 0.1)), SpecGenError, "BRDFTable"),
    "bake-negative-tolerance": (lambda w: _api("bake.lookup").bake_atlas(BRDFTable.load(w.npz_good), w.out / "a.exr", tolerance=-1), SpecGenError, "tolerance"),
    "bake-nan-wavelengths": (lambda w: _api("bake.lookup").bake_atlas(BRDFTable.load(w.npz_good), w.out / "a.exr", wavelengths_nm=np.array([np.nan, 500.0])), SpecGenError, "finite"),
    "bake-path-under-file": (lambda w: _api("bake.lookup").bake_atlas(BRDFTable.load(w.npz_good), w.blocker / "a.exr"), SpecGenError, "is a file"),
    "sphere-array-empty": (lambda w: _api("photo.sphere_image").prepare_sphere_array(np.zeros((0, 0, 3))), ImageInputError, "too small"),
    "sphere-array-strings": (lambda w: _api("photo.sphere_image").prepare_sphere_array(np.array([["a"]])), ImageInputError, "array of numbers"),
}


def _api(module: str):
    return __import__(f"specgen_addon.{module}", fromlist=["x"])


@pytest.mark.parametrize("name", sorted(API_CASES))
def test_python_api_raises_one_named_error(name, ws):
    call, error, needle = API_CASES[name]
    before = snapshot(ws.root)
    with pytest.raises(error) as info:
        call(ws)
    # files made by the case's inputs are part of ``before`` only if created there; compare after
    assert needle.lower() in str(info.value).lower()
    assert "\n" not in str(info.value)
    assert {k for k in snapshot(ws.root)} >= set(before)


@NEEDS_WEIGHTS
def test_generate_brdf_refuses_nan_weights_in_the_api(ws):
    from specgen_addon.model.runtime.inference import generate_brdf

    with pytest.raises(WeightsError, match="NaN or infinite"):
        generate_brdf(str(EXAMPLE), weights=ws.weights_nan, wavelengths_nm=np.linspace(400, 700, 4))


# ------------------------------------------------------------------------------------ photos
def _photo_variants(root: Path) -> dict[str, Path]:
    from PIL import Image

    im = Image.open(EXAMPLE).convert("RGB")
    paths = {}
    for mode in ("L", "LA", "P", "CMYK", "RGBA"):
        p = root / f"{mode}.{'jpg' if mode == 'CMYK' else 'png'}"
        (im.convert(mode) if mode != "RGBA" else im.convert("RGBA")).save(p, quality=95)
        paths[mode] = p
    gray16 = (np.asarray(im.convert("L")).astype(np.uint16) * 257)
    Image.fromarray(gray16).save(root / "gray16.png")
    paths["I;16"] = root / "gray16.png"
    im.save(root / "q95.jpg", quality=95)
    paths["JPEG q95"] = root / "q95.jpg"
    return paths


@pytest.mark.parametrize("mode", ["L", "LA", "P", "CMYK", "RGBA", "I;16", "JPEG q95"])
def test_ordinary_photos_are_read_and_their_sphere_found(mode, tmp_path):
    from specgen_addon.photo import sphere_image as input_image

    path = _photo_variants(tmp_path)[mode]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        got = input_image.load_sphere_image(path)
    reference = input_image.load_sphere_image(EXAMPLE)
    assert got.shape == reference.shape
    # same sphere found: its silhouette matches the original's (colour differs for gray modes)
    assert np.mean((got.max(-1) > 0) == (reference.max(-1) > 0)) > 0.97
    if mode not in ("RGBA", "JPEG q95"):
        assert any("converted" in str(w.message) for w in caught), [str(w.message) for w in caught]


def test_conversion_notes_print_as_one_warning_line(tmp_path, capsys):
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.common.errors import one_line_warnings

    path = _photo_variants(tmp_path)["L"]
    with warnings.catch_warnings(), one_line_warnings():
        warnings.simplefilter("always")
        input_image.load_sphere_image(path)
    err = capsys.readouterr().err
    assert err.startswith("warning: ") and "converted" in err, err
    assert all(line.startswith("warning: ") for line in err.splitlines()), err  # no source lines


def test_a_warning_attributed_to_batch_py_prints_as_one_line_too(capsys):
    """A warning raised with ``stacklevel`` lands in the caller's file: batch.py's and the Blender
    tier's are SpecGen's too, and print as one ``warning:`` line, while a library's keep theirs."""
    from specgen_addon.common.errors import one_line_warnings

    with warnings.catch_warnings(), one_line_warnings():
        warnings.simplefilter("always")
        warnings.warn_explicit("the onnx backend cannot run", UserWarning, str(REPO / "batch.py"), 197)
        warnings.warn_explicit("a library's own", UserWarning, "/usr/lib/python3/site-packages/x.py", 3)
    # the library's goes to the handler that was there before (pytest's record, here)
    assert capsys.readouterr().err.splitlines() == ["warning: the onnx backend cannot run"]


def test_negative_exr_pixels_are_clamped_with_a_count(tmp_path):
    from specgen_addon.photo import sphere_image as input_image

    rgb = _sphere_rgb()
    rgb[0, :5] = -0.5
    with pytest.warns(UserWarning, match="15 negative values"):
        input_image.load_sphere_image(_exr(tmp_path / "neg.exr", rgb))


def test_large_photos_are_downsampled_while_decoding(tmp_path):
    from PIL import Image
    from specgen_addon.photo import sphere_image as input_image
    from specgen_addon.common.limits import MAX_WORK_SIDE

    big = Image.open(EXAMPLE).convert("RGB").resize((MAX_WORK_SIDE * 2 + 8,) * 2, Image.NEAREST)
    big.save(tmp_path / "big.png")
    with pytest.warns(UserWarning, match="downsampled 3×"):
        arr = input_image.read_image(tmp_path / "big.png")
    assert max(arr.shape[:2]) <= MAX_WORK_SIDE


# ------------------------------------------------------------------------------------ operators
@pytest.fixture
def addon(tmp_path):
    bpy = pytest.importorskip("bpy")
    import batch

    pkg = batch.load_package()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg.register()
    try:
        s = bpy.context.scene.specgen
        s.output_dir = str(tmp_path / "out")
        yield bpy, s
    finally:
        pkg.unregister()


OP_CASES = {
    "render-filename-dotdot": (lambda bpy, s, w: bpy.ops.specgen.render_stack(filename="../../x.exr"), "plain file name"),
    "render-filename-absolute": (lambda bpy, s, w: bpy.ops.specgen.render_stack(filename="/tmp/specgen_x.exr"), "plain file name"),
    "render-filename-png": (lambda bpy, s, w: bpy.ops.specgen.render_stack(filename="x.png"), ".exr"),
    "render-nothing-to-render": (lambda bpy, s, w: bpy.ops.specgen.render_stack(), "no camera"),  # full-scene mode
    "generate-no-image": (lambda bpy, s, w: bpy.ops.specgen.generate_brdf(), "choose an input image"),
    "generate-missing-image": (lambda bpy, s, w: setattr(s, "image_path", str(w.root / "nope.png")) or bpy.ops.specgen.generate_brdf(), "not found"),
    "generate-image-without-sphere": (lambda bpy, s, w: setattr(s, "image_path", str(w.png_flat)) or bpy.ops.specgen.generate_brdf(), "no sphere"),
    "generate-image-over-limit": (lambda bpy, s, w: setattr(s, "image_path", str(w.png_huge)) or bpy.ops.specgen.generate_brdf(), "megapixels"),
    "generate-weights-missing": (lambda bpy, s, w: (setattr(s, "image_path", str(EXAMPLE)), setattr(s, "weights_path", str(w.root / "w.pt")), bpy.ops.specgen.generate_brdf()), "not found"),
}


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_operators_report_one_sentence_and_write_nothing(name, addon, ws):
    bpy, s = addon
    call, needle = OP_CASES[name]
    ws.png_flat, ws.png_huge  # inputs exist before the snapshot
    before = snapshot(ws.root)
    with pytest.raises(RuntimeError) as info:
        call(bpy, s, ws)
    text = str(info.value)
    assert "Traceback" not in text and needle.lower() in text.lower(), text
    assert len([l for l in text.splitlines() if l.strip()]) == 1, text
    assert snapshot(ws.root) == before
    assert not Path("/tmp/specgen_x.exr").exists()


def test_an_image_datablock_over_the_pixel_limit_is_refused_before_its_pixels_are_copied(addon, monkeypatch):
    """A photo already loaded in Blender (no file to read a header from): its size is checked
    against the same limit before the operator copies its pixels."""
    bpy, s = addon
    limits_mod = import_module("specgen_addon.common.limits")
    monkeypatch.setattr(limits_mod, "MAX_IMAGE_PIXELS", 1000)
    s.image = bpy.data.images.new("big photo", 64, 64)      # 4096 pixels, no file behind it
    with pytest.raises(RuntimeError) as info:
        bpy.ops.specgen.generate_brdf()
    text = str(info.value)
    assert "'big photo': image is 64×64" in text and "megapixels" in text and "Traceback" not in text, text


# ------------------------------------------------------------------------------------ interrupts
def _wait_for(proc: subprocess.Popen, log: Path, needle: str, timeout: float = 240) -> None:
    t0 = time.time()
    while needle not in log.read_text(errors="replace"):
        if proc.poll() is not None or time.time() - t0 > timeout:
            raise AssertionError(f"never saw {needle!r}: " + log.read_text(errors="replace")[-2000:])
        time.sleep(0.1)


def _interrupt(cmd: list[str], tmp_path: Path, needle: str, sig: int, delay: float = 0.0,
               env: dict | None = None) -> tuple[int, str]:
    log = tmp_path / "log.txt"
    with open(log, "w") as fh:
        proc = subprocess.Popen(cmd, cwd=REPO, stdout=fh, stderr=subprocess.STDOUT,
                                env={**os.environ, **(env or {})})
        try:
            _wait_for(proc, log, needle)
            time.sleep(delay)
            proc.send_signal(sig)
            code = proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
    return code, log.read_text(errors="replace")


@pytest.mark.slow
@NEEDS_WEIGHTS
@pytest.mark.parametrize("sig, phase, needle, delay", [
    (signal.SIGINT, "scene set-up|spectral render", "BRDF ready", 0.3),  # Blender sets up the scene
    (signal.SIGINT, "spectral render", "BRDF ready", 5.0),   # inside the Cycles render (minutes long)
    (signal.SIGTERM, "BRDF generation", "generate: ", 0.0),  # inside the network run
])
def test_batch_stops_cleanly_on_a_signal(sig, phase, needle, delay, tmp_path):
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    before = snapshot(out)
    # a render long enough (~10 s of Cycles) that the signal lands inside it
    code, text = _interrupt([sys.executable, "batch.py", "--image", str(EXAMPLE), "--out", str(out),
                             "--resolution", "256", "--samples", "1024", "--bands", "6"],
                            tmp_path, needle, sig, delay=delay)
    assert code == 128 + sig, text
    assert "Traceback" not in text
    assert re.search(f"cancelled: batch.py ({phase}) stopped by {signal.Signals(sig).name}; "
                     "nothing partial was left", text), text
    assert snapshot(out) == before
    assert "wrote" not in text


GENERATE_SCRIPT = r"""
import sys, time
sys.path.insert(0, {repo!r})
import bpy, batch
pkg = batch.load_package()
from importlib import import_module
interrupts = import_module("specgen_addon.common.interrupts")
pkg.register()
s = bpy.context.scene.specgen
s.image_path = {image!r}
s.output_dir = {out!r}
print("GENERATE-START", flush=True)
with interrupts.stop_on_signals():
    try:
        result = bpy.ops.specgen.generate_brdf()
    except RuntimeError as exc:
        result = str(exc)
    stopped = interrupts.stop_requested()
print("RESULT", result, flush=True)
sys.exit(130 if stopped else 0)
"""


@pytest.mark.slow
@NEEDS_WEIGHTS
@pytest.mark.parametrize("delay", [0.2, 1.0, 2.0, 3.0])  # imports, network, refinement, bake
def test_generate_operator_stops_cleanly_on_sigint(delay, tmp_path):
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("x")
    before = snapshot(out)
    script = tmp_path / "gen.py"
    script.write_text(GENERATE_SCRIPT.format(repo=str(REPO), image=str(EXAMPLE), out=str(out)))
    code, text = _interrupt([sys.executable, str(script)], tmp_path, "GENERATE-START", signal.SIGINT,
                            delay=delay)
    assert code == 130, text
    assert "Traceback" not in text
    assert "cancelled by SIGINT; nothing partial was left" in text, text
    assert snapshot(out) == before


@pytest.mark.slow
@NEEDS_WEIGHTS
def test_cli_infer_stops_cleanly_on_sigint(tmp_path):
    out = tmp_path / "out"
    out.mkdir()
    code, text = _interrupt([sys.executable, "-m", "specgen_addon", "infer", str(EXAMPLE), "-o",
                             str(out / "b.npz"), "--rgb"], tmp_path, "infer:", signal.SIGINT, delay=0.5)
    assert code == 130, text
    assert "Traceback" not in text
    assert "cancelled: infer stopped by SIGINT; nothing partial was left" in text
    assert list(out.iterdir()) == []


def test_output_guard_removes_what_it_made_keeps_what_it_is_told_and_never_a_neighbours_file(tmp_path):
    """Ownership is by identity: the files this process published and the folders it made go;
    a file another process wrote into the same folders meanwhile stays, as does ``keep``."""
    from specgen_addon.common.interrupts import OutputGuard
    from specgen_addon.common.atomic_io import atomic_write, make_dirs

    out = tmp_path / "run"
    out.mkdir()
    (out / "old.txt").write_text("old")
    guard = OutputGuard([out, tmp_path / "created"], keep=[out / "checkpoint.pt"])
    with pytest.raises(KeyboardInterrupt):
        with guard:
            with atomic_write(out / "checkpoint.pt") as tmp:
                tmp.write_text("resumable")
            make_dirs(out / "sub")
            with atomic_write(out / "sub" / "partial.npz") as tmp:
                tmp.write_text("partial")
            make_dirs(tmp_path / "created")
            with atomic_write(tmp_path / "created" / "x") as tmp:
                tmp.write_text("x")
            (out / "neighbour.exr").write_text("another process's finished output")
            raise KeyboardInterrupt
    assert sorted(p.name for p in out.iterdir()) == ["checkpoint.pt", "neighbour.exr", "old.txt"]
    assert not (tmp_path / "created").exists()
    assert guard.left_behind() == f"kept {out / 'checkpoint.pt'}"


@NEEDS_WEIGHTS
@pytest.mark.parametrize("polled_in,stage", [("", "generation"), ("/generate/refine/", "refinement"),
                                             ("/bake/", "bake")])
def test_cancelled_generate_leaves_nothing_in_the_lookup_folder(polled_in, stage, tmp_path):
    """The panel's Esc: Generate's worker polls ``cancel`` between network blocks, in the
    refinement and between bake groups; wherever it stops, nothing is left. Esc is pressed at the
    first poll made from inside the stage's code (``polled_in``: a part of its path)."""
    pytest.importorskip("bpy")
    import inspect
    from importlib import import_module

    pipeline = import_module("specgen_addon.generate.pipeline")
    errors = import_module("specgen_addon.common.errors")
    out = tmp_path / "lookup"

    def cancel() -> bool:
        return any(polled_in in Path(f.filename).as_posix() for f in inspect.stack(0)[1:])

    with pytest.raises(errors.Cancelled) as info:
        pipeline.generate(str(EXAMPLE), out_dir=out, wavelengths_nm=np.linspace(400, 700, 4), backend=None, cancel=cancel)
    assert stage in str(info.value)
    assert not out.exists()


# ------------------------------------------------------------------------------- the campaign
# The independent campaign (tests/bad_input_cases.py: its own fixtures and ~390 cases across every
# command, batch.py and the Python API), each case a fresh process in its own folder with TMPDIR
# inside it. Slow: about 8 minutes on two cores (`-m slow -k campaign`).
import bad_input_cases as campaign  # noqa: E402

CAMPAIGN = {c.name: c for c in campaign.cases(campaign.RGL_DIR.is_dir(), big=False)}


@pytest.fixture(scope="module")
def campaign_fixtures(tmp_path_factory):
    base = tmp_path_factory.mktemp("campaign")
    campaign.make_fixtures(base / "fixtures", big=False)
    before = campaign.snapshot(base / "fixtures")
    yield base
    assert campaign.snapshot(base / "fixtures") == before, "a case changed the shared fixtures"


def _flags(r) -> list[str]:
    return [k for k in ("traceback", "silently_accepted", "wrongly_refused", "internal", "misleading",
                        "timeout") if getattr(r, k)] + ([f"leftovers {r.leftovers}"] if r.leftovers else [])


@pytest.mark.slow
@pytest.mark.parametrize("name", list(CAMPAIGN))
def test_campaign_case_ends_as_decided_with_one_line_and_no_leftovers(name, campaign_fixtures):
    r = campaign.run_case(CAMPAIGN[name], campaign_fixtures, campaign_fixtures / "fixtures")
    assert r.clean, f"{name}: {', '.join(_flags(r))} (exit {r.exit}): {r.message}"


@pytest.mark.slow
def test_campaign_infer_on_an_8000_px_photo_peaks_under_2_gb(tmp_path):
    if not Path("/usr/bin/time").is_file():
        pytest.skip("needs /usr/bin/time -v for the peak resident memory")
    campaign.make_fixtures(tmp_path / "fixtures", big=True)
    [case] = [c for c in campaign.cases(False, big=True) if c.measure_memory]
    r = campaign.run_case(case, tmp_path, tmp_path / "fixtures")
    assert r.clean, f"{', '.join(_flags(r))} (exit {r.exit}): {r.message}"
    assert r.peak_rss_gb is not None and r.peak_rss_gb <= 2.0, r.peak_rss_gb
