"""The bad-input campaign's fixtures and cases: every command run as a careful, adversarial user
would, each case one fresh subprocess (``python -m specgen_addon …``, ``python batch.py …`` or a
``python -c`` call of the Python API) in its own folder, with ``TMPDIR`` pointed inside it.

:func:`run_case` records, and ``tests/house/test_bad_input.py`` asserts for every case:

- the exit status and the last line of stderr (the message);
- ``traceback``: "Traceback" anywhere in stdout/stderr;
- ``silently_accepted``: exit 0 for an input that must be refused;
- ``wrongly_refused``: an ordinary input (e.g. a grayscale photo) refused;
- ``leftovers``: a file that appeared or changed in the case folder (inputs, output folder, the
  existing output, the temp folder); for an accepted run only the temp folder must stay empty;
- ``internal``: the catch-all "internal error" message (a bug caught generically);
- ``misleading``: the message does not name the problem (a per-case keyword is missing);
- ``timeout`` and the wall time.

One case decodes an 8000×8000 PNG through ``infer`` and records its peak resident memory
(``/usr/bin/time -v``; target ≤ 2 GB).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import subprocess
import sys
import textwrap
import time
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
PY = sys.executable
RGL_DIR = REPO.parent / "shared" / "data" / "rgl"
TIMEOUT_S = 60.0
THIRD_PARTY_TEMP = "tmp/.ses"

# The Python API cases: a SpecGenError is the clean refusal (message on stderr, exit 2); any
# other exception escapes with its traceback and is counted.
API_PRELUDE = textwrap.dedent("""
    import sys, numpy as np
    sys.path.insert(0, {repo!r})
    from specgen_addon.common.errors import SpecGenError
    def main():
    {body}
    try:
        main()
    except SpecGenError as exc:
        print("error:", exc, file=sys.stderr)
        sys.exit(2)
""")


@dataclass
class Case:
    name: str
    argv: list[str]                    # after the interpreter; {fx} {work} {out} {repo} expanded
    expect: str = "refuse"             # "refuse" | "accept" | "either"
    mentions: tuple[str, ...] = ()     # the message must contain one of these (case-insensitive)
    prepare: str = ""                  # fixtures copied into {out} first ("name->dest;name2->dest2")
    timeout: float = TIMEOUT_S
    measure_memory: bool = False


@dataclass
class Result:
    name: str
    expect: str
    exit: int | None
    seconds: float
    message: str
    traceback: bool = False
    silently_accepted: bool = False
    wrongly_refused: bool = False
    leftovers: list[str] = field(default_factory=list)
    internal: bool = False
    misleading: bool = False
    timeout: bool = False
    peak_rss_gb: float | None = None
    third_party_temp: list[str] = field(default_factory=list)

    @property
    def clean(self) -> bool:
        return not (self.traceback or self.silently_accepted or self.wrongly_refused or self.leftovers
                    or self.internal or self.misleading or self.timeout)


# ------------------------------------------------------------------------------------ fixtures
def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_declaring(width: int, height: int, color_type: int = 2) -> bytes:
    """A PNG header claiming width × height, with one tiny IDAT (decoding it would need GBs)."""
    ihdr = struct.pack(">IIBBBBB", width, height, 8, color_type, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr)
            + _png_chunk(b"IDAT", zlib.compress(b"\0" * 64)) + _png_chunk(b"IEND", b""))


def jpeg_declaring(width: int, height: int) -> bytes:
    """SOI + a baseline SOF0 marker claiming width × height, then EOI."""
    sof = struct.pack(">BHHB", 8, height, width, 3) + b"\x01\x11\x00\x02\x11\x00\x03\x11\x00"
    return b"\xff\xd8" + b"\xff\xc0" + struct.pack(">H", len(sof) + 2) + sof + b"\xff\xd9"


def make_fixtures(fx: Path, big: bool) -> None:
    """Write every input file the cases read into ``fx`` (read-only for the cases)."""
    from PIL import Image

    from specgen_addon.brdf.formats.merl import MERLData, write_merl
    from specgen_addon.brdf.formats.rgl import read_tensor_file, write_tensor_file
    from specgen_addon.common.image_io import read_exr, write_exr
    from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable

    fx.mkdir(parents=True)
    good_png = REPO / "examples" / "sphere.png"
    good_exr = REPO / "examples" / "sphere.exr"
    shutil.copy(good_png, fx / "good.png")
    shutil.copy(good_exr, fx / "good.exr")
    img = Image.open(good_png).convert("RGB")
    png_bytes = good_png.read_bytes()
    exr_bytes = good_exr.read_bytes()

    # --- images: broken
    (fx / "empty.png").write_bytes(b"")
    (fx / "trunc.png").write_bytes(png_bytes[: len(png_bytes) // 3])
    (fx / "header_only.png").write_bytes(png_bytes[:33])
    (fx / "text.png").write_text("this is not an image\n")
    (fx / "trunc.exr").write_bytes(exr_bytes[: len(exr_bytes) // 2])
    (fx / "text.exr").write_text("not an exr")
    (fx / "zero.png").write_bytes(png_declaring(0, 0))
    (fx / "huge_decl.png").write_bytes(png_declaring(100_000, 100_000))
    (fx / "bomb20k.png").write_bytes(png_declaring(20_000, 20_000))
    (fx / "huge_decl.jpg").write_bytes(jpeg_declaring(65_000, 65_000))
    (fx / "trunc.jpg").write_bytes(b"\xff\xd8\xff\xe0" + b"\0" * 20)
    Image.new("RGB", (1, 1), (200, 100, 50)).save(fx / "one.png")
    Image.new("RGB", (3, 3), (200, 100, 50)).save(fx / "three.png")
    Image.new("RGB", (128, 128), (0, 0, 0)).save(fx / "black.png")
    Image.new("RGB", (128, 128), (255, 255, 255)).save(fx / "white.png")
    Image.new("RGB", (4000, 2), (128, 128, 128)).save(fx / "sliver.png")
    img.save(fx / "sphere.bmp")
    img.save(fx / "sphere.tif")
    img.save(fx / "sphere.gif")
    (fx / "png_named.jpg").write_bytes(png_bytes)
    # --- images: ordinary photos in other modes (must be accepted)
    img.convert("L").save(fx / "gray.png")
    img.convert("LA").save(fx / "gray_alpha.png")
    img.convert("P").save(fx / "palette.png")
    Image.fromarray((np.asarray(img.convert("L"), np.uint16) * 257)).save(fx / "gray16.png")
    img.convert("RGBA").save(fx / "rgba.png")
    img.save(fx / "q95.jpg", quality=95)
    img.convert("CMYK").save(fx / "cmyk.jpg", quality=95)
    # --- EXR with bad pixels
    chans, _ = read_exr(good_exr)
    rgb = {k: v for k, v in chans.items() if k in ("R", "G", "B")}
    for kind, value in (("nan", np.nan), ("inf", np.inf), ("neg", -5.0)):
        planes = {k: v.astype(np.float32).copy() for k, v in rgb.items()}
        h, w = planes["R"].shape
        planes["R"][h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3] = value
        write_exr(fx / f"{kind}.exr", planes)
    all_nan = {k: np.full_like(v, np.nan, dtype=np.float32) for k, v in rgb.items()}
    write_exr(fx / "allnan.exr", all_nan)
    write_exr(fx / "y_only.exr", {"Y": rgb["G"].astype(np.float32)})

    # --- BRDF tables
    wl = np.linspace(400, 700, 4)
    ok = np.full(GRID_SHAPE + (4,), 0.1, np.float32)
    BRDFTable(ok, wl).save(fx / "good.npz")
    good_npz = (fx / "good.npz").read_bytes()
    (fx / "trunc.npz").write_bytes(good_npz[: len(good_npz) // 2])
    (fx / "empty.npz").write_bytes(b"")

    def raw_table(name: str, values, wavelengths=wl, extra: dict | None = None, header: bool = True) -> None:
        fields = {"values": values, "wavelengths": wavelengths}
        if header:
            hdr = {"format": "specgen-brdf-table", "version": 1,
                   "channels": [f"{w:g}nm" for w in np.atleast_1d(wavelengths)], "metadata": {}}
            fields["header"] = np.frombuffer(json.dumps(hdr).encode(), dtype=np.uint8)
        fields.update(extra or {})
        with open(fx / name, "wb") as fh:
            np.savez(fh, **fields)

    for kind, value in (("nan", np.nan), ("inf", np.inf), ("neg", -1.0), ("overflow", 1e38)):
        v = ok.copy()
        v[10:20, 10:20, :, 1] = value
        raw_table(f"{kind}.npz", v)
    raw_table("shape.npz", np.ones((10, 10, 10, 4), np.float32))
    raw_table("wl_desc.npz", ok, wavelengths=wl[::-1].copy())
    raw_table("wl_nan.npz", ok, wavelengths=np.array([400, np.nan, 600, 700.0]))
    raw_table("wl_count.npz", ok, wavelengths=np.array([400.0, 500.0]))
    raw_table("no_header.npz", ok, header=False)
    raw_table("int.npz", np.ones(GRID_SHAPE + (4,), np.int32))
    with open(fx / "no_values.npz", "wb") as fh:
        np.savez(fh, wavelengths=wl)
    with open(fx / "pickle.npz", "wb") as fh:
        np.savez(fh, values=np.array([{"evil": 1}], dtype=object), wavelengths=wl)

    # --- MERL
    merl_dims = struct.pack("<3i", 90, 90, 180)
    n = 90 * 90 * 180
    good_merl = MERLData(np.full((3, 90, 90, 180), 0.1))
    write_merl(fx / "good.binary", good_merl)
    data = (fx / "good.binary").read_bytes()
    (fx / "trunc.binary").write_bytes(data[: len(data) // 2])
    (fx / "empty.binary").write_bytes(b"")
    (fx / "dims_zero.binary").write_bytes(struct.pack("<3i", 0, 0, 0))
    (fx / "dims_neg.binary").write_bytes(struct.pack("<3i", -90, 90, 180) + data[12:])
    (fx / "dims_huge.binary").write_bytes(struct.pack("<3i", 100000, 100000, 100000) + data[12:1000])
    (fx / "big_values.binary").write_bytes(merl_dims + np.full(3 * n, 1e300).tobytes())
    (fx / "nan.binary").write_bytes(merl_dims + np.full(3 * n, np.nan).tobytes())
    (fx / "allneg.binary").write_bytes(merl_dims + np.full(3 * n, -1.0).tobytes())
    (fx / "extra.binary").write_bytes(data + b"\0" * 1000)

    # --- RGL
    rgl = sorted(RGL_DIR.glob("*.bsdf")) if RGL_DIR.is_dir() else []
    if rgl:
        raw = rgl[0].read_bytes()
        shutil.copy(rgl[0], fx / "good.bsdf")
        (fx / "trunc.bsdf").write_bytes(raw[: len(raw) // 2])
        (fx / "header_trunc.bsdf").write_bytes(raw[:40])
        (fx / "bad_magic.bsdf").write_bytes(b"tensor_fXle\0" + raw[12:])
        (fx / "bad_version.bsdf").write_bytes(raw[:12] + b"\x09" + raw[13:])
        fields = {k: np.array(v) for k, v in read_tensor_file(rgl[0]).items()}
        for key in ("luminance", "rgb", "ndf"):
            if key in fields:
                bad = dict(fields)
                bad[key] = fields[key].astype(fields[key].dtype, copy=True)
                bad[key].reshape(-1)[: max(1, bad[key].size // 10)] = np.nan
                write_tensor_file(fx / f"nan_{key}.bsdf", bad)
        if "version" in fields:
            bad = dict(fields)
            bad["version"] = np.array([1.5, 2.5], np.float32)
            write_tensor_file(fx / "float_version.bsdf", bad)
        if "theta_i" in fields:
            bad = dict(fields)
            bad["theta_i"] = np.zeros((2, 2, 2), np.float32)
            write_tensor_file(fx / "theta_3d.bsdf", bad)
        missing = {k: v for k, v in fields.items() if k != "theta_i"}
        write_tensor_file(fx / "no_theta.bsdf", missing)
    (fx / "empty.bsdf").write_bytes(b"")
    (fx / "unknown.xyz").write_bytes(b"\x00\x01garbage" * 10)

    # --- weights
    (fx / "empty.pt").write_bytes(b"")
    (fx / "text.pt").write_text("not weights")
    wraw = (REPO / "weights" / "specgen_default.pt").read_bytes()
    (fx / "trunc.pt").write_bytes(wraw[: len(wraw) // 2])
    import pickle

    class Evil:
        def __reduce__(self):
            return (os.system, ("touch {}".format(fx / "PWNED"),))

    (fx / "evil.pt").write_bytes(pickle.dumps(Evil()))
    import torch

    ckpt = torch.load(REPO / "weights" / "specgen_default.pt", map_location="cpu", weights_only=True)
    state = dict(ckpt["state_dict"])
    name = next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    state[name] = torch.full_like(state[name], float("nan"))
    torch.save({**ckpt, "state_dict": state}, fx / "nan.pt")
    torch.save({"something": torch.zeros(3)}, fx / "foreign.pt")

    # --- meshes
    (fx / "empty.obj").write_text("")
    (fx / "verts_only.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n")
    (fx / "trunc.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2")
    (fx / "nan.obj").write_text("v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n")
    (fx / "bad_index.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n")
    (fx / "zero_index.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n")
    (fx / "garbage.obj").write_bytes(os.urandom(2000))
    (fx / "not_a.blend").write_bytes(b"BLENDER-v300" + b"\0" * 50)

    # --- training configs
    cfgs = {
        "steps_str.json": {"train": {"steps": "ten"}},
        "lr_nan.json": '{"train": {"lr": NaN}}',
        "steps_zero.json": {"train": {"steps": 0}},
        "steps_neg.json": {"train": {"steps": -5}},
        "steps_bool.json": {"train": {"steps": True}},
        "steps_float.json": {"train": {"steps": 2.5}},
        "unknown_key.json": {"train": {"stepz": 10}},
        "unknown_section.json": {"trian": {"steps": 10}},
        "model_int.json": {"model": 5},
        "list_top.json": [1, 2, 3],
        "syntax.json": '{"train": {"steps": 10,}',
        "empty.json": "",
        "lr_neg.json": {"train": {"lr": -0.1}},
        "threads_zero.json": {"train": {"threads": 0}},
        "image_size_huge.json": {"model": {"image_size": 100000}},
        "lambda_inf.json": '{"model": {"lambda_min_nm": Infinity}}',
        "nested_null.json": {"train": None},
        "device_tpu.json": {"train": {"device": "tpu"}},
        "device_int.json": {"train": {"device": 3}},
    }
    for name, content in cfgs.items():
        (fx / name).write_text(content if isinstance(content, str) else json.dumps(content))
    (fx / "steps_str.toml").write_text('[train]\nsteps = "ten"\n')
    (fx / "syntax.toml").write_text('[train\nsteps = 10\n')
    (fx / "lr_array.toml").write_text('[train]\nlr = [1, 2]\n')
    (fx / "config.yaml").write_text("train:\n  steps: 10\n")
    (fx / "bad_manifest.json").write_text("{not json")
    (fx / "manifest_wrong.json").write_text(json.dumps({"materials": 5}))
    (fx / "inputs_list.txt").write_text("# comment\n/nonexistent/photo.png\n")
    (fx / "inputs_bad.json").write_text('["a", ')
    (fx / "a_file").write_text("I am a file\n")
    (fx / "corrupt_checkpoint.pt").write_bytes(b"PK\x03\x04garbage" * 10)
    shutil.copy(REPO / "weights" / "specgen_default.pt", fx / "good.pt")
    os.symlink(fx / "gone.npz", fx / "dangling.npz")
    for name in ("fifo.png", "fifo.npz", "fifo.json", "fifo.obj"):   # reading a named pipe blocks
        os.mkfifo(fx / name)

    if big:
        from script_modules import load_script

        sphere_photo = load_script("bench/image_memory.py").sphere_photo   # a band-drawn sphere photo

        Image.fromarray(sphere_photo(8000)).save(fx / "big8000.png", compress_level=1)
    for p in fx.iterdir():
        if p.is_file() and not p.is_symlink():
            os.chmod(p, 0o444)


# ------------------------------------------------------------------------------------ cases
def cli(*args: str) -> list[str]:
    return ["-m", "specgen_addon", *args]


def batch(*args: str) -> list[str]:
    return ["{repo}/batch.py", *args]


def api(body: str) -> list[str]:
    return ["-c", API_PRELUDE.format(repo=str(REPO), body=textwrap.indent(textwrap.dedent(body), "    "))]


def _has_cuda() -> bool:
    try:
        import torch
    except ImportError:
        return False
    return torch.cuda.is_available()


def cases(have_rgl: bool, big: bool) -> list[Case]:
    C = Case
    out = []
    add = out.append
    img, npz = "{fx}/good.png", "{fx}/good.npz"

    # ---- info
    for f, m in (("nonexistent.npz", "not found"), ("empty.npz", ""), ("trunc.npz", ""),
                 ("pickle.npz", ""), ("no_values.npz", "values"), ("shape.npz", "shape"),
                 ("wl_desc.npz", "wavelength"), ("wl_nan.npz", "wavelength"), ("wl_count.npz", ""),
                 ("nan.npz", "nan"), ("inf.npz", ""), ("neg.npz", "negative"), ("overflow.npz", ""),
                 ("int.npz", ""), ("trunc.binary", ""), ("empty.binary", ""), ("dims_zero.binary", ""),
                 ("dims_neg.binary", ""), ("dims_huge.binary", ""), ("big_values.binary", ""),
                 ("nan.binary", "nan"), ("allneg.binary", "no valid"), ("extra.binary", ""),
                 ("empty.bsdf", ""), ("unknown.xyz", "unknown"), ("good.png", ""), ("a_file", "")):
        add(C(f"info {f}", cli("info", "{fx}/" + f), mentions=(m,) if m else ()))
    add(C("info folder", cli("info", "{fx}"), mentions=("folder",)))
    add(C("info good.npz", cli("info", npz), expect="accept"))
    add(C("info good.binary --json", cli("info", "--json", "{fx}/good.binary"), expect="accept"))
    if have_rgl:
        for f in ("trunc.bsdf", "header_trunc.bsdf", "bad_magic.bsdf", "bad_version.bsdf",
                  "nan_luminance.bsdf", "nan_rgb.bsdf", "nan_ndf.bsdf", "float_version.bsdf",
                  "theta_3d.bsdf", "no_theta.bsdf"):
            add(C(f"info {f}", cli("info", "{fx}/" + f)))
        add(C("info good.bsdf", cli("info", "{fx}/good.bsdf"), expect="accept"))

    # ---- tabulate
    tab = lambda *a: cli("tabulate", *a)  # noqa: E731
    add(C("tabulate --bands 0", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--bands", "0"), mentions=("bands",)))
    add(C("tabulate --bands -3", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--bands", "-3"), mentions=("bands",)))
    add(C("tabulate --bands abc", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--bands", "abc"), mentions=("bands",)))
    add(C("tabulate --wl-min 2000", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--wl-min", "2000"), mentions=("wavelength",)))
    add(C("tabulate --wl-min nan", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--wl-min", "nan"), mentions=("wavelength", "nan")))
    add(C("tabulate wl-min>wl-max", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--wl-min", "700", "--wl-max", "400"), mentions=("increase",)))
    add(C("tabulate missing input", tab("{fx}/nope.binary", "-o", "{out}/t.npz"), mentions=("not found", "no such")))
    add(C("tabulate existing out", tab("{fx}/good.binary", "-o", "{out}/t.npz"), prepare="good.npz->t.npz", mentions=("exists",)))
    add(C("tabulate out dir missing", tab("{fx}/good.binary", "-o", "{out}/no/such/t.npz")))
    add(C("tabulate out is folder", tab("{fx}/good.binary", "-o", "{out}"), mentions=("folder",)))
    add(C("tabulate out under a file", tab("{fx}/good.binary", "-o", "{fx}/a_file/t.npz")))
    add(C("tabulate nan merl", tab("{fx}/nan.binary", "-o", "{out}/t.npz")))
    add(C("tabulate big merl", tab("{fx}/big_values.binary", "-o", "{out}/t.npz")))
    add(C("tabulate merl", tab("{fx}/good.binary", "-o", "{out}/t.npz", "--quiet"), expect="accept"))
    if have_rgl:
        add(C("tabulate trunc rgl", tab("{fx}/trunc.bsdf", "-o", "{out}/t.npz")))
        add(C("tabulate nan_luminance rgl", tab("{fx}/nan_luminance.bsdf", "-o", "{out}/t.npz")))

    # ---- corpus
    co = lambda *a: cli("corpus", "--out", "{out}/c", *a)  # noqa: E731
    for v in ("0", "-1", "1000000000", "abc", "2.5", "nan"):
        add(C(f"corpus --n {v}", co("--n", v), mentions=("n",)))
    add(C("corpus --seed abc", co("--seed", "abc"), mentions=("seed",)))
    add(C("corpus --seed -1", co("--seed", "-1", "--n", "2"), expect="either"))
    add(C("corpus --seed 2**80", co("--seed", str(2 ** 80), "--n", "2"), expect="either"))
    add(C("corpus --bands 0", co("--n", "2", "--tabulate", "mat0000", "--bands", "0"), mentions=("bands",)))
    add(C("corpus --bands 100000", co("--n", "2", "--tabulate", "mat0000", "--bands", "100000"), mentions=("bands",)))
    add(C("corpus --tabulate ../x", co("--n", "2", "--tabulate", "../x"), mentions=("..", "name")))
    add(C("corpus --tabulate a/b", co("--n", "2", "--tabulate", "a/b"), mentions=("name", "/")))
    add(C("corpus --tabulate ''", co("--n", "2", "--tabulate", "")))
    add(C("corpus --tabulate unknown material", co("--n", "2", "--tabulate", "mat9999")))
    add(C("corpus --families nosuch", co("--n", "2", "--families", "nosuch"), mentions=("famil", "nosuch")))
    add(C("corpus --families classic=-1", co("--n", "2", "--families", "classic=-1")))
    add(C("corpus --families classic=nan", co("--n", "2", "--families", "classic=nan")))
    add(C("corpus --families classic=0", co("--n", "2", "--families", "classic=0")))
    add(C("corpus --families =", co("--n", "2", "--families", "=")))
    add(C("corpus --families empty", co("--n", "2", "--families", "")))
    add(C("corpus --workers 0", co("--n", "2", "--inputs", "--workers", "0"), mentions=("workers",)))
    add(C("corpus --workers -2", co("--n", "2", "--inputs", "--workers", "-2"), mentions=("workers",)))
    add(C("corpus --workers 100000", co("--n", "2", "--inputs", "--workers", "100000"), mentions=("workers",)))
    add(C("corpus --out under a file", cli("corpus", "--n", "2", "--out", "{fx}/a_file/c")))
    add(C("corpus existing manifest", cli("corpus", "--n", "2", "--out", "{out}"),
          prepare="a_file->manifest.json", mentions=("exists",)))
    add(C("corpus small", co("--n", "2", "--quiet"), expect="accept"))

    # ---- train
    tr = lambda *a: cli("train", "--out", "{out}/run", *a)  # noqa: E731
    for v in ("0", "-1", "abc", "1e12", "2.5"):
        add(C(f"train --steps {v}", tr("--steps", v), mentions=("steps",)))
    for v in ("0", "-1", "nan", "inf", "abc"):
        add(C(f"train --max-minutes {v}", tr("--max-minutes", v, "--steps", "1"), mentions=("minutes",)))
    add(C("train --seed abc", tr("--seed", "abc"), mentions=("seed",)))
    add(C("train --device tpu", tr("--device", "tpu"), mentions=("device",)))
    if not _has_cuda():
        add(C("train --device cuda without a GPU", tr("--device", "cuda", "--steps", "1"), mentions=("GPU",)))
    add(C("train --config missing", tr("--config", "{fx}/nope.json"), mentions=("not found", "no such")))
    add(C("train --config folder", tr("--config", "{fx}"), mentions=("folder",)))
    for f, m in (("steps_str.json", "steps"), ("lr_nan.json", "lr"), ("steps_zero.json", "steps"),
                 ("steps_neg.json", "steps"), ("steps_bool.json", "steps"), ("steps_float.json", "steps"),
                 ("unknown_key.json", "stepz"), ("unknown_section.json", "trian"), ("model_int.json", "model"),
                 ("list_top.json", ""), ("syntax.json", ""), ("empty.json", ""), ("lr_neg.json", "lr"),
                 ("threads_zero.json", "threads"), ("image_size_huge.json", "image_size"),
                 ("lambda_inf.json", "lambda"), ("nested_null.json", "train"), ("device_tpu.json", "device"),
                 ("device_int.json", "device"), ("steps_str.toml", "steps"),
                 ("syntax.toml", ""), ("lr_array.toml", "lr"), ("config.yaml", "")):
        add(C(f"train --config {f}", tr("--config", "{fx}/" + f, "--steps", "1"), mentions=(m,) if m else ()))
    add(C("train --resume no checkpoint", tr("--resume", "--steps", "1"), mentions=("checkpoint",)))
    add(C("train --resume corrupt checkpoint", cli("train", "--out", "{out}", "--resume", "--steps", "1"),
          prepare="corrupt_checkpoint.pt->checkpoint.pt", mentions=("checkpoint",)))
    add(C("train over existing run", cli("train", "--out", "{out}", "--steps", "1"),
          prepare="good.npz->specgen.pt", mentions=("exist", "resume")))
    add(C("train --out under a file", cli("train", "--out", "{fx}/a_file/run", "--steps", "1"), mentions=("file",)))
    add(C("train --brdf-dir missing", tr("--brdf-dir", "{fx}/nope", "--steps", "1")))
    add(C("train --brdf-dir is a file", tr("--brdf-dir", "{fx}/a_file", "--steps", "1")))

    # ---- infer
    inf = lambda *a, src=img: cli("infer", src, "-o", "{out}/b.npz", "--quiet", *a)  # noqa: E731
    for v in ("0", "-1", "10000", "abc", "nan", "1.5"):
        add(C(f"infer --bands {v}", inf("--bands", v), mentions=("bands",)))
    for a, b in (("780", "380"), ("nan", "780"), ("100", "200"), ("380", "inf"), ("500", "500")):
        add(C(f"infer --range {a} {b}", inf("--range", a, b), mentions=("wavelength", "range")))
    for v in ("nan", "inf", "1e400"):
        add(C(f"infer --input-rotation {v}", inf("--input-rotation", v), mentions=("rotation",)))
    for v in ("0", "-1", "nan", "inf", "1e308"):
        add(C(f"infer --input-exposure {v}", inf("--input-exposure", v), mentions=("exposure",)))
    add(C("infer --input-env nosuch", inf("--input-env", "nosuch"), mentions=("nosuch",)))
    add(C("infer --input-env ../studio", inf("--input-env", "../studio")))
    add(C("infer --input-env missing.exr", inf("--input-env", "{fx}/nope.exr")))
    add(C("infer --input-env trunc.exr", inf("--input-env", "{fx}/trunc.exr")))
    add(C("infer --input-env nan.exr", inf("--input-env", "{fx}/nan.exr")))
    add(C("infer --weights missing", inf("--weights", "{fx}/nope.pt"), mentions=("nope.pt",)))
    add(C("infer --weights folder", inf("--weights", "{fx}"), mentions=("folder",)))
    for f in ("empty.pt", "text.pt", "trunc.pt", "evil.pt", "foreign.pt", "nan.pt"):
        add(C(f"infer --weights {f}", inf("--weights", "{fx}/" + f), mentions=(f,)))
    add(C("infer --backend onnx weights without onnx", inf("--backend", "onnx", "--weights", "{fx}/trunc.pt")))
    for f in ("nonexistent.png", "empty.png", "trunc.png", "header_only.png", "text.png", "trunc.exr",
              "text.exr", "zero.png", "huge_decl.png", "bomb20k.png", "huge_decl.jpg", "trunc.jpg",
              "one.png", "three.png", "black.png", "white.png", "sliver.png", "nan.exr", "inf.exr",
              "allnan.exr", "y_only.exr", "good.npz", "a_file"):
        add(C(f"infer image {f}", inf(src="{fx}/" + f)))
    add(C("infer image folder", inf(src="{fx}"), mentions=("folder",)))
    add(C("infer existing output", inf(), prepare="good.npz->b.npz", mentions=("exists",)))
    add(C("infer existing _rgb output", inf("--rgb"), prepare="good.npz->b_rgb.npz", mentions=("exists",)))
    add(C("infer output dir missing", cli("infer", img, "-o", "{out}/no/such/b.npz")))
    add(C("infer output is folder", cli("infer", img, "-o", "{out}"), mentions=("folder",)))
    add(C("infer output under a file", cli("infer", img, "-o", "{fx}/a_file/b.npz")))
    add(C("infer output .png suffix", cli("infer", img, "-o", "{out}/b.png"), expect="either"))

    # ---- evaluate
    ev = lambda *a: cli("evaluate", "--quiet", *a)  # noqa: E731
    for v in ("0", "-1", "100000", "abc"):
        add(C(f"evaluate --limit {v}", ev("--limit", v), mentions=("limit",)))
    add(C("evaluate --json folder", ev("--limit", "1", "--json", "{out}"), mentions=("folder",)))
    add(C("evaluate --json dir missing", ev("--limit", "1", "--json", "{out}/no/such/r.json")))
    add(C("evaluate --json existing", ev("--limit", "1", "--json", "{out}/r.json"), prepare="a_file->r.json",
          mentions=("exists",)))
    add(C("evaluate --json under a file", ev("--limit", "1", "--json", "{fx}/a_file/r.json")))
    add(C("evaluate --families -1", ev("--limit", "1", "--families", "-1"), mentions=("families",)))
    for v in ("0", "-5", "100000"):
        add(C(f"evaluate --family-resolution {v}", ev("--limit", "1", "--families", "1", "--family-resolution", v),
              mentions=("resolution",)))
    add(C("evaluate --weights missing", ev("--limit", "1", "--weights", "{fx}/nope.pt")))
    add(C("evaluate --weights nan.pt", ev("--limit", "1", "--weights", "{fx}/nan.pt")))

    # ---- export-onnx
    add(C("export-onnx --weights missing", cli("export-onnx", "--weights", "{fx}/nope.pt")))
    add(C("export-onnx --weights trunc", cli("export-onnx", "--weights", "{fx}/trunc.pt")))
    add(C("export-onnx --weights folder", cli("export-onnx", "--weights", "{fx}")))
    add(C("export-onnx --weights evil", cli("export-onnx", "--weights", "{fx}/evil.pt")))
    add(C("export-onnx over existing graphs", cli("export-onnx", "--weights", "{out}/w.pt"),
          prepare="good.pt->w.pt;a_file->w.tables.onnx", mentions=("exists",)))
    add(C("export-onnx --weights nan", cli("export-onnx", "--weights", "{fx}/nan.pt"), mentions=("NaN",)))


    # ---- render-input
    ri = lambda mat, *a: cli("render-input", mat, "-o", "{out}/in.exr", "--quiet", *a)  # noqa: E731
    for v in ("0", "15", "100000", "nan", "-16", "abc"):
        add(C(f"render-input --size {v}", ri(npz, "--size", v), mentions=("size",)))
    for m in ("mat9999", "mat99999999", "-1", "abc", "mat", "mat-3", "200"):
        add(C(f"render-input material {m}", ri(m)))
    for f in ("nan.npz", "neg.npz", "inf.npz", "trunc.npz", "nan.binary", "allneg.binary", "nope.npz"):
        add(C(f"render-input {f}", ri("{fx}/" + f)))
    for v in ("-1", "1000000000", "abc"):
        add(C(f"render-input --variant {v}", ri(npz, "--variant", v), mentions=("variant",)))
    add(C("render-input -o .txt", cli("render-input", npz, "-o", "{out}/in.txt")))
    add(C("render-input existing", ri(npz), prepare="a_file->in.exr", mentions=("exists",)))
    add(C("render-input existing sibling png", ri(npz), prepare="a_file->in.png", mentions=("exists",)))
    add(C("render-input dir missing", cli("render-input", npz, "-o", "{out}/no/such/in.exr")))
    add(C("render-input --manifest missing", ri("mat0001", "--manifest", "{fx}/nope.json")))
    add(C("render-input --manifest bad json", ri("mat0001", "--manifest", "{fx}/bad_manifest.json")))
    add(C("render-input --manifest wrong shape", ri("mat0001", "--manifest", "{fx}/manifest_wrong.json")))

    # ---- ablate
    ab = lambda *a: cli("ablate", "--out", "{out}/a.md", *a)  # noqa: E731
    for v in ("0", "-3", "abc", "1e12"):
        add(C(f"ablate --steps {v}", ab("--steps", v), mentions=("steps",)))
    add(C("ablate --seeds 1 1", ab("--seeds", "1", "1"), mentions=("seeds",)))
    add(C("ablate --seeds -1", ab("--seeds", "-1"), mentions=("seeds",)))
    add(C("ablate --arms nope", ab("--arms", "nope"), mentions=("arm",)))
    add(C("ablate --workers 0", ab("--workers", "0"), mentions=("workers",)))
    add(C("ablate --out dir missing", cli("ablate", "--out", "{out}/no/such/a.md")))
    add(C("ablate --json folder", cli("ablate", "--json", "{out}")))
    add(C("ablate --with-records missing", ab("--with-records", "{fx}/nope.json"), mentions=("not found",)))
    add(C("ablate --with-records bad json", ab("--with-records", "{fx}/bad_manifest.json"), mentions=("json",)))
    add(C("ablate --with-records a folder", ab("--with-records", "{fx}"), mentions=("folder",)))

    # ---- paper-tables
    pt = lambda *a: cli("paper-tables", "--out", "{out}/r.md", "--quiet", *a)  # noqa: E731
    for v in ("0", "-1", "100000"):
        add(C(f"paper-tables --resolution {v}", pt("--resolution", v), mentions=("resolution",)))
    for v in ("0", "-1", "../x", "a/b", "nosuch"):
        add(C(f"paper-tables --materials {v}", pt("--materials", v)))
    add(C("paper-tables --budget-minutes -1", pt("--budget-minutes", "-1"), mentions=("minutes",)))
    add(C("paper-tables --ablation-steps 0", pt("--ablation-steps", "0"), mentions=("steps",)))
    add(C("paper-tables --out dir missing", cli("paper-tables", "--out", "{out}/no/such/r.md")))
    add(C("paper-tables --out folder", cli("paper-tables", "--out", "{out}")))
    add(C("paper-tables --weights missing", pt("--weights", "{fx}/nope.pt")))
    add(C("paper-tables --img-dir a file", pt("--img-dir", "{fx}/a_file", "--report-only")))
    add(C("paper-tables --report-only empty cache", pt("--report-only")))

    # ---- batch-many
    bm = lambda *a: cli("batch-many", "--out", "{out}/bm", "--quiet", *a)  # noqa: E731
    add(C("batch-many no inputs", bm()))
    add(C("batch-many nonexistent input", bm("{fx}/nope.png")))
    add(C("batch-many --workers 0", bm("--workers", "0", img), mentions=("workers",)))
    add(C("batch-many --retries -1", bm("--retries", "-1", img), mentions=("retries",)))
    add(C("batch-many --timeout 0", bm("--timeout", "0", img), mentions=("timeout",)))
    add(C("batch-many --timeout nan", bm("--timeout", "nan", img), mentions=("timeout",)))
    add(C("batch-many --batch-args --resolution 0", bm("--batch-args=--resolution 0", img), mentions=("resolution",)))
    add(C("batch-many --batch-args bad quote", bm("--batch-args=--env 'studio", img)))
    add(C("batch-many --batch-args --out", bm("--batch-args=--out /tmp/x", img)))
    add(C("batch-many --manifest missing", bm("--manifest", "{fx}/nope.txt")))
    add(C("batch-many --manifest bad json", bm("--manifest", "{fx}/inputs_bad.json")))
    add(C("batch-many --manifest missing entries", bm("--manifest", "{fx}/inputs_list.txt")))
    add(C("batch-many --scheduler bogus", bm("--scheduler", "not a url", img)))
    add(C("batch-many --blender missing", bm("--blender", "{fx}/no-blender", img)))
    add(C("batch-many --out is a file", cli("batch-many", "--out", "{fx}/a_file", img)))

    # ---- batch.py
    bt = lambda *a, src=("--brdf", npz): batch(*src, "--out", "{out}/o", *a)  # noqa: E731
    for v in ("0", "-1", "100000", "abc"):
        add(C(f"batch --resolution {v}", bt("--resolution", v), mentions=("resolution",)))
    for v in ("0", "10000"):
        add(C(f"batch --bands {v}", bt("--bands", v), mentions=("bands",)))
    for v in ("0", "-5", "nan"):
        add(C(f"batch --samples {v}", bt("--samples", v), mentions=("samples",)))
    add(C("batch --env-samples 0", bt("--env-samples", "0"), mentions=("env-samples",)))
    add(C("batch --wl-min 2000", bt("--wl-min", "2000"), mentions=("wavelength",)))
    add(C("batch --env nosuch", bt("--env", "nosuch"), mentions=("nosuch",)))
    add(C("batch --env ../world/studio", bt("--env", "../world/studio"), mentions=("name",)))
    add(C("batch --mesh nosuch", bt("--mesh", "nosuch")))
    for f in ("empty.obj", "verts_only.obj", "trunc.obj", "nan.obj", "bad_index.obj", "zero_index.obj", "garbage.obj"):
        add(C(f"batch --mesh {f}", bt("--mesh", "{fx}/" + f)))
    add(C("batch --image missing", bt(src=("--image", "{fx}/nope.png"))))
    add(C("batch --image trunc", bt(src=("--image", "{fx}/trunc.png"))))
    add(C("batch --image folder", bt(src=("--image", "{fx}")), mentions=("folder",)))
    add(C("batch --image huge header", bt(src=("--image", "{fx}/huge_decl.png")), mentions=("megapixel",)))
    add(C("batch --brdf nan", bt(src=("--brdf", "{fx}/nan.npz"))))
    add(C("batch --brdf trunc", bt(src=("--brdf", "{fx}/trunc.npz"))))
    add(C("batch --brdf rgb-only merl", bt(src=("--brdf", "{fx}/big_values.binary"))))
    add(C("batch --out under a file", batch("--brdf", npz, "--out", "{fx}/a_file/o")))
    add(C("batch existing lookup", batch("--brdf", npz, "--out", "{out}"), prepare="a_file->lookup/x.exr",
          mentions=("exists", "overwrite")))
    add(C("batch --input-exposure nan", bt("--input-exposure", "nan", src=("--image", img)), mentions=("exposure",)))
    add(C("batch --scene missing", batch("--scene", "{fx}/nope.blend", "--out", "{out}/o")))
    add(C("batch --scene not a blend", batch("--scene", "{fx}/not_a.blend", "--out", "{out}/o")))
    add(C("batch --weights missing", bt("--weights", "{fx}/nope.pt", src=("--image", img))))
    add(C("batch no source", batch("--out", "{out}/o")))

    # ---- special files and odd names
    add(C("info /dev/zero", cli("info", "/dev/zero"), mentions=("not a regular file",)))
    add(C("info /dev/null", cli("info", "/dev/null"), mentions=("not a regular file",)))
    add(C("infer image /dev/zero", cli("infer", "/dev/zero", "-o", "{out}/b.npz")))
    add(C("infer image /dev/null", cli("infer", "/dev/null", "-o", "{out}/b.npz")))
    add(C("infer -o /dev/null", cli("infer", img, "-o", "/dev/null")))
    add(C("info named pipe", cli("info", "{fx}/fifo.npz"), mentions=("not a regular file",)))
    add(C("infer image named pipe", cli("infer", "{fx}/fifo.png", "-o", "{out}/b.npz"), mentions=("not a regular file",)))
    add(C("train --config named pipe", tr("--config", "{fx}/fifo.json", "--steps", "1"), mentions=("not a regular file",)))
    add(C("batch --mesh named pipe", bt("--mesh", "{fx}/fifo.obj"), mentions=("not a regular file",)))
    add(C("batch --image named pipe", bt(src=("--image", "{fx}/fifo.png")), mentions=("not a regular file",)))
    add(C("info unicode path", cli("info", "{out}/ünï cödé ✓.npz"), prepare="good.npz->ünï cödé ✓.npz",
          expect="accept"))
    add(C("info dangling symlink", cli("info", "{fx}/dangling.npz"), mentions=("not found", "no such")))
    add(C("batch --image is a table", batch("--image", npz, "--out", "{out}/o")))
    add(C("batch --brdf is a photo", batch("--brdf", img, "--out", "{out}/o")))
    add(C("batch --image name with newline", batch("--image", "{out}/a\nb.png", "--out", "{out}/o"),
          prepare="good.png->a\nb.png"))
    add(C("render-input --manifest folder", ri("mat0001", "--manifest", "{fx}"), mentions=("folder",)))
    add(C("evaluate --weights text", ev("--limit", "1", "--weights", "{fx}/text.pt")))
    add(C("paper-tables --img-dir under a file", pt("--img-dir", "{fx}/a_file/img", "--report-only")))
    add(C("corpus --tabulate dup name", co("--n", "2", "--tabulate", "mat0000", "--tabulate", "mat0000"),
          expect="either"))

    # ---- Python API
    add(C("api generate_brdf missing path", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf('/nonexistent/x.png')""")))
    add(C("api generate_brdf NaN array", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(np.full((128, 128, 3), np.nan))""")))
    add(C("api generate_brdf 1-d array", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(np.ones(5))""")))
    add(C("api generate_brdf empty array", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(np.zeros((0, 0, 3)))""")))
    add(C("api generate_brdf string array", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(np.array([['a']]))""")))
    add(C("api generate_brdf wavelengths []", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, wavelengths_nm=[])""" % str(REPO / "examples/sphere.png"))))
    add(C("api generate_brdf wavelengths decreasing", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, wavelengths_nm=[700, 400])""" % str(REPO / "examples/sphere.png"))))
    add(C("api generate_brdf wavelengths NaN", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, wavelengths_nm=[np.nan])""" % str(REPO / "examples/sphere.png"))))
    add(C("api generate_brdf wavelengths 100 nm", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, wavelengths_nm=[100.0])""" % str(REPO / "examples/sphere.png"))))
    add(C("api generate_brdf backend foo", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, backend='foo')""" % str(REPO / "examples/sphere.png"))))
    add(C("api generate_brdf weights missing", api("""
        from specgen_addon.model.runtime.inference import generate_brdf
        generate_brdf(%r, weights='/nonexistent.pt')""" % str(REPO / "examples/sphere.png"))))
    add(C("api BRDFTable.load missing", api("""
        from specgen_addon.brdf.table import BRDFTable
        BRDFTable.load('/nonexistent.npz')""")))
    for f in ("trunc.npz", "nan.npz", "pickle.npz", "shape.npz", "empty.npz", "overflow.npz"):
        add(C(f"api BRDFTable.load {f}", api(f"""
            from specgen_addon.brdf.table import BRDFTable
            BRDFTable.load('{{fx}}/{f}')""")))
    add(C("api BRDFTable.load folder", api("""
        from specgen_addon.brdf.table import BRDFTable
        BRDFTable.load('{fx}')""")))
    for f in ("unknown.xyz", "trunc.binary", "dims_huge.binary", "empty.bsdf", "nope.npz"):
        add(C(f"api load_brdf {f}", api(f"""
            from specgen_addon.brdf.formats import load_brdf
            load_brdf('{{fx}}/{f}')""")))
    add(C("api refine_brdf RGB table", api("""
        from specgen_addon.brdf.table import BRDFTable, GRID_SHAPE
        from specgen_addon.generate.refine import refine_brdf
        t = BRDFTable(np.full(GRID_SHAPE + (3,), 0.1, np.float32), None)
        refine_brdf(t, np.full((128, 128, 3), 0.1))""")))
    add(C("api refine_brdf photo shape", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.generate.refine import refine_brdf
        refine_brdf(BRDFTable.load('{fx}/good.npz'), np.full((5, 7), 0.1))""")))
    add(C("api refine_brdf photo NaN", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.generate.refine import refine_brdf
        refine_brdf(BRDFTable.load('{fx}/good.npz'), np.full((128, 128, 3), np.nan))""")))
    add(C("api refine_brdf not a table", api("""
        from specgen_addon.generate.refine import refine_brdf
        refine_brdf('table.npz', np.full((128, 128, 3), 0.1))""")))
    add(C("api bake_atlas not a table", api("""
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(np.ones(3), '{out}/a.exr')""")))
    add(C("api bake_atlas path under a file", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{fx}/a_file/a.exr')""")))
    add(C("api bake_atlas max_coeffs 0", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', max_coeffs=0)""")))
    add(C("api bake_atlas n_phi_d 0", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', n_phi_d=0)""")))
    add(C("api bake_atlas tolerance -1", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', tolerance=-1)""")))
    add(C("api bake_atlas wavelengths 2000 nm", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', wavelengths_nm=np.array([2000.0]))""")))
    add(C("api bake_atlas wavelengths NaN", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', wavelengths_nm=np.array([np.nan, 500.0]))""")))
    add(C("api bake_atlas existing no overwrite", api("""
        from specgen_addon.brdf.table import BRDFTable
        from specgen_addon.bake.lookup import bake_atlas
        bake_atlas(BRDFTable.load('{fx}/good.npz'), '{out}/a.exr', overwrite=False)"""),
        prepare="a_file->a.exr", expect="either"))
    # ordinary photos: must be accepted (converted, with a note)
    for f in ("gray.png", "gray_alpha.png", "palette.png", "gray16.png", "rgba.png", "q95.jpg", "cmyk.jpg",
              "png_named.jpg", "neg.exr"):
        add(C(f"api load_sphere_image {f}", api(f"""
            from specgen_addon.photo.sphere_image import load_sphere_image
            img = load_sphere_image('{{fx}}/{f}')
            assert img.shape[-1] == 3 and np.isfinite(img).all(), img.shape"""), expect="accept"))
    for f in ("sphere.bmp", "sphere.tif", "sphere.gif"):   # other formats: read, or refused in one line
        add(C(f"api load_sphere_image {f}", api(f"""
            from specgen_addon.photo.sphere_image import load_sphere_image
            load_sphere_image('{{fx}}/{f}')"""), expect="either"))
    add(C("infer gray.png", inf("--no-refine", src="{fx}/gray.png"), expect="accept", timeout=300))
    if big:
        add(C("infer 8000x8000 png", cli("infer", "{fx}/big8000.png", "-o", "{out}/b.npz", "--quiet",
                                         "--no-refine"), expect="accept", timeout=600, measure_memory=True))
    return out


# ------------------------------------------------------------------------------------ running
def snapshot(folder: Path) -> dict[str, str]:
    """Relative path → sha256 (or "dir") of everything under ``folder``."""
    snap = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        snap[rel] = hashlib.sha256(p.read_bytes()).hexdigest() if p.is_file() else "dir"
    return snap


def expand(s: str, work: Path, fx: Path) -> str:
    return (s.replace("{fx}", str(fx)).replace("{out}", str(work / "out"))
            .replace("{work}", str(work)).replace("{repo}", str(REPO)))


def run_case(case: Case, base: Path, fx: Path) -> Result:
    work = base / "cases" / "".join(c if c.isalnum() else "_" for c in case.name)
    (work / "out").mkdir(parents=True)
    (work / "tmp").mkdir()
    for step in filter(None, case.prepare.split(";")):
        src, dest = step.split("->")
        (work / "out" / dest).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(fx / src, work / "out" / dest)
    argv = [PY, *[expand(a, work, fx) for a in case.argv]]
    if case.measure_memory:
        argv = ["/usr/bin/time", "-v", *argv]
    env = {**os.environ, "TMPDIR": str(work / "tmp"), "PYTHONPATH": str(REPO)}
    env.pop("SPECGEN_VERBOSE", None)
    before = snapshot(work)
    t0 = time.perf_counter()
    try:
        done = subprocess.run(argv, cwd=work, env=env, capture_output=True, text=True, timeout=case.timeout,
                              stdin=subprocess.DEVNULL)
        code, stdout, stderr, timed_out = done.returncode, done.stdout, done.stderr, False
    except subprocess.TimeoutExpired as exc:
        code, timed_out = None, True
        stdout = (exc.stdout or b"").decode(errors="replace") if isinstance(exc.stdout, bytes) else exc.stdout or ""
        stderr = (exc.stderr or b"").decode(errors="replace") if isinstance(exc.stderr, bytes) else exc.stderr or ""
    seconds = time.perf_counter() - t0
    peak = None
    if case.measure_memory:
        for line in stderr.splitlines():
            if "Maximum resident set size" in line:
                peak = int(line.split(":")[1]) / 2**20
        stderr = stderr.split("\tCommand being timed")[0]
    lines = [ln for ln in stderr.strip().splitlines() if ln.strip()]
    message = lines[-1] if lines else ""
    after = snapshot(work)
    if code == 0:   # an accepted run may write its outputs, but nothing in the temp folder
        changed = [k for k, v in after.items() if k.startswith("tmp/") and before.get(k) != v]
    else:
        changed = [k for k, v in after.items() if before.get(k) != v]
    # onnxruntime writes its session id to $TMPDIR/.ses when imported (one fixed, overwritten file,
    # not SpecGen's output): recorded, not counted
    third_party = [k for k in changed if k == THIRD_PARTY_TEMP]
    changed = [k for k in changed if k != THIRD_PARTY_TEMP]
    changed += [f"(removed) {k}" for k in before if k not in after and not (code == 0 and k.startswith("out/"))]
    r = Result(case.name, case.expect, code, round(seconds, 2), message[:300], peak_rss_gb=peak,
               third_party_temp=third_party)
    r.traceback = "Traceback" in stdout or "Traceback" in stderr
    r.timeout = timed_out
    r.silently_accepted = case.expect == "refuse" and code == 0
    r.wrongly_refused = case.expect == "accept" and code not in (0, None)
    r.leftovers = changed
    r.internal = "internal error" in stderr
    if code not in (0, None) and case.mentions:
        r.misleading = not any(m.lower() in stderr.lower() for m in case.mentions)
    if code not in (0, None) and "error:" not in message:   # the refusal must end in its one error line
        r.misleading = True
    shutil.rmtree(work, ignore_errors=True)
    return r
