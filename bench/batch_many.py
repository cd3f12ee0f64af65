"""Benchmark: ``batch-many`` wall time on a LocalCluster with 1, 2, … workers, and a projection.

Runs the same N photos (copies of examples/sphere.png) through batch.py's pipeline on a fresh
LocalCluster per worker count, each into a fresh output folder; prints wall time (cluster start
included), mean per-item time, speed-up over the first count, and the paper projection for 1000
materials on W workers: ``T(W) ≈ t_start + ceil(1000 / W) · t_item``, one item per worker at a
time, each worker on its own core. t_item is given twice: the mean item wall time with the first
worker count, and the mean CPU seconds of an item's processes (what an item costs on a core of
its own, whatever else the machine is doing).

Run: ``.venv/bin/python bench/batch_many.py [--items 4 --workers 1 2 --batch-args='--resolution 64']``.
"""

from __future__ import annotations

import argparse
import math
import shlex
import shutil
import sys
import tempfile
import time
from pathlib import Path

from machine import describe_machine  # bench/machine.py, beside this script

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--items", type=int, default=4)
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--batch-args", default="--resolution 64 --samples 4 --bands 8")
    ap.add_argument("--project", type=int, nargs="+", default=[1, 2, 8, 32, 128],
                    help="worker counts of the 1000-material projection")
    args = ap.parse_args(argv)

    from specgen_addon.scale.batch_many import BatchManyOptions, run_batch_many

    print(f"machine: {describe_machine()}")
    print(f"batch-many: {args.items} photos, batch.py {args.batch_args}")
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench_batch_many_") as tmp:
        src = Path(tmp) / "in"
        src.mkdir()
        for i in range(args.items):
            shutil.copy(REPO / "examples" / "sphere.png", src / f"photo{i:03d}.png")
        for w in args.workers:
            out = Path(tmp) / f"out{w}"
            t0 = time.perf_counter()
            rep = run_batch_many(BatchManyOptions(inputs=[src], out=out, batch_args=shlex.split(args.batch_args),
                                                  workers=w, dashboard_address=":0", progress=False),
                                 log=lambda s: None)
            wall = time.perf_counter() - t0
            done = [r for r in rep["items"] if r["status"] == "done"]
            if len(done) != args.items:
                print(f"  {w} workers: {rep['counts']} — not all items finished", file=sys.stderr)
                return 1
            rows.append((w, wall, sum(r["seconds"] for r in done) / len(done),
                         sum(r["cpu_seconds"] for r in done) / len(done)))
            print(f"  {w} workers: {wall:6.1f} s wall, {rows[-1][2]:5.1f} s wall and {rows[-1][3]:5.1f} s CPU "
                  f"mean per item (load average {describe_machine().rsplit(' ', 1)[-1]})", flush=True)
    w0, wall0, item0, cpu0 = rows[0]
    for w, wall, _, _ in rows[1:]:
        print(f"speed-up {w0} → {w} workers: {wall0 / wall:.2f}x (ideal {w / w0:.0f}x)")
    start = max(0.0, wall0 - math.ceil(args.items / w0) * item0)
    print(f"projection, 1000 materials (t_start {start:.1f} s; t_item = {item0:.1f} s wall | {cpu0:.1f} s CPU):")
    for w in args.project:
        n = math.ceil(1000 / w)
        print(f"  {w:4d} workers: {(start + n * item0) / 3600:6.2f} h | {(start + n * cpu0) / 3600:6.2f} h")
    return 0


if __name__ == "__main__":
    sys.exit(main())
