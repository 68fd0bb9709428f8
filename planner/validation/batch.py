"""Validate many grasps in parallel: a process pool whose workers each keep compiled scenes.

Jobs are ordered by object so that a worker reuses the scene it compiled for the previous
grasp; the hand and the objects travel to each worker once (pool initializer), grasps per job.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import pickle
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import Any

import numpy as np

from models.errors import ObjectError
from models.grasp import Grasp
from planner.validation.hands import HandAdapter, as_hand
from planner.validation.objects import CollisionObject, as_collision_object
from planner.validation.protocol import Protocol, get_protocol
from planner.validation.validator import ValidationResult, validate

_WORKER: dict[str, Any] = {}


def _init_worker(
    hand: HandAdapter,
    objects: dict[str, CollisionObject],
    protocol: Protocol,
    parent: int | None = None,
) -> None:
    if parent is not None:  # a pool worker: it ends when the process that started it is killed
        from planner.lifeline import die_with

        die_with(parent)
    _WORKER.update(hand=hand, objects=objects, protocol=protocol)


def _run_job(
    index: int, grasp: Grasp, key: str, pose: np.ndarray | None
) -> tuple[int, ValidationResult]:
    w = _WORKER
    return index, validate(grasp, w["objects"][key], w["hand"], w["protocol"], object_pose=pose)


def _picklable(value: Any) -> bool:
    try:
        pickle.dumps(value)
    except Exception:  # noqa: BLE001 - any pickling failure means "run serially"
        return False
    return True


def validate_many(
    grasps: Sequence[Grasp],
    objects: Any,
    hand: Any,
    protocol: str | Protocol = "dexgraspbench",
    *,
    object_poses: Sequence[Any] | None = None,
    workers: int | None = None,
    all_directions: bool | None = None,
    progress: bool | Callable[[int], None] = False,
) -> list[ValidationResult]:
    """Validate each grasp; `objects` is one object for all or one per grasp (any form
    `as_collision_object` accepts). Results come back in the grasps' order.

    `workers` defaults to the CPU count; `progress=True` shows a tqdm bar, a callable is called
    with the number of grasps finished so far.
    """
    n = len(grasps)
    proto = get_protocol(protocol)
    if all_directions is not None:
        proto = proto.replace(all_directions=all_directions)
    adapter = as_hand(hand)
    per_grasp = isinstance(objects, Sequence) and not isinstance(objects, str | bytes)
    per_grasp = per_grasp and len(objects) == n and not _is_piece_list(objects)
    table: dict[str, CollisionObject] = {}
    keys: list[str] = []
    for i in range(n):
        if per_grasp or i == 0:
            body = as_collision_object(objects[i] if per_grasp else objects)
            table.setdefault(body.key, body)
        keys.append(body.key)
    if object_poses is not None and len(object_poses) != n:
        raise ObjectError(f"{len(object_poses)} object poses for {n} grasps")
    poses = [None if object_poses is None else np.asarray(object_poses[i]) for i in range(n)]
    order = sorted(range(n), key=lambda i: keys[i])

    bar = None
    if progress is True:
        from tqdm import tqdm

        bar = tqdm(total=n, unit="grasp", desc="validate")
    results: list[ValidationResult | None] = [None] * n
    done = 0

    def finished() -> None:
        nonlocal done
        done += 1
        if bar is not None:
            bar.update(1)
        elif callable(progress):
            progress(done)

    workers = (os.cpu_count() or 1) if workers is None else workers
    try:
        if workers <= 1 or n <= 1 or not _picklable(adapter):
            _init_worker(adapter, table, proto)
            for i in order:
                results[i] = _run_job(i, grasps[i], keys[i], poses[i])[1]
                finished()
        else:
            ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
            with ProcessPoolExecutor(
                max_workers=min(workers, n),
                mp_context=ctx,
                initializer=_init_worker,
                initargs=(adapter, table, proto, os.getpid()),
            ) as pool:
                futures = [pool.submit(_run_job, i, grasps[i], keys[i], poses[i]) for i in order]
                for future in as_completed(futures):
                    i, result = future.result()
                    results[i] = result
                    finished()
    finally:
        if bar is not None:
            bar.close()
    return [r for r in results if r is not None]


def _is_piece_list(objects: Sequence[Any]) -> bool:
    """True when `objects` is itself one object's pieces (arrays), not one object per grasp."""
    first = objects[0] if len(objects) else None
    return isinstance(first, np.ndarray) or (
        isinstance(first, tuple) and len(first) == 2 and isinstance(first[0], np.ndarray)
    )
