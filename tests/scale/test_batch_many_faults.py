"""batch-many under faults: every item done exactly once, one run per output folder, safe item
names, stale staging cleaned, the dashboard on loopback."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from specgen_addon.common.errors import OutputBusyError
from specgen_addon.common.atomic_io import lock_path
from specgen_addon.scale import items as items_mod
from specgen_addon.scale.batch_many import (SCRATCH_OWNER, SCRATCH_PREFIX, BatchManyOptions,
                                            remove_stale_scratch, run_batch_many)
from specgen_addon.scale.worker import PYTHON, RECORD_NAME, run_item
from batch_stand_in import stand_in, touch_inputs

REPO = Path(__file__).resolve().parents[2]

#: Stand-in for batch.py: writes one output and appends the input's name to ``runs.txt`` beside
#: the inputs, so a test can count how often each item was really made; sleeps SLOW seconds.
FAKE_BATCH = '''
    time.sleep(float(os.environ.get("FAKE_BATCH_SLOW", "0")))
    with open(src.parent / "runs.txt", "a") as fh:
        fh.write(src.name + "\\n")
    (pathlib.Path(a.out) / "render.exr").write_text(src.name)
'''


def _script(tmp_path: Path) -> Path:
    return stand_in(tmp_path / "fake_batch.py", FAKE_BATCH)


# ------------------------------------------------------------------------------------ names
def test_item_folders_never_take_batch_many_s_own_names(tmp_path):
    """``failed.png`` was published over OUT/failed/ (the failure logs), ``.work.png`` into the
    staging folder, and ``...png`` named OUT/.. itself."""
    files = touch_inputs(tmp_path / "in", "failed.png", "Failed.exr", ".work.png", "...png", "..png",
                         "report.json.png", "work.png", "item.png", ".hidden.png")
    ids = [it.id for it in items_mod.make_items(files)]
    assert len({i.lower() for i in ids}) == len(ids), ids
    for i in ids:
        assert not i.startswith("."), i
        assert i.lower() not in items_mod.RESERVED_NAMES, i
        assert set(i) != {"."}, i


# ------------------------------------------------------------------------------- exactly once
def test_an_item_published_by_a_lost_attempt_is_not_made_again(tmp_path):
    """A worker that published its item and died before returning: Dask's retry finds the
    published result of this run and returns its record, which is item.json's."""
    script = _script(tmp_path)
    [src] = touch_inputs(tmp_path / "in", "oak.png")
    out = tmp_path / "out"
    out.mkdir()
    [it] = items_mod.make_items([src])

    def attempt():
        return run_item(it.to_dict(), str(out), "r1", [PYTHON, str(script)], [], str(REPO), it.fingerprint([]))

    first = attempt()
    again = attempt()
    assert (tmp_path / "in" / "runs.txt").read_text().splitlines() == ["oak.png"]  # made once
    assert again == first == json.loads((out / "oak" / RECORD_NAME).read_text())
    # another run (--overwrite, new settings) does make it again
    rec = run_item(it.to_dict(), str(out), "r2", [PYTHON, str(script)], [], str(REPO), it.fingerprint([]))
    assert rec["run"] == "r2" and len((tmp_path / "in" / "runs.txt").read_text().splitlines()) == 2


# ------------------------------------------------------------------------------- lock, .work
def _opts(tmp_path: Path, inputs: list[Path], **kw) -> BatchManyOptions:
    return BatchManyOptions(inputs=inputs, out=tmp_path / "out", batch_script=_script(tmp_path),
                            progress=False, workers=2, dashboard_address=":0", **kw)


def test_a_second_batch_many_on_one_output_folder_is_refused_before_any_work(tmp_path):
    inputs = touch_inputs(tmp_path / "in", "a.png")
    (tmp_path / "out").mkdir()
    holder = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        lock_path(tmp_path / "out").write_text(json.dumps({"pid": holder.pid, "host": socket.gethostname()}))
        with pytest.raises(OutputBusyError, match=f"SpecGen process {holder.pid}"):
            run_batch_many(_opts(tmp_path, inputs), log=lambda m: None)
    finally:
        holder.kill()
        holder.wait()
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == []


def test_stale_staging_of_a_killed_run_is_removed_by_the_next_run(tmp_path):
    inputs = touch_inputs(tmp_path / "in", "a.png")
    out = tmp_path / "out"
    [it] = items_mod.make_items(inputs)
    (out / "a").mkdir(parents=True)  # finished already: the rerun starts no cluster
    (out / "a" / RECORD_NAME).write_text(json.dumps({"id": "a", "status": "done", "seconds": 1.0,
                                                      "fingerprint": it.fingerprint([])}))
    stale = out / ".work" / "b.20260101T000000-abcdef"
    stale.mkdir(parents=True)
    (stale / "render.exr").write_text("half")
    (out / ".work" / "b.20260101T000000-abcdef.attempts").write_text("1")
    # the killed run's lock, its process gone
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    lock_path(out).write_text(json.dumps({"pid": int(gone), "host": socket.gethostname()}))
    report = run_batch_many(_opts(tmp_path, inputs), log=lambda m: None)
    assert report["counts"] == {"done": 0, "skipped": 1, "failed": 0}
    assert not (out / ".work").exists() and not lock_path(out).exists()


# ------------------------------------------------------------------------------- dashboard
def test_the_dashboard_listens_on_loopback_unless_an_address_is_given(monkeypatch):
    distributed = pytest.importorskip("distributed")
    from specgen_addon.cli.app import build_parser
    from specgen_addon.scale import batch_many

    seen = {}

    class Stop(Exception):
        pass

    def fake_cluster(**kw):
        seen.update(kw)
        raise Stop

    monkeypatch.setattr(distributed, "LocalCluster", fake_cluster)
    args = build_parser().parse_args(["batch-many", "x.png", "--out", "o"])
    opts = BatchManyOptions(inputs=[], out=Path("o"), dashboard_address=args.dashboard_address)
    run = batch_many._Run(opts, "r1")
    try:
        with pytest.raises(Stop):
            batch_many._connect(opts, run)
    finally:
        run.close(cancel=True)
    assert seen["dashboard_address"].startswith("127.0.0.1:")
    assert BatchManyOptions(inputs=[], out=Path("o")).dashboard_address.startswith("127.0.0.1:")


# ------------------------------------------------------------------------------- kill -9
def test_the_scratch_folder_of_a_killed_run_is_removed_and_a_running_one_s_kept(tmp_path):
    gone = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    owners = {"killed": {"pid": int(gone), "host": socket.gethostname()},
              "running": {"pid": os.getppid(), "host": socket.gethostname()},
              "elsewhere": {"pid": int(gone), "host": socket.gethostname() + "-other"}}
    for name, owner in owners.items():
        (tmp_path / (SCRATCH_PREFIX + name) / "dask").mkdir(parents=True)
        (tmp_path / (SCRATCH_PREFIX + name) / SCRATCH_OWNER).write_text(json.dumps(owner))
    (tmp_path / (SCRATCH_PREFIX + "no-owner")).mkdir()   # not one of batch-many's (or not yet)
    assert remove_stale_scratch(tmp_path) == [tmp_path / (SCRATCH_PREFIX + "killed")]
    assert sorted(p.name.removeprefix(SCRATCH_PREFIX) for p in tmp_path.iterdir()) == \
        ["elsewhere", "no-owner", "running"]



@pytest.mark.slow
def test_after_kill_9_of_the_main_process_a_rerun_does_every_item_exactly_once(tmp_path):
    """Kill -9 of batch-many (and then of what it left running), rerun: every item made exactly
    once, report.json and every item.json agree, no .work left, and the killed run's scratch
    folder is removed by the rerun."""
    psutil = pytest.importorskip("psutil")
    pytest.importorskip("distributed")
    inputs = touch_inputs(tmp_path / "in", "a.png", "b.png", "c.png", "d.png", "e.png", "f.png")
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "specgen_addon", "batch-many", *map(str, inputs), "--out", str(out),
           "--workers", "2", "--dashboard-address", ":0", "--quiet", "--batch-script", str(_script(tmp_path))]
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    env = dict(os.environ, FAKE_BATCH_SLOW="1.5", TMPDIR=str(tmp))
    proc = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 240
        while not any(out.glob(f"*/{RECORD_NAME}")) and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        family = psutil.Process(proc.pid).children(recursive=True)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        _, alive = psutil.wait_procs(family, timeout=30)  # workers notice their parent is gone
        for p in alive:                                   # or are killed with it
            p.kill()
        psutil.wait_procs(alive, timeout=10)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    done_before = {p.parent.name for p in out.glob(f"*/{RECORD_NAME}")}
    assert done_before and len(done_before) < 6, "the kill must land mid-run"
    assert [p.name[:len(SCRATCH_PREFIX)] for p in tmp.iterdir()] == [SCRATCH_PREFIX]   # the killed run's
    again = subprocess.run(cmd, cwd=REPO, env=dict(env, FAKE_BATCH_SLOW="0"), capture_output=True,
                           text=True, timeout=600)
    assert again.returncode == 0, again.stdout[-2000:] + again.stderr[-2000:]
    runs = (tmp_path / "in" / "runs.txt").read_text().splitlines()
    assert sorted(set(runs)) == [p.name for p in inputs]
    for d in done_before:  # published before the kill: never made again (in-flight ones are redone)
        assert runs.count(f"{d}.png") == 1, (runs, done_before)
    report = json.loads((out / "report.json").read_text())
    for rec in report["items"]:
        published = json.loads((out / rec["id"] / RECORD_NAME).read_text())
        assert {k: v for k, v in rec.items() if k != "status"} == \
               {k: v for k, v in published.items() if k != "status"}
    assert not (out / ".work").exists()
    assert sum(r["status"] == "skipped" for r in report["items"]) == len(done_before)
    assert sorted(tmp.iterdir()) == []


def test_a_full_disk_while_publishing_is_the_item_s_one_sentence_error(tmp_path, monkeypatch):
    import errno

    script = _script(tmp_path)
    [src] = touch_inputs(tmp_path / "in", "oak.png")
    out = tmp_path / "out"
    out.mkdir()
    [it] = items_mod.make_items([src])
    real = Path.write_text

    def full(self, text, *a, **k):
        if self.name == RECORD_NAME:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(self))
        return real(self, text, *a, **k)

    monkeypatch.setattr(Path, "write_text", full)
    rec = run_item(it.to_dict(), str(out), "r1", [PYTHON, str(script)], [], str(REPO), it.fingerprint([]))
    assert rec["status"] == "failed"
    assert rec["error"].endswith(f"{RECORD_NAME}: cannot be written (No space left on device); "
                                 "nothing partial was left"), rec["error"]
    assert not (out / "oak").exists() and not any((out / ".work").glob("oak.r1"))
