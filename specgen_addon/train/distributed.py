"""Data-parallel training under ``torchrun`` with PyTorch DDP.

Every rank builds the *same* global batch of a step from the seeded stream ``(seed, step)``
(:func:`~specgen_addon.train.loop.make_step_batches`) and keeps a disjoint, contiguous shard of its
materials. Its share of the loss is weighted so that the mean over ranks — what DDP's gradient
all-reduce averages — is exactly the single-process loss of the whole batch:

* ``L_spec`` / ``L_RGB`` (masked means over points): ``W · n_valid(shard) / n_valid(batch)``;
* ``L_TV`` (a mean over the batch's planes): ``W · B(shard) / B(batch)``;

Only the BRDF targets of the rank's own shard are evaluated (the costly part of making a batch);
the random stream is drawn for the whole batch all the same, so every shard is what a single
process would make.

with ``W`` the world size. So the gradients, the updates and the logged losses equal a
single-process run of the same global batch up to float rounding; with ``W = 1`` (weights
exactly 1) DDP training is plain :func:`~specgen_addon.train.loop.train`, bit for bit.

Rank 0 alone writes checkpoints, history and weights; on ``--resume`` it reads the checkpoint and
broadcasts it, so other nodes need no shared file system for it. Backend: gloo when the network
trains on the CPU, nccl when it trains on GPUs (``device = "cuda"``: rank ``LOCAL_RANK`` of a node
uses GPU ``LOCAL_RANK``). Targets, inputs and their shards are made on the CPU either way.
"""

from __future__ import annotations

import atexit
import contextlib
import dataclasses
import os
from dataclasses import dataclass
from typing import Any, Callable, Iterator

import numpy as np
import torch
import torch.distributed as dist

from specgen_addon.common.errors import SpecGenError
from specgen_addon.train.data import Batch


@dataclass(frozen=True)
class DistContext:
    """This process' place in the job: ``rank`` of ``world_size`` (0 of 1 without torchrun)."""

    rank: int = 0
    world_size: int = 1
    group: bool = False   #: a process group is initialised (torchrun), even of size 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def parallel(self) -> bool:
        return self.world_size > 1


def train_device(requested: str = "cpu") -> torch.device:
    """The device this rank trains on: ``"cpu"``; ``"cuda"`` (GPU ``LOCAL_RANK``, refused without
    one); ``"auto"``: cuda when available, else the CPU."""
    if requested not in ("cpu", "cuda", "auto"):
        raise SpecGenError(f"training config: device must be 'cpu', 'cuda' or 'auto', got {requested!r}")
    if requested == "cpu" or (requested == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise SpecGenError("training device 'cuda' asked for, but torch sees no CUDA GPU "
                           "(use --device cpu, or auto)")
    # deterministic cuBLAS (torch.use_deterministic_algorithms needs it on CUDA)
    os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    index = int(os.environ.get("LOCAL_RANK", "0"))
    if index >= torch.cuda.device_count():
        raise SpecGenError(f"rank {index} of this node has no GPU (only {torch.cuda.device_count()}): "
                           "start at most one process per GPU")
    torch.cuda.set_device(index)
    return torch.device("cuda", index)


def backend(device: torch.device) -> str:
    """nccl for a model on GPUs, gloo for one on the CPU."""
    return "nccl" if device.type == "cuda" else "gloo"


def init_from_env(device: str = "cpu") -> DistContext:
    """Join the process group when started by ``torchrun`` (``WORLD_SIZE`` etc. in the
    environment); a plain ``python -m specgen_addon train`` stays a single process. ``device`` is
    the training config's: it picks the backend (:func:`backend`)."""
    if dist.is_available() and not dist.is_initialized() and "WORLD_SIZE" in os.environ \
            and "MASTER_ADDR" in os.environ:
        dist.init_process_group(backend(train_device(device)))
        atexit.register(shutdown)
    return context()


def context() -> DistContext:
    """The current process group's rank and size (single process when none is initialised)."""
    if dist.is_available() and dist.is_initialized():
        return DistContext(dist.get_rank(), dist.get_world_size(), True)
    return DistContext()


def shutdown() -> None:
    if dist.is_available() and dist.is_initialized():
        dist.destroy_process_group()


def silent(*args: Any, **kwargs: Any) -> None:
    """``print`` for ranks other than 0."""


@contextlib.contextmanager
def main_first(ctx: DistContext) -> Iterator[None]:
    """Rank 0 runs the block first (filling shared caches), the others after it finished."""
    if ctx.parallel and not ctx.is_main:
        dist.barrier()
    yield
    if ctx.parallel and ctx.is_main:
        dist.barrier()


def broadcast(obj: Any, ctx: DistContext) -> Any:
    """Rank 0's ``obj`` on every rank (pickled; for checkpoints and small records)."""
    if not ctx.parallel:
        return obj
    box = [obj if ctx.is_main else None]
    dist.broadcast_object_list(box, src=0)
    return box[0]


def check_shardable(counts: dict[str, int], ctx: DistContext) -> None:
    """Each rank needs at least one material of every group a step draws."""
    for name, k in counts.items():
        if 0 < k < ctx.world_size:
            raise SpecGenError(f"{name} = {k} cannot be shared by {ctx.world_size} ranks: "
                               f"use at least one material per rank (≥ {ctx.world_size})")


def shard_rows(n_materials: int, ctx: DistContext) -> np.ndarray:
    """Indices of this rank's contiguous share of a group of ``n_materials`` materials."""
    return np.array_split(np.arange(n_materials), ctx.world_size)[ctx.rank]


def shard(b: Batch, ctx: DistContext) -> tuple[Batch, float, float]:
    """This rank's contiguous slice of the batch's materials, with the weights of its masked MSE
    and of its TV term (module docstring)."""
    rows = shard_rows(b.images.shape[0], ctx)
    sl = slice(int(rows[0]), int(rows[-1]) + 1)
    part = Batch(**{f.name: (None if getattr(b, f.name) is None else getattr(b, f.name)[sl])
                    for f in dataclasses.fields(Batch)})
    n_all = max(int(b.valid.sum()), 1)
    w_mse = ctx.world_size * int(part.valid.sum()) / n_all
    w_tv = ctx.world_size * rows.size / b.images.shape[0]
    return part, w_mse, w_tv


class _StepLosses(torch.nn.Module):
    """One forward for all of a step's groups, so DDP sees one forward per backward."""

    def __init__(self, model: torch.nn.Module, group_loss: Callable):
        super().__init__()
        self.model = model
        self.group_loss = group_loss

    def forward(self, *groups: tuple[Batch, float, float] | None):
        out = []
        for g in groups:
            if g is None:
                out.append(None)
                continue
            b, w_mse, w_tv = g
            mse, tv = self.group_loss(self.model, b)
            out.append((mse * w_mse, tv * w_tv))
        return out


def step_losses(model: torch.nn.Module, group_loss: Callable, ctx: DistContext
                ) -> Callable[..., list[tuple[torch.Tensor, torch.Tensor] | None]]:
    """``f(*batches) -> [(L_mse, L_TV) or None per group]``: this rank's weighted share of a step,
    through DDP when there are several ranks (its backward then averages the gradients)."""
    if not ctx.group:
        return lambda *batches: [None if b is None else group_loss(model, b) for b in batches]
    dev = next(model.parameters()).device
    ddp = torch.nn.parallel.DistributedDataParallel(_StepLosses(model, group_loss),
                                                    device_ids=[dev.index] if dev.type == "cuda" else None)
    return lambda *batches: ddp(*[None if b is None else shard(b, ctx) for b in batches])


def mean_record(rec: dict[str, float], ctx: DistContext) -> dict[str, float]:
    """Logged losses of the whole step: the mean of the ranks' weighted shares."""
    if not ctx.group:
        return rec
    keys = [k for k in ("spec", "rgb", "tv", "loss") if k in rec]
    # nccl reduces CUDA tensors only: on the rank's GPU then, on the CPU for gloo
    on = torch.device("cuda", torch.cuda.current_device()) if dist.get_backend() == "nccl" else "cpu"
    t = torch.tensor([rec[k] for k in keys], dtype=torch.float64, device=on)
    dist.all_reduce(t)
    return {**rec, **{k: float(v) / ctx.world_size for k, v in zip(keys, t)}}
