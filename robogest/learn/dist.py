"""Device choice and torch.distributed set-up (DistributedDataParallel when launched with ``torchrun``)."""

from __future__ import annotations

import os
from dataclasses import dataclass

from robogest.errors import InputError
from robogest.learn import require_torch


@dataclass(frozen=True)
class DistInfo:
    """Where this process sits in a (possibly one-process) job."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    enabled: bool = False  # True when a process group was initialised (torchrun / RANK + WORLD_SIZE set)

    @property
    def is_main(self) -> bool:
        return self.rank == 0


def pick_device(pref: str = "auto", local_rank: int = 0):  # -> torch.device
    """``auto``: CUDA when available, else CPU; ``cuda`` without a GPU is an :class:`InputError`."""
    torch = require_torch()
    if pref not in ("auto", "cpu", "cuda"):
        raise InputError(f"device must be auto, cpu or cuda, got {pref!r}")
    if pref == "cpu" or (pref == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise InputError("--device cuda was asked for but PyTorch sees no CUDA GPU; use --device cpu or auto")
    return torch.device("cuda", local_rank % torch.cuda.device_count())


def setup(device_pref: str = "auto"):  # -> tuple[DistInfo, torch.device]
    """Initialise the process group when ``RANK`` and ``WORLD_SIZE`` are set (``torchrun``), else run alone.

    The backend is NCCL on CUDA and gloo on CPU.
    """
    torch = require_torch()
    if "RANK" not in os.environ or "WORLD_SIZE" not in os.environ:
        return DistInfo(), pick_device(device_pref)
    rank, world = int(os.environ["RANK"]), int(os.environ["WORLD_SIZE"])
    local = int(os.environ.get("LOCAL_RANK", rank))
    device = pick_device(device_pref, local)
    import torch.distributed as dist

    if not dist.is_initialized():
        os.environ.setdefault("MASTER_ADDR", "127.0.0.1")
        os.environ.setdefault("MASTER_PORT", "29500")
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo", rank=rank, world_size=world)
    if device.type == "cuda":
        torch.cuda.set_device(device)
    return DistInfo(rank, world, local, True), device


def barrier(info: DistInfo) -> None:
    """Wait until every rank gets here (no-op when not distributed)."""
    if info.enabled and info.world_size > 1:
        import torch.distributed as dist

        dist.barrier()


def builder_first(info: DistInfo, build, read):
    """``build()`` on each node's first process (``LOCAL_RANK`` 0), then ``read()`` on the others once it is done.

    For data written once to local disk and memory-mapped by every rank (feature cache, training windows): the
    other ranks neither compute nor hold a copy of their own. Returns what this process's call returned.
    """
    result = build() if info.local_rank == 0 else None
    barrier(info)
    return result if info.local_rank == 0 else read()


def all_reduce_mean(values: list[float], info: DistInfo, device) -> list[float]:
    """Mean of ``values`` over all ranks (identity when not distributed)."""
    if not info.enabled or info.world_size == 1:
        return list(values)
    torch = require_torch()
    import torch.distributed as dist

    t = torch.tensor(values, dtype=torch.float64, device=device)
    dist.all_reduce(t)
    return (t / info.world_size).tolist()


def teardown(info: DistInfo) -> None:
    if info.enabled:
        import torch.distributed as dist

        if dist.is_initialized():
            dist.destroy_process_group()
