"""Where jobs run: in this process, on a local process pool, or on Ray (local or a cluster).

Each backend takes (index, job) pairs and yields (index, record) as jobs finish, in any order;
the runner restores job order. `run_one` wraps the job function so that an exception becomes
an error record instead of stopping the batch, and pins one math thread per worker (two
workers on two cores must not fight over threads, and results must not depend on them).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
import traceback
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from planner.batch.jobs import Job

JobFn = Callable[[Job], dict[str, Any]]
Indexed = tuple[int, Job]
MAX_RAY_ATTEMPTS = 2  # Ray retries a task whose worker died once


def _worker_init(parent: int) -> None:
    """A pool worker: one math thread, and it ends when the batch's process is killed."""
    from planner.lifeline import die_with

    die_with(parent)
    one_thread()


def one_thread() -> None:
    """One torch/OpenMP thread in this process, and its plans' solves in this process only
    (planner.parallel): a pool worker on a machine whose cores the workers share. With
    torch's default (a thread per core), two workers on this 2-core machine each ran a D(R,O)
    forward in 0.195 s against 0.083 s with one thread each (median of 30, both workers at
    once); eval.benchmark's runs without this pin recorded D(R,O) at 0.23-0.27 s a sample
    against 0.10 s with it."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    import torch

    from planner.parallel import mark_pool_worker

    mark_pool_worker()

    if torch.get_num_threads() != 1:
        torch.set_num_threads(1)


def error_record(job: Job, kind: str, message: str, where: str = "") -> dict[str, Any]:
    return {
        "id": job.id,
        "job": job.to_dict(),
        "success": False,
        "valid": False,
        "error": {"type": kind, "message": message, "where": where},
        "times": {},
    }


def run_one(job_fn: JobFn, job: Job) -> dict[str, Any]:
    """The record of one job: the job function's fields, or its error (type and message)."""
    one_thread()
    start = time.perf_counter()
    try:
        out = dict(job_fn(job))
    except Exception as err:  # noqa: BLE001 - a job's failure is data, never the batch's end
        frame = traceback.extract_tb(err.__traceback__)[-1] if err.__traceback__ else None
        where = f"{os.path.basename(frame.filename)}:{frame.name}" if frame else ""
        record = error_record(job, type(err).__name__, str(err), where)
    else:
        times = out.pop("times", {}) or {}
        record = {"id": job.id, "job": job.to_dict(), **out, "error": None, "times": times}
    record["times"]["job"] = time.perf_counter() - start
    return record


def run_serial(job_fn: JobFn, items: Sequence[Indexed]) -> Iterator[tuple[int, dict]]:
    """In this process, in order: for one worker and for debugging (tracebacks stay local)."""
    for index, job in items:
        yield index, run_one(job_fn, job)


def _pool(workers: int, job_fn: JobFn) -> ProcessPoolExecutor:
    # forkserver: workers fork from a clean server process that has imported the job function's
    # module once, never from a parent whose torch/OpenMP threads run (fork-unsafe).
    ctx = mp.get_context("forkserver")
    ctx.set_forkserver_preload([job_fn.__module__])
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=ctx,
        initializer=_worker_init,
        initargs=(os.getpid(),),
    )


def _submit(
    pool: ProcessPoolExecutor,
    job_fn: JobFn,
    inflight: dict[Future, tuple[Indexed, bool]],
    item: Indexed,
    alone: bool,
    origin: list[Indexed],
) -> bool:
    """Submit one job; False if the pool broke before this submission (a worker died since the
    last wait), and the job goes back to `origin` untried."""
    try:
        inflight[pool.submit(run_one, job_fn, item[1])] = (item, alone)
    except BrokenProcessPool:
        origin.append(item)
        return False
    return True


def run_pool(job_fn: JobFn, items: Sequence[Indexed], workers: int) -> Iterator[tuple[int, dict]]:
    """A local process pool with at most 2 jobs queued per worker (memory stays flat on big
    batches). A worker that dies (segfault, OOM) breaks the pool: the pool is rebuilt and the
    jobs that were in flight are retried one at a time, so the one that kills its worker alone
    is recorded as crashed and the others complete."""
    queue = list(reversed(items))
    suspects: list[Indexed] = []
    while queue or suspects:
        pool = _pool(workers, job_fn)
        inflight: dict[Future, tuple[Indexed, bool]] = {}  # future -> (job, run alone)
        broken = False
        try:
            while not broken:
                alone_running = any(alone for _, alone in inflight.values())
                if suspects and not inflight:
                    broken = not _submit(pool, job_fn, inflight, suspects.pop(), True, suspects)
                elif not suspects and not alone_running:
                    while not broken and queue and len(inflight) < 2 * workers:
                        broken = not _submit(pool, job_fn, inflight, queue.pop(), False, queue)
                if broken or not inflight:
                    break
                done, _ = wait(inflight, return_when=FIRST_COMPLETED)
                for future in done:
                    item, alone = inflight.pop(future)
                    try:
                        yield item[0], future.result()
                    except BrokenProcessPool:
                        broken = True
                        if alone:
                            msg = "the worker process died running this job (alone)"
                            yield item[0], error_record(item[1], "WorkerCrashed", msg)
                        else:
                            suspects.append(item)
                    except Exception as err:  # noqa: BLE001 - e.g. an unpicklable result
                        yield item[0], error_record(item[1], type(err).__name__, str(err))
            for item, _ in inflight.values():  # the broken pool fails them all
                suspects.append(item)
        finally:
            pool.shutdown(wait=not broken, cancel_futures=True)


def run_ray(
    job_fn: JobFn, items: Sequence[Indexed], workers: int, address: str | None
) -> Iterator[tuple[int, dict]]:
    """Ray tasks of one CPU each: `address=None` starts a local instance with `workers` CPUs;
    otherwise joins that cluster (every node needs drograsp installed) and uses its CPUs."""
    import ray

    started = False
    if not ray.is_initialized():
        if address is None:
            path = os.pathsep.join(p for p in (os.getcwd(), os.environ.get("PYTHONPATH")) if p)
            ray.init(
                num_cpus=workers,
                include_dashboard=False,
                log_to_driver=False,
                runtime_env={"env_vars": {"PYTHONPATH": path, "OMP_NUM_THREADS": "1"}},
            )
        else:
            ray.init(address=address, log_to_driver=False)
        started = True
    try:
        capacity = int(ray.cluster_resources().get("CPU", workers)) if address else workers
        remote = ray.remote(num_cpus=1, max_retries=MAX_RAY_ATTEMPTS - 1)(run_one)
        fn_ref = ray.put(job_fn)
        queue = list(reversed(items))
        inflight: dict[Any, Indexed] = {}
        while queue or inflight:
            while queue and len(inflight) < 2 * capacity:
                item = queue.pop()
                inflight[remote.remote(fn_ref, item[1])] = item
            ready, _ = ray.wait(list(inflight), num_returns=1)
            for ref in ready:
                item = inflight.pop(ref)
                try:
                    yield item[0], ray.get(ref)
                except ray.exceptions.RayError as err:  # worker died, task lost
                    yield item[0], error_record(item[1], type(err).__name__, str(err)[:2000])
    finally:
        if started:
            ray.shutdown()
