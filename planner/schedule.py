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
    """Solve proposals 0..count-1 a batch at a time and validate each batch's solved candidates
    best first, until one holds on `part` or `settings.max_candidates` are validated.

    Candidates without force closure (epsilon below `min_quality`) rarely hold: they wait until
    `gate_solves` proposals are solved, then queue with the rest by task metric. After
    `sweep_after` validations without a grasp on the part, every remaining proposal is solved
    at once and the remaining validations go to the best of them. `validate` fills the
    candidate's `success` and `part`; `order` is set here."""
    s = settings
    candidates: list[CandidateResult] = []
    deferred: list[CandidateResult] = []
    found: CandidateResult | None = None
    fallback: CandidateResult | None = None
    position = 0

    def try_in_order(cands: list[CandidateResult]) -> bool:
        nonlocal position, found, fallback
        for cand in sorted(cands, key=lambda c: validation_key(c, s.ranking)):
            if position >= s.max_candidates:
                return False
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

    first = 0
    while first < count and position < s.max_candidates:
        size = s.solve_batch if s.sweep_after is None or position < s.sweep_after else count
        solved = [solve(i) for i in range(first, min(first + size, count))]
        first += len(solved)
        candidates.extend(solved)
        good = [c for c in solved if c.solve.ok and c.quality >= s.min_quality]
        deferred += [c for c in solved if c.solve.ok and c.quality < s.min_quality]
        if len(candidates) >= s.gate_solves:
            good, deferred = good + deferred, []
        if try_in_order(good):
            break
    if found is None and fallback is None:
        try_in_order(deferred)
    return Scheduled(candidates, found, fallback)
