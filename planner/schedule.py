"""Which proposals are solved, and which solved candidates are validated in what order.

This is the policy of `FunctionalPlanner.plan`, kept apart from how a solve or a validation is
done. A candidate's solve and verdict do not depend on when they happen, so on records in which
every proposal was solved and every solved candidate validated, running this policy with
recorded outcomes gives what planning with it would have given: `eval/replay.py` does that to
compare policies without solving again.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from planner.results import CandidateResult
from planner.settings import PlannerSettings


@dataclass
class Scheduled:
    candidates: list[CandidateResult]  # every solved candidate, in solve (proposal) order
    # the first validated one that held on the instructed part and meets the intent
    found: CandidateResult | None
    fallback: CandidateResult | None  # the first validated one that held on any part
    # the first validated one that held on the instructed part but missed the intent: returned
    # when no candidate meets the intent
    off_intent: CandidateResult | None = None
    # ranks passed over unsolved in the search for a grasp meeting the intent, with why
    passed: dict[int, str] = field(default_factory=dict)

    @property
    def on_part(self) -> CandidateResult | None:
        """What planning returns when a grasp held on the instructed part."""
        return self.found or self.off_intent


def meets_intent(cand: CandidateResult) -> bool:
    """Unknown (None: not checked, as in records made before intent checks) counts as met."""
    return cand.intent_ok is not False


def validation_key(
    cand: CandidateResult, ranking: str, prefer_intent: bool = True
) -> tuple[bool, float, int]:
    """Validation order: candidates meeting their intent first (where preferred), then best
    quality (task metric or epsilon), then proposal rank."""
    quality = cand.task_quality if ranking == "task" else cand.quality
    return (prefer_intent and not meets_intent(cand), -quality, cand.rank)


def run_schedule(
    count: int,
    solve: Callable[[list[int]], list[CandidateResult]],
    validate: Callable[[CandidateResult], None],
    part: str,
    settings: PlannerSettings,
    more: Callable[[], int] | None = None,
    misses: Callable[[int], str | None] | None = None,
    confirms: Callable[[CandidateResult], bool] | None = None,
) -> Scheduled:
    """Solve proposals 0..count-1 a batch at a time and validate the solved candidates best
    first, until one holds on `part` and meets its intent, or `max_candidates` are validated
    (the fields named here are those of `settings.schedule`). `solve` solves the proposals of
    the ranks it is given (a batch at a time, so that they may be solved in parallel).
    `more`: proposals after the first `count` that are made only if the search reaches them
    (the learned proposer's region proposals: most plans end before): called at most once,
    when the first `count` are solved or the sweep begins, it makes them and says how many.
    `misses`: why the proposal of a rank will not meet the intent as drawn, or None
    (planner.intent.proposal_misses); consulted only in the search after a hold that missed
    the intent, where such proposals are passed over unsolved (`Scheduled.passed`).
    `confirms`: whether a candidate meeting the intent, held after one that missed it, touches
    the part surely enough to be returned in its place (the learned pipeline's labels:
    `learned.switch_reach`); one it refuses is passed over as if it had missed the intent.

    Candidates whose solved configuration meets the intent (`intent_ok`, planner.intent) are
    validated before the others for the first `intent_first` validations; after them the
    queue goes by quality alone, so that a part whose intent-meeting candidates slip still gets
    a grasp. Once a grasp has held on the part without meeting the intent, only candidates
    meeting it are validated, and at most `intent_search` more proposals are solved (None:
    every proposal): it is returned unless one of them holds.

    Candidates without force closure (epsilon below `min_quality`) rarely hold: they wait until
    `gate_solves` proposals are solved, then queue with the rest by task metric. Once
    `sweep_after` validations have failed to hold on the part, every remaining proposal is
    solved before the next validation (even in the middle of a batch's queue), and the remaining
    validations go to the best of all of them. `validate` fills the candidate's `success` and
    `part`; `order` is set here."""
    s = settings.schedule
    candidates: list[CandidateResult] = []
    queue: list[CandidateResult] = []  # solved, released by the gate, not yet validated
    deferred: list[CandidateResult] = []  # solved with weak closure, held back by the gate
    found: CandidateResult | None = None
    fallback: CandidateResult | None = None
    off_intent: CandidateResult | None = None
    passed: dict[int, str] = {}
    position = 0
    following = 0  # the next proposal to solve or pass over

    def sweeping() -> bool:
        return s.sweep_after is not None and position >= s.sweep_after

    def validate_queue() -> bool:
        """Validate the queue best first; True once a grasp holds on the part. Returns early,
        leaving the rest queued, when the sweep is due and proposals are left unsolved."""
        nonlocal position, found, fallback, off_intent, solved_at_off
        while queue and position < s.max_candidates:
            if sweeping() and remaining() > 0:
                return False
            prefer = off_intent is not None or position < s.intent_first
            queue.sort(key=lambda c: validation_key(c, s.ranking, prefer))
            if off_intent is not None and not s.validate_all and not meets_intent(queue[0]):
                return False  # the queue holds no candidate that could do better
            cand = queue.pop(0)
            cand.order = position
            position += 1
            validate(cand)
            if cand.success and cand.part == part:
                if meets_intent(cand) and found is None and not doubted(cand):
                    found = cand
                    if not s.validate_all:
                        return True
                elif not meets_intent(cand) and off_intent is None:
                    off_intent = cand
                    solved_at_off = len(candidates)
            if cand.success and fallback is None:
                fallback = cand
        return False

    def doubted(cand: CandidateResult) -> bool:
        """A candidate meeting the intent after a hold that missed it, that `confirms` refuses."""
        return off_intent is not None and confirms is not None and not confirms(cand)

    def searching() -> int:
        """Proposals still to solve: after a hold that missed the intent, `intent_search`
        more at most (the search for one meeting it is paid in solves)."""
        left = count - following
        if off_intent is None or s.validate_all or s.intent_search is None:
            return left
        return min(left, solved_at_off + s.intent_search - len(candidates))

    def remaining() -> int:
        """`searching()`, with the later proposals made (`more`) once they are due."""
        nonlocal count, more
        if more is not None and (sweeping() or following >= count):
            count, more = count + more(), None
        return searching()

    def next_ranks(size: int) -> list[int]:
        """Up to `size` proposals to solve next, passing over (in the search for the intent)
        those `misses` says will miss it."""
        nonlocal following
        ranks: list[int] = []
        while len(ranks) < size and following < count:
            rank, following = following, following + 1
            why = None
            if off_intent is not None and not s.validate_all and misses is not None:
                why = misses(rank)
            if why is None:
                ranks.append(rank)
            else:
                passed[rank] = why
        return ranks

    solved_at_off = 0
    while position < s.max_candidates and remaining() > 0:
        size = min(count if sweeping() else s.solve_batch, searching())
        ranks = next_ranks(size)
        if not ranks:
            continue
        solved = solve(ranks)
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
    elif found is None and off_intent is not None:
        validate_queue()  # the intent-meeting candidates of the last solves
    return Scheduled(candidates, found, fallback, off_intent, passed)
