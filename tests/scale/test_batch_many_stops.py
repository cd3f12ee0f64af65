"""batch-many stopped: Ctrl-C at any moment (the LocalCluster's start included) ends the run with
exit 130, one line and nothing of it left but the items finished before the stop; an item stopped
by --timeout gets its clean stop first and leaves no temporary work; a run leaves nothing in the
temporary folder (Dask's scratch space included).

The cluster runs are small on purpose (1–2 workers, stand-ins for batch.py): the machine is shared.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from specgen_addon.scale import batch_many
from specgen_addon.scale import items as items_mod
from specgen_addon.scale import worker as worker_mod
from specgen_addon.scale.worker import PYTHON, run_item
from batch_stand_in import stand_in, touch_inputs

REPO = Path(__file__).resolve().parents[2]
CANCELLED = "cancelled: batch-many stopped by SIGINT; nothing partial was left"

#: Stand-in for batch.py that works as the real one does in its temporary folder: "bad*" is
#: refused (exit 2), "slow*" renders for a minute, anything else writes its output; each run is
#: recorded in runs.txt beside the inputs. Only a batch.py that ends by itself removes its
#: temporary folder (a killed one cannot).
STAND_IN = '''
    import shutil, tempfile
    scratch = pathlib.Path(tempfile.mkdtemp(prefix="specgen_batch_"))
    (scratch / "render.tmp").write_text("partial")
    with open(src.parent / "runs.txt", "a") as fh:
        fh.write(src.name + "\\n")
    if src.stem.startswith("bad"):
        print("batch.py: error: no sphere found", file=sys.stderr); sys.exit(2)
    if src.stem.startswith("slow"):
        time.sleep(60)
    (pathlib.Path(a.out) / "render.exr").write_text(src.name)
    shutil.rmtree(scratch)
'''


def _cli(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "specgen_addon", "batch-many", *args, "--dashboard-address", ":0", "--quiet"]


def _env(tmp: Path) -> dict:
    tmp.mkdir(exist_ok=True)
    return dict(os.environ, TMPDIR=str(tmp), TEMP=str(tmp), TMP=str(tmp))


def _popen(cmd: list[str], env: dict) -> subprocess.Popen:
    """The command in a process group of its own, so that a test can send SIGINT to the whole
    group, as a terminal's Ctrl-C does."""
    return subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))


def _wait_for(proc: subprocess.Popen, ready, what: str, limit: float = 90.0) -> None:
    deadline = time.monotonic() + limit
    while not ready():
        assert proc.poll() is None, f"batch-many ended before {what}: {proc.communicate()}"
        assert time.monotonic() < deadline, f"{what} never happened"
        time.sleep(0.05)


def _ctrl_c(proc: subprocess.Popen) -> str:
    """SIGINT to the group; the stderr of the stopped command (killed after a minute)."""
    try:
        os.killpg(proc.pid, signal.SIGINT)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return err


def _group_left(pgid: int) -> list:
    """Processes of the group still running 15 s after its leader ended (zombies aside)."""
    psutil = pytest.importorskip("psutil")  # a dependency of distributed

    def alive() -> list:
        found = []
        for p in psutil.process_iter(["status"]):
            with contextlib.suppress(psutil.Error, OSError):
                if os.getpgid(p.pid) == pgid and p.info["status"] != psutil.STATUS_ZOMBIE:
                    found.append(p)
        return found

    deadline = time.monotonic() + 15
    while alive() and time.monotonic() < deadline:
        time.sleep(0.2)
    return alive()


# ------------------------------------------------------------------------------ Ctrl-C
#: batch-many whose LocalCluster says (in a flag file) when its start begins, and takes a second
#: longer than usual once its workers are up: a Ctrl-C sent on the flag lands inside the start.
SLOW_START = '''
import pathlib, sys, time
import distributed
from specgen_addon.cli.app import main

class Starting(distributed.LocalCluster):
    def __init__(self, *args, **kwargs):
        pathlib.Path(sys.argv[1]).write_text("starting")
        super().__init__(*args, **kwargs)
        time.sleep(1.0)

distributed.LocalCluster = Starting
sys.exit(main(sys.argv[2:]))
'''


@pytest.mark.slow
def test_ctrl_c_while_the_cluster_starts_stops_the_run_before_any_item(tmp_path):
    """The workers start with Ctrl-C blocked (it reaches the whole group), but this process only
    holds it until they are up: the run then stops, exit 130, one line, before any item ran."""
    pytest.importorskip("distributed")
    script = stand_in(tmp_path / "fake_batch.py", STAND_IN)
    inputs = touch_inputs(tmp_path / "in", "a.png", "b.png")
    out, flag, tmp = tmp_path / "out", tmp_path / "starting", tmp_path / "tmp"
    args = [*map(str, inputs), "--out", str(out), "--batch-script", str(script), "--workers", "1",
            "--dashboard-address", ":0", "--quiet"]
    proc = _popen([sys.executable, "-c", SLOW_START, str(flag), "batch-many", *args], _env(tmp))
    _wait_for(proc, flag.exists, "the cluster's start")
    err = _ctrl_c(proc)
    assert proc.returncode == 130, err[-3000:]
    assert err.strip().splitlines() == [CANCELLED], err[-3000:]
    assert not (tmp_path / "in" / "runs.txt").exists()   # no item ran
    assert not out.exists()
    assert sorted(tmp.iterdir()) == []   # no Dask scratch space, no temporary folder
    assert not _group_left(proc.pid)


@pytest.mark.slow
def test_ctrl_c_during_a_run_leaves_only_the_items_finished_before_it(tmp_path):
    """A finished item stays (whole, skipped next time); a failure log, the staging, the items'
    temporary folders and the report of the stopped run do not."""
    pytest.importorskip("distributed")
    script = stand_in(tmp_path / "fake_batch.py", STAND_IN)
    inputs = touch_inputs(tmp_path / "in", "bad.png", "quick.png", "slow.png")
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    proc = _popen(_cli([*map(str, inputs), "--out", str(out), "--batch-script", str(script), "--workers", "2",
                        "--retries", "0"]), _env(tmp))
    runs = tmp_path / "in" / "runs.txt"

    def settled() -> bool:   # quick published, bad reported, slow rendering
        return (out / "quick" / "item.json").is_file() and runs.is_file() and \
            sorted(runs.read_text().split()) == ["bad.png", "quick.png", "slow.png"] and \
            ((out / "failed" / "bad.log").is_file() or any((out / ".work").glob("bad.*.log")))

    _wait_for(proc, settled, "the quick, bad and slow items")
    err = _ctrl_c(proc)
    assert proc.returncode == 130, err[-3000:]
    assert err.strip().splitlines() == [CANCELLED], err[-3000:]
    assert sorted(p.name for p in out.iterdir()) == ["quick"]
    assert json.loads((out / "quick" / "item.json").read_text())["status"] == "done"
    assert sorted(tmp.iterdir()) == []
    assert not _group_left(proc.pid)


# ------------------------------------------------------------------------------ --timeout
def _one_item(tmp_path: Path, body: str, name: str = "slow.png"):
    script = stand_in(tmp_path / "fake_batch.py", body)
    [src] = touch_inputs(tmp_path / "in", name)
    out = tmp_path / "out"
    out.mkdir()
    [it] = items_mod.make_items([src])
    return it, out, [PYTHON, str(script)]


@pytest.fixture
def private_tmp(tmp_path, monkeypatch) -> Path:
    """This process's and its children's temporary folder, empty."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    for name in ("TMPDIR", "TEMP", "TMP"):
        monkeypatch.setenv(name, str(tmp))
    monkeypatch.setattr(tempfile, "tempdir", None)
    return tmp


def test_an_item_stopped_by_its_timeout_gets_its_clean_stop_first(tmp_path, private_tmp):
    """SIGTERM, not SIGKILL: batch.py's own clean stop removes what it made."""
    it, out, cmd = _one_item(tmp_path, '''
        import signal
        signal.signal(signal.SIGTERM, lambda *_: (src.with_suffix(".stopped").write_text("clean"), sys.exit(143)))
        time.sleep(60)
    ''')
    with pytest.raises(RuntimeError, match="timed out after 1 s"):
        run_item(it.to_dict(), str(out), "r1", cmd, [], str(REPO), it.fingerprint([]), 1.0)
    assert (tmp_path / "in" / "slow.stopped").read_text() == "clean"


def test_an_item_killed_after_its_timeout_leaves_no_temporary_work(tmp_path, private_tmp, monkeypatch):
    """A batch.py that outlives the grace after SIGTERM is killed, and what it had in its
    temporary folder goes with the folder batch-many gave it."""
    monkeypatch.setattr(worker_mod, "TERM_GRACE_S", 0.5, raising=False)
    it, out, cmd = _one_item(tmp_path, '''
        import signal, tempfile
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        scratch = pathlib.Path(tempfile.mkdtemp(prefix="specgen_batch_"))
        (scratch / "render.tmp").write_text("partial")
        (pathlib.Path(tempfile.gettempdir()) / "blender_a1b2").mkdir()
        time.sleep(60)
    ''')
    t0 = time.monotonic()
    with pytest.raises(RuntimeError, match="timed out after 1 s"):
        run_item(it.to_dict(), str(out), "r1", cmd, [], str(REPO), it.fingerprint([]), 1.0)
    assert time.monotonic() - t0 < 10
    assert sorted(private_tmp.iterdir()) == []
    assert sorted(p.name for p in (out / ".work").iterdir()) == ["slow.r1.attempts", "slow.r1.log"]


def test_an_item_s_temporary_folder_is_its_own_and_goes_when_it_ends(tmp_path, private_tmp):
    it, out, cmd = _one_item(tmp_path, '''
        import tempfile
        (pathlib.Path(a.out) / "render.exr").write_text(tempfile.gettempdir())
        (pathlib.Path(tempfile.gettempdir()) / "left.tmp").write_text("x")
    ''', name="oak.png")
    rec = run_item(it.to_dict(), str(out), "r1", cmd, [], str(REPO), it.fingerprint([]), None, None,
                   str(private_tmp))
    assert rec["status"] == "done", rec
    used = Path((out / "oak" / "render.exr").read_text())
    assert used.parent == private_tmp and used.name.startswith("specgen_item_")
    assert sorted(private_tmp.iterdir()) == []


@pytest.mark.slow
def test_a_run_leaves_nothing_in_the_temporary_folder_not_even_after_a_timeout(tmp_path):
    """Dask's scratch space and every item's temporary folder live in one folder of the run's,
    removed at its end; an item stopped by --timeout is reported with its log."""
    pytest.importorskip("distributed")
    script = stand_in(tmp_path / "fake_batch.py", STAND_IN)
    inputs = touch_inputs(tmp_path / "in", "oak.png", "slow.png")
    out, tmp = tmp_path / "out", tmp_path / "tmp"
    done = subprocess.run(_cli([*map(str, inputs), "--out", str(out), "--batch-script", str(script),
                                "--workers", "1", "--timeout", "2", "--retries", "0"]),
                          cwd=REPO, env=_env(tmp), capture_output=True, text=True, timeout=180)
    assert done.returncode == 1, done.stdout + done.stderr[-3000:]
    assert "failed slow: timed out after 2 s" in done.stdout
    assert done.stderr.strip() == "", done.stderr[-3000:]   # no worker log lines
    assert sorted(p.name for p in out.iterdir()) == ["failed", "oak", "report.json"]
    assert [p.name for p in (out / "failed").iterdir()] == ["slow.log"]
    assert sorted(tmp.iterdir()) == []


# ------------------------------------------------------------------------------ failure logs
def test_failure_logs_reach_out_failed_when_the_run_ends_and_a_stop_puts_the_folder_back(tmp_path):
    """OUT/failed/ is touched only as a run ends: a failed item's log replaces the one an earlier
    run left, a done item's old log goes; a stop then puts every log back as it was."""
    out = tmp_path / "out"
    staging = out / ".work"
    staging.mkdir(parents=True)
    (out / "failed").mkdir()
    (out / "failed" / "oak.log").write_text("oak failed last time")
    (out / "failed" / "felt.log").write_text("felt failed last time")
    worker_mod.staged_log(staging, "oak", "r2").write_text("oak failed again")
    worker_mod.staged_log(staging, "gold", "r2").write_text("gold failed")
    logs = batch_many._FailedLogs(out, staging, "r2")
    logs.publish([{"id": "oak", "status": "failed"}, {"id": "gold", "status": "failed"},
                  {"id": "felt", "status": "done"}])
    assert {p.name: p.read_text() for p in (out / "failed").iterdir()} == \
        {"oak.log": "oak failed again", "gold.log": "gold failed"}
    logs.undo()
    assert {p.name: p.read_text() for p in (out / "failed").iterdir()} == \
        {"oak.log": "oak failed last time", "felt.log": "felt failed last time"}
