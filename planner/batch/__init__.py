"""Offline batch solving: jobs files, a resumable sharded runner (local pool or Ray), variant
planning, cross-hand transfer. See `drograsp jobs`, `drograsp batch` and `drograsp dataset`."""

from planner.batch.jobs import Job, JobError, make_jobs, read_jobs, write_jobs
from planner.batch.runner import BatchSummary, read_results, run_batch
from planner.batch.transfer import hand_size, transfer_grasp
from planner.batch.variants import VariantPlanner

__all__ = [
    "BatchSummary",
    "Job",
    "JobError",
    "VariantPlanner",
    "hand_size",
    "make_jobs",
    "read_jobs",
    "read_results",
    "run_batch",
    "transfer_grasp",
    "write_jobs",
]
