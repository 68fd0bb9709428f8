"""Resumable evaluation runs: tasks planned in a process pool, each record appended to a JSONL
file as it finishes, so a stopped run (a session's end, a crash) loses no finished plan and
the same command continues it. Shared by eval.benchmark and eval.real_objects.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict
from pathlib import Path
from typing import Any, TypeVar

import torch
from tqdm import tqdm

from planner.batch.executors import one_thread

R = TypeVar("R")


def read_records(path: Path, record: Callable[..., R]) -> list[R]:
    """The records of a JSONL file (none where it does not exist), each built by `record`
    from its fields."""
    if not path.is_file():
        return []
    return [record(**json.loads(line)) for line in path.read_text().splitlines() if line.strip()]


def run_resumable(
    tasks: Sequence[Any],
    run_task: Callable[[Any], R],
    records_path: Path,
    record: Callable[..., R],
    workers: int = 1,
    desc: str = "tasks",
) -> list[R]:
    """Every task's record, in the order of `tasks`: those already in `records_path` (matched
    by `.key`, which tasks and records share) read back, the others planned (in `workers`
    processes of one torch thread each, or here with one thread: the same results either way)
    and appended as they finish. Records of tasks not asked for stay in the file, unused."""
    records_path.parent.mkdir(parents=True, exist_ok=True)
    done = {r.key: r for r in read_records(records_path, record)}
    todo = [t for t in tasks if t.key not in done]
    print(f"{len(tasks)} tasks, {len(tasks) - len(todo)} done before", flush=True)
    with records_path.open("a") as sink:

        def keep(rec: R) -> None:
            done[rec.key] = rec
            sink.write(json.dumps(asdict(rec)) + "\n")
            sink.flush()

        if workers > 1:
            with ProcessPoolExecutor(workers, initializer=one_thread) as pool:
                for rec in tqdm(pool.map(run_task, todo), total=len(todo), desc=desc):
                    keep(rec)
        else:
            torch.set_num_threads(1)
            for task in tqdm(todo, desc=desc):
                keep(run_task(task))
    return [done[t.key] for t in tasks if t.key in done]
