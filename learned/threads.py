"""One torch thread for the learned stages' inference, whatever the process is set to.

Torch splits a forward pass's sums over its threads, so the same input on one thread and on two
gives outputs that differ in the last bits (a sentence embedding by 1e-7), and a plan is chaotic
in the last bits of its inputs (models/reproducible.py): `drograsp plan` in a process with
torch's default (a thread per core) returned other grasps than eval.benchmark's one-thread
workers for the same pair. Inference therefore runs on one thread, the count every figure is
measured with, and the plans are the same on machines with any number of cores. The models are
small enough that one thread costs little (docs/learned_log.md, "Plans that depended on the
thread count"); training keeps its own `threads` setting.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import ParamSpec, TypeVar

P = ParamSpec("P")
R = TypeVar("R")


def one_thread(fn: Callable[P, R]) -> Callable[P, R]:
    """`fn` run with torch at one thread, the process's own count restored after."""

    @functools.wraps(fn)
    def pinned(*args: P.args, **kwargs: P.kwargs) -> R:
        import torch

        before = torch.get_num_threads()
        if before == 1:
            return fn(*args, **kwargs)
        torch.set_num_threads(1)
        try:
            return fn(*args, **kwargs)
        finally:
            torch.set_num_threads(before)

    return pinned
