"""``batch-many``: ``batch.py``'s pipeline over many inputs on a Dask cluster, with one report.

By default a :class:`distributed.LocalCluster` (one single-threaded worker process per item slot)
runs on this machine; ``scheduler="tcp://HOST:PORT"`` uses an existing cluster instead. Each item
is one Dask task (:func:`.worker.run_item`) that runs ``batch.py`` in a child process, so every
item has its own ``bpy``. Finished items are skipped on a rerun with the same input and settings
(:mod:`.items`); failures other than a bad input are retried ``retries`` times; a failed item is
reported and never stops the others.
"""

from __future__ import annotations

import contextlib
import json
import logging
import math
import operator
import os
import shutil
import signal
import sys
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


def _validate(opts: BatchManyOptions) -> list[items_mod.Item]:
    check_number("workers", opts.workers)
    if opts.retries < 0:
        raise SpecGenError(f"--retries must be 0 or more, got {opts.retries}")
    if opts.timeout is not None and not (math.isfinite(opts.timeout) and opts.timeout > 0):
        raise SpecGenError(f"--timeout must be a positive number of seconds, got {opts.timeout}")
    if opts.scheduler is not None and "://" not in opts.scheduler:
        raise SpecGenError(f"--scheduler {opts.scheduler}: expected an address like tcp://HOST:8786")
    if opts.blender and not Path(opts.blender).is_file() and not shutil.which(opts.blender):
        raise SpecGenError(f"{opts.blender}: Blender executable not found")
    check_batch_args(Path(opts.batch_script), opts.batch_args)
    found = items_mod.make_items(items_mod.collect_inputs(opts.inputs, opts.manifest))
    if opts.out.exists() and not opts.out.is_dir():
        raise SpecGenError(f"{opts.out}: exists and is not a folder")
    parent = next(p for p in [opts.out.absolute(), *opts.out.absolute().parents] if p.exists())
    if not os.access(parent, os.W_OK):
        raise SpecGenError(f"{opts.out}: {parent} is not writable")
    return found


def _connect(opts: BatchManyOptions):
    """(client, cluster or None) — a LocalCluster here, or the cluster at ``opts.scheduler``."""
    from distributed import Client, LocalCluster

    if opts.scheduler:
        try:
            client = Client(opts.scheduler, timeout="15s")
        except (OSError, TimeoutError) as exc:
            raise SpecGenError(f"cannot reach the Dask scheduler at {opts.scheduler} ({exc})") from None
        try:
            client.wait_for_workers(1, timeout=60)
        except TimeoutError:
            client.close()
            raise SpecGenError(f"no Dask worker joined {opts.scheduler} within 60 s") from None
        return client, None
    with _workers_ignore_ctrl_c():
        cluster = LocalCluster(n_workers=opts.workers, threads_per_worker=1, processes=True,
                               dashboard_address=opts.dashboard_address, silence_logs=logging.ERROR)
    return Client(cluster), cluster


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Start worker processes with SIGINT ignored (inherited by their batch.py children): Ctrl-C
    in the terminal reaches the whole process group, but only this process should handle it,
    by shutting the cluster down (workers and their children then end without tracebacks)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


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

    client, cluster = _connect(opts)
    staging = opts.out / ".work"
    results: dict[str, dict] = {}
    futures: dict = {}
    bar = None
    try:
        try:  # made only now: a run refused while connecting leaves nothing behind
            opts.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise SpecGenError(f"{opts.out}: cannot create the output folder ({exc.strerror})") from None
        out = str(opts.out.resolve())
        meta["scheduler"] = client.scheduler.address
        meta["workers"] = len(client.scheduler_info()["workers"])
        meta["dashboard"] = client.dashboard_link
        log(f"Dask: {meta['workers']} workers at {meta['scheduler']}; dashboard {meta['dashboard']}")
        cmd = batch_command(opts)
        run_item = _shipped_run_item(client)
        for it in todo:
            fut = client.submit(operator.call, run_item, it.to_dict(), out, run, cmd, list(opts.batch_args),
                                str(REPO), it.fingerprint(opts.batch_args), opts.timeout, os.getcwd(),
                                key=f"specgen-{it.id}-{run}", retries=opts.retries, pure=False)
            futures[fut] = it
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
                counter = staging / f"{it.id}.{run}.attempts"
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
    except KeyboardInterrupt:
        client.cancel(list(futures), force=True)
        raise
    finally:
        if bar is not None:
            bar.close()
        client.close()
        if cluster is not None:
            cluster.close()
        # this run's unfinished items (Ctrl-C, lost workers), and the lock of a batch.py killed
        # by a timeout
        for p in [*staging.glob(f"*.{run}*"), *staging.glob(f".*.{run}*")]:
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
        if staging.is_dir() and not any(staging.iterdir()):
            staging.rmdir()
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
