"""Which proposals are solved, and which solved candidates are validated in what order.

This is the policy of `FunctionalPlanner.plan`, kept apart from how a solve or a validation is
done. A candidate's solve and verdict do not depend on when they happen, so on records in which
every proposal was solved and every solved candidate validated, running this policy with
recorded outcomes gives what planning with it would have given: `eval/replay.py` does that to
compare policies without solving again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # planner.functional imports this module
    from planner.functional import CandidateResult, PlannerSettings


@dataclass
class Scheduled:
    candidates: list[CandidateResult]  # every solved candidate, in solve (proposal) order
    found: CandidateResult | None  # the first validated one that held on the instructed part
    fallback: CandidateResult | None  # the first validated one that held on any part


def validation_key(cand: CandidateResult, ranking: str) -> tuple[float, int]:
    """Validation order: best quality first (task metric or epsilon), then proposal rank."""
    quality = cand.task_quality if ranking == "task" else cand.quality
    return (-quality, cand.rank)


def run_schedule(
    count: int,
    solve: Callable[[int], CandidateResult],
    validate: Callable[[CandidateResult], None],
    part: str,
    settings: PlannerSettings,
) -> Scheduled:
    """Solve proposals 0..count-1 a batch at a time and validate the solved candidates best
    first, until one holds on `part` or `settings.max_candidates` are validated.

    Candidates without force closure (epsilon below `min_quality`) rarely hold: they wait until
    `gate_solves` proposals are solved, then queue with the rest by task metric. Once
    `sweep_after` validations have failed to hold on the part, every remaining proposal is
    solved before the next validation (even in the middle of a batch's queue), and the remaining
    validations go to the best of all of them. `validate` fills the candidate's `success` and
    `part`; `order` is set here."""
    s = settings
    candidates: list[CandidateResult] = []
    queue: list[CandidateResult] = []  # solved, released by the gate, not yet validated
    deferred: list[CandidateResult] = []  # solved with weak closure, held back by the gate
    found: CandidateResult | None = None
    fallback: CandidateResult | None = None
    position = 0

    def sweeping() -> bool:
        return s.sweep_after is not None and position >= s.sweep_after

    def validate_queue() -> bool:
        """Validate the queue best first; True once a grasp holds on the part. Returns early,
        leaving the rest queued, when the sweep is due and proposals are left unsolved."""
        nonlocal position, found, fallback
        queue.sort(key=lambda c: validation_key(c, s.ranking))
        while queue and position < s.max_candidates:
            if sweeping() and len(candidates) < count:
                return False
            cand = queue.pop(0)
            cand.order = position
            position += 1
            validate(cand)
            if cand.success and cand.part == part and found is None:
                found = cand
                if not s.validate_all:
                    return True
            if cand.success and fallback is None:
                fallback = cand
        return False

    while len(candidates) < count and position < s.max_candidates:
        first = len(candidates)
        size = count if sweeping() else s.solve_batch
        solved = [solve(i) for i in range(first, min(first + size, count))]
        candidates.extend(solved)
        queue += [c for c in solved if c.solve.ok and c.quality >= s.min_quality]
        deferred += [c for c in solved if c.solve.ok and c.quality < s.min_quality]
        if len(candidates) >= s.gate_solves:
            queue, deferred = queue + deferred, []
        if validate_queue():
            break
    if found is None and fallback is None:
        queue += deferred
        validate_queue()
    return Scheduled(candidates, found, fallback)
