"""Replay the planner's solve and validation policy on recorded outcomes, without solving again.

A candidate's solve and verdict do not depend on the order in which the planner reaches them,
so on benchmark records in which every proposal was solved and every solved candidate validated
(`eval.planner_benchmark --candidates 24 --set schedule.validate_all=True --out RECORDS.jsonl`:
the 16 proposals and LEAP's 8 pinches after them), running the policy of `planner.schedule`
with other settings gives what planning with them would give.
Times per grasp are the recorded stage times of the solves and validations the policy uses.

    python -m eval.replay RECORDS.jsonl [--candidates 8] \
        [--set schedule.sweep_after=null schedule.gate_solves=8]

`eval.benchmark` records of one method replay the same way (`--out DIR` with `--candidates 24
--set schedule.validate_all=true`: for the learned pipeline its 16 samples and the region
proposals after them, in the order they were solved); they are scored as eval.benchmark scores
them, held on the full object and on the instructed part of the labelled object, while the
policy sees only what the method saw (a learned plan has no part labels):

    python -m eval.replay runs/bl_all3/records.jsonl --method learned --set schedule.gate_solves=24

Passing over proposals that will miss the intent (`schedule.pass_over_misses`, in the search
after a grasp held off its intent) is not replayed: it needs each proposal's drawn wrist and
the labels its intent was measured on, which records do not keep, so a replay is the policy
with it off.

`--retry OTHER.jsonl [...]` (records of the same pairs made with another squeeze,
`--set program.squeeze_depth=D program.retry_squeeze_depths=[]`) replays squeeze retries at
those depths in turn: a candidate that slips in RECORDS holds if it holds in one of them, as
`finish_grasp` decides.
"""

from __future__ import annotations

import argparse
import json
import statistics
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


# recorded stage times (CandidateResult.times) that a solved / a validated candidate costs (the
# first candidate carries the plan's own: building, proposing, drawing the samples)
SOLVE_STAGES = (
    "build",
    "propose",
    "solve",
    "quality",
    "intent",
    "dro",
    "interaction",
    "region",
    "direct",
)
VALIDATE_STAGES = ("pregrasp", "validate", "retry")


class RecordsError(DrograspError):
    """Records that cannot be replayed (not every solved candidate validated, or too few)."""


def load_records(path: Path) -> list[PairRecord]:
    """`eval.planner_benchmark --out` records, or a RecordsError saying why they cannot be read."""
    try:
        return read_records(path)
    except (OSError, json.JSONDecodeError, TypeError) as err:
        raise RecordsError(f"cannot read benchmark records from {path}: {err}") from err


def is_benchmark_file(path: Path) -> bool:
    """True for `eval.benchmark` records (their rows name a method), False for
    `eval.planner_benchmark` ones."""
    try:
        with path.open() as f:
            first = next((line for line in f if line.strip()), "{}")
        return "method" in json.loads(first)
    except (OSError, json.JSONDecodeError) as err:
        raise RecordsError(f"cannot read benchmark records from {path}: {err}") from err


def load_benchmark_records(path: Path, method: str | None) -> tuple[list[PairRecord], bool]:
    """One method's `eval.benchmark` records as PairRecords, and whether that method plans with
    part labels (the model-based planner; the learned methods see none). Their candidate
    summaries keep how eval.benchmark scores them: `held_full` and `touched`."""
    from eval.benchmark import METHODS

    try:
        rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except (OSError, json.JSONDecodeError) as err:
        raise RecordsError(f"cannot read benchmark records from {path}: {err}") from err
    methods = sorted({r["method"] for r in rows})
    if method is None and len(methods) == 1:
        method = methods[0]
    if method not in methods:
        raise RecordsError(f"{path} holds the methods {methods}; choose one with --method")
    try:
        records = [_benchmark_pair(r) for r in rows if r["method"] == method and not r["error"]]
    except KeyError as err:
        raise RecordsError(f"{path}: a record lacks {err}; not eval.benchmark records?") from err
    return records, METHODS[method]["proposer"] == "model"


def _benchmark_pair(r: dict) -> PairRecord:
    """One eval.benchmark record as a PairRecord."""
    return PairRecord(
        hand=r["hand"],
        category=r["category"],
        seed=r["seed"],
        instruction=r["instruction"],
        part=r["part"],
        first_holds=any(_scored(c)[0] for c in r["candidate_summaries"] if c["validated_as"] == 0),
        first_part_ok=r["first_ok"],
        returned_holds=r["held"],
        part_ok=r["returned_ok"],
        candidates=r["candidates"],
        solve_times=[c["times"].get("solve", 0.0) for c in r["candidate_summaries"]],
        plan_time=r["plan_time"],
        error=r["error"],
        candidate_summaries=r["candidate_summaries"],
        intent_ok=r["intent_ok"],
    )


def with_retry(records: list[PairRecord], other: list[PairRecord]) -> list[PairRecord]:
    """`records` as a squeeze retry at the depth of `other` (deeper or shallower) would have
    made them: a candidate that slipped holds where it held in `other` (its voted part depends
    on the grasp, not on the squeeze), and the retry's validation time is added. The two must
    hold the same pairs and the same solves: only the squeeze may differ."""
    if len(records) != len(other):
        raise RecordsError(f"{len(records)} records but {len(other)} with the other squeeze")
    merged = []
    for rec, alt in zip(records, other, strict=True):
        key = (rec.hand, rec.category, rec.seed, rec.instruction)
        if key != (alt.hand, alt.category, alt.seed, alt.instruction):
            raise RecordsError(
                f"the other squeeze's records hold {alt.instruction!r} where "
                f"{rec.instruction!r} was expected: record the same pairs"
            )
        by_rank = {c["rank"]: c for c in alt.candidate_summaries}
        summaries = []
        for c in rec.candidate_summaries:
            d = by_rank.get(c["rank"])
            if d is None or (c["solved"], c["task_quality"]) != (d["solved"], d["task_quality"]):
                raise RecordsError(
                    f"{rec.hand} {rec.category} {rec.seed}: candidate {c['rank']} was solved "
                    "differently with the other squeeze; record both with the same settings "
                    "but the squeeze depth"
                )
            c = dict(c)
            if c["solved"] and not c["success"] and d["validated_as"] is not None:
                retry = c["times"].get("retry", 0.0) + d["times"].get("validate", 0.0)
                c["times"] = c["times"] | {"retry": retry}
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


def _scored(summary: dict) -> tuple[bool, str | None]:
    """How a recorded candidate is scored: held and the part it touches, as the planner saw it
    or (eval.benchmark records) on the full, labelled object."""
    return (
        bool(summary.get("held_full", summary["success"])),
        summary.get("touched", summary["part"]),
    )


def replay_pair(
    record: PairRecord, settings: PlannerSettings, labelled: bool = True, ordered: bool = False
) -> PairRecord:
    """The record as the planner with `settings` would have produced it. `labelled`: the
    planner knew the part labels (else any held grasp ends the search, as for an unlabelled
    object); `ordered`: the recorded candidates are the proposals in solve order (eval.benchmark
    records) rather than proposals to choose from by `settings.proposals`."""
    if ordered:
        recorded = sorted(record.candidate_summaries, key=lambda c: c["rank"])
        recorded = [c | {"rank": i} for i, c in enumerate(recorded)]
    else:
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
    scored = {c["rank"]: _scored(c) for c in recorded}

    def validate(cand: CandidateResult) -> None:
        cand.success, cand.part = verdicts[cand.rank]

    scheduled = run_schedule(
        count,
        lambda ranks: [_candidate(recorded[i]) for i in ranks],
        validate,
        record.part if labelled else None,
        settings,
    )
    # what planning returns: a grasp held on the part (meeting the intent if one does), else
    # one held elsewhere
    returned = scheduled.on_part or scheduled.fallback
    first = next((c for c in scheduled.candidates if c.order == 0), None)
    first_scored = scored[first.rank] if first is not None else (False, None)
    returned_scored = scored[returned.rank] if returned is not None else (False, None)
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
        first_holds=first_scored[0],
        first_part_ok=first_scored == (True, record.part),
        returned_holds=returned_scored[0],
        part_ok=returned_scored == (True, record.part),
        # eval.benchmark checks the intent on the labelled object, which records do not replay
        intent_ok=None if ordered or scheduled.on_part is None else scheduled.found is not None,
        candidates=len(used),
        solve_times=[c.solve.solve_time for c in used],
        plan_time=plan_time,
        # the recorded summaries as this policy leaves them: validated or not, in what order
        candidate_summaries=[
            recorded[c.rank] | {"validated_as": c.order, "success": c.success, "part": c.part}
            for c in used
        ],
    )


def any_holds(
    records: list[PairRecord], settings: PlannerSettings, ordered: bool = False
) -> dict[str, float]:
    """Per hand, the share of pairs where any of the proposals `settings` solves holds on the
    part: the most any validation order can return (`ordered`: as in replay_pair)."""
    out: dict[str, list[bool]] = {}
    for r in records:
        used = r.candidate_summaries if ordered else proposals_used(r, settings)
        held = any(_scored(c) == (True, r.part) for c in used)
        out.setdefault(r.hand, []).append(held)
    return {hand: sum(v) / len(v) for hand, v in sorted(out.items())}


def print_benchmark_table(records: list[PairRecord], candidates: int) -> None:
    """eval.benchmark's columns for replayed records: first validated candidate held on the
    part, held on the part within `candidates` validations, held anywhere, part accuracy,
    solves and time per pair."""
    print(
        f"{'hand':<8} {'pairs':>5} {'first':>6} {f'within {candidates}':>9} {'held':>6} "
        f"{'part acc':>8} {'solves':>6} {'median s/pair':>13}"
    )
    for hand in sorted({r.hand for r in records}):
        rs = [r for r in records if r.hand == hand]
        held = [r for r in rs if r.returned_holds]
        accuracy = sum(r.part_ok for r in held) / len(held) if held else float("nan")
        print(
            f"{hand:<8} {len(rs):>5} {np.mean([r.first_part_ok for r in rs]):>6.1%} "
            f"{np.mean([r.part_ok for r in rs]):>9.1%} {len(held) / len(rs):>6.1%} "
            f"{accuracy:>8.1%} {np.mean([r.candidates for r in rs]):>6.1f} "
            f"{statistics.median(r.plan_time for r in rs):>13.2f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "records",
        type=Path,
        help="eval.planner_benchmark --out JSONL, or eval.benchmark's OUT/records.jsonl",
    )
    parser.add_argument(
        "--method", help="eval.benchmark records: the method to replay (learned, model, ...)"
    )
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
        nargs="+",
        metavar="OTHER",
        help="records of the same pairs with other squeezes: replay squeeze retries in turn",
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
    labelled, ordered = True, False
    try:
        if is_benchmark_file(args.records):
            if args.retry is not None:
                raise RecordsError("--retry replays eval.planner_benchmark records only")
            records, labelled = load_benchmark_records(args.records, args.method)
            ordered = True
        elif args.method is not None:
            raise RecordsError("--method chooses among eval.benchmark records' methods")
        else:
            records = load_records(args.records)
        for other in args.retry or ():
            records = with_retry(records, load_records(other))
        replayed = [replay_pair(r, settings, labelled, ordered) for r in records]
    except RecordsError as err:
        raise SystemExit(f"error: {err}") from None
    print(
        f"{len(records)} recorded pairs replayed, up to {args.candidates} validations"
        + (f", settings {' '.join(args.set)}" if args.set else "")
        + (f", slips retried as in {', '.join(map(str, args.retry))}" if args.retry else "")
    )
    if ordered:
        print_benchmark_table(replayed, args.candidates)
    else:
        print_table(summarize(replayed))
    try:
        bound = any_holds(records, settings, ordered)
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
