"""Validated grasps per hour of batch solving: 1 and 2 local workers and Ray with 2 workers.

The same real planner jobs run three times into fresh folders (wall time includes starting
the workers; Ray's own start-up is timed apart and reported both ways). Prints the rates, Ray's
overhead as a ratio to the 2-worker pool, and whether all three gave identical records.

    /work/venv/bin/python benchmarks/bench_batch.py [--jobs 40] [--candidates 4]
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from planner.batch import Job, make_jobs, read_results, run_batch


def bench_jobs(n: int, candidates: int) -> list[Job]:
    """n jobs spread evenly over categories, hands and instructions (one variant each)."""
    per_category = 1
    while True:  # enough train objects that n jobs can be spread over them
        every = make_jobs(
            splits=["train"],
            category_names=["mug", "bottle", "knife", "hammer", "bowl", "pan"],
            objects_per_category=per_category,
            variants=1,
            max_candidates=candidates,
        )
        if len(every) >= n or per_category > 50:
            break
        per_category += 1
    step = max(len(every) // n, 1)
    return every[::step][:n]


def comparable(out: Path) -> list[dict]:
    return [{k: v for k, v in r.items() if k != "times"} for r in read_results(out)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=40)
    parser.add_argument("--candidates", type=int, default=4, help="proposals per job")
    args = parser.parse_args()
    jobs = bench_jobs(args.jobs, args.candidates)
    print(f"{len(jobs)} jobs, up to {args.candidates} candidates each, {os.cpu_count()} CPUs")
    runs = {}
    with tempfile.TemporaryDirectory() as tmp:
        for label, kwargs in (
            ("pool x1", {"workers": 1}),
            ("pool x2", {"workers": 2}),
            ("ray x2", {"workers": 2, "ray": True}),
        ):
            ray_start = 0.0
            start = time.perf_counter()
            if kwargs.get("ray"):
                import ray

                ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False,
                         runtime_env={"env_vars": {"OMP_NUM_THREADS": "1"}})  # fmt: skip
                ray_start = time.perf_counter() - start
            summary = run_batch(jobs, Path(tmp) / label, progress=False, **kwargs)
            wall = time.perf_counter() - start
            if kwargs.get("ray"):
                ray.shutdown()
            runs[label] = (summary.ran_valid, wall, ray_start, comparable(Path(tmp) / label))
            rate = 3600 * summary.ran_valid / wall
            print(
                f"{label}: {summary.ran_valid}/{len(jobs)} valid, {summary.errors} errors, "
                f"{wall:.1f} s -> {rate:.0f} validated grasps/hour, "
                f"{3600 * len(jobs) / wall:.0f} jobs/hour"
                + (f" (Ray start-up {ray_start:.1f} s)" if ray_start else "")
            )
    _, pool_wall, _, pool_records = runs["pool x2"]
    _, ray_wall, ray_start, ray_records = runs["ray x2"]
    print(f"speed-up of 2 local workers over 1: {runs['pool x1'][1] / pool_wall:.2f}x")
    print(f"Ray overhead vs 2 local workers: {ray_wall / pool_wall:.3f}x wall time")
    print(f"  excluding Ray start-up: {(ray_wall - ray_start) / pool_wall:.3f}x")
    same = runs["pool x1"][3] == pool_records == ray_records
    print(f"identical records across the three runs: {'yes' if same else 'NO'}")


if __name__ == "__main__":
    main()
