"""``batch-many``: ``batch.py``'s pipeline over many inputs on a Dask cluster, with one report.

By default a :class:`distributed.LocalCluster` (one single-threaded worker process per item slot)
runs on this machine; ``scheduler="tcp://HOST:PORT"`` uses an existing cluster instead. Each item
is one Dask task (:func:`.worker.run_item`) that runs ``batch.py`` in a child process, so every
item has its own ``bpy``. Finished items are skipped on a rerun with the same input and settings
(:mod:`.items`); failures other than a bad input are retried ``retries`` times; a failed item is
reported and never stops the others.

A stop (Ctrl-C, SIGTERM) at any moment ends the run with nothing of it left but the items
published before the stop: no staging, no failure logs, no report, no temporary folder, and no
output folder it created that holds nothing. A stop while the LocalCluster starts is held until
the workers are up (:func:`_stops_held`), then acted on before any item is submitted.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import operator
import os
import re
import shutil
import signal
import socket
import sys
import tempfile
import threading
import time
import uuid
from dataclasses import dataclass, field
from importlib import util as importlib_util
from pathlib import Path
from typing import Callable, Iterator

from specgen_addon.brdf.formats.export import size_text
from specgen_addon.common.atomic_io import OutputLock, atomic_write
from specgen_addon.common.errors import SpecGenError
from specgen_addon.common.interrupts import raise_if_stopped
from specgen_addon.common.limits import check_number
from specgen_addon.photo.photo_lighting import attach_signed_values
from specgen_addon.scale import items as items_mod
from specgen_addon.scale import worker as worker_mod

REPO = Path(__file__).resolve().parents[2]
DEFAULT_BATCH_SCRIPT = REPO / "batch.py"
REPORT_NAME = "report.json"
#: batch.py options batch-many sets itself for every item.
OWN_OPTIONS = ("--image", "--brdf", "--out", "--overwrite")
#: batch.py options (flag, namespace name) that name a file of their own to write: refused in
#: ``--batch-args``, since an item writes only into its folder (every item would write the one file,
#: outside OUT, replaced without --overwrite as batch-many passes it, a relative name in the worker's
#: folder).
OUTPUT_PATH_OPTIONS = (("--circle-preview", "circle_preview"),)


@dataclass
class BatchManyOptions:
    """Everything ``batch-many`` is asked to do (the CLI fills it from its arguments)."""

    inputs: list[Path]
    out: Path
    manifest: Path | None = None
    batch_args: list[str] = field(default_factory=list)   #: passed to batch.py for every item
    scheduler: str | None = None       #: tcp://HOST:PORT of an existing cluster; None: LocalCluster
    workers: int = 2                   #: LocalCluster worker processes (ignored with a scheduler)
    retries: int = 1                   #: extra attempts after a failure that is not a bad input
    overwrite: bool = False
    timeout: float | None = None       #: seconds per pipeline step of one item
    #: LocalCluster dashboard (":0" picks a free port); loopback unless another address is given
    dashboard_address: str = "127.0.0.1:8787"
    batch_script: Path = DEFAULT_BATCH_SCRIPT
    blender: str | None = None         #: run batch.py in this Blender instead of the bpy module
    progress: bool = True


def check_batch_args(batch_script: Path, batch_args: list[str]) -> None:
    """Refuse, before any work, arguments ``batch.py``'s own parser would refuse, and the
    options batch-many sets per item."""
    if not batch_script.is_file():
        raise SpecGenError(f"{batch_script}: batch script not found")
    spec = importlib_util.spec_from_file_location("_specgen_batch_script", batch_script)
    module = importlib_util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
        parser = module.build_parser()
    except Exception as exc:  # noqa: BLE001 - any failure to load is the script's fault
        raise SpecGenError(f"{batch_script}: cannot load its argument parser ({exc})") from None

    def refuse(message: str):
        raise SpecGenError(f"batch.py arguments: {message}")

    parser.error = refuse
    if {"-h", "--help"} & set(batch_args):
        refuse("--help is not an item setting")
    sentinel = "\0batch-many"
    ns = parser.parse_args(attach_signed_values(["--image", sentinel, "--out", sentinel, *batch_args]))
    if ns.image != sentinel or ns.out != sentinel or getattr(ns, "overwrite", False):
        raise SpecGenError(f"batch.py arguments: {', '.join(OWN_OPTIONS)} are set by batch-many per item")
    for flag, dest in OUTPUT_PATH_OPTIONS:
        if getattr(ns, dest, None) is not None:
            refuse(f"{flag} names one file outside the item folders, so batch-many refuses it "
                   "(an item writes only into OUT/<name>/, and its batch.log gives the circle used)")
    if Path(batch_script).resolve() == Path(DEFAULT_BATCH_SCRIPT).resolve():   # values, as batch.py checks them
        try:
            module.check_settings(ns)   # sizes, names, files and the photo options, without a photo
        except SpecGenError as exc:
            refuse(str(exc))


def batch_command(opts: BatchManyOptions) -> list[str]:
    """How a worker starts ``batch.py`` (input, ``--out`` and settings are appended)."""
    script = str(Path(opts.batch_script).resolve())
    if opts.blender:
        return [opts.blender, "--background", "--factory-startup", "--python", script, "--"]
    return [worker_mod.PYTHON, script]


def check_dashboard_address(address: str, local: bool = True) -> None:
    """``HOST:PORT``, ``:PORT`` or ``PORT`` with a port from 0 to 65535; with ``local``, a HOST
    must also be an address of this machine (the LocalCluster's dashboard listens there)."""
    host, sep, port = address.rpartition(":")
    if not re.fullmatch(r"-?[0-9]+", port, re.ASCII) or ":" in host or "," in host:
        raise SpecGenError(f"--dashboard-address {address}: expected HOST:PORT or :PORT (:0 picks a free port)")
    if not 0 <= int(port) <= 65535:
        raise SpecGenError(f"--dashboard-address {address}: the port must be between 0 and 65535")
    if not host or not local:
        return
    try:
        infos = socket.getaddrinfo(host, 0, type=socket.SOCK_STREAM)
    except (OSError, UnicodeError):
        raise SpecGenError(f"--dashboard-address {address}: unknown host {host!r}") from None
    for family, kind, proto, _, where in infos:
        try:
            with socket.socket(family, kind, proto) as probe:
                probe.bind(where)
            return
        except OSError:
            continue
    raise SpecGenError(f"--dashboard-address {address}: {host} is not an address of this machine")


def check_blender(exe: str) -> None:
    """A Blender executable: a path to an executable file, or a program name found on PATH."""
    if os.sep in exe or (os.altsep and os.altsep in exe):
        path = Path(exe)
        if path.is_dir():
            raise SpecGenError(f"--blender {exe}: is a folder, expected the Blender executable")
        if not path.is_file():
            raise SpecGenError(f"--blender {exe}: Blender executable not found")
        if not os.access(path, os.X_OK):
            raise SpecGenError(f"--blender {exe}: not an executable file")
    elif shutil.which(exe) is None:
        raise SpecGenError(f"--blender {exe}: no such program on PATH (give the path of the Blender executable)")


def _validate(opts: BatchManyOptions) -> list[items_mod.Item]:
    check_number("workers", opts.workers)
    if opts.retries < 0:
        raise SpecGenError(f"--retries must be 0 or more, got {opts.retries}")
    if opts.timeout is not None and not (math.isfinite(opts.timeout) and opts.timeout > 0):
        raise SpecGenError(f"--timeout must be a positive number of seconds, got {opts.timeout}")
    if opts.scheduler is not None and "://" not in opts.scheduler:
        raise SpecGenError(f"--scheduler {opts.scheduler}: expected an address like tcp://HOST:8786")
    check_dashboard_address(opts.dashboard_address, local=opts.scheduler is None)
    if opts.blender:
        check_blender(opts.blender)
    check_batch_args(Path(opts.batch_script), opts.batch_args)
    found = items_mod.make_items(items_mod.collect_inputs(opts.inputs, opts.manifest))
    if opts.out.exists() and not opts.out.is_dir():
        raise SpecGenError(f"{opts.out}: exists and is not a folder")
    parent = next(p for p in [opts.out.absolute(), *opts.out.absolute().parents] if p.exists())
    if not os.access(parent, os.W_OK):
        raise SpecGenError(f"{opts.out}: {parent} is not writable")
    return found


class _Run:
    """What one run starts and makes besides published items, and how it is taken down: the
    client and cluster, the cluster's scratch folder, this run's staging in ``OUT/.work``, the
    failure logs it moves into ``OUT/failed``, and the output folders it creates."""

    def __init__(self, opts: BatchManyOptions, run: str):
        self.opts, self.run = opts, run
        self.staging = opts.out / ".work"
        out = opts.out.absolute()
        self.new_folders = [p for p in [out, *out.parents] if not p.exists()]   # deepest first
        self.client = None
        self.cluster = None
        self.scratch: Path | None = None   #: a LocalCluster's scratch and the items' temporary folders
        self.futures: list = []
        self.logs = _FailedLogs(opts.out, self.staging, run)

    @property
    def items_tmp(self) -> str | None:
        return str(self.scratch / "items") if self.scratch is not None else None

    def close(self, cancel: bool) -> None:
        """Take the run down; with ``cancel``, leave nothing of it but the items it published.

        Every step runs even when a stop arrives during another; a stop turns what is left of a
        finished run's clean-up into a cancel's, and is raised again at the end."""
        stop: list[BaseException] = []
        workers: list = []
        children: list = []

        def step(fn) -> None:
            try:
                fn()
            except KeyboardInterrupt as exc:
                stop.append(exc)
            except Exception:  # noqa: BLE001 - the clean-up goes on; the run's own error is reported
                pass

        def cancelling() -> bool:
            return cancel or bool(stop)

        def mark() -> None:   # an attempt that starts or ends from now on makes nothing
            if cancelling() and self.opts.out.is_dir():
                self.staging.mkdir(exist_ok=True)
                worker_mod.cancel_marker(self.staging, self.run).touch()

        def snapshot() -> None:
            found = _worker_processes(self.cluster)
            workers.extend(found[0])
            children.extend(found[1])

        def stop_items() -> None:
            if cancelling():
                if self.client is not None:
                    self.client.cancel(self.futures, force=True)
                _terminate(children)

        def wait() -> None:   # nothing of the run may still write when its folders are cleaned
            _wait_or_kill(workers + children, worker_mod.TERM_GRACE_S)

        def undo_logs() -> None:
            if cancelling():
                self.logs.undo()

        def sweep() -> None:
            # this run's unfinished items, kept logs, counters and marker, and the lock of a
            # batch.py killed by a timeout
            for p in [*self.staging.glob(f"*.{self.run}*"), *self.staging.glob(f".*.{self.run}*")]:
                if p.is_dir() and not p.is_symlink():
                    shutil.rmtree(p, ignore_errors=True)
                else:
                    p.unlink(missing_ok=True)
            if self.staging.is_dir() and not any(self.staging.iterdir()):
                self.staging.rmdir()

        def remove_new_folders() -> None:
            if cancelling():
                for folder in self.new_folders:
                    with contextlib.suppress(OSError):
                        folder.rmdir()   # only when empty: published items stay

        step(mark)
        step(snapshot)
        step(stop_items)
        step(lambda: self.client is not None and self.client.close())
        step(lambda: self.cluster is not None and self.cluster.close())
        step(wait)
        step(undo_logs)
        step(sweep)
        step(remove_new_folders)
        step(lambda: self.scratch is not None and shutil.rmtree(self.scratch, ignore_errors=True))
        if stop:
            raise stop[0]


class _FailedLogs:
    """``OUT/failed/`` as a finished run leaves it: the log of each item that failed (kept by its
    worker in ``OUT/.work``) moved in, the log an earlier run left for an item now done removed.
    Each log replaced is set aside in ``OUT/.work`` first, so :meth:`undo` (a stop) puts the
    folder back as it was."""

    def __init__(self, out: Path, staging: Path, run: str):
        self.folder, self.staging, self.run = out / "failed", staging, run
        self.made = not self.folder.exists()
        self.moves: list[tuple[Path, Path, bool]] = []   #: (log, its old version set aside, had one)

    def publish(self, records) -> None:
        for rec in records:
            dest = self.folder / f"{rec['id']}.log"
            kept = worker_mod.staged_log(self.staging, rec["id"], self.run)
            new = rec["status"] == "failed" and kept.is_file()
            if not new and not (rec["status"] == "done" and dest.exists()):
                continue
            aside = self.staging / f"{rec['id']}.{self.run}.old-log"
            self.moves.append((dest, aside, dest.exists()))
            if dest.exists():
                os.replace(dest, aside)
            if new:
                self.folder.mkdir(exist_ok=True)
                os.replace(kept, dest)

    def undo(self) -> None:
        for dest, aside, had_one in reversed(self.moves):
            if aside.exists():
                os.replace(aside, dest)
            elif not had_one:
                dest.unlink(missing_ok=True)
        if self.made:
            with contextlib.suppress(OSError):
                self.folder.rmdir()


def _worker_processes(cluster) -> tuple[list, list]:
    """(workers, what they started: the items' ``batch.py``) of a LocalCluster, as psutil
    processes, found now: once their worker is gone, its children are no longer ours to find."""
    if cluster is None:
        return [], []
    import psutil

    workers, items = [], []
    for worker in getattr(cluster, "workers", {}).values():
        with contextlib.suppress(psutil.Error, TypeError, ValueError):
            proc = psutil.Process(worker.pid)
            workers.append(proc)
            items += proc.children(recursive=True)
    return workers, items


def _terminate(procs: list) -> None:
    """SIGTERM: an item's ``batch.py`` takes its clean stop (its partial files removed)."""
    import psutil

    for p in procs:
        with contextlib.suppress(psutil.Error):
            p.terminate()


def _wait_or_kill(procs: list, grace: float) -> None:
    """Wait up to ``grace`` seconds for ``procs`` to end; kill what is left."""
    if not procs:
        return
    import psutil

    _, alive = psutil.wait_procs(procs, timeout=grace)
    for p in alive:
        with contextlib.suppress(psutil.Error):
            p.kill()
    psutil.wait_procs(alive, timeout=5)


#: A LocalCluster run's scratch folder in the temporary folder, and the file naming its process.
SCRATCH_PREFIX = "specgen_batch_many_"
SCRATCH_OWNER = "owner.json"


def remove_stale_scratch(tmp: Path | None = None) -> list[Path]:
    """Remove the scratch folders of runs killed on this host (kill -9: no clean-up ran); a
    folder whose process still runs, or of another host, stays. Returns those removed."""
    removed = []
    for folder in Path(tmp or tempfile.gettempdir()).glob(SCRATCH_PREFIX + "*"):
        try:
            owner = json.loads((folder / SCRATCH_OWNER).read_text())
            pid, host = int(owner["pid"]), owner["host"]
        except (OSError, ValueError, KeyError, TypeError):
            continue   # not one of ours, or its owner is still writing it
        if host != socket.gethostname() or pid == os.getpid():
            continue
        try:
            os.kill(pid, 0)
            continue   # still running
        except ProcessLookupError:
            pass
        except OSError:   # another user's process
            continue
        shutil.rmtree(folder, ignore_errors=True)
        removed.append(folder)
    return removed


def _connect(opts: BatchManyOptions, run: _Run) -> None:
    """Set ``run.client`` (and ``run.cluster``): a LocalCluster here, or the cluster at ``opts.scheduler``."""
    from distributed import Client, LocalCluster

    if opts.scheduler:
        try:
            client = Client(opts.scheduler, timeout="15s")
        except (OSError, TimeoutError) as exc:
            raise SpecGenError(f"cannot reach the Dask scheduler at {opts.scheduler} ({exc})") from None
        run.client = client
        try:
            client.wait_for_workers(1, timeout=60)
        except TimeoutError:
            raise SpecGenError(f"no Dask worker joined {opts.scheduler} within 60 s") from None
        return
    import dask

    remove_stale_scratch()
    run.scratch = Path(tempfile.mkdtemp(prefix=SCRATCH_PREFIX))
    (run.scratch / SCRATCH_OWNER).write_text(json.dumps({"pid": os.getpid(), "host": socket.gethostname()}))
    (run.scratch / "items").mkdir()
    raise_if_stopped()   # a stop that arrived during the imports: before any worker starts
    # Dask's scratch space (scheduler, nannies, workers) goes into the run's scratch folder
    with _stops_held(), dask.config.set({"temporary-directory": str(run.scratch)}):
        run.cluster = LocalCluster(n_workers=opts.workers, threads_per_worker=1, processes=True,
                                   dashboard_address=opts.dashboard_address,
                                   local_directory=str(run.scratch / "dask"), silence_logs=logging.CRITICAL)
    run.client = Client(run.cluster)


@contextlib.contextmanager
def _stops_held() -> Iterator[None]:
    """Start worker processes that never see Ctrl-C, without losing a Ctrl-C meant for this one.

    Ctrl-C in the terminal reaches the whole process group, but only this process should act on
    it, by shutting the cluster down (workers and their children then end without tracebacks).
    So SIGINT is blocked in this thread while the workers start: the threads and processes
    started meanwhile inherit the mask, and the workers' ``batch.py`` children in turn. Here,
    SIGINT and SIGTERM are only noted while the block runs (a stop halfway through a cluster's
    start would leave it half started), and acted on as it ends: the caller's own handlers get
    them then, before any item is submitted. Where signal masks do not exist, the workers start
    with SIGINT ignored, as is this process meanwhile."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if not hasattr(signal, "pthread_sigmask"):
        previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
        try:
            yield
        finally:
            signal.signal(signal.SIGINT, previous)
        return
    from multiprocessing import resource_tracker

    # the tracker unblocks SIGINT in the thread that starts it: start it before the mask is set
    resource_tracker.ensure_running()
    held: list[int] = []
    previous = {s: signal.signal(s, lambda signum, frame: held.append(signum))
                for s in (signal.SIGINT, signal.SIGTERM)}
    wakeup = signal.set_wakeup_fd(-1)   # a noted signal must not wake the caller's stop watcher
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if signal.SIGINT in signal.sigpending():   # sent to this thread while it was blocked
            signal.sigwait({signal.SIGINT})
            held.append(signal.SIGINT)
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        signal.set_wakeup_fd(wakeup, warn_on_full_buffer=False)
        for s, handler in previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
    for signum in dict.fromkeys(held):   # only when the block itself ended without an error
        signal.raise_signal(signum)


def run_batch_many(opts: BatchManyOptions, log: Callable[[str], None] = print) -> dict:
    """Run every item not finished yet; returns the report (also written to ``OUT/report.json``).

    One batch-many at a time per output folder (its lock file); what a killed earlier run left
    in ``OUT/.work`` is removed first. Items are done exactly once: a published item is skipped
    by every later attempt and run, and the report takes each item's record from ``item.json``.
    """
    all_items = _validate(opts)
    with OutputLock([opts.out]):
        _remove_stale_work(opts.out)
        return _run_locked(opts, all_items, log)


def _remove_stale_work(out: Path) -> None:
    """``OUT/.work`` of a killed run (with the folder's lock held, no other run is using it)."""
    staging = out / ".work"
    if staging.is_dir() and not staging.is_symlink():
        shutil.rmtree(staging, ignore_errors=True)


def _published(opts: BatchManyOptions, it: items_mod.Item, run: str) -> dict | None:
    return worker_mod.published_record(opts.out / it.id, run, it.fingerprint(opts.batch_args))


def _run_locked(opts: BatchManyOptions, all_items: list[items_mod.Item], log: Callable[[str], None]) -> dict:
    todo_plan = items_mod.plan(all_items, opts.out, opts.batch_args, overwrite=opts.overwrite)
    run = time.strftime("%Y%m%dT%H%M%S") + "-" + uuid.uuid4().hex[:6]
    records: dict[str, dict] = {it.id: {**rec, "status": "skipped"} for it, rec in todo_plan.skipped}
    t0 = time.perf_counter()
    meta: dict = {"scheduler": None, "workers": 0, "dashboard": None}
    if todo_plan.todo:
        log(f"{len(all_items)} inputs: {len(todo_plan.skipped)} already done, "
            f"{len(todo_plan.todo)} to run")
        records.update(_run_on_cluster(opts, todo_plan.todo, run, meta, log))
    wall = time.perf_counter() - t0
    ordered = [records[it.id] for it in all_items]
    counts = {s: sum(r["status"] == s for r in ordered) for s in ("done", "skipped", "failed")}
    report = {"run": run, "out": str(opts.out.resolve()), "batch_args": opts.batch_args, **meta,
              "wall_seconds": round(wall, 2), "counts": counts, "items": ordered}
    with atomic_write(opts.out / REPORT_NAME, overwrite=True) as tmp:
        tmp.write_text(json.dumps(report, indent=1))
    log(format_summary(report))
    return report


def _run_on_cluster(opts: BatchManyOptions, todo: list[items_mod.Item], run: str, meta: dict,
                    log: Callable[[str], None]) -> dict[str, dict]:
    from distributed import as_completed

    res = _Run(opts, run)
    results: dict[str, dict] = {}
    bar = None
    finished = False
    try:
        _connect(opts, res)
        try:  # made only now: a run refused while connecting leaves nothing behind
            opts.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SpecGenError(f"{opts.out}: cannot create the output folder ({exc.strerror})") from None
        out = str(opts.out.resolve())
        client = res.client
        meta["scheduler"] = client.scheduler.address
        meta["workers"] = len(client.scheduler_info()["workers"])
        meta["dashboard"] = client.dashboard_link
        log(f"Dask: {meta['workers']} workers at {meta['scheduler']}; dashboard {meta['dashboard']}")
        cmd = batch_command(opts)
        run_item = _shipped_run_item(client)
        futures: dict = {}
        for it in todo:
            fut = client.submit(operator.call, run_item, it.to_dict(), out, run, cmd, list(opts.batch_args),
                                str(REPO), it.fingerprint(opts.batch_args), opts.timeout, os.getcwd(),
                                res.items_tmp, key=f"specgen-{it.id}-{run}", retries=opts.retries, pure=False)
            futures[fut] = it
            res.futures.append(fut)
        if opts.progress:
            from tqdm import tqdm

            bar = tqdm(total=len(todo), desc="batch-many", unit="item", file=sys.stderr, dynamic_ncols=True)
        failed = 0
        for fut in as_completed(futures):
            it = futures[fut]
            published = _published(opts, it, run)
            if published is not None:  # item.json is the truth (a lost worker may have made it)
                rec = published
            elif fut.status == "finished":
                rec = fut.result()
            else:
                counter = res.staging / f"{it.id}.{run}.attempts"
                attempts = int(counter.read_text()) if counter.is_file() else opts.retries + 1
                counter.unlink(missing_ok=True)
                exc = fut.exception()
                rec = {"id": it.id, "input": it.input, "status": "failed", "attempts": attempts,
                       "error": str(exc).removeprefix(f"{it.id}: ") or type(exc).__name__,
                       "log": str(opts.out.resolve() / "failed" / f"{it.id}.log")}
            results[it.id] = rec
            failed += rec["status"] == "failed"
            if bar is not None:
                bar.set_postfix(failed=failed, refresh=False)
                bar.update(1)
        res.logs.publish(results.values())
        finished = True
    finally:
        try:
            if bar is not None:
                bar.close()
        except BaseException:
            finished = False
            raise
        finally:
            res.close(cancel=not finished)
    return results


def _shipped_run_item(client):
    """A future of :func:`.worker.run_item`, scattered to every worker by value (cloudpickle): the
    scheduler and workers import nothing from this package, and tasks call it with
    ``operator.call``. Broadcast, so no worker is preferred for holding it."""
    import cloudpickle

    cloudpickle.register_pickle_by_value(worker_mod)
    try:
        [future] = client.scatter([worker_mod.run_item], broadcast=True, hash=False)
    finally:
        cloudpickle.unregister_pickle_by_value(worker_mod)
    return future


def format_summary(report: dict) -> str:
    """Printed summary: counts, wall time, mean item time, and one line per failed item."""
    c = report["counts"]
    done = [r for r in report["items"] if r["status"] == "done"]
    mean = sum(r["seconds"] for r in done) / len(done) if done else 0.0
    lines = [f"batch-many: {len(report['items'])} items: {c['done']} done, {c['skipped']} skipped, "
             f"{c['failed']} failed in {report['wall_seconds']:.1f} s"
             + (f" (mean {mean:.1f} s per item on {report['workers']} workers)" if done else "")]
    if done:
        n_files = sum(len(r.get("outputs", ())) for r in done)
        lines.append(f"wrote {n_files} files in {len(done)} item folders under {report['out']} "
                     f"({size_text(sum(r.get('bytes', 0) for r in done))})")
    lines += [f"  failed {r['id']}: {r['error']} (log: {r['log']})" for r in report["items"]
              if r["status"] == "failed"]
    lines.append(f"report: {Path(report['out']) / REPORT_NAME}")
    return "\n".join(lines)
