"""batch-many: inputs and resume plan, the per-item worker, and runs on Dask clusters.

The cluster tests are small on purpose (2 workers, tiny renders): the machine is shared.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.scale import items as items_mod
from specgen_addon.scale.batch_many import DEFAULT_BATCH_SCRIPT, check_batch_args
from specgen_addon.scale.worker import PYTHON, run_item
from batch_stand_in import stand_in, stand_in_source, touch_inputs

REPO = Path(__file__).resolve().parents[2]

#: Stand-in for batch.py (same options): "flaky*" crashes on its first attempt, "crash*" always,
#: "bad*" is refused as bad input (exit 2), anything else writes an output.
FAKE_BATCH = stand_in_source('''
    if src.stem.startswith("flaky") and not src.with_suffix(".tried").exists():
        src.with_suffix(".tried").write_text("1"); sys.exit(1)
    if src.stem.startswith("crash"):
        print("Segmentation fault (simulated)"); sys.exit(139)
    if src.stem.startswith("bad"):
        print("batch.py: error: no sphere found", file=sys.stderr); sys.exit(2)
    (pathlib.Path(a.out) / (src.stem + "_render.exr")).write_text(str(a.samples))
''')


def test_folders_and_manifests_give_inputs_with_stable_unique_names(tmp_path):
    touch_inputs(tmp_path / "lib", "oak.png", "oak.exr", "felt.bsdf", "notes.txt")
    touch_inputs(tmp_path / "more", "oak.png", "gold.binary")
    (tmp_path / "list.txt").write_text("# studio list\nmore/gold.binary\n\nmore/oak.png  # again\n")
    (tmp_path / "list.json").write_text(json.dumps({"inputs": ["lib/felt.bsdf"]}))
    files = items_mod.collect_inputs([tmp_path / "lib"], tmp_path / "list.txt")
    got = [(it.id, Path(it.input).relative_to(tmp_path).as_posix(), it.kind) for it in items_mod.make_items(files)]
    assert got == [("felt", "lib/felt.bsdf", "brdf"), ("oak_exr", "lib/oak.exr", "image"),
                   ("oak_png", "lib/oak.png", "image"), ("gold", "more/gold.binary", "brdf"),
                   ("oak_png_2", "more/oak.png", "image")]
    assert [Path(p).name for p in items_mod.collect_inputs([tmp_path / "lib" / "felt.bsdf"],
                                                           tmp_path / "list.json")] == ["felt.bsdf"]
    with pytest.raises(SpecGenError, match="notes.txt: not a known input"):
        items_mod.collect_inputs([tmp_path / "lib" / "notes.txt"])
    with pytest.raises(SpecGenError, match="missing.png: input not found"):
        items_mod.collect_inputs([tmp_path / "missing.png"])


def test_plan_skips_finished_items_and_refuses_to_replace_other_results(tmp_path):
    its = items_mod.make_items(touch_inputs(tmp_path / "in", "a.png", "b.png"))
    out = tmp_path / "out"
    (out / "a").mkdir(parents=True)
    (out / "a" / "item.json").write_text(json.dumps({"fingerprint": its[0].fingerprint(["--samples", "4"])}))
    p = items_mod.plan(its, out, ["--samples", "4"])
    assert [i.id for i in p.todo] == ["b"] and [i.id for i, _ in p.skipped] == ["a"]
    with pytest.raises(SpecGenError, match="holds results of another input or other settings"):
        items_mod.plan(its, out, ["--samples", "8"])
    assert [i.id for i in items_mod.plan(its, out, ["--samples", "8"], overwrite=True).todo] == ["a", "b"]
    (out / "b").mkdir()
    with pytest.raises(SpecGenError, match="not a batch-many result"):
        items_mod.plan(its, out, ["--samples", "4"])


def test_batch_arguments_are_checked_by_batch_py_before_any_work():
    check_batch_args(DEFAULT_BATCH_SCRIPT, ["--mesh", "suzanne", "--samples", "4"])
    with pytest.raises(SpecGenError, match="invalid int value"):
        check_batch_args(DEFAULT_BATCH_SCRIPT, ["--samples", "many"])
    with pytest.raises(SpecGenError, match="set by batch-many per item"):
        check_batch_args(DEFAULT_BATCH_SCRIPT, ["--out", "elsewhere"])


def test_an_item_runs_in_the_folder_batch_many_was_started_in(tmp_path):
    """Relative paths in --batch-args (a mask, a mesh, a map) were checked against the user's folder
    before the run, so each item's batch.py runs there too, not in the repository."""
    script = stand_in(tmp_path / "fake_batch.py",
                      '(pathlib.Path(a.out) / (src.stem + "_render.exr")).write_text(os.getcwd())')
    inputs = touch_inputs(tmp_path / "in", "ball.png")
    out, here = tmp_path / "out", tmp_path / "where the user was"
    out.mkdir()
    here.mkdir()
    item = items_mod.make_items(inputs)[0]
    rec = run_item(item.to_dict(), str(out), "r1", [PYTHON, str(script)], [], str(REPO), item.fingerprint([]),
                   None, str(here))
    assert rec["status"] == "done", rec
    assert (out / "ball" / "ball_render.exr").read_text() == str(here)


def test_worker_publishes_an_item_whole_or_not_at_all(tmp_path):
    script = tmp_path / "fake_batch.py"
    script.write_text(FAKE_BATCH)
    inputs = touch_inputs(tmp_path / "in", "good.png", "bad.png", "crash.png")
    out = tmp_path / "out"
    out.mkdir()
    its = {it.id: it for it in items_mod.make_items(inputs)}

    def run(name):
        return run_item(its[name].to_dict(), str(out), "r1", [PYTHON, str(script)], ["--samples", "3"], str(REPO),
                        its[name].fingerprint(["--samples", "3"]))

    rec = run("good")
    assert rec["status"] == "done" and rec["attempts"] == 1
    assert (out / "good" / "good_render.exr").read_text() == "3"
    assert json.loads((out / "good" / "item.json").read_text())["fingerprint"]["input"] == its["good"].input
    rec = run("bad")  # bad input: reported at once, not worth a retry
    assert rec["status"] == "failed" and rec["error"] == "batch.py: error: no sphere found"
    with pytest.raises(RuntimeError, match="Segmentation fault"):  # crash: raised, so Dask retries it
        run("crash")
    assert not (out / "bad").exists() and not (out / "crash").exists()
    # the logs wait in the staging folder: the client moves them to OUT/failed/ when the run ends
    assert "no sphere found" in (out / ".work" / "bad.r1.log").read_text()
    assert "Segmentation fault" in (out / ".work" / "crash.r1.log").read_text()
    assert sorted(p.name for p in (out / ".work").iterdir()) == ["bad.r1.log", "crash.r1.attempts", "crash.r1.log"]
    assert not (out / "failed").exists()


def _spectral_npz(path: Path) -> Path:
    from specgen_addon.brdf.rusinkiewicz import io_from_half_diff
    from specgen_addon.brdf.table import BRDFTable
    from specgen_standins import RampMaterial

    wl = np.linspace(380.0, 780.0, 4)  # batch.py's default range
    m = RampMaterial()
    BRDFTable.tabulate(lambda th, td, pd: m.eval(*io_from_half_diff(th, td, pd), wl), wl).save(path)
    return path


@pytest.mark.slow
@pytest.mark.blender
def test_batch_many_on_a_local_cluster_reports_a_bad_input_while_the_others_finish(tmp_path):
    pytest.importorskip("bpy")
    pytest.importorskip("distributed")
    colour = pytest.importorskip("colour")
    src = tmp_path / "in"
    src.mkdir()
    shutil.copy(REPO / "examples" / "sphere.png", src / "linen.png")
    shutil.copy(REPO / "examples" / "sphere.exr", src / "velvet.exr")
    _spectral_npz(src / "ramp.npz")
    noise = (np.random.default_rng(0).random((48, 48, 3)) * 255).astype(np.uint8)
    from PIL import Image

    Image.fromarray(noise).save(src / "bad.png")  # no sphere in it
    cmd = [sys.executable, "-m", "specgen_addon", "batch-many", str(src), "--out", str(tmp_path / "out"),
           "--workers", "2", "--dashboard-address", ":0", "--quiet",
           "--batch-args=--resolution 24 --samples 1 --bands 4"]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=600)
    assert done.returncode == 1, done.stderr[-3000:]
    assert "dashboard http://" in done.stdout
    assert "4 items: 3 done, 0 skipped, 1 failed" in done.stdout
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    status = {r["id"]: r for r in report["items"]}
    assert {k: r["status"] for k, r in status.items()} == {"bad": "failed", "linen": "done", "ramp": "done",
                                                            "velvet": "done"}
    assert "no sphere" in status["bad"]["error"] and status["bad"]["attempts"] == 1
    assert report["workers"] == 2 and len({r["worker"] for r in status.values()}) == 2  # both took items
    for name, mesh in (("linen", "linen_sphere_studio"), ("velvet", "velvet_sphere_studio"),
                       ("ramp", "ramp_sphere_studio")):
        wavelengths, values = colour.read_spectral_image_Fichet2021(tmp_path / "out" / name / f"{mesh}.exr")["S0"]
        assert values.shape == (24, 24, 4) and np.all(np.isfinite(values)) and values.max() > 0
        assert (tmp_path / "out" / name / f"{mesh}_preview.png").is_file()
    assert not (tmp_path / "out" / "bad").exists() and not (tmp_path / "out" / ".work").exists()
    # a rerun without the bad photo skips every finished item (no cluster is even started)
    (src / "bad.png").unlink()
    again = subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=600)
    assert again.returncode == 0 and "3 items: 0 done, 3 skipped, 0 failed" in again.stdout, again.stderr[-2000:]
    assert "Dask:" not in again.stdout


def _start(cmd: list[str], cwd: Path) -> subprocess.Popen:
    """A Dask process with its scratch space in ``cwd``, in a process group of its own."""
    return subprocess.Popen(cmd, cwd=cwd, env=dict(os.environ, TMPDIR=str(cwd)), stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


def _stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        os.killpg(proc.pid, signal.SIGTERM)  # the group this test started (CLI + its nannies)
        try:
            proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


@pytest.mark.slow
def test_batch_many_on_a_separate_scheduler_and_workers_retries_then_reports(tmp_path):
    pytest.importorskip("distributed")
    sched_file = tmp_path / "scheduler.json"
    procs = [_start([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                     "--no-dashboard", "--scheduler-file", str(sched_file)], tmp_path)]
    try:
        deadline = time.monotonic() + 60
        while not sched_file.is_file() and time.monotonic() < deadline:
            time.sleep(0.2)
        # workers run outside the repository: they import nothing from it (the task ships by value)
        procs.append(_start([sys.executable, "-m", "dask", "worker", "--scheduler-file", str(sched_file),
                             "--nworkers", "2", "--nthreads", "1", "--no-dashboard",
                             "--local-directory", str(tmp_path / "dask")], tmp_path))
        address = json.loads(sched_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        from distributed import Client

        with Client(address, timeout="30s") as probe:
            probe.wait_for_workers(2, timeout=60)
        script = tmp_path / "fake_batch.py"
        script.write_text(FAKE_BATCH)
        inputs = touch_inputs(tmp_path / "in", "good.png", "flaky.png", "crash.png", "bad.png")
        done = subprocess.run([sys.executable, "-m", "specgen_addon", "batch-many", *map(str, inputs),
                               "--out", str(tmp_path / "out"), "--scheduler", address, "--retries", "1",
                               "--batch-script", str(script), "--quiet"],
                              capture_output=True, text=True, cwd=REPO, timeout=300)
    finally:
        for p in reversed(procs):
            _stop(p)
    assert done.returncode == 1, done.stdout + done.stderr[-3000:]
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    got = {r["id"]: (r["status"], r["attempts"]) for r in report["items"]}
    assert got == {"good": ("done", 1), "flaky": ("done", 2), "crash": ("failed", 2), "bad": ("failed", 1)}
    assert report["scheduler"] == address and report["workers"] == 2
    assert "Segmentation fault (simulated)" in {r["id"]: r for r in report["items"]}["crash"]["error"]
    assert (tmp_path / "out" / "flaky" / "flaky_render.exr").is_file()
    assert not (tmp_path / "out" / "failed" / "flaky.log").exists()


@pytest.mark.slow
def test_ctrl_c_stops_batch_many_cleanly_with_exit_130(tmp_path):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it): one line, exit 130,
    no item folder, no staging, not even the output folder the run created, and no process of
    the group survives."""
    pytest.importorskip("distributed")
    script = tmp_path / "slow_batch.py"
    script.write_text(FAKE_BATCH.replace("    (pathlib.Path(a.out)", "    import time; time.sleep(60)\n    (pathlib.Path(a.out)"))
    inputs = touch_inputs(tmp_path / "in", "a.png", "b.png", "c.png")
    out = tmp_path / "out"
    proc = subprocess.Popen([sys.executable, "-m", "specgen_addon", "batch-many", *map(str, inputs), "--out", str(out),
                             "--batch-script", str(script), "--dashboard-address", ":0", "--quiet"],
                            cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        deadline = time.monotonic() + 90
        while not (out / ".work").is_dir() or not any((out / ".work").glob("*.attempts")):
            assert time.monotonic() < deadline and proc.poll() is None, "items never started"
            time.sleep(0.2)
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        _stop(proc)
    assert proc.returncode == 130
    assert err.strip().splitlines() == ["cancelled: batch-many stopped by SIGINT; nothing partial was left"], err[-2000:]
    assert not out.exists()
    psutil = pytest.importorskip("psutil")  # a dependency of distributed

    def alive() -> list:  # processes of the group, zombies waiting for init to reap them aside
        found = []
        for p in psutil.process_iter(["status"]):
            with contextlib.suppress(psutil.Error, OSError):
                if os.getpgid(p.pid) == proc.pid and p.info["status"] != psutil.STATUS_ZOMBIE:
                    found.append(p)
        return found

    deadline = time.monotonic() + 15
    while alive() and time.monotonic() < deadline:
        time.sleep(0.5)
    assert not alive()  # workers and their batch.py children are gone


@pytest.mark.slow
def test_prepare_renders_rgb_brdfs_to_their_photo_and_passes_spectral_tables(tmp_path, rgl_files, capsys):
    from specgen_addon.photo.sphere_image import load_sphere_image
    from specgen_addon.scale import prepare

    kind, path = prepare.prepare(rgl_files["felt"], tmp_path / "w")  # real RGL RGB measurement
    assert kind == "image" and path == tmp_path / "w" / "acrylic_felt_green_rgb.exr"
    sphere = load_sphere_image(path)  # what batch.py --image will accept
    assert sphere.shape[-1] == 3 and sphere[..., 1].mean() > sphere[..., 2].mean()  # green felt
    table = _spectral_npz(tmp_path / "ramp.npz")
    assert prepare.prepare(table, tmp_path / "w") == ("brdf", table)
    (tmp_path / "junk.binary").write_bytes(os.urandom(1000))
    assert prepare.main([str(tmp_path / "junk.binary"), str(tmp_path / "w")]) == prepare.EXIT_BAD_INPUT
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("prepare: error:")


FAKE_BLENDER = '''#!/bin/sh
# Stand-in for a Blender executable: checks Blender's own command line
# (--background --factory-startup --python SCRIPT -- ARGS), records it, then runs SCRIPT the way
# Blender's Python would see it: sys.argv holds the whole command line, "--" included.
[ "$1" = --background ] && [ "$2" = --factory-startup ] && [ "$3" = --python ] && [ "$5" = -- ] || exit 9
echo "$@" > "$(dirname "$0")/argv.txt"
script="$4"
shift 4
exec {python} "$script" "$@"
'''


@pytest.mark.slow
@pytest.mark.blender
def test_an_item_runs_through_a_blender_executable_with_its_command_line(tmp_path):
    """``batch-many --blender EXE``: the worker starts EXE with Blender's command line and
    batch.py reads its arguments after "--", as inside a real Blender."""
    pytest.importorskip("bpy")
    from specgen_addon.scale.batch_many import BatchManyOptions, batch_command

    exe = tmp_path / "blender"
    exe.write_text(FAKE_BLENDER.format(python=sys.executable))
    exe.chmod(0o755)
    (tmp_path / "in").mkdir()
    src = _spectral_npz(tmp_path / "in" / "ramp.npz")
    out = tmp_path / "out"
    out.mkdir()
    item = items_mod.make_items([src])[0]
    args = ["--resolution", "16", "--samples", "1", "--bands", "4"]
    cmd = batch_command(BatchManyOptions(inputs=[src], out=out, blender=str(exe)))
    rec = run_item(item.to_dict(), str(out), "r1", cmd, args, str(REPO), item.fingerprint(args))
    assert rec["status"] == "done", rec
    argv = (tmp_path / "argv.txt").read_text().split()
    assert argv[:5] == ["--background", "--factory-startup", "--python", str(DEFAULT_BATCH_SCRIPT.resolve()), "--"]
    assert "--brdf" in argv and "--resolution" in argv
    assert (out / "ramp" / "ramp_sphere_studio.exr").is_file()
