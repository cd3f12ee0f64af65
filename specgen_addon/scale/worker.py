"""What a Dask worker runs for one ``batch-many`` item (standard library only).

The pipeline is ``batch.py``'s (generate → refine where asked → bake → render the scene →
spectral EXR + preview), run as a child process, so every item gets a fresh ``bpy`` in its own
process and a crash cannot take the worker down. BRDF files go through :mod:`.prepare` first.

Atomicity: the item is made in ``OUT/.work/<id>.<run>/`` and renamed to ``OUT/<id>/`` (one
``rename`` on the same file system) only after everything, ``item.json`` last, was written. A
failed item leaves no ``OUT/<id>/``, only its log, kept as ``OUT/.work/<id>.<run>.log`` until the
client moves it to ``OUT/failed/<id>.log`` at the end of the run (a cancelled run moves none).
While the client cancels a run it leaves :func:`cancel_marker` in ``OUT/.work``: an attempt that
sees it starts nothing and publishes nothing.

Temporary files: every child runs with ``TMPDIR``/``TEMP``/``TMP`` set to a folder of its own,
removed when the step ends, so a child stopped by ``timeout`` (SIGTERM, then SIGKILL after
:data:`TERM_GRACE_S`) or killed with its worker leaves none of its temporary work behind.

Failures: a bad input (exit status 2, the pipeline's clean one-line refusal) would fail the same
way again, so it is returned as a failed record at once. Anything else (a crash, a signal, a
timeout) raises, and Dask retries the item (``retries=``) before the client reports it.

This module imports nothing from the package: the client ships it to workers by value
(cloudpickle), so a ``dask worker`` needs only the Python environment and the repository
(the same path on every host, usually a shared file system, like the output folder).
"""

from __future__ import annotations

import ctypes
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

EXIT_BAD_INPUT = 2
RECORD_NAME = "item.json"
PYTHON = "{python}"  #: placeholder in a command for the worker's own interpreter
#: Seconds a child stopped by ``timeout`` has for its own clean stop (SIGTERM) before SIGKILL.
TERM_GRACE_S = 10.0


def cancel_marker(staging: Path, run: str) -> Path:
    """The file whose presence in ``OUT/.work`` tells the attempts of run ``run`` it is cancelled."""
    return staging / f".cancel.{run}"


def staged_log(staging: Path, item_id: str, run: str) -> Path:
    """Where a failed attempt keeps its log until the client moves it to ``OUT/failed/``."""
    return staging / f"{item_id}.{run}.log"


def _die_with_parent() -> None:  # pragma: no cover - runs in the child between fork and exec
    """Linux: the child gets SIGTERM when the worker that started it dies (cluster shut down)."""
    try:
        ctypes.CDLL(None).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _child_cpu_seconds() -> float:
    try:
        import resource

        ru = resource.getrusage(resource.RUSAGE_CHILDREN)
        return ru.ru_utime + ru.ru_stime
    except (ImportError, OSError):  # not POSIX
        return float("nan")


def _run(cmd: list[str], log: Path, cwd: str, env: dict, timeout: float | None,
         cpu: list[float]) -> tuple[int, str]:
    """Run ``cmd`` with stdout and stderr appended to ``log``; (exit status, last output line).
    Adds the child's CPU seconds to ``cpu[0]`` (one task per worker thread: the delta is its own)."""
    c0 = _child_cpu_seconds()
    try:
        return _run_logged(cmd, log, cwd, env, timeout)
    finally:
        cpu[0] += _child_cpu_seconds() - c0


def _run_logged(cmd: list[str], log: Path, cwd: str, env: dict, timeout: float | None) -> tuple[int, str]:
    with open(log, "a") as fh:
        fh.write("$ " + " ".join(cmd) + "\n")
        fh.flush()
        proc = subprocess.Popen(cmd, stdout=fh, stderr=subprocess.STDOUT, cwd=cwd, env=env,
                                preexec_fn=_die_with_parent if os.name == "posix" else None)
        try:
            code = proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            _stop_child(proc)
            fh.write(f"timed out after {timeout:g} s\n")
            return -1, f"timed out after {timeout:g} s"
        except BaseException:
            _stop_child(proc)
            raise
    lines = [ln.strip() for ln in log.read_text(errors="replace").splitlines() if ln.strip()]
    return code, lines[-1] if lines else ""


def _stop_child(proc: subprocess.Popen) -> None:
    """Stop a child the way a user would: SIGTERM (batch.py's clean stop removes what it made),
    then SIGKILL if it is still running after :data:`TERM_GRACE_S`."""
    try:
        proc.terminate()
        proc.wait(TERM_GRACE_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    except OSError:  # already gone
        proc.wait()


def run_item(item: dict, out: str, run: str, batch_cmd: list[str], batch_args: list[str], repo: str,
             fingerprint: dict, timeout: float | None = None, cwd: str | None = None,
             tmp_root: str | None = None) -> dict:
    """Make one item's results in ``out/<id>/``; returns its record (status "done" or "failed").

    ``batch_cmd`` starts ``batch.py`` (``{python}`` stands for this worker's interpreter); the
    input option, ``--out`` and ``--overwrite`` are added, then ``batch_args``. It runs in
    ``cwd`` (the folder batch-many was started in, so that relative paths in ``batch_args`` mean
    what they meant there; default: ``repo``). Its temporary files go to a folder of its own in
    ``tmp_root`` (default: this worker's temporary folder), removed when the item ends. Raises
    RuntimeError on a failure worth retrying, and when the run is being cancelled.
    """
    t0 = time.perf_counter()
    out_dir = Path(out)
    item_id = item["id"]
    done = published_record(out_dir / item_id, run, fingerprint)
    if done is not None:  # an earlier attempt of this run published it, then its worker was lost
        return done
    staging = out_dir / ".work"
    work = staging / f"{item_id}.{run}"
    failed_log = out_dir / "failed" / f"{item_id}.log"   # where the client moves the kept log
    kept_log = staged_log(staging, item_id, run)
    counter = staging / f"{item_id}.{run}.attempts"
    staging.mkdir(parents=True, exist_ok=True)
    if cancel_marker(staging, run).exists():
        raise RuntimeError(f"{item_id}: cancelled")
    attempt = int(counter.read_text()) + 1 if counter.is_file() else 1
    counter.write_text(str(attempt))
    shutil.rmtree(work, ignore_errors=True)   # what a killed earlier attempt left
    work.mkdir()
    log = work / "batch.log"
    scratch = tempfile.mkdtemp(prefix="specgen_item_", dir=tmp_root)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [repo, os.environ.get("PYTHONPATH")])),
               TMPDIR=scratch, TEMP=scratch, TMP=scratch)
    record = {"id": item_id, "input": item["input"], "worker": f"{socket.gethostname()}:{os.getpid()}",
              "attempts": attempt, "stages_s": {}}

    cpu = [0.0]

    def fail(message: str, retry: bool) -> dict:
        try:
            shutil.copyfile(log, kept_log)
        except OSError as exc:  # a full disk: the record still says what failed
            message += f" (its log could not be kept: {exc.strerror})"
            kept_log.unlink(missing_ok=True)
        shutil.rmtree(work, ignore_errors=True)
        if retry:
            raise RuntimeError(f"{item_id}: {message}")
        counter.unlink(missing_ok=True)
        return {**record, "status": "failed", "error": message, "log": str(failed_log),
                "seconds": round(time.perf_counter() - t0, 2)}

    try:
        option, source = ("--image", item["input"]) if item["kind"] == "image" else ("--brdf", item["input"])
        if item["kind"] != "image":
            t = time.perf_counter()
            code, last = _run([sys.executable, "-m", "specgen_addon.scale.prepare", item["input"],
                               str(work / "input")], log, repo, env, timeout, cpu)
            record["stages_s"]["prepare"] = round(time.perf_counter() - t, 2)
            if code != 0:
                return fail(last or f"prepare exited with status {code}", retry=code != EXIT_BAD_INPUT)
            kind, source = last.split(" ", 1)
            option = "--image" if kind == "image" else "--brdf"
        cmd = [sys.executable if c == PYTHON else c for c in batch_cmd]
        t = time.perf_counter()
        code, last = _run(cmd + [option, source, "--out", str(work), "--overwrite", *batch_args],
                          log, cwd or repo, env, timeout, cpu)
        record["stages_s"]["batch"] = round(time.perf_counter() - t, 2)
        if code != 0:
            return fail(last or f"batch.py exited with status {code}", retry=code != EXIT_BAD_INPUT)
        shutil.rmtree(work / "input", ignore_errors=True)  # prepared inputs are intermediate
        files = sorted(p for p in work.rglob("*") if p.is_file())
        outputs = [str(p.relative_to(work)) for p in files]
        record.update(status="done", error=None, outputs=outputs, bytes=sum(p.stat().st_size for p in files),
                      seconds=round(time.perf_counter() - t0, 2),
                      cpu_seconds=round(cpu[0], 2), fingerprint=fingerprint, run=run)
        if cancel_marker(staging, run).exists():   # the run is being cancelled: publish nothing
            raise RuntimeError(f"{item_id}: cancelled")
        try:
            (work / RECORD_NAME).write_text(json.dumps(record, indent=1))
            _publish(work, out_dir / item_id, staging / f"{item_id}.old.{run}")
        except OSError as exc:  # disk full, quota: one sentence naming what could not be written
            return fail(f"{exc.filename or work / RECORD_NAME}: cannot be written ({exc.strerror}); "
                        "nothing partial was left", retry=False)
    except BaseException:
        shutil.rmtree(work, ignore_errors=True)
        raise
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    kept_log.unlink(missing_ok=True)   # an earlier attempt's
    counter.unlink(missing_ok=True)
    return record


def published_record(folder: Path, run: str, fingerprint: dict) -> dict | None:
    """The record of ``folder`` if run ``run`` already published it with this fingerprint (a
    worker lost after publishing: its item is done, and must not be made again), else None."""
    try:
        record = json.loads((folder / RECORD_NAME).read_text())
    except (OSError, ValueError):
        return None
    if isinstance(record, dict) and record.get("run") == run and record.get("fingerprint") == fingerprint \
            and record.get("status") == "done":
        return record
    return None


def _publish(work: Path, final: Path, aside: Path) -> None:
    """Rename the finished folder into place; an old result (``--overwrite``) is moved aside
    first and deleted after, so ``final`` is at every moment either the old or the new result
    (or, for the instant between two renames, absent)."""
    if final.exists():
        os.rename(final, aside)
    os.rename(work, final)
    shutil.rmtree(aside, ignore_errors=True)
