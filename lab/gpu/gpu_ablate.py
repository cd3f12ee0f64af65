"""Train ablation arms on a lent GPU under the keys `ablate` looks up, so `ablate` scores them here.

An arm's key leaves out where and how fast it trains (``ablation.RUN_ONLY_FIELDS``), so an arm
trained here with ``--device cuda`` and copied into this checkout's ``.cache/specgen/ablation/KEY/``
is found by ``python -m specgen_addon ablate --steps N --arms … --seeds …``, which then only scores
it. A GPU repeats a CPU run to float rounding, not bit for bit (docs/scale.md).

    python bench/gpu_ablate.py --steps 6000 --seeds 6 8 --arms joint-aff joint-hadamard \\
        --device cuda --data-workers 2 --render-workers 16 --max-minutes 6

1. renders the training inputs every arm shares, once, with ``--render-workers`` processes;
2. trains every (arm, seed) at once, one process each, each stopping at ``--max-minutes`` (a
   stopped arm resumes from its checkpoint on the next call, and has no ``arm.json`` until done);
3. prints one line per arm: its key, the steps done, and whether it is complete.

``--pack TAR`` then writes the complete arms' files into one tar for the trip back (split it: the
lease brings back files of at most 16 MB), and ``--unpack TAR`` extracts it into the cache here. ``--smoke`` rehearses the whole path on the tiny CI configuration.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from multiprocessing import get_context
from pathlib import Path


from specgen_addon.evaluation import ablation as abl  # noqa: E402
from specgen_addon.evaluation.ablation_study import study_settings  # noqa: E402
from specgen_addon.common.cache import cache_root  # noqa: E402

#: Files of an arm's folder that `ablate` and the figures need (not the resumable checkpoint).
ARM_FILES = ("specgen.pt", "arm.json", "history.csv")


def arms_cache(args: argparse.Namespace) -> Path:
    """Where the arms live: ``--cache``, or the folder ``ablate`` reads."""
    return Path(args.cache) if args.cache else cache_root() / "ablation"


def settings_for(args: argparse.Namespace) -> abl.AblationSettings:
    settings = study_settings(args.steps, args.seeds, args.arms)
    if args.smoke:
        settings = dataclasses.replace(settings, train={**settings.train, **abl.SMOKE_TRAIN})
    return settings


def _train_one(settings: abl.AblationSettings, arm: str, seed: int, cache: str, overrides: dict) -> None:
    import torch

    torch.set_num_threads(1)
    one = dataclasses.replace(settings, seeds=(seed,), arms=(arm,))
    abl.train_arms(one, Path(cache), progress=False, log=lambda s: print(s, flush=True), run_overrides=overrides)


def train_all(args: argparse.Namespace) -> int:
    settings = settings_for(args)
    cache = arms_cache(args)
    t0 = time.perf_counter()
    # 1. the inputs, once, before the arms start (each would otherwise render them itself)
    arm0 = "joint-aff" if any(abl.ARMS_BY_NAME[a].joint for a in settings.arms) else settings.arms[0]
    mcfg, tcfg = settings.configs(abl.ARMS_BY_NAME[arm0], settings.seeds[0])
    abl._material_sets(dataclasses.replace(tcfg, render_workers=args.render_workers), mcfg,
                       abl._data_cache(), lambda s: print(s, flush=True))
    print(f"gpu_ablate: inputs ready after {time.perf_counter() - t0:.0f} s", flush=True)
    minutes = args.max_minutes
    if args.train_until is not None:  # what is left of the call, less the arms' start and saving
        minutes = (args.train_until - (time.perf_counter() - t0)) / 60.0
        if minutes <= 0.2:
            print("gpu_ablate: no time left to train after the inputs", flush=True)
            return 3
        print(f"gpu_ablate: each arm trains for at most {minutes:.2f} min", flush=True)
    overrides = {"device": args.device, "data_workers": args.data_workers,
                 "render_workers": args.render_workers, "max_minutes": minutes}
    # 2. every arm at once, one process each (not a Pool: its daemonic workers may not start the
    #    arms' own data workers)
    ctx = get_context("spawn")
    procs = [(a, s, ctx.Process(target=_train_one, args=(settings, a, s, str(cache), overrides)))
             for s in settings.seeds for a in settings.arms]
    for *_, proc in procs:
        proc.start()
    try:
        for *_, proc in procs:
            proc.join()
    except KeyboardInterrupt:
        for *_, proc in procs:
            proc.terminate()
        raise
    # 3. where each arm stands
    missing = 0
    for arm, seed, proc in procs:
        key = settings.key(abl.ARMS_BY_NAME[arm], seed)
        complete = (cache / key / "arm.json").is_file()
        missing += not complete
        print(f"gpu_ablate: {arm} seed {seed} key {key}: {'complete' if complete else 'not complete'} "
              f"(exit {proc.exitcode}); {time.perf_counter() - t0:.0f} s in all", flush=True)
    return 0 if missing == 0 else 3


def pack(args: argparse.Namespace) -> int:
    """Write the complete arms' files into one tar (``KEY/NAME``, sorted, fixed times, so the same
    arms give the same bytes); split it for the trip back with ``split -b 15M``."""
    import tarfile

    settings = settings_for(args)
    cache = arms_cache(args)
    with tarfile.open(args.pack, "w", format=tarfile.PAX_FORMAT) as tar:
        for seed in settings.seeds:
            for arm in settings.arms:
                key = settings.key(abl.ARMS_BY_NAME[arm], seed)
                if not (cache / key / "arm.json").is_file():
                    print(f"gpu_ablate: {key} is not complete; not packed", flush=True)
                    continue
                for name in ARM_FILES:
                    info = tar.gettarinfo(str(cache / key / name), arcname=f"{key}/{name}")
                    info.mtime, info.uid, info.gid, info.uname, info.gname = 0, 0, 0, "", ""
                    with open(cache / key / name, "rb") as fh:
                        tar.addfile(info, fh)
                print(f"gpu_ablate: packed {key}", flush=True)
    return 0


def unpack(args: argparse.Namespace) -> int:
    """Extract a tar written by :func:`pack` into the cache. A tar cut short (chunks left behind) gives
    the arms it holds whole; an arm is written only with all of :data:`ARM_FILES`, ``arm.json``
    last, so an arm copied in part is never taken as complete. Refuses any member outside
    ``KEY/NAME``."""
    import tarfile

    cache = arms_cache(args)
    files: dict[str, dict[str, bytes]] = {}
    with tarfile.open(args.unpack, "r|") as tar:
        try:
            for m in tar:
                key, _, name = m.name.partition("/")
                if not m.isfile() or name not in ARM_FILES or not key.replace("-", "").isalnum():
                    raise SystemExit(f"gpu_ablate: {args.unpack} holds {m.name!r}, which is not an arm's file")
                files.setdefault(key, {})[name] = tar.extractfile(m).read()
        except tarfile.ReadError:
            print(f"gpu_ablate: {args.unpack} is cut short after {sum(map(len, files.values()))} whole files")
    for key, got in sorted(files.items()):
        if set(got) != set(ARM_FILES):
            print(f"gpu_ablate: {key} lacks {', '.join(sorted(set(ARM_FILES) - set(got)))}; skipped")
            continue
        (cache / key).mkdir(parents=True, exist_ok=True)
        for name in sorted(ARM_FILES, key=lambda n: n == "arm.json"):
            (cache / key / name).write_bytes(got[name])
        print(f"gpu_ablate: unpacked {key}")
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--steps", type=int, default=6000, help="steps of every arm (as ablate --steps)")
    p.add_argument("--seeds", type=int, nargs="+", default=[0])
    p.add_argument("--arms", nargs="+", default=["joint-aff", "joint-hadamard"], choices=sorted(abl.ARMS_BY_NAME))
    p.add_argument("--device", default="cuda", choices=("cpu", "cuda"))
    p.add_argument("--data-workers", type=int, default=2, help="batch-making processes per arm")
    p.add_argument("--render-workers", type=int, default=16, help="processes rendering the inputs")
    p.add_argument("--max-minutes", type=float, default=None, help="stop every arm after this long (resumable)")
    p.add_argument("--train-until", type=float, default=None, metavar="S",
                   help="stop every arm this many seconds after this command started (resumable)")
    p.add_argument("--cache", default=None, help="arms' cache (default: .cache/specgen/ablation, as ablate)")
    p.add_argument("--smoke", action="store_true", help="the tiny CI configuration (a rehearsal)")
    p.add_argument("--pack", default=None, metavar="TAR", help="only write the complete arms' files into TAR")
    p.add_argument("--unpack", default=None, metavar="TAR", help="only extract a --pack TAR into the cache")
    args = p.parse_args(argv)
    if args.steps < 1 or any(v is not None and v <= 0 for v in (args.max_minutes, args.train_until)):
        p.error("--steps, --max-minutes and --train-until must be positive")
    if args.unpack:
        return unpack(args)
    if args.pack:
        return pack(args)
    return train_all(args)


if __name__ == "__main__":
    sys.exit(main())
