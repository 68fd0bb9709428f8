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


def fake_grasp_solve(job: Job) -> dict[str, Any]:
    """A record shaped like the planner's: a valid grasp unless the variant is 2 (slips); variant
    3 repeats variant 0's grasp exactly (a duplicate to drop)."""
    import numpy as np

    from models.hands import load_hand

    hand = load_hand(job.hand)
    digest = int(hashlib.sha256(job.id.replace("/v3", "/v0").encode()).hexdigest(), 16)
    rng = np.random.default_rng(digest % 2**32)
    q = rng.uniform(hand.lower, hand.upper)
    part = job.instruction.rsplit(" ", 1)[-1]
    quat = rng.normal(size=4)
    grasp = {
        "hand": hand.name,
        "wrist_pos": rng.normal(scale=0.1, size=3).tolist(),
        "wrist_quat": (quat / np.linalg.norm(quat)).tolist(),
        "grasp": q.tolist(),
        "pregrasp": (0.9 * q).tolist(),
        "squeeze": (1.1 * q).tolist(),
        "anchors": rng.normal(scale=0.05, size=(4, 3)).tolist(),
        "instruction": job.instruction,
        "metrics": {},
    }
    holds = job.variant != 2
    validation = {"success": holds, "translation": 0.001, "rotation_deg": 0.5}
    validation |= {"grasp_penetration": 0.0, "contact_count": 5}
    return {
        "success": holds,
        "valid": holds,
        "part_voted": part,
        "part_instructed": part,
        "anchor_error": 0.002,
        "min_distance": 0.0004,
        "validation": validation,
        "grasp": grasp,
    }
