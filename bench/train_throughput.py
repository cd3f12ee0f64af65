"""Training throughput: seconds per step for making the data (CPU) and for the network (CPU or GPU).

A training step is two jobs: drawing the step's batch (numpy: lighting mix, BRDF targets of every
material at its angles and bands) and the network's forward, backward and Adam update. This times
each on its own, over ``--steps`` steps after ``--warmup``, for a training config with a small
corpus (its input renders are cached as training caches them), so it says which of the two bounds a
run on a given machine, and how the batch scales on a GPU.

Usage: ``.venv/bin/python bench/train_throughput.py [--config configs/shipped.json]
[--device cpu|cuda] [--batch-scale 1 4] [--model-override '{"trunk_upsample_stages": 0}']
[--corpus-size 96] [--steps 40] [--json F]``. The weights are random (``init_weights`` is not
read): throughput does not depend on them.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def time_config(mcfg, tcfg, sets, device: str, steps: int, warmup: int) -> dict:
    """Mean seconds per step for data and network, and the parameter count."""
    import torch

    from specgen_addon.model import SpecGen, count_parameters
    from specgen_addon.train import distributed as ddp
    from specgen_addon.train.loop import group_loss, make_step_batches, total_loss

    spectral, rgb, _ = sets
    dev = ddp.train_device(device)
    model = SpecGen(mcfg).to(dev)
    opt = torch.optim.Adam(model.parameters(), lr=1e-4)
    t_data = t_net = 0.0
    for step in range(warmup + steps):
        t0 = time.perf_counter()
        b_spec, b_rgb = make_step_batches(tcfg, mcfg, spectral, rgb, step)
        t1 = time.perf_counter()
        opt.zero_grad(set_to_none=True)
        loss, _ = total_loss(tcfg, *(None if b is None else group_loss(model, b) for b in (b_spec, b_rgb)))
        loss.backward()
        opt.step()
        if dev.type == "cuda":
            torch.cuda.synchronize()
        t2 = time.perf_counter()
        if step >= warmup:
            t_data += t1 - t0
            t_net += t2 - t1
    return {"data_s": t_data / steps, "network_s": t_net / steps, "parameters": count_parameters(model)}


def main() -> int:
    import torch
    from machine import describe_machine  # bench/machine.py

    from specgen_addon.model import Config
    from specgen_addon.train import build_material_sets
    from specgen_addon.train.loop import load_config

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", type=Path, default=REPO / "configs" / "shipped.json")
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cpu")
    ap.add_argument("--threads", type=int, default=1, help="torch threads (default 1)")
    ap.add_argument("--batch-scale", type=int, nargs="+", default=[1],
                    help="multiply the materials per step by each of these (default 1)")
    ap.add_argument("--model-override", action="append", default=[],
                    help="JSON object of model config fields; each gives one more row")
    ap.add_argument("--corpus-size", type=int, default=96)
    ap.add_argument("--render-workers", type=int, default=2)
    ap.add_argument("--steps", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=5)
    ap.add_argument("--cache", type=Path, default=REPO / ".cache" / "specgen" / "train-data")
    ap.add_argument("--json", type=Path, default=None, help="also write the rows here")
    args = ap.parse_args()
    if min(args.batch_scale) < 1 or args.corpus_size < 8 or args.steps < 1 or args.warmup < 0:
        ap.error("--batch-scale ≥ 1, --corpus-size ≥ 8, --steps ≥ 1 and --warmup ≥ 0")
    overrides = [json.loads(o) for o in args.model_override]
    torch.set_num_threads(args.threads)
    mcfg, tcfg = load_config(args.config)
    tcfg = dataclasses.replace(tcfg, corpus_size=args.corpus_size, render_workers=args.render_workers,
                               init_weights=None)
    t0 = time.perf_counter()
    sets = build_material_sets(mcfg, tcfg, args.cache, log=print)
    print(f"machine: {describe_machine()}\nconfig {args.config.name}, device {args.device}, "
          f"{args.threads} torch thread(s); corpus {args.corpus_size} ({len(sets[0])} spectral training "
          f"materials) ready in {time.perf_counter() - t0:.0f} s")
    rows = []
    for over in [{}] + overrides:
        cfg = Config.from_dict({**mcfg.to_dict(), **over})
        if cfg.image_size != mcfg.image_size:  # the input stacks at this model's resolution
            mcfg, sets = cfg, build_material_sets(cfg, tcfg, args.cache, log=print)
        for k in args.batch_scale:
            t = dataclasses.replace(tcfg, spectral_materials_per_step=k * tcfg.spectral_materials_per_step,
                                    rgb_materials_per_step=k * tcfg.rgb_materials_per_step)
            r = time_config(cfg, t, sets, args.device, args.steps, args.warmup)
            r.update(model=over or "config's", materials_per_step=t.spectral_materials_per_step
                     + t.rgb_materials_per_step, device=args.device)
            rows.append(r)
            bound = "data" if r["data_s"] > r["network_s"] else "network"
            print(f"model {json.dumps(r['model'])} ({r['parameters'] / 1e6:.2f} M parameters), "
                  f"{r['materials_per_step']} materials/step: data {1e3 * r['data_s']:.1f} ms, network "
                  f"{1e3 * r['network_s']:.1f} ms per step → {1 / (r['data_s'] + r['network_s']):.2f} "
                  f"steps/s serial ({bound}-bound)")
    if args.json:
        args.json.write_text(json.dumps({"machine": describe_machine(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
