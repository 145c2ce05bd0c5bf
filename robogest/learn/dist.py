"""Device choice and torch.distributed set-up (DistributedDataParallel when launched with ``torchrun``)."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, TypeVar

from robogest.errors import InputError
from robogest.learn import require_torch

T = TypeVar("T")


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


def pick_device(pref: str = "auto", local_rank: int = 0) -> Any:  # torch.device
    """``auto``: CUDA when available, else CPU; ``cuda`` without a GPU is an :class:`InputError`."""
    torch = require_torch()
    if pref not in ("auto", "cpu", "cuda"):
        raise InputError(f"device must be auto, cpu or cuda, got {pref!r}")
    if pref == "cpu" or (pref == "auto" and not torch.cuda.is_available()):
        return torch.device("cpu")
    if not torch.cuda.is_available():
        raise InputError("--device cuda was asked for but PyTorch sees no CUDA GPU; use --device cpu or auto")
    return torch.device("cuda", local_rank % torch.cuda.device_count())


#: Default process-group timeout, s: long enough for rank 0 to build a large dataset's caches while the other
#: ranks wait at a barrier (PyTorch's own default is 10 min for NCCL, 30 min for gloo).
DEFAULT_TIMEOUT_S = 7200.0


def setup(device_pref: str = "auto", timeout_s: float = DEFAULT_TIMEOUT_S) -> tuple[DistInfo, Any]:  # Any: torch.device
    """Initialise the process group when ``RANK`` and ``WORLD_SIZE`` are set (``torchrun``), else run alone.

    The backend is NCCL on CUDA and gloo on CPU. ``timeout_s``: how long a collective (a barrier included) waits
    for the other ranks before the job fails.
    """
    if not timeout_s > 0:
        raise InputError(f"the process-group timeout must be > 0 s, got {timeout_s}; e.g. --dist-timeout-s 7200")
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
        from datetime import timedelta

        backend = "nccl" if device.type == "cuda" else "gloo"
        dist.init_process_group(backend, rank=rank, world_size=world, timeout=timedelta(seconds=timeout_s))
    if device.type == "cuda":
        torch.cuda.set_device(device)
    return DistInfo(rank, world, local, True), device


def barrier(info: DistInfo) -> None:
    """Wait until every rank gets here (no-op when not distributed)."""
    if info.enabled and info.world_size > 1:
        import torch.distributed as dist

        dist.barrier()


def builder_first(info: DistInfo, build: Callable[[], T], read: Callable[[], T]) -> T:
    """``build()`` on each node's first process (``LOCAL_RANK`` 0), then ``read()`` on the others once it is done.

    For data written once to local disk and memory-mapped by every rank (feature cache, training windows): the
    other ranks neither compute nor hold a copy of their own. Returns what this process's call returned.
    """
    if info.local_rank == 0:
        result = build()
        barrier(info)
        return result
    barrier(info)
    return read()


def all_reduce_mean(values: list[float], info: DistInfo, device: Any) -> list[float]:
    """Mean of ``values`` over all ranks (identity when not distributed)."""
    if not info.enabled or info.world_size == 1:
        return list(values)
    torch = require_torch()
    import torch.distributed as dist

    t = torch.tensor(values, dtype=torch.float64, device=device)
    dist.all_reduce(t)
    means: list[float] = (t / info.world_size).tolist()
    return means


class Sync:
    """In-place collectives over all ranks, for model state that changes outside gradient steps (a codebook)."""

    def __init__(self, info: DistInfo) -> None:
        self.info = info

    @property
    def is_main(self) -> bool:
        return self.info.is_main

    def all_reduce_sum_(self, t: Any) -> None:
        """``t`` becomes its sum over ranks, the same on every rank."""
        import torch.distributed as dist

        dist.all_reduce(t)

    def broadcast_(self, t: Any, src: int = 0) -> None:
        """``t`` becomes rank ``src``'s."""
        import torch.distributed as dist

        dist.broadcast(t, src)


def sync_of(info: DistInfo) -> Sync | None:
    """A :class:`Sync` when several ranks run, else None (one process: nothing to agree on)."""
    return Sync(info) if info.enabled and info.world_size > 1 else None


def teardown(info: DistInfo) -> None:
    if info.enabled:
        import torch.distributed as dist

        if dist.is_initialized():
            dist.destroy_process_group()
