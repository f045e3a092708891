"""Data-parallel training across processes (``torchrun`` + ``DistributedDataParallel``).

    # make train NPROC=2:
    torchrun --standalone --nproc_per_node=2 -m pipeline.stages.train experiment=default

``torchrun`` sets ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK`` and the rendezvous; without them
training runs in one process, exactly as before. Backend: ``nccl`` on CUDA (one GPU per
process, ``cuda:<LOCAL_RANK>``), ``gloo`` on CPUs.

What stays the same as one process: the global batch (``train.batch_size`` images) and every
epoch's image order and flips (``pipeline.stages.train.epoch_order``). Each global batch is split
into ``W`` contiguous parts, rank r takes part r (``split_batch``), and its loss is weighted
by ``W·n_r/n`` so that DDP's gradient average equals the gradient of the mean loss over the
whole batch. Every image of the epoch is seen exactly once, by one rank.

What differs: BatchNorm normalises each rank's part with that part's own statistics (DDP's
usual semantics; ``SyncBatchNorm`` is used on CUDA, where PyTorch supports it, but not on CPU,
where it does not), and DDP's bucketed all-reduce sums in another order; the final weights
therefore differ from a one-process run in the last digits and drift apart a little over
training. How to run it and what it changes: docs/scaling.md ("Data-parallel training").
"""

from __future__ import annotations

import datetime
import os
from dataclasses import dataclass

import torch
import torch.distributed as dist


@dataclass(frozen=True)
class DistContext:
    """This process's place in the job. ``world_size == 1``: no process group."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    local_world_size: int = 1

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def active(self) -> bool:
        return self.world_size > 1


def from_env() -> DistContext:
    """The context ``torchrun`` describes in the environment (one process if it does not)."""
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world <= 1:
        return DistContext()
    return DistContext(
        rank=int(os.environ["RANK"]),
        world_size=world,
        local_rank=int(os.environ.get("LOCAL_RANK", "0")),
        local_world_size=int(os.environ.get("LOCAL_WORLD_SIZE", str(world))),
    )


def init(ctx: DistContext, device: torch.device) -> torch.device:
    """Join the process group; returns this rank's device (``cuda:<local_rank>`` on CUDA)."""
    if not ctx.active:
        return device
    if device.type == "cuda":
        torch.cuda.set_device(ctx.local_rank)
        device = torch.device("cuda", ctx.local_rank)
    if not dist.is_initialized():
        # Long timeout: rank 0 alone computes the validation loss between epochs.
        dist.init_process_group(
            "nccl" if device.type == "cuda" else "gloo", timeout=datetime.timedelta(hours=2)
        )
    return device


def shutdown(ctx: DistContext) -> None:
    if ctx.active and dist.is_initialized():
        dist.destroy_process_group()


def broadcast(ctx: DistContext, value):
    """Rank 0's ``value`` (any picklable object) on every rank."""
    if not ctx.active:
        return value
    box = [value]
    dist.broadcast_object_list(box, src=0)
    return box[0]


def barrier(ctx: DistContext) -> None:
    if ctx.active:
        dist.barrier()


def split_batch(
    indices: list[int], flips: list[str], rank: int, world_size: int
) -> tuple[list[int], list[str], float]:
    """Rank ``rank``'s part of one global batch and its loss weight ``W·n_r/n``.

    Parts are contiguous and as equal as possible (``[0, 1, 2, 3, 4]`` over 2 ranks:
    ``[0, 1, 2]`` and ``[3, 4]``). A rank whose part would be empty (a last batch smaller than
    the number of ranks) gets the batch's first image with weight 0: every rank must run a
    forward and backward pass for DDP's all-reduce, and a zero weight keeps the gradient exact.
    """
    n = len(indices)
    if n == 0 or not 0 <= rank < world_size:
        raise ValueError(f"cannot split {n} images for rank {rank} of {world_size}")
    base, extra = divmod(n, world_size)
    start = rank * base + min(rank, extra)
    stop = start + base + (1 if rank < extra else 0)
    if stop == start:
        return [indices[0]], [flips[0]], 0.0
    return list(indices[start:stop]), list(flips[start:stop]), world_size * (stop - start) / n


def all_mean(
    ctx: DistContext, values: list[float], weight: float, device: torch.device | None = None
) -> list[float]:
    """``Σ_r weight_r · values_r / W`` over ranks: with the weights of ``split_batch`` the
    batch-mean of per-image values, as one process would compute it."""
    if not ctx.active:
        return values
    t = torch.tensor([v * weight for v in values], dtype=torch.float64, device=device)
    dist.all_reduce(t)
    return (t / ctx.world_size).tolist()
