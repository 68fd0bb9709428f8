"""Cheap job functions for testing the batch machinery (importable by worker processes)."""

from __future__ import annotations

import hashlib
import os
import time
from typing import Any

from planner.batch import Job


def fake_solve(job: Job) -> dict[str, Any]:
    """A deterministic record derived from the job; sleeps BATCH_FAKE_SLEEP seconds; raises for
    instructions containing "raise" and kills its worker for ones containing "crash"."""
    time.sleep(float(os.environ.get("BATCH_FAKE_SLEEP", "0")))
    if "raise" in job.instruction:
        raise ValueError(f"cannot solve {job.instruction!r}")
    if "crash" in job.instruction:
        os._exit(3)
    digest = int(hashlib.sha256(job.id.encode()).hexdigest(), 16)
    return {
        "success": digest % 3 != 0,
        "valid": digest % 3 == 1,
        "part_voted": "handle",
        "part_instructed": "handle",
        "value": digest % 1000 / 7.0,
        "times": {"solve": time.perf_counter() % 1},  # measured: excluded from comparisons
    }


def fake_jobs(n: int, special: dict[int, str] | None = None) -> list[Job]:
    """n jobs on mug seeds; job i gets instruction `special[i]` where given."""
    special = special or {}
    return [
        Job(
            {"category": "mug", "seed": i // 4},
            special.get(i, "Use a mug by handle"),
            "allegro",
            i % 4,
        )
        for i in range(n)
    ]
