"""How many torch threads a block of work gets (training, evaluation, rendering)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

import torch


@contextmanager
def torch_threads(n: int) -> Iterator[None]:
    """Run torch ops on ``n`` threads inside the block. A small MLP on a few hundred rows
    runs ~20x slower on 2 threads than on 1 when the cores are busy (physics, other jobs)."""
    old = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(old)
