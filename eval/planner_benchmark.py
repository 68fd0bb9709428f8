"""Benchmark the model-based functional planner on the procedural object library.

For every (object, instruction) pair of a split and every hand: plan with up to N candidates
and record whether the first candidate holds, whether the returned grasp holds, whether it
touches the instructed part (DESIGN.md's voting rule), NLP solve times and time per grasp.

    python -m eval.planner_benchmark --split test --objects-per-category 2 --workers 2
"""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

import numpy as np
from tqdm import tqdm

from models.errors import PlanningError
from models.hands import available_hands
from models.objects import HELDOUT, categories, instructions, make_object, seeds
from models.objects.names import INTENTS
from planner.batch.executors import one_thread
from planner.commands.validate import parse_overrides
from planner.functional import FunctionalPlanner
from planner.settings import PlannerSettings, ScheduleSettings, with_overrides


@dataclass
class PairRecord:
    hand: str
    category: str
    seed: int
    instruction: str
    part: str
    first_holds: bool
    first_part_ok: bool
    returned_holds: bool
    part_ok: bool
    candidates: int
    solve_times: list[float]
    plan_time: float
    error: str = ""
    # every candidate's CandidateResult.summary(): features (quality, task quality, anchor
    # error, pregrasp penetration) and outcome, for fitting a validation order offline
    candidate_summaries: list[dict] = field(default_factory=list)
    # the returned grasp meets its intent's definition (planner.intent; None: no grasp or not
    # checked) and its wrist [x, y, z, qw, qx, qy, qz], for distinct grasps across intents
    intent_ok: bool | None = None
    wrist: list[float] | None = None
    # why the intent cannot be met on the part (PlanResult.unmeetable); None: it can
    unmeetable: str | None = None


def write_records(records: Sequence[PairRecord], path: Path) -> None:
    """The `--out` file: one PairRecord per line (JSONL)."""
    path.write_text("".join(json.dumps(asdict(r)) + "\n" for r in records))


def read_records(path: Path) -> list[PairRecord]:
    """Records written by `write_records` (fields added since are left at their defaults)."""
    names = {f.name for f in fields(PairRecord)}
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return [PairRecord(**{k: v for k, v in row.items() if k in names}) for row in rows]


def pairs(
    split: str, per_category: int, hands: list[str], intents: Sequence[str] | None = None
) -> list[tuple[str, str, int, str]]:
    """(hand, category, seed, instruction) of the split; `intents`: only theirs (None: all)."""
    out = []
    for cat in categories():
        if (split == "heldout") != (cat in HELDOUT):
            continue
        for seed in seeds(cat, split, per_category):
            for ins in instructions(cat):
                if intents is not None and ins.intent not in intents:
                    continue
                for hand in hands:
                    out.append((hand, cat, seed, ins.text))
    return out


_PLANNERS: dict[str, FunctionalPlanner] = {}


def planner_settings(max_candidates: int, overrides: Sequence[str] = ()) -> PlannerSettings:
    """PlannerSettings with `--set` overrides (`schedule.solve_batch=2`, `intent.aware=False`,
    `program.major_iterations=60`; planner.settings.with_overrides)."""
    settings = PlannerSettings(schedule=ScheduleSettings(max_candidates=max_candidates))
    try:
        return with_overrides(settings, parse_overrides(list(overrides)))
    except PlanningError as err:
        raise SystemExit(f"--set: {err}") from None


def run_pair(args: tuple[str, str, int, str, int, tuple[str, ...]]) -> PairRecord:
    hand, cat, seed, text, max_candidates, overrides = args
    if hand not in _PLANNERS:
        _PLANNERS[hand] = FunctionalPlanner(hand, planner_settings(max_candidates, overrides))
    planner = _PLANNERS[hand]
    obj = make_object(cat, seed)
    part = text.rsplit(" by ", 1)[1]
    start = time.perf_counter()
    try:
        result = planner.plan(obj, text)
    except Exception as err:  # noqa: BLE001 - a benchmark records failures and goes on
        return PairRecord(
            hand, cat, seed, text, part, False, False, False, False, 0, [], 0.0, repr(err)
        )
    elapsed = time.perf_counter() - start
    first = next((c for c in result.candidates if c.order == 0), None)  # the planner's top pick
    return PairRecord(
        hand=hand,
        category=cat,
        seed=seed,
        instruction=text,
        part=part,
        first_holds=bool(first and first.success),
        first_part_ok=bool(first and first.success and first.part == part),
        returned_holds=result.success,
        part_ok=result.success and result.part_touched == part,
        candidates=len(result.candidates),
        solve_times=[c.solve.solve_time for c in result.candidates],
        plan_time=elapsed,
        candidate_summaries=[c.summary() for c in result.candidates],
        intent_ok=result.intent_ok,
        unmeetable=result.unmeetable,
        wrist=(
            None
            if result.grasp is None
            else [*map(float, result.grasp.wrist_pos), *map(float, result.grasp.wrist_quat)]
        ),
    )


def summarize(records: list[PairRecord]) -> list[dict]:
    rows = []
    for hand in sorted({r.hand for r in records}):
        rs = [r for r in records if r.hand == hand]
        solved = [t for r in rs for t in r.solve_times]
        held = [r for r in rs if r.returned_holds]
        rows.append(
            {
                "hand": hand,
                "pairs": len(rs),
                "first_candidate_success": sum(r.first_holds for r in rs) / len(rs),
                "returned_success": len(held) / len(rs),
                # what the instruction asked for: the returned grasp holds and touches the part
                "returned_on_part": sum(r.part_ok for r in held) / len(rs),
                "part_accuracy": (sum(r.part_ok for r in held) / len(held)) if held else 0.0,
                "median_solve_s": statistics.median(solved) if solved else float("nan"),
                "median_time_per_returned_grasp_s": (
                    statistics.median(r.plan_time for r in held) if held else float("nan")
                ),
                # machine-independent work behind the time per grasp: solve times on this
                # 2-core VM drift by 25% or more between runs of identical code
                "mean_solves_per_returned_grasp": (
                    statistics.mean(r.candidates for r in held) if held else float("nan")
                ),
                "errors": sum(bool(r.error) for r in rs),
                # of the returned grasps held on the instructed part: meeting their intent,
                # and the same where the definition can be met on the part
                "intent_ok": _share([r.intent_ok for r in rs if r.part_ok]),
                "intent_ok_meetable": _share(
                    [r.intent_ok for r in rs if r.part_ok and r.unmeetable is None]
                ),
                "unmeetable_pairs": sum(r.unmeetable is not None for r in rs),
            }
        )
    return rows


def _share(flags: Sequence[bool | None]) -> float:
    known = [f for f in flags if f is not None]
    return sum(known) / len(known) if known else float("nan")


def intent_rows(records: list[PairRecord]) -> list[dict]:
    """Per hand and intent: pairs, held on the part, and the share of those meeting the
    intent's definition."""
    rows = []
    for hand in sorted({r.hand for r in records}):
        for intent in ("Use", "Hold", "Handover", "Liftup"):
            rs = [r for r in records if r.hand == hand and r.instruction.startswith(intent)]
            if not rs:
                continue
            held = [r for r in rs if r.part_ok]
            rows.append(
                {
                    "hand": hand,
                    "intent": intent,
                    "pairs": len(rs),
                    "on_part": len(held) / len(rs),
                    "intent_ok": _share([r.intent_ok for r in held]),
                }
            )
    return rows


def distinct_grasps(records: list[PairRecord]) -> dict[str, float]:
    """For the same (hand, object, part), how far apart the grasps returned for different
    intents are: pairs compared, mean wrist distance (cm) and the share that are the same
    grasp (wrist within 1 mm and 1 degree)."""
    by_key: dict[tuple, list[PairRecord]] = {}
    for r in records:
        if r.wrist is not None and r.part_ok:
            by_key.setdefault((r.hand, r.category, r.seed, r.part), []).append(r)
    dists, same = [], 0
    for group in by_key.values():
        for i, a in enumerate(group):
            for b in group[i + 1 :]:
                d = float(np.linalg.norm(np.subtract(a.wrist[:3], b.wrist[:3])))
                dot = abs(float(np.dot(a.wrist[3:], b.wrist[3:])))
                angle = float(np.degrees(2 * np.arccos(min(1.0, dot))))
                dists.append(d)
                same += d < 0.001 and angle < 1.0
    return {
        "pairs": len(dists),
        "mean_wrist_distance_cm": 100 * float(np.mean(dists)) if dists else float("nan"),
        "same_grasp": same / len(dists) if dists else float("nan"),
    }


def print_table(rows: list[dict]) -> None:
    print(
        f"{'hand':<8} {'pairs':>5} {'first-cand':>10} {'returned':>9} {'on part':>8} {'part acc':>9} "
        f"{'solve med s':>11} {'s/grasp med':>11} {'solves/grasp':>12} {'errors':>6} "
        f"{'intent ok':>9}"
    )
    for r in rows:
        print(
            f"{r['hand']:<8} {r['pairs']:>5} {r['first_candidate_success']:>10.1%} "
            f"{r['returned_success']:>9.1%} {r['returned_on_part']:>8.1%} {r['part_accuracy']:>9.1%} "
            f"{r['median_solve_s']:>11.3f} "
            f"{r['median_time_per_returned_grasp_s']:>11.2f} "
            f"{r['mean_solves_per_returned_grasp']:>12.2f} {r['errors']:>6} "
            f"{r['intent_ok']:>9.1%}"
        )


def print_by_part(records: list[PairRecord]) -> None:
    """Pairs held on the instructed part per (category, part) and hand: where the planner
    fails (a grasp that held on another part counts as a failure here)."""
    hands = sorted({r.hand for r in records})
    print(f"{'category/part':<24}" + "".join(f"{h:>10}" for h in hands))
    for cat, part in sorted({(r.category, r.part) for r in records}):
        cells = []
        for hand in hands:
            rs = [r for r in records if (r.category, r.part, r.hand) == (cat, part, hand)]
            cells.append(f"{sum(r.part_ok for r in rs)}/{len(rs)}".rjust(10))
        print(f"{cat + '/' + part:<24}" + "".join(cells))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--objects-per-category", type=int, default=2)
    parser.add_argument("--hands", nargs="+", default=available_hands())
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=None, help="first N pairs only (quick look)")
    parser.add_argument(
        "--intents",
        nargs="+",
        choices=INTENTS,
        default=None,
        help="only the instructions of these intents (e.g. --intents Liftup)",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="write per-pair records with candidates (JSONL)"
    )
    parser.add_argument(
        "--set",
        nargs="*",
        default=[],
        metavar="KEY=VALUE",
        help="planner setting overrides by dotted key, e.g. schedule.solve_batch=2 "
        "intent.aware=False program.major_iterations=60 (planner/settings.py)",
    )
    parser.add_argument(
        "--by-part",
        action="store_true",
        help="also print pairs held on the instructed part per category/part",
    )
    args = parser.parse_args()
    planner_settings(args.candidates, args.set)  # fail early on a bad override
    jobs = [
        (*p, args.candidates, tuple(args.set))
        for p in pairs(args.split, args.objects_per_category, args.hands, args.intents)
    ][: args.limit]
    records: list[PairRecord] = []
    with ProcessPoolExecutor(args.workers, initializer=one_thread) as pool:
        for rec in tqdm(pool.map(run_pair, jobs, chunksize=1), total=len(jobs), unit="pair"):
            records.append(rec)
    if args.out:
        write_records(records, args.out)
    print(
        f"split {args.split}, {args.objects_per_category} objects per category, "
        f"up to {args.candidates} candidates, paper validation preset"
        + (f", intents {' '.join(args.intents)}" if args.intents else "")
        + (f", settings {' '.join(args.set)}" if args.set else "")
    )
    rows = summarize(records)
    print_table(rows)
    print("\nper intent: held on the part, and of those meeting the intent's definition")
    for r in intent_rows(records):
        print(
            f"{r['hand']:<8} {r['intent']:<9} {r['pairs']:>5} {r['on_part']:>8.1%} "
            f"{r['intent_ok']:>9.1%}"
        )
    if any(r["unmeetable_pairs"] for r in rows):
        print(
            "meeting the intent where its definition can be met on the part "
            "(planner.intent.unmeetable): "
            + ", ".join(
                f"{r['hand']} {r['intent_ok_meetable']:.1%} ({r['unmeetable_pairs']} pairs left out)"
                for r in rows
            )
        )
    d = distinct_grasps(records)
    if d["pairs"]:  # none where one intent was planned (--intents)
        print(
            f"distinct grasps: {d['pairs']} pairs of intents on the same (hand, object, part): "
            f"mean wrist distance {d['mean_wrist_distance_cm']:.1f} cm, same grasp "
            f"{d['same_grasp']:.0%}"
        )
    if args.by_part:
        print_by_part(records)


if __name__ == "__main__":
    main()
