"""Faults lose nothing: shared outputs, locks, full disks, long names, damaged networks.

The disk-full cases use a 1 MiB tmpfs where the machine lets the tests mount one (root on
Linux), and a write patched to fail with ENOSPC everywhere else.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.common.errors import OutputBusyError, OutputExistsError, OutputWriteError, SpecGenError
from specgen_addon.common.atomic_io import OutputLock, atomic_write, lock_path
from stop_stand_ins import fake_blender_modules, sigint_when_ready

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "examples" / "sphere.png"
WEIGHTS = REPO / "weights" / "specgen_default.pt"


# ------------------------------------------------------------------------ owning what it made
def test_a_failed_command_never_removes_a_file_another_process_published(tmp_path):
    """The loser of a race on one output used to delete the winner's file on its way out."""
    from specgen_addon.cli.app import run_guarded

    out = tmp_path / "b.npz"

    def work():
        out.write_text("the other process's finished table")  # published meanwhile, not by us
        with atomic_write(out) as tmp:  # our own write then finds it: refused
            tmp.write_text("ours")

    code = run_guarded("infer", work, ([], [out]))
    assert code == 2
    assert out.read_text() == "the other process's finished table"


def test_a_write_without_overwrite_never_replaces_a_file_that_appeared_meanwhile(tmp_path):
    out = tmp_path / "t.json"
    with pytest.raises(OutputExistsError, match="another process"):
        with atomic_write(out) as tmp:
            tmp.write_text("ours")
            out.write_text("theirs")
    assert out.read_text() == "theirs"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.json"]


def _a_neighbour_publishes_beside_ours(out: Path) -> None:
    (out / "theirs.exr").write_text("a neighbour's finished render")


def _another_process_replaces_ours(out: Path) -> None:
    os.unlink(out / "ours.exr")
    (out / "ours.exr").write_text("theirs, same name")  # another inode: not ours any more


@pytest.mark.parametrize("stop, neighbour, left", [
    (KeyboardInterrupt, _a_neighbour_publishes_beside_ours, {"theirs.exr": "a neighbour's finished render"}),
    (RuntimeError, _another_process_replaces_ours, {"ours.exr": "theirs, same name"}),
], ids=["stopped-with-a-neighbours-file-beside", "failed-after-ours-was-replaced"])
def test_cleanup_removes_only_what_the_command_made(tmp_path, stop, neighbour, left):
    """Two batch.py runs into one folder, or our output replaced by another process after we wrote
    it: the clean-up of the stopped or failed command removes only its own files."""
    from specgen_addon.common.interrupts import OutputGuard

    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(stop):
        with OutputGuard([out]):
            with atomic_write(out / "ours.exr") as tmp:
                tmp.write_text("ours")
            neighbour(out)
            raise stop
    assert {p.name: p.read_text() for p in out.iterdir()} == left


# ------------------------------------------------------------------------------------ locks
def test_an_output_being_written_is_refused_up_front_by_its_lock(tmp_path):
    out = tmp_path / "b.npz"
    with OutputLock([out]):
        assert lock_path(out).is_file()
        info = json.loads(lock_path(out).read_text())
        assert info["pid"] == os.getpid() and info["host"] == socket.gethostname()
        # another process on the same output: refused in well under a second, nothing written
        t0 = time.perf_counter()
        done = subprocess.run([sys.executable, "-m", "specgen_addon", "infer", str(EXAMPLE), "-o", str(out),
                               "--quiet"], cwd=REPO, capture_output=True, text=True, timeout=120)
        text = done.stdout + done.stderr
        assert done.returncode == 2, text
        assert "Traceback" not in text and f"SpecGen process {os.getpid()}" in text, text
        assert time.perf_counter() - t0 < 60
    assert not lock_path(out).exists()  # released on exit
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_stale_lock_of_a_process_that_is_gone_is_taken_over(tmp_path):
    out = tmp_path / "out"
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    lock_path(out).write_text(json.dumps({"pid": int(gone), "host": socket.gethostname()}))
    with OutputLock([out]) as lock:
        assert lock.held and json.loads(lock_path(out).read_text())["pid"] == os.getpid()
    assert not lock_path(out).exists()


def test_a_lock_held_on_another_host_is_refused_with_its_owner(tmp_path):
    out = tmp_path / "out"
    lock_path(out).write_text(json.dumps({"pid": 1, "host": "render-node-7"}))
    with pytest.raises(OutputBusyError, match="process 1 on render-node-7"):
        with OutputLock([out]):
            pass
    assert lock_path(out).exists()  # not ours to remove


def test_a_long_output_name_gets_a_lock_name_that_fits(tmp_path):
    out = tmp_path / ("x" * 250 + ".npz")
    assert len(lock_path(out).name.encode()) <= 255
    with OutputLock([out]):
        assert lock_path(out).is_file()


# ------------------------------------------------------------------------------------ names
@pytest.mark.parametrize("size", [246, 250, 255])
def test_names_up_to_the_file_system_limit_are_written_despite_the_staging_name(tmp_path, size):
    out = tmp_path / ("n" * (size - 4) + ".npz")
    with atomic_write(out) as tmp:
        assert len(tmp.name.encode()) <= 255 and tmp.suffix == ".npz"
        tmp.write_bytes(b"x")
    assert out.read_bytes() == b"x"


def test_a_name_over_the_limit_is_one_sentence_before_any_work(tmp_path):
    from specgen_addon.common.limits import check_output_file

    with pytest.raises(SpecGenError, match="256 bytes long"):
        check_output_file(tmp_path / ("n" * 252 + ".npz"))


# ------------------------------------------------------------------------------- full disks
@pytest.fixture
def full_dir(tmp_path):
    """A 1 MiB tmpfs (every table, render or big JSON overflows it); skipped where mounting is
    not permitted (not root, a container without CAP_SYS_ADMIN, not Linux)."""
    folder = tmp_path / "small"
    folder.mkdir()
    if sys.platform != "linux" or shutil.which("mount") is None:
        pytest.skip("needs Linux mount for a size-limited tmpfs")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(folder)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a size-limited tmpfs here ({done.stderr.strip() or done.returncode})")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)


def _big_table():
    from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable

    return BRDFTable(np.full(GRID_SHAPE + (2,), 0.1, np.float32), np.array([500.0, 600.0]),
                     ("500", "600"), {})


def _writers(folder: Path) -> dict:
    from specgen_addon.common import image_io
    from specgen_addon.render import spectral_exr

    def big_json():
        with atomic_write(folder / "report.json") as tmp:
            tmp.write_text(json.dumps(list(range(400_000))))

    return {
        "npz": (folder / "t.npz", lambda: _big_table().save(folder / "t.npz")),
        "exr": (folder / "a.exr", lambda: image_io.write_exr(
            folder / "a.exr", {c: np.random.rand(512, 512).astype(np.float32) for c in "RGB"})),
        "spectral-exr": (folder / "s.exr", lambda: spectral_exr.write_spectral_exr(
            folder / "s.exr", np.random.rand(128, 128, 21).astype(np.float32), np.linspace(380, 780, 21))),
        "png": (folder / "p.png", lambda: image_io.write_png8(
            folder / "p.png", (np.random.rand(1024, 1024, 3) * 255).astype(np.uint8))),
        "json": (folder / "report.json", big_json),
    }


@pytest.mark.parametrize("kind", ["npz", "exr", "spectral-exr", "png", "json"])
def test_a_full_disk_is_one_sentence_naming_the_output_and_leaves_nothing(kind, full_dir):
    target, write = _writers(full_dir)[kind]
    with pytest.raises(OutputWriteError) as info:
        write()
    assert str(info.value) == f"{target}: cannot be written (No space left on device); nothing partial was left"
    assert list(full_dir.iterdir()) == []


@pytest.mark.parametrize("kind", ["npz", "json"])
def test_a_write_failing_with_enospc_is_one_sentence_where_no_tmpfs_can_be_mounted(kind, tmp_path,
                                                                                   monkeypatch):
    import builtins

    real_open = builtins.open

    class Full:
        def __init__(self, fh):
            self.fh, self.n = fh, 0

        def write(self, data):
            self.n += len(data)
            if self.n > 100_000:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
            return self.fh.write(data)

        def __getattr__(self, name):
            return getattr(self.fh, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.fh.close()

    def fake_open(path, mode="r", *a, **k):
        fh = real_open(path, mode, *a, **k)
        return Full(fh) if "w" in mode and str(path).startswith(str(tmp_path)) else fh

    monkeypatch.setattr(builtins, "open", fake_open)
    monkeypatch.setattr(Path, "write_text", lambda self, text, *a, **k: fake_open(self, "w").write(text))
    target, write = _writers(tmp_path)[kind]
    with pytest.raises(OutputWriteError, match=f"^{target}: cannot be written \\(No space left on device\\)"):
        write()
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_under_the_cli_prints_one_line_without_a_traceback(full_dir):
    """numpy's zip writer used to leave its archive open after ENOSPC: one line of error, then
    "Exception ignored … ValueError: seek of closed file" at exit."""
    code = ("import sys, numpy as np; sys.path.insert(0, %r)\n"
            "from specgen_addon.cli.app import run_guarded\n"
            "from specgen_addon.brdf.table import GRID_SHAPE, BRDFTable\n"
            "t = BRDFTable(np.full(GRID_SHAPE + (2,), 0.1, np.float32), np.array([500.0, 600.0]), ('a', 'b'), {})\n"
            "sys.exit(run_guarded('infer', lambda: t.save(%r), ([], [%r])))\n"
            % (str(REPO), str(full_dir / "b.npz"), str(full_dir / "b.npz")))
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    text = done.stdout + done.stderr
    assert done.returncode == 2, text
    assert text.strip() == f"error: {full_dir / 'b.npz'}: cannot be written (No space left on device); " \
                           "nothing partial was left", text
    assert list(full_dir.iterdir()) == []


# -------------------------------------------------------------------------- damaged networks
def _copy_shipped(tmp_path: Path) -> Path:
    if not (WEIGHTS.is_file() and (WEIGHTS.parent / "SHA256SUMS").is_file()):
        pytest.skip("needs the shipped weights and their SHA256SUMS")
    for name in ("specgen_default.pt", "specgen_default.tables.onnx", "specgen_default.head.onnx", "SHA256SUMS"):
        shutil.copyfile(WEIGHTS.parent / name, tmp_path / name)
    return tmp_path / "specgen_default.pt"


def test_every_shipped_network_file_is_listed_with_its_current_sum():
    from specgen_addon.model.checksums import read_sums, sha256

    sums = read_sums(WEIGHTS.parent)
    shipped = sorted(p.name for p in WEIGHTS.parent.iterdir() if p.suffix in (".pt", ".onnx"))
    assert shipped and sorted(sums) == shipped
    assert all(sha256(WEIGHTS.parent / n) == h for n, h in sums.items())


def test_flipped_bytes_in_shipped_weights_are_refused_with_the_file_named(tmp_path):
    pytest.importorskip("torch")
    from specgen_addon.model import load_weights
    from specgen_addon.model.checksums import DamagedWeightsError

    pt = _copy_shipped(tmp_path)
    data = bytearray(pt.read_bytes())
    for i in range(64):
        data[len(data) // 2 + i] ^= 0xFF
    pt.write_bytes(bytes(data))
    with pytest.raises(DamagedWeightsError, match=f"^{pt}: damaged or modified"):
        load_weights(pt)


def test_a_truncated_shipped_graph_is_refused_not_replaced_by_torch(tmp_path):
    """batch.py's onnx→torch fallback used to take a damaged graph silently."""
    pytest.importorskip("onnxruntime")
    from specgen_addon.generate.pipeline import generate
    from specgen_addon.model.checksums import DamagedWeightsError

    pt = _copy_shipped(tmp_path)
    graph = tmp_path / "specgen_default.tables.onnx"
    graph.write_bytes(graph.read_bytes()[: graph.stat().st_size // 2])
    with pytest.raises(DamagedWeightsError, match="specgen_default.tables.onnx: damaged"):
        generate(str(EXAMPLE), out_dir=tmp_path / "lookup", wavelengths_nm=np.linspace(400, 700, 4), weights=pt,
                 backend=None, refine=False)
    assert not (tmp_path / "lookup").exists()


def test_a_fallback_to_torch_is_said(tmp_path, monkeypatch):
    """Graphs missing beside the user's own weights: the torch backend runs, with a warning."""
    pytest.importorskip("onnxruntime")
    pytest.importorskip("torch")
    from specgen_addon.generate import pipeline
    from specgen_addon.common.errors import WeightsError

    calls = []

    def fake_generate(image, backend, **kw):
        calls.append(backend)
        if backend == "onnx":
            raise WeightsError("w.tables.onnx: ONNX graph not found")
        raise RuntimeError("stop here")

    monkeypatch.setattr(pipeline, "_generate", fake_generate)
    with pytest.warns(UserWarning, match="onnx backend cannot run .*using the torch backend"):
        with pytest.raises(RuntimeError, match="stop here"):
            pipeline.generate(str(EXAMPLE), out_dir=tmp_path / "lookup", wavelengths_nm=np.linspace(400, 700, 4),
                              backend=None)
    assert calls == ["onnx", "torch"]


# ----------------------------------------------------------------------------- environment maps
def _tiled_exr(path: Path, rgb: np.ndarray, tile: int = 16) -> Path:
    oiio = pytest.importorskip("OpenImageIO")
    spec = oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.FLOAT)
    spec.tile_width = spec.tile_height = tile
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), spec)
    out.write_image(np.ascontiguousarray(rgb, np.float32))
    out.close()
    return path


def test_a_20000_by_10000_map_is_refused_from_its_header_in_under_a_second(tmp_path):
    import struct

    from specgen_addon.common import image_io
    from specgen_addon.photo.photo_lighting import LightingError, parse_lighting

    path = tmp_path / "huge.exr"
    image_io.write_exr(path, {c: np.full((1, 2), 0.5, np.float32) for c in "RGB"})
    data = bytearray(path.read_bytes())  # the header declares 20000×10000
    for name in (b"dataWindow", b"displayWindow"):
        at = data.index(name + b"\0box2i\0") + len(name) + 11
        data[at:at + 16] = struct.pack("<4i", 0, 0, 19999, 9999)
    path.write_bytes(bytes(data))
    t0 = time.perf_counter()
    with pytest.raises(LightingError, match="20000×10000 = 200 megapixels; the limit is 100 megapixels"):
        parse_lighting(str(path))
    assert time.perf_counter() - t0 < 1.0


@pytest.mark.parametrize("shape", [(64, 64), (8, 512), (512, 8)])
def test_a_map_that_is_not_2_to_1_is_refused(tmp_path, shape):
    from specgen_addon.common import image_io
    from specgen_addon.photo.photo_lighting import LightingError, parse_lighting

    path = tmp_path / "map.exr"
    image_io.write_exr(path, {c: np.full(shape, 0.5, np.float32) for c in "RGB"})
    with pytest.raises(LightingError, match="twice as wide as it is high"):
        parse_lighting(str(path))


@pytest.mark.parametrize("tiled", [False, True])
def test_a_map_is_read_in_strips_as_the_renderer_reads_it_and_negative_texels_are_said(tmp_path, tiled):
    from specgen_addon.common import image_io
    from specgen_addon.photo.image_checks import ImageNote
    from specgen_addon.photo.photo_lighting import read_map_bounded
    from specgen_addon.render.environment import _box_downsample, read_exr_rgb

    rgb = np.random.default_rng(1).random((1024, 2048, 3)).astype(np.float32)
    rgb[:3, :5, 1] = -0.25
    path = tmp_path / "map.exr"
    if tiled:
        _tiled_exr(path, rgb)
    else:
        image_io.write_exr(path, {c: rgb[..., i] for i, c in enumerate("RGB")})
    with pytest.warns(ImageNote, match="15 negative values .* clamped to 0"):
        got = read_map_bounded(path, max_width=512)
    want = _box_downsample(read_exr_rgb(path), 512)
    assert got.shape == want.shape == (256, 512, 3)
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------- two real processes, one output
def _wait_for_lock(proc: subprocess.Popen, lock: Path, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while not lock.exists():
        assert proc.poll() is None and time.monotonic() < deadline, "the first command never took its lock"
        time.sleep(0.05)


@pytest.mark.slow
def test_two_infer_on_one_npz_the_second_is_refused_and_the_first_keeps_its_file(tmp_path):
    out = tmp_path / "b.npz"
    cmd = [sys.executable, "-m", "specgen_addon", "infer", str(EXAMPLE), "-o", str(out), "--quiet", "--no-refine"]
    first = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        _wait_for_lock(first, lock_path(out))
        t0 = time.perf_counter()
        second = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)
        assert second.returncode == 2 and f"SpecGen process {first.pid}" in second.stderr, second.stderr
        assert "Traceback" not in second.stderr and time.perf_counter() - t0 < 30
        text, _ = first.communicate(timeout=900)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, text
    from specgen_addon.brdf.table import BRDFTable

    assert BRDFTable.load(out).is_spectral
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.npz"]


def _batch_cmd(out: Path, *extra: str) -> list[str]:
    return [sys.executable, str(REPO / "batch.py"), "--image", str(EXAMPLE), "--out", str(out),
            "--resolution", "16", "--samples", "1", "--bands", "4", *extra]


@pytest.mark.slow
@pytest.mark.blender
def test_two_batch_py_into_one_folder_the_second_is_refused_before_any_work(tmp_path):
    pytest.importorskip("bpy")
    out = tmp_path / "out"
    first = subprocess.Popen(_batch_cmd(out), cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                             text=True)
    try:
        _wait_for_lock(first, lock_path(out))
        second = subprocess.run(_batch_cmd(out, "--mesh", "suzanne"), cwd=REPO, capture_output=True,
                                text=True, timeout=300)
        assert second.returncode == 2 and "is writing it" in second.stderr, second.stderr
        assert "generate:" not in second.stdout
        text, _ = first.communicate(timeout=900)
    finally:
        if first.poll() is None:
            first.kill()
    assert first.returncode == 0, text
    assert (out / "sphere_sphere_studio.exr").is_file() and not lock_path(out).exists()


@pytest.mark.slow
@pytest.mark.blender
def test_a_stopped_batch_py_removes_its_own_files_and_keeps_a_neighbours(tmp_path):
    import signal

    pytest.importorskip("bpy")
    out = tmp_path / "out"
    out.mkdir()
    proc = subprocess.Popen(_batch_cmd(out), cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    try:
        deadline = time.monotonic() + 300
        while not (out / "lookup").is_dir():  # batch.py is generating into its folder
            assert proc.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        (out / "neighbour_render.exr").write_text("another program's finished render")
        (out / "lookup" / "neighbour.npz").write_text("another program's table")
        proc.send_signal(signal.SIGINT)
        text, _ = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, text
    assert "nothing partial was left" in text, text
    left = sorted(str(p.relative_to(out)) for p in out.rglob("*"))
    assert left == ["lookup", "lookup/neighbour.npz", "neighbour_render.exr"], left


HARD_STOP_SCRIPT = r"""
import sys
from pathlib import Path
sys.path.insert(0, {repo!r})
sys.path.insert(0, {blender!r})
import fake_blender
from specgen_addon.cli.app import run_guarded
from specgen_addon.common.atomic_io import atomic_write

out = Path({out!r})

def work():
    with atomic_write(out) as tmp:
        tmp.write_bytes(b"half of a table")
        print("READY", flush=True)
        fake_blender.stuck_in_a_c_call(30.0)   # a long C call: the watcher's hard stop ends it

sys.exit(run_guarded("infer", work, ([], [out])))
"""


@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals")
def test_a_hard_stop_while_an_output_is_staged_removes_the_staging_file(tmp_path):
    """SIGINT during a long C call inside a write: the watcher ends the process itself, and the
    half-written staging file beside the single output goes too."""
    blender = fake_blender_modules(tmp_path)
    work = tmp_path / "work"
    work.mkdir()
    script = tmp_path / "s.py"
    script.write_text(HARD_STOP_SCRIPT.format(repo=str(REPO), blender=str(blender), out=str(work / "b.npz")))
    code, text = sigint_when_ready([sys.executable, str(script)], delay=0.3)
    assert code == 130, text
    assert sorted(p.name for p in work.iterdir()) == [], text


def test_a_new_output_folder_in_new_parents_is_locked_too_and_they_go_when_it_fails(tmp_path):
    """batch.py --out new/deep/out: the lock needs a folder beside the output to live in."""
    from specgen_addon.cli.app import run_guarded

    out = tmp_path / "new" / "deep" / "out"
    seen = []

    def work():
        seen.append(lock_path(out).is_file())
        raise SpecGenError("refused later")

    assert run_guarded("batch.py", work, ([out], [])) == 2
    assert seen == [True]
    assert sorted(p.name for p in tmp_path.iterdir()) == []
