"""Training one gait on several processes: several GPUs, or CPU ranks, through rsl-rl's own multi-GPU support.

``torchrun --nproc-per-node N`` (https://pytorch.org/docs/stable/elastic/run.html) starts N copies of
``gaitlib train`` and tells each its place through ``WORLD_SIZE``, ``RANK`` and ``LOCAL_RANK``. rsl-rl's
``OnPolicyRunner`` then averages the PPO gradients of all ranks at every update, so each rank runs its own worlds
(the preset's ``num_envs``, with its own seed) and the ranks together collect N times the samples per iteration.
rsl-rl sets up only CUDA ranks (NCCL, one GPU each); :func:`join` does the same for CPU ranks over gloo, which
is how the tests run this path on a machine without a GPU. Rank 0 alone checkpoints, logs and writes the library
entry; every decision that ends the loop is taken by rank 0 and shared, so no rank waits for a collective that
another has left.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch

__all__ = ["Ranks", "agree", "join", "leave", "parameters_in_sync", "rank_device"]


@dataclass(frozen=True)
class Ranks:
    """Where this process stands among the training processes (torchrun's environment variables)."""

    world_size: int
    """Processes training together (1: not distributed)."""
    rank: int
    """This process's global rank, 0 to ``world_size - 1``."""
    local_rank: int
    """Its rank on this machine: the GPU index it uses."""

    @staticmethod
    def from_env() -> Ranks:
        """Read ``WORLD_SIZE``, ``RANK`` and ``LOCAL_RANK`` (unset: one process)."""
        return Ranks(
            world_size=int(os.getenv("WORLD_SIZE", "1")),
            rank=int(os.getenv("RANK", "0")),
            local_rank=int(os.getenv("LOCAL_RANK", "0")),
        )

    @property
    def distributed(self) -> bool:
        return self.world_size > 1

    @property
    def main(self) -> bool:
        """The rank that checkpoints, logs and writes the library entry."""
        return self.rank == 0


def rank_device(backend: str, ranks: Ranks) -> str | None:
    """The torch device of this rank's simulator: its own GPU for ``newton`` when distributed, the CPU for
    ``mujoco``; ``None`` (the backend's choice) for a single process."""
    if not ranks.distributed:
        return None
    return f"cuda:{ranks.local_rank}" if backend == "newton" else "cpu"


def join(ranks: Ranks) -> dict | None:
    """Join the process group of a CPU rank (gloo) and return rsl-rl's ``multi_gpu`` configuration for it;
    ``None`` for a single process."""
    if not ranks.distributed:
        return None
    if not torch.distributed.is_initialized():
        torch.distributed.init_process_group(backend="gloo", rank=ranks.rank, world_size=ranks.world_size)
    return {"global_rank": ranks.rank, "local_rank": ranks.local_rank, "world_size": ranks.world_size}


def leave() -> None:
    """Leave the process group, if this process joined one."""
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        torch.distributed.destroy_process_group()


def agree(flag: bool, *, device: str) -> bool:
    """Rank 0's ``flag`` on every rank (a collective: every rank must call it); ``flag`` itself when alone."""
    if not (torch.distributed.is_available() and torch.distributed.is_initialized()):
        return flag
    shared = torch.tensor([int(flag)], device=device)
    torch.distributed.broadcast(shared, src=0)
    return bool(shared.item())


def parameters_in_sync(module: torch.nn.Module, *, device: str) -> bool:
    """Whether every rank holds the same parameters in ``module`` (a collective); ``True`` when alone."""
    if not (torch.distributed.is_available() and torch.distributed.is_initialized()):
        return True
    flat = torch.cat([p.detach().reshape(-1) for p in module.parameters()]).to(device)
    first = flat.clone()
    torch.distributed.broadcast(first, src=0)
    same = torch.tensor([int(torch.equal(flat, first))], device=device)
    torch.distributed.all_reduce(same, op=torch.distributed.ReduceOp.MIN)
    return bool(same.item())
