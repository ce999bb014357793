"""Where a training process runs: device, and its place in a ``torchrun`` job.

``torchrun --nproc-per-node N ...`` (torch.distributed's launcher) sets ``RANK``,
``WORLD_SIZE``, ``LOCAL_RANK`` and ``MASTER_ADDR``/``MASTER_PORT`` in each process;
:func:`setup` reads them and joins the process group (gloo on CPU, nccl on CUDA unless a
backend is named). Without them the process runs alone (rank 0 of 1).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import torch
import torch.distributed as dist

BACKENDS = ("auto", "gloo", "nccl")


@dataclass(frozen=True)
class Placement:
    """One training process.

    Attributes:
        rank: this process's index in the job, 0 .. world_size - 1 (rank 0 writes files).
        world_size: processes in the job (1 without torchrun).
        device: the torch device it computes on ("cpu", "cuda:LOCAL_RANK").
        backend: the process group's backend, or None when alone.
    """

    rank: int
    world_size: int
    device: torch.device
    backend: str | None

    @property
    def distributed(self) -> bool:
        return self.world_size > 1


def check_device(device: str) -> None:
    """ValueError (one line) unless ``device`` is "cpu" or "cuda[:N]" with a GPU present."""
    if device == "cpu":
        return
    if device != "cuda" and not (device.startswith("cuda:") and device[5:].isdigit()):
        raise ValueError(f"device must be cpu, cuda or cuda:N, got {device!r}")
    if not torch.cuda.is_available():
        raise ValueError(f"device {device}: no CUDA GPU is available (torch.cuda.is_available())")


def check_backend(backend: str, device: str) -> str:
    """The process-group backend for ``backend`` (auto: gloo on CPU, nccl on CUDA); ValueError
    (one line) for an unknown one, nccl on CPU, or one this torch build lacks."""
    if backend not in BACKENDS:
        raise ValueError(f"ddp backend must be one of {', '.join(BACKENDS)}, got {backend!r}")
    name = ("nccl" if device.startswith("cuda") else "gloo") if backend == "auto" else backend
    if name == "nccl" and not device.startswith("cuda"):
        raise ValueError("ddp backend nccl needs device cuda; use gloo (or auto) on cpu")
    if not dist.is_available() or not dist.is_backend_available(name):
        raise ValueError(f"ddp backend {name} is not available in this torch build")
    return name


def setup(device: str = "cpu", backend: str = "auto") -> Placement:
    """Check the device, and join the ``torchrun`` process group when its variables are set.

    On CUDA each process takes GPU ``LOCAL_RANK``. Idempotent: a group already initialised
    is reused.
    """
    check_device(device)
    world = int(os.environ.get("WORLD_SIZE", "1"))
    rank = int(os.environ.get("RANK", "0"))
    if world < 1 or not 0 <= rank < world:
        raise ValueError(f"RANK must be in [0, WORLD_SIZE), got RANK={rank}, WORLD_SIZE={world}")
    dev = torch.device(device)
    if dev.type == "cuda" and dev.index is None:
        dev = torch.device("cuda", int(os.environ.get("LOCAL_RANK", "0")))
    if world == 1:
        return Placement(0, 1, dev, None)
    name = check_backend(backend, device)
    if not dist.is_initialized():
        if dev.type == "cuda":
            torch.cuda.set_device(dev)
        dist.init_process_group(name, rank=rank, world_size=world)
    return Placement(rank, world, dev, name)


def all_reduce(values: list[float], op: str, placement: Placement) -> list[float]:
    """Sum or max (``op``) of floats over every process (the values themselves when alone)."""
    if not placement.distributed:
        return values
    t = torch.tensor(values, dtype=torch.float64)
    if placement.backend == "nccl":
        t = t.to(placement.device)
    dist.all_reduce(t, op=dist.ReduceOp.SUM if op == "sum" else dist.ReduceOp.MAX)
    return [float(v) for v in t.cpu()]
