"""Worker pools under each start method SpecGen may meet: ``fork`` (Linux) and ``spawn`` (Windows,
macOS). ``SPECGEN_START_METHOD`` picks it; every test here runs under both, so a fork-only habit
(a closure sent to a worker, state copied at fork, a worker's own Ctrl-C traceback) fails here."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.processes import ENV_START_METHOD, can_pool, start_method
from specgen_addon.train.data import render_all
from specgen_addon.train.prefetch import step_batches

REPO = Path(__file__).resolve().parents[2]
METHODS = [m for m in ("fork", "spawn") if m in mp.get_all_start_methods()]


def _write_pid(path: str) -> None:
    """A render task: leaves the worker's process id in ``path``."""
    Path(path).write_text(str(os.getpid()))


def _square(step: int) -> int:
    return step * step


@pytest.fixture(params=METHODS)
def method(request, monkeypatch) -> str:
    monkeypatch.setenv(ENV_START_METHOD, request.param)
    return request.param


def test_the_start_method_follows_the_environment_and_refuses_an_unknown_one(method, monkeypatch):
    assert start_method() == method
    monkeypatch.setenv(ENV_START_METHOD, "teleport")
    with pytest.raises(SpecGenError, match="SPECGEN_START_METHOD=teleport is not available"):
        start_method()


def test_render_workers_run_module_level_tasks_in_their_own_processes(method, tmp_path):
    paths = [str(tmp_path / f"{i}.pid") for i in range(4)]
    render_all(_write_pid, paths, workers=2, chunksize=1)
    pids = {int(Path(p).read_text()) for p in paths}
    assert os.getpid() not in pids and 1 <= len(pids) <= 2


def test_a_closure_that_cannot_reach_a_worker_runs_in_process(method, tmp_path):
    seen: list[int] = []
    task = lambda i: seen.append(os.getpid())  # a closure, on purpose
    assert can_pool(task) == (method == "fork")      # given once at the workers' start: fork copies it
    assert not can_pool(task, per_task=True)        # given with each task: always pickled
    render_all(task, [0, 1], workers=2)
    assert seen == [os.getpid()] * 2


def test_data_workers_make_the_same_batches_in_order(method):
    gen = step_batches(_square, 3, 9, workers=2, ahead=3)
    assert list(gen) == [s * s for s in range(3, 9)]


SCRIPT = r"""
import sys, time
sys.path.insert(0, {repo!r})
sys.path.insert(0, {mods!r})
from specgen_addon.common.interrupts import Interrupted, stop_on_signals
from specgen_addon.train.data import render_all
import slow_task

if __name__ == "__main__":
    try:
        with stop_on_signals():
            print("READY", flush=True)
            render_all(slow_task.work, list(range(4)), workers=2, chunksize=1)
        print("NOT STOPPED", flush=True)
    except Interrupted as exc:
        print("RAISED", exc.signal_name, flush=True)
        sys.exit(exc.exit_code)
"""


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="sends Ctrl-C to a process group (POSIX)")
def test_ctrl_c_to_the_group_stops_a_render_pool_with_130_and_no_worker_traceback(method, tmp_path):
    mods = tmp_path / "mods"
    mods.mkdir()
    (mods / "slow_task.py").write_text(
        "import os, time\n"
        "def work(i):\n"
        f"    open(os.path.join({str(tmp_path)!r}, f'started.{{os.getpid()}}'), 'w').close()\n"
        "    time.sleep(60)\n")
    script = tmp_path / "run.py"
    script.write_text(SCRIPT.format(repo=str(REPO), mods=str(mods)))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, env={**os.environ, ENV_START_METHOD: method})
    try:
        deadline = time.monotonic() + 90
        while len(list(tmp_path.glob("started.*"))) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.2)
        assert len(list(tmp_path.glob("started.*"))) == 2, "the workers never started"
        os.killpg(proc.pid, signal.SIGINT)   # what Ctrl-C in a terminal does
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode == 130, out + err
    assert "RAISED SIGINT" in out and "Traceback" not in err, out + err
    for marker in tmp_path.glob("started.*"):   # no worker is left behind
        pid = int(marker.name.split(".")[1])
        with pytest.raises(ProcessLookupError):
            for _ in range(50):
                os.kill(pid, 0)
                time.sleep(0.1)
