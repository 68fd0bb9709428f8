"""Solves of one plan shared over this machine's cores by forking.

A plan solves its proposals a batch at a time (planner.schedule), and a solve is a pure function
of the built program and the proposal, so a batch can be split over processes without changing
any result. Forking (not a pool) is what makes that cheap: the child inherits the built Drake
programs, the object and the proposals, so nothing is rebuilt or loaded, and only the solved
configurations travel back through a pipe. The child runs Drake and SNOPT only (D(R,O)'s torch
forward and the contact scoring stay in this process), and ends with `os._exit`.

Inside a pool worker (`planner.batch.executors.one_thread`) the cores are already shared
between workers, so `processes()` is 1 there. Where a child fails, is killed or does not answer
within `CHILD_TIMEOUT`, this process solves its share itself: a plan never loses a solve to
the parallelism.
"""

from __future__ import annotations

import os
import pickle
import select
import time
import warnings
from collections.abc import Callable, Sequence
from typing import TypeVar

T = TypeVar("T")
R = TypeVar("R")

# s: a child's share of one batch (a few solves of 0.1-0.5 s each) is far below this; a child
# stuck past it (say a lock held at fork by another thread) is killed and its share solved here
CHILD_TIMEOUT = 120.0

_IN_POOL = False


def mark_pool_worker() -> None:
    """This process is one of several workers sharing the cores: plans solve serially here."""
    global _IN_POOL
    _IN_POOL = True


def available_cores() -> int:
    """Cores this process may run on (its affinity where the OS says, else the CPU count)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def processes(setting: int | None) -> int:
    """Processes a plan solves with: `setting` (ScheduleSettings.solve_processes) or, where it
    is None, one per available core, one in a pool worker or where fork is unavailable."""
    if not hasattr(os, "fork"):
        return 1
    if setting is not None:
        return max(1, setting)
    return 1 if _IN_POOL else available_cores()


def forked_map(fn: Callable[[T], R], items: Sequence[T], count: int) -> list[R]:
    """[fn(x) for x in items], the items dealt round-robin over `count` processes (this one and
    count - 1 forked children). `fn` must not depend on what the other items did: the children
    see this process as it was at the fork."""
    items = list(items)
    count = min(count, len(items))
    if count <= 1:
        return [fn(x) for x in items]
    children = []  # (pid, read end, indices); pid None: the fork failed, solved here
    for k in range(1, count):
        share = list(range(k, len(items), count))
        read, write = os.pipe()
        try:
            pid = os.fork()
        except OSError:  # no memory or processes left for a child: this process solves it
            os.close(read)
            os.close(write)
            children.append((None, None, share))
            continue
        if pid == 0:  # the child: solve its share, send it back, leave without cleanup
            os.close(read)
            _child(fn, [items[i] for i in share], write)
        os.close(write)
        children.append((pid, read, share))
    outcomes = {i: _attempt(fn, items[i]) for i in range(0, len(items), count)}
    for pid, read, share in children:  # every child collected before anything is raised
        answer = None if pid is None else _collect(pid, read)
        if answer is None:  # the child failed (or was never made): its share is solved here
            answer = [_attempt(fn, items[i]) for i in share]
        outcomes.update(zip(share, answer, strict=True))
    results = []
    for i in range(len(items)):  # the first item's error, as solving one by one would raise
        kind, value = outcomes[i]
        if kind == "error":
            raise value
        results.append(value)
    return results


def _attempt(fn: Callable, x) -> tuple[str, object]:
    """("ok", fn(x)), or ("error", the exception it raised)."""
    try:
        return "ok", fn(x)
    except Exception as error:  # raised later, in item order
        return "error", error


def _child(fn: Callable, items: list, write: int) -> None:
    """Run in the forked child: every item's outcome (`_attempt`) pickled to `write`."""
    code = 0
    try:
        answer = [_attempt(fn, x) for x in items]
        data = pickle.dumps(answer, protocol=pickle.HIGHEST_PROTOCOL)
        with os.fdopen(write, "wb") as pipe:
            pipe.write(data)
    except BaseException:  # nothing readable reaches the parent, which solves the share itself
        code = 1
    finally:
        os._exit(code)


def _collect(pid: int, read: int) -> list | None:
    """A child's pickled answer, or None if it died, sent nothing readable or timed out."""
    chunks, deadline = [], time.monotonic() + CHILD_TIMEOUT
    try:
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([read], [], [], left)[0]:
                os.kill(pid, 9)
                warnings.warn(
                    f"a solve process was silent for {CHILD_TIMEOUT:g} s and was stopped; "
                    "this process solved its share (the plan is complete, only slower). "
                    "Set schedule.solve_processes=1 to solve in one process.",
                    RuntimeWarning,
                    stacklevel=2,
                )
                return None
            chunk = os.read(read, 1 << 20)
            if not chunk:
                break
            chunks.append(chunk)
    finally:
        os.close(read)
        os.waitpid(pid, 0)
    try:
        return pickle.loads(b"".join(chunks))
    except Exception:
        return None
