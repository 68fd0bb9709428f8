"""Replay the planner's solve and validation policy on recorded outcomes, without solving again.

A candidate's solve and verdict do not depend on the order in which the planner reaches them,
so on benchmark records in which every proposal was solved and every solved candidate validated
(`eval.planner_benchmark --candidates 24 --set schedule.validate_all=True --out RECORDS.jsonl`:
the 16 proposals and LEAP's 8 pinches after them), running the policy of `planner.schedule`
with other settings gives what planning with them would give.
Times per grasp are the recorded stage times of the solves and validations the policy uses.

    python -m eval.replay RECORDS.jsonl [--candidates 8] \
        [--set schedule.sweep_after=null schedule.gate_solves=8]

`--retry DEEPER.jsonl` (records of the same pairs made with a deeper squeeze,
`--set program.squeeze_depth=D program.retry_squeeze_depth=0`) replays a squeeze retry at that
depth: a candidate that slips in RECORDS holds if it holds in DEEPER, as `finish_grasp` decides.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

import numpy as np

from eval.planner_benchmark import (
    PairRecord,
    planner_settings,
    print_by_part,
    print_table,
    read_records,
    summarize,
)
from models.errors import DrograspError
from models.hands import load_hand
from planner.functional import CandidateResult, PlannerSettings, Proposal
from planner.grasp_program import SolveResult
from planner.intent import IntentCheck
from planner.schedule import run_schedule
from planner.settings import setting_keys

# settings that only decide which recorded solves and verdicts are used; the others change the
# proposals or the solves and need eval.planner_benchmark
REPLAYABLE = (
    "schedule.solve_batch",
    "schedule.min_quality",
    "schedule.gate_solves",
    "schedule.sweep_after",
    "schedule.ranking",
    "schedule.intent_first",
    "schedule.intent_search",
    "proposals.max_proposals",
    "proposals.pinch_proposals",
)


# recorded stage times (CandidateResult.times) that a solved / a validated candidate costs
SOLVE_STAGES = ("build", "propose", "solve", "quality", "intent")
VALIDATE_STAGES = ("pregrasp", "validate", "retry")


class RecordsError(DrograspError):
    """Records that cannot be replayed (not every solved candidate validated, or too few)."""


def load_records(path: Path) -> list[PairRecord]:
    """`eval.planner_benchmark --out` records, or a RecordsError saying why they cannot be read."""
    try:
        return read_records(path)
    except (OSError, json.JSONDecodeError, TypeError) as err:
        raise RecordsError(f"cannot read benchmark records from {path}: {err}") from err


def with_retry(records: list[PairRecord], deeper: list[PairRecord]) -> list[PairRecord]:
    """`records` as a squeeze retry at the depth of `deeper` would have made them: a candidate
    that slipped holds where it held in `deeper` (its voted part depends on the grasp, not on the
    squeeze), and the retry's validation time is added. The two must hold the same pairs and
    the same solves: only the squeeze may differ."""
    if len(records) != len(deeper):
        raise RecordsError(f"{len(records)} records but {len(deeper)} with the deeper squeeze")
    merged = []
    for rec, deep in zip(records, deeper, strict=True):
        key = (rec.hand, rec.category, rec.seed, rec.instruction)
        if key != (deep.hand, deep.category, deep.seed, deep.instruction):
            raise RecordsError(
                f"the deeper squeeze's records hold {deep.instruction!r} where "
                f"{rec.instruction!r} was expected: record the same pairs"
            )
        other = {c["rank"]: c for c in deep.candidate_summaries}
        summaries = []
        for c in rec.candidate_summaries:
            d = other.get(c["rank"])
            if d is None or (c["solved"], c["task_quality"]) != (d["solved"], d["task_quality"]):
                raise RecordsError(
                    f"{rec.hand} {rec.category} {rec.seed}: candidate {c['rank']} was solved "
                    "differently with the deeper squeeze; record both with the same settings "
                    "but the squeeze depth"
                )
            c = dict(c)
            if c["solved"] and not c["success"] and d["validated_as"] is not None:
                c["times"] = c["times"] | {"retry": d["times"].get("validate", 0.0)}
                c["success"] = bool(d["success"])
            summaries.append(c)
        merged.append(replace(rec, candidate_summaries=summaries))
    return merged


def _candidate(summary: dict) -> CandidateResult:
    """A recorded candidate with what the policy reads: solved, qualities, verdict, part."""
    empty = np.zeros(0)
    solve = SolveResult(
        empty,
        empty,
        bool(summary["solved"]),
        0.0,
        0.0,
        False,
        "recorded",
        summary["times"]["solve"],
    )
    proposal = Proposal(np.zeros(7), empty, np.zeros((4, 3)), np.zeros((4, 3)), 0.0)
    intent = summary.get("intent_ok")  # absent from records made before intent checks
    return CandidateResult(
        summary["rank"],
        proposal,
        solve,
        quality=summary["quality"],
        task_quality=summary["task_quality"],
        times=dict(summary["times"]),
        intent=None if intent is None else IntentCheck("recorded", bool(intent), (), "recorded"),
    )


def proposals_used(record: PairRecord, settings: PlannerSettings) -> list[dict]:
    """The recorded proposals that planning with `settings` solves, ranked as
    FunctionalPlanner.propose orders them: the regular ones, then the pinches."""
    recorded = sorted(record.candidate_summaries, key=lambda c: c["rank"])
    # the main ranking: regular proposals and (Hold) the power grasps between them
    rows = [c for c in recorded if c.get("kind", "row") != "pinch"]
    pinches = [c for c in recorded if c.get("kind") == "pinch"]
    most = settings.proposals.max_proposals
    if len(rows) < most:
        raise RecordsError(
            f"{record.hand} {record.category} {record.seed}: {len(rows)} proposals recorded, "
            f"proposals.max_proposals={most} asked; record every proposal with --candidates 24 "
            "--set schedule.validate_all=True (or replay fewer: --set proposals.max_proposals=N)"
        )
    wanted = settings.proposals.pinch_proposals
    if wanted is None:
        wanted = load_hand(record.hand).meta.pinch_proposals
    if len(pinches) < wanted:
        raise RecordsError(
            f"{record.hand} {record.category} {record.seed}: {len(pinches)} pinch proposals "
            f"recorded, {wanted} asked; record them with --set proposals.pinch_proposals={wanted} "
            "(or replay fewer: --set proposals.pinch_proposals=N; 0 for records made before "
            "pinches)"
        )
    kept = rows[:most] + pinches[:wanted]
    return [c | {"rank": i} for i, c in enumerate(kept)]


def replay_pair(record: PairRecord, settings: PlannerSettings) -> PairRecord:
    """The record as the planner with `settings` would have produced it."""
    recorded = proposals_used(record, settings)
    count = len(recorded)
    unvalidated = [c["rank"] for c in recorded if c["solved"] and c["validated_as"] is None]
    if unvalidated:
        raise RecordsError(
            f"{record.hand} {record.category} {record.seed}: solved candidates {unvalidated} were "
            "not validated; record with --candidates 24 --set schedule.validate_all=True (as many "
            "as proposals)"
        )
    verdicts = {c["rank"]: (bool(c["success"]), c["part"]) for c in recorded}

    def validate(cand: CandidateResult) -> None:
        cand.success, cand.part = verdicts[cand.rank]

    scheduled = run_schedule(
        count, lambda i: _candidate(recorded[i]), validate, record.part, settings
    )
    # what planning returns: a grasp held on the part (meeting the intent if one does), else
    # one held elsewhere
    returned = scheduled.on_part or scheduled.fallback
    first = next((c for c in scheduled.candidates if c.order == 0), None)
    used = scheduled.candidates
    plan_time = sum(
        c.times.get(stage, 0.0)
        for c in used
        for stage in SOLVE_STAGES + (VALIDATE_STAGES if c.order is not None else ())
    )
    return PairRecord(
        hand=record.hand,
        category=record.category,
        seed=record.seed,
        instruction=record.instruction,
        part=record.part,
        first_holds=bool(first and first.success),
        first_part_ok=bool(first and first.success and first.part == record.part),
        returned_holds=returned is not None,
        part_ok=scheduled.on_part is not None,
        intent_ok=None if scheduled.on_part is None else scheduled.found is not None,
        candidates=len(used),
        solve_times=[c.solve.solve_time for c in used],
        plan_time=plan_time,
        # the recorded summaries as this policy leaves them: validated or not, in what order
        candidate_summaries=[
            recorded[c.rank] | {"validated_as": c.order, "success": c.success, "part": c.part}
            for c in used
        ],
    )


def any_holds(records: list[PairRecord], settings: PlannerSettings) -> dict[str, float]:
    """Per hand, the share of pairs where any of the proposals `settings` solves holds on the
    part: the most any validation order can return."""
    out: dict[str, list[bool]] = {}
    for r in records:
        held = any(c["success"] and c["part"] == r.part for c in proposals_used(r, settings))
        out.setdefault(r.hand, []).append(held)
    return {hand: sum(v) / len(v) for hand, v in sorted(out.items())}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("records", type=Path, help="eval.planner_benchmark --out JSONL")
    parser.add_argument("--candidates", type=int, default=8, help="validations at most")
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help=f"policy settings: {', '.join(REPLAYABLE)}",
    )
    parser.add_argument(
        "--by-part", action="store_true", help="pairs held on the instructed part, per part"
    )
    parser.add_argument(
        "--retry",
        type=Path,
        metavar="DEEPER",
        help="records of the same pairs with a deeper squeeze: replay a squeeze retry",
    )
    args = parser.parse_args()
    for item in args.set:
        name = item.partition("=")[0].strip()
        if name in setting_keys() and name not in REPLAYABLE:  # unknown ones: planner_settings
            raise SystemExit(
                f"--set {name}: changes proposals or solves, which records cannot replay; "
                f"replayable: {', '.join(REPLAYABLE)}"
            )
    settings = planner_settings(args.candidates, args.set)
    try:
        records = load_records(args.records)
        if args.retry is not None:
            records = with_retry(records, load_records(args.retry))
        replayed = [replay_pair(r, settings) for r in records]
    except RecordsError as err:
        raise SystemExit(f"error: {err}") from None
    print(
        f"{len(records)} recorded pairs replayed, up to {args.candidates} validations"
        + (f", settings {' '.join(args.set)}" if args.set else "")
        + (f", slips retried as in {args.retry}" if args.retry else "")
    )
    print_table(summarize(replayed))
    try:
        bound = any_holds(records, settings)
    except RecordsError as err:
        raise SystemExit(f"error: {err}") from None
    print(
        "any of the proposals solved holds on the part: "
        + ", ".join(f"{hand} {share:.1%}" for hand, share in bound.items())
    )
    if args.by_part:
        print_by_part(replayed)


if __name__ == "__main__":
    main()
