"""Tiny training runs for tests/train/test_train_distributed.py: ``python ddp_tiny_run.py OUT`` or under
``torchrun``. Each rank writes into OUT/rank<r>/: ``full`` (4 steps) and ``resumed`` (2 steps, then
resumed to 4). Only rank 0 should leave files there."""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE.parent), str(HERE)]

from specgen_addon.model import Config  # noqa: E402
from specgen_addon.train import distributed as ddp  # noqa: E402
from specgen_addon.train.loop import TrainConfig, train  # noqa: E402
from tiny_training import FAST_TRAIN as FAST, TRAIN_MODEL as SMALL, material_sets as sets  # noqa: E402

TINY = TrainConfig(**{**FAST, "steps": 4, "spectral_materials_per_step": 4, "rgb_materials_per_step": 2})


def main(base: Path) -> None:
    ctx = ddp.init_from_env()
    out = base / f"rank{ctx.rank}"
    spec, rgb, val = sets(4)
    mcfg = Config(**SMALL)
    train(mcfg, TINY, spec, rgb, val, out / "full", show_progress=False)
    train(mcfg, TrainConfig(**{**TINY.__dict__, "steps": 2}), spec, rgb, val, out / "resumed",
          show_progress=False)
    train(mcfg, TINY, spec, rgb, val, out / "resumed", resume=True, show_progress=False)
    ddp.shutdown()


if __name__ == "__main__":
    main(Path(sys.argv[1]))
