"""The schedule's later proposals (planner.schedule `more`): made only when the search gets there."""

from __future__ import annotations

import numpy as np

from planner.grasp_program import SolveResult
from planner.intent import IntentCheck
from planner.results import CandidateResult, Proposal
from planner.schedule import run_schedule
from planner.settings import PlannerSettings, ScheduleSettings


def _candidate(rank: int) -> CandidateResult:
    wrist, q = np.array([0, 0, 0, 1.0, 0, 0, 0]), np.zeros(16)
    proposal = Proposal(wrist, q, np.zeros((4, 3)), np.zeros((4, 3)), 0.0)
    solved = SolveResult(wrist, q, True, 0.001, 0.0, True, "fake", 0.0)
    return CandidateResult(rank, proposal, solved, quality=0.5, task_quality=1 - rank / 100)


def _run(holder: int, count: int, later: int, **schedule) -> tuple[list[list[int]], int]:
    """Solve batches asked for, and how often `more` was called; proposal `holder` holds (the
    schedule must find it; -1: none holds)."""
    batches, calls = [], []

    def solve(ranks: list[int]) -> list[CandidateResult]:
        batches.append(ranks)
        return [_candidate(r) for r in ranks]

    def validate(cand: CandidateResult) -> None:
        cand.success, cand.part = cand.rank == holder, "handle"

    def more() -> int:
        calls.append(1)
        return later

    settings = PlannerSettings(schedule=ScheduleSettings(**schedule))
    found = run_schedule(count, solve, validate, "handle", settings, more).found
    assert (found.rank if found is not None else -1) == holder
    return batches, len(calls)


def test_later_proposals_are_not_made_when_an_early_grasp_holds():
    batches, calls = _run(holder=1, count=8, later=4, solve_batch=4)
    assert batches == [[0, 1, 2, 3]] and calls == 0


def test_later_proposals_are_made_once_and_solved_after_the_first():
    # batch by batch: the later ones follow the first 8 in batches of their own
    batches, calls = _run(10, 8, 4, solve_batch=4, sweep_after=None, max_candidates=12)
    assert batches == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]] and calls == 1
    # the sweep (after 3 failed validations) solves them with the rest, as if made at once
    batches, calls = _run(10, 8, 4, solve_batch=4, sweep_after=3, max_candidates=12)
    assert batches == [[0, 1, 2, 3], list(range(4, 12))] and calls == 1


def test_where_none_are_made_the_search_ends_with_the_first():
    batches, calls = _run(-1, 8, 0, solve_batch=4, sweep_after=None, max_candidates=12)
    assert batches == [[0, 1, 2, 3], [4, 5, 6, 7]] and calls == 1


def _search(misses, count: int = 12, confirms=None, **schedule):
    """Proposal 0 holds without meeting the intent, proposals 9 and 11 hold and meet it; the
    solve batches asked for and what was scheduled."""
    batches: list[list[int]] = []

    def solve(ranks: list[int]) -> list[CandidateResult]:
        batches.append(ranks)
        cands = [_candidate(r) for r in ranks]
        for c in cands:
            c.intent = IntentCheck("Handover", c.rank in (9, 11), (), "")
        return cands

    def validate(cand: CandidateResult) -> None:
        cand.success, cand.part = cand.rank in (0, 9, 11), "handle"

    settings = PlannerSettings(schedule=ScheduleSettings(solve_batch=4, **schedule))
    scheduled = run_schedule(count, solve, validate, "handle", settings, None, misses, confirms)
    return batches, scheduled


def test_the_search_for_the_intent_passes_over_proposals_that_will_miss_it():
    def misses(rank: int) -> str | None:
        return "an anchor lies 2 mm from the blade" if rank in (4, 5, 6, 7, 8) else None

    batches, scheduled = _search(misses)
    # the first batch is solved whole (nothing has held yet, so any grasp may be the one
    # returned); after proposal 0 held off its intent, 4-8 are passed over unsolved
    assert batches[0] == [0, 1, 2, 3] and batches[1] == [9, 10, 11]
    assert scheduled.found.rank == 9 and scheduled.off_intent.rank == 0
    assert sorted(scheduled.passed) == [4, 5, 6, 7, 8]
    assert [c.rank for c in scheduled.candidates] == [0, 1, 2, 3, 9, 10, 11]


def test_without_a_reason_to_pass_over_every_proposal_is_solved():
    batches, scheduled = _search(None)
    assert batches == [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]] and not scheduled.passed
    assert scheduled.found.rank == 9


def test_passing_over_every_remaining_proposal_ends_the_search():
    batches, scheduled = _search(lambda rank: "the drawn wrist fails palm_down")
    assert batches == [[0, 1, 2, 3]] and scheduled.found is None
    assert scheduled.on_part.rank == 0 and sorted(scheduled.passed) == list(range(4, 12))


def test_a_grasp_meeting_the_intent_replaces_the_one_held_only_where_confirmed():
    # proposal 9 meets the intent but its part is in doubt (learned.switch_reach): passed over
    # as if it had missed, and the search goes on to 11
    batches, scheduled = _search(None, confirms=lambda cand: cand.rank != 9)
    assert scheduled.found.rank == 11 and scheduled.off_intent.rank == 0
    # doubted everywhere: the grasp held first, off its intent, is what planning returns
    batches, scheduled = _search(None, confirms=lambda cand: False)
    assert scheduled.found is None and scheduled.on_part.rank == 0


def test_a_grasp_meeting_the_intent_with_nothing_held_before_is_not_doubted():
    def solve(ranks: list[int]) -> list[CandidateResult]:
        cands = [_candidate(r) for r in ranks]
        for c in cands:
            c.intent = IntentCheck("Handover", c.rank == 1, (), "")
        return cands

    def validate(cand: CandidateResult) -> None:
        cand.success, cand.part = cand.rank == 1, "handle"

    asked: list[int] = []

    def confirms(cand: CandidateResult) -> bool:
        asked.append(cand.rank)
        return False

    settings = PlannerSettings(schedule=ScheduleSettings(solve_batch=4))
    scheduled = run_schedule(4, solve, validate, "handle", settings, None, None, confirms)
    # the first grasp to hold meets the intent: returned, its part never questioned
    assert scheduled.found.rank == 1 and asked == []
