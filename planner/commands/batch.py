"""`drograsp batch JOBS_FILE OUT_DIR`: solve a jobs file on a local pool or Ray, resumably."""

from __future__ import annotations

import argparse
import importlib
import json
from typing import Any

from models.errors import DrograspError
from models.paths import output_folder
from planner.commands.args import positive_int
from planner.commands.jobs import add_backend_arguments

SHARD_SIZE = 16  # planner.batch.runner.SHARD_SIZE (checked in tests)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "batch",
        help="solve a jobs file offline (local process pool or Ray), resumably",
        description="Run every job of JOBS_FILE (make one with `drograsp jobs make`) and write "
        "result shards to OUT_DIR. Re-running the same command skips finished shards; a job "
        "that raises is recorded with its error; results do not depend on the worker count. "
        "Exit code 0: some job's grasp holds; 1: none does; 2: bad input.",
    )
    p.add_argument("jobs", metavar="JOBS_FILE")
    p.add_argument("out", metavar="OUT_DIR")
    add_backend_arguments(p)
    p.add_argument(
        "--shard-size",
        type=positive_int,
        default=SHARD_SIZE,
        help=f"jobs per result shard (default {SHARD_SIZE}); fixed for an OUT_DIR",
    )
    p.add_argument(
        "--job-fn",
        metavar="MODULE:FUNCTION",
        help="solve jobs with this function (Job -> dict) instead of the planner",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def load_job_fn(spec: str) -> Any:
    module, sep, name = spec.partition(":")
    if not sep or not module or not name:
        raise DrograspError(f"--job-fn {spec!r}: give MODULE:FUNCTION, e.g. mypkg.jobs:solve")
    try:
        fn = getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError, ValueError) as err:
        raise DrograspError(f"cannot load job function {spec!r} (MODULE:FUNCTION): {err}") from None
    if not callable(fn):
        raise DrograspError(f"{spec} is not callable")
    return fn


def run(args: argparse.Namespace) -> int:
    from planner.batch import read_jobs, run_batch

    jobs = read_jobs(args.jobs)
    output_folder(args.out, "batch output folder")
    job_fn = load_job_fn(args.job_fn) if args.job_fn else None
    summary = run_batch(
        jobs,
        args.out,
        workers=args.workers,
        ray=args.ray,
        ray_address=args.ray_address,
        shard_size=args.shard_size,
        job_fn=job_fn,
        progress=not args.no_progress,
    )
    if args.json:
        print(json.dumps(summary.to_dict(), indent=2))
    else:
        s = summary
        print(
            f"{s.jobs} jobs ({s.skipped} done before, {s.ran} run now on {s.backend} x{s.workers} "
            f"in {s.wall_time:.1f} s): {s.success} hold, {s.valid} valid (hold and touch the "
            f"instructed part), {s.errors} errors; {s.valid_per_hour:.0f} valid grasps/hour"
        )
    return 0 if summary.success or not summary.jobs else 1
