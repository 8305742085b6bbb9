"""torch.distributed plumbing for ``crossing-train`` under ``torchrun`` (DistributedDataParallel).

A run is distributed when ``WORLD_SIZE`` (set by ``torchrun``) is greater than 1; otherwise
nothing here starts a process group and training is the plain one-process loop. Under
``torchrun`` every rank holds the whole (small) cached feature set and computes the same
deterministic epoch order; each global batch of ``batch_size`` samples is split across the ranks
(``batch[rank::world]``, what ``DistributedSampler`` gives for a sequential order), and each rank's
loss is scaled so that DDP's gradient average equals the one-process gradient of the global
batch. Rank 0 alone builds the frozen-feature cache (the others wait at a barrier, then read it)
and writes the run folder.
"""

from __future__ import annotations

import os
import sys
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator, NoReturn

import numpy as np
import torch
import torch.distributed as dist


@dataclass(frozen=True)
class Context:
    """Where this process stands: ``rank`` of ``world`` (0 of 1 when not distributed)."""

    rank: int = 0
    world: int = 1

    @property
    def active(self) -> bool:
        return self.world > 1

    @property
    def main(self) -> bool:
        return self.rank == 0


def requested() -> bool:
    """True when launched by ``torchrun`` (or alike) with more than one process."""
    try:
        return int(os.environ.get("WORLD_SIZE", "1")) > 1
    except ValueError:
        return False


def setup() -> Context:
    """Join the process group named by the ``torchrun`` environment (idempotent); a one-process
    run (``WORLD_SIZE`` unset or 1) starts nothing. The loop runs on the CPU (cached features
    make an epoch cheap), so the backend is gloo (nccl needs the loop's tensors on a GPU)."""
    if not requested():
        return Context()
    if not dist.is_initialized():
        dist.init_process_group(backend="gloo")
    return Context(dist.get_rank(), dist.get_world_size())


def teardown() -> None:
    if dist.is_initialized():
        dist.destroy_process_group()


def leave(code: int = 0) -> NoReturn:
    """End this ``torchrun`` worker now, its run complete and its process group destroyed: the
    output flushed, then ``os._exit``, skipping the interpreter's shutdown. Finished workers have
    died after their run (rank 1, SIGABRT, "terminate called without an active exception": once in
    four clean-clone CI runs and once in two full local test runs, never in 184 runs of the test's
    commands alone), most likely in that shutdown; torchrun then reports a failed job although
    every file was written."""
    for stream in (sys.stdout, sys.stderr):
        stream.flush()
    os._exit(code)


def barrier(ctx: Context) -> None:
    if ctx.active:
        dist.barrier()


@contextmanager
def main_first(ctx: Context) -> Iterator[None]:
    """Rank 0 runs the block first (e.g. builds the feature cache); the others wait at a barrier,
    then run it (finding the cache built)."""
    if ctx.active and not ctx.main:
        dist.barrier()
    yield
    if ctx.active and ctx.main:
        dist.barrier()


def all_sum(ctx: Context, value: float) -> float:
    """Sum of ``value`` over the ranks (the value itself when not distributed)."""
    if not ctx.active:
        return value
    t = torch.tensor([value], dtype=torch.float64)
    dist.all_reduce(t)
    return float(t[0])


def rank_slice(batch: np.ndarray, ctx: Context) -> tuple[np.ndarray, np.ndarray]:
    """This rank's part of a global batch: ``(indices, keep)``. A rank left without samples (a last
    batch smaller than the world) gets the batch's first sample with ``keep`` 0, so every rank runs
    the same number of forward/backward passes (DDP needs that) and the padded sample adds nothing."""
    part = batch[ctx.rank::ctx.world]
    if len(part):
        return part, np.ones(len(part), np.float32)
    return batch[:1], np.zeros(1, np.float32)


class Forward(torch.nn.Module):
    """``policy.forward_from`` as a module ``forward`` so DistributedDataParallel can wrap it."""

    def __init__(self, policy: torch.nn.Module, start: int):
        super().__init__()
        self.policy = policy
        self.start = start

    def forward(self, x: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
        return self.policy.forward_from(x, self.start, samples=1, mc=True, window=window)[0]


def wrap(policy: torch.nn.Module, start: int, ctx: Context) -> torch.nn.Module:
    """The training forward: DDP over :class:`Forward` when distributed, else :class:`Forward`."""
    fwd = Forward(policy, start)
    if not ctx.active:
        return fwd
    from torch.nn.parallel import DistributedDataParallel

    return DistributedDataParallel(fwd)
