"""Offline batch solving: jobs files, a resumable sharded runner (local pool or Ray), variant
planning (`planner.batch.variants`), cross-hand transfer (`planner.batch.transfer`).

Kept light to import: the planner is loaded by the job function, not by the machinery.
"""

from planner.batch.jobs import Job, JobError, make_jobs, read_jobs, write_jobs
from planner.batch.runner import BatchSummary, read_results, run_batch

__all__ = [
    "BatchSummary",
    "Job",
    "JobError",
    "make_jobs",
    "read_jobs",
    "read_results",
    "run_batch",
    "write_jobs",
]
