"""Data-parallel training under ``torchrun`` (gloo on CPU, NCCL on GPU), and a network run on another device.

``torchrun --nproc_per_node N ...`` starts N processes with ``RANK``, ``WORLD_SIZE``, ``LOCAL_RANK`` and the
rendezvous address in their environment; :func:`init_distributed` joins them into one process group. Without those
variables every function here is a no-op for one process, so single-process code runs unchanged.
"""
from __future__ import annotations

import os

import torch
from torch import distributed as dist
from torch import nn

__all__ = ["init_distributed", "world", "is_main_process", "group_device", "mean_across", "barrier", "finish_distributed", "OnDevice"]


def init_distributed() -> torch.device:
    """Join the process group ``torchrun`` describes (once) and return this process's device.

    NCCL and ``cuda:LOCAL_RANK`` where CUDA is available, gloo and the CPU otherwise; the CPU with no process group
    when the environment holds no ``WORLD_SIZE`` (plain ``python``).
    """
    if not dist.is_available() or "WORLD_SIZE" not in os.environ:
        return torch.device("cpu")
    cuda = torch.cuda.is_available()
    if not dist.is_initialized():
        dist.init_process_group("nccl" if cuda else "gloo")
    if cuda:
        device = torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
        torch.cuda.set_device(device)
        return device
    return torch.device("cpu")


def world() -> tuple[int, int]:
    """``(rank, world size)`` of this process: ``(0, 1)`` outside a process group."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def is_main_process() -> bool:
    """Whether this process writes files and logs (rank 0, or the only process)."""
    return world()[0] == 0


def group_device() -> torch.device:
    """The device this process computes on: its CUDA device under NCCL, else the CPU."""
    if dist.is_available() and dist.is_initialized() and dist.get_backend() == "nccl":
        return torch.device("cuda", torch.cuda.current_device())
    return torch.device("cpu")


def mean_across(values: dict) -> dict:
    """``{name: float}`` averaged over the processes of the group (unchanged for one process)."""
    if world()[1] == 1 or not values:
        return values
    keys = sorted(values)
    t = torch.tensor([float(values[k]) for k in keys], dtype=torch.float64, device=group_device())
    dist.all_reduce(t)
    return {k: float(v) / world()[1] for k, v in zip(keys, t.tolist())}


def barrier() -> None:
    """Wait for every process of the group (nothing to wait for alone)."""
    if world()[1] > 1:
        dist.barrier()


def finish_distributed() -> None:
    """Wait for every process, then leave the process group (nothing to do alone)."""
    if dist.is_available() and dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()


class OnDevice(nn.Module):
    """Run ``module`` on ``device`` for callers that work on the CPU: tensor arguments go to ``device``, tensor
    results come back to the CPU (gradients flow through both copies)."""

    def __init__(self, module: nn.Module, device: torch.device):
        super().__init__()
        self.module, self.device = module, torch.device(device)

    def forward(self, *args):
        out = self.module(*(a.to(self.device) if isinstance(a, torch.Tensor) else a for a in args))
        if isinstance(out, torch.Tensor):
            return out.cpu()
        return type(out)(o.cpu() if isinstance(o, torch.Tensor) else o for o in out)
