"""How often does the current planner's grasp meet its intent's definition?

For every (object, instruction) pair of a split and every hand: plan with the model-based planner
(`FunctionalPlanner(hand).plan(obj, text)`, default settings) and measure with
`planner.intent.check_intent` (definitions in models/objects/intents.py):

- the returned grasp: does it meet its intent, and each criterion;
- every validated candidate (those with a grasp): the share meeting their intent, and in how
  many pairs one that held on the instructed part does (what the planner could return if it
  preferred such candidates among those it validated);
- every solved candidate (validated or not): the same, from its configuration alone (what a
  preference could reach with more validations);
- distinct grasps: for the same (object, part), how far apart the grasps returned for different
  intents are (wrist distance and rotation), and how many are the same grasp.

    python -m eval.intent_rates --split test --objects-per-category 1 --workers 2
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import time
from collections import defaultdict
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from eval.planner_benchmark import pairs
from models.hands import available_hands
from models.objects import INTENTS, make_object, parse_instruction
from models.objects.intents import CRITERIA
from planner.functional import FunctionalPlanner
from planner.intent import IntentCheck, check_configuration, check_intent

SAME_POSITION = 0.001  # m: returned grasps this close ...
SAME_ANGLE = 1.0  # deg: ... and turned less than this are the same grasp


@dataclass
class IntentRecord:
    hand: str
    category: str
    seed: int
    instruction: str
    intent: str
    part: str
    returned: bool = False  # a grasp was returned
    holds: bool = False  # it held in validation
    part_ok: bool = False  # it held and touched the instructed part
    ok: bool | None = None  # it meets its intent (None: no grasp)
    criteria: dict[str, bool] = field(default_factory=dict)  # the returned grasp's
    values: dict[str, float] = field(default_factory=dict)
    reason: str = ""
    wrist: list[float] | None = None  # the returned grasp's [x, y, z, qw, qx, qy, qz]
    # every validated candidate: ok, held on the part
    validated: list[dict] = field(default_factory=list)
    solved: list[bool] = field(default_factory=list)  # every solved candidate: ok
    plan_time: float = 0.0
    error: str = ""


def _passes(check: IntentCheck) -> dict[str, bool]:
    return {c.name: c.passed for c in check.criteria}


_PLANNERS: dict[str, FunctionalPlanner] = {}


def run_pair(args: tuple[str, str, int, str]) -> IntentRecord:
    hand_name, cat, seed, text = args
    if hand_name not in _PLANNERS:
        _PLANNERS[hand_name] = FunctionalPlanner(hand_name)
    planner = _PLANNERS[hand_name]
    ins = parse_instruction(text)
    rec = IntentRecord(hand_name, cat, seed, text, ins.intent, ins.part)
    obj = make_object(cat, seed)
    start = time.perf_counter()
    try:
        result = planner.plan(obj, ins)
    except Exception as err:  # noqa: BLE001 - an evaluation records failures and goes on
        rec.error = repr(err)
        return rec
    rec.plan_time = time.perf_counter() - start
    hand = planner.hand
    if result.grasp is not None:
        check = check_intent(result.grasp, obj, hand, ins)
        rec.returned, rec.holds = True, result.success
        rec.part_ok = result.success and result.part_touched == ins.part
        rec.ok, rec.criteria, rec.reason = check.ok, _passes(check), check.reason
        rec.values = {c.name: c.value for c in check.criteria}
        rec.wrist = [*map(float, result.grasp.wrist_pos), *map(float, result.grasp.wrist_quat)]
    for cand in result.candidates:
        if not cand.solve.ok:
            continue
        check = check_configuration(cand.solve.wrist, cand.solve.q, obj, hand, ins)
        rec.solved.append(check.ok)
        if cand.grasp is not None:
            rec.validated.append(
                {
                    "ok": check.ok,
                    "held_on_part": bool(cand.success and cand.part == ins.part),
                    "criteria": _passes(check),
                }
            )
    return rec


def _share(hits: int, total: int) -> str:
    return f"{hits}/{total} {100 * hits / total:3.0f}%" if total else "-"


def summarize(records: list[IntentRecord]) -> list[dict]:
    """One row per hand and intent (and per hand over every intent)."""
    rows = []
    for hand in sorted({r.hand for r in records}):
        for intent in (*INTENTS, "all"):
            rs = [r for r in records if r.hand == hand and intent in (r.intent, "all")]
            if not rs:
                continue
            back = [r for r in rs if r.returned]
            held = [r for r in rs if r.part_ok]
            validated = [v for r in rs for v in r.validated]
            solved = [s for r in rs for s in r.solved]
            row = {
                "hand": hand,
                "intent": intent,
                "pairs": len(rs),
                "returned": len(back),
                "returned_ok": sum(bool(r.ok) for r in back),
                "held_on_part": len(held),
                "held_on_part_ok": sum(bool(r.ok) for r in held),
                "validated": len(validated),
                "validated_ok": sum(v["ok"] for v in validated),
                # pairs where a validated candidate held on the part and meets the intent
                "pairs_preferable": sum(
                    any(v["ok"] and v["held_on_part"] for v in r.validated) for r in rs
                ),
                "solved": len(solved),
                "solved_ok": sum(solved),
                "pairs_with_solved_ok": sum(any(r.solved) for r in rs),
                "criteria": {},
                "errors": sum(bool(r.error) for r in rs),
            }
            names = CRITERIA[intent] if intent != "all" else ()
            for name in names:
                have = [r for r in back if name in r.criteria]
                vals = [v for r in rs for v in r.validated if name in v["criteria"]]
                row["criteria"][name] = {
                    "returned": (sum(r.criteria[name] for r in have), len(have)),
                    "validated": (sum(v["criteria"][name] for v in vals), len(vals)),
                }
            rows.append(row)
    return rows


def distinct(records: list[IntentRecord]) -> list[dict]:
    """Per hand: for the same (object, part), the returned grasps of different intents
    compared pairwise: wrist distance (cm), wrist rotation (deg), and how many are the same."""
    out = []
    for hand in sorted({r.hand for r in records}):
        groups = defaultdict(list)
        for r in records:
            if r.hand == hand and r.wrist is not None:
                groups[(r.category, r.seed, r.part)].append(r)
        dists, angles, same, detail = [], [], 0, []
        for key, rs in sorted(groups.items()):
            for a, b in itertools.combinations(rs, 2):
                wa, wb = np.array(a.wrist), np.array(b.wrist)
                dist = float(np.linalg.norm(wa[:3] - wb[:3]))
                ra = Rotation.from_quat(wa[3:], scalar_first=True)
                rb = Rotation.from_quat(wb[3:], scalar_first=True)
                angle = float(np.degrees((ra.inv() * rb).magnitude()))
                dists.append(dist)
                angles.append(angle)
                identical = dist < SAME_POSITION and angle < SAME_ANGLE
                same += identical
                detail.append((f"{key[0]}/{key[2]}", a.intent, b.intent, dist, angle, identical))
        out.append(
            {
                "hand": hand,
                "pairs_compared": len(dists),
                "mean_wrist_distance_cm": 100 * statistics.mean(dists) if dists else float("nan"),
                "mean_wrist_angle_deg": statistics.mean(angles) if angles else float("nan"),
                "same_grasp": same,
                "detail": detail,
            }
        )
    return out


def print_tables(records: list[IntentRecord]) -> None:
    rows = summarize(records)
    print(
        f"{'hand':<8} {'intent':<9} {'pairs':>5} {'returned ok':>13} {'held&part ok':>13} "
        f"{'validated ok':>14} {'pairs pref.':>13} {'solved ok':>14} {'pairs solv.':>13}"
    )
    for r in rows:
        print(
            f"{r['hand']:<8} {r['intent']:<9} {r['pairs']:>5} "
            f"{_share(r['returned_ok'], r['returned']):>13} "
            f"{_share(r['held_on_part_ok'], r['held_on_part']):>13} "
            f"{_share(r['validated_ok'], r['validated']):>14} "
            f"{_share(r['pairs_preferable'], r['pairs']):>13} "
            f"{_share(r['solved_ok'], r['solved']):>14} "
            f"{_share(r['pairs_with_solved_ok'], r['pairs']):>13}"
        )
    print("\ncriterion pass rates (returned grasps | all validated candidates)")
    for r in rows:
        for name, c in r["criteria"].items():
            print(
                f"{r['hand']:<8} {r['intent']:<9} {name:<20} "
                f"{_share(*c['returned']):>12} | {_share(*c['validated']):>12}"
            )
    print("\ndistinct grasps: the same (object, part), different intents (returned grasps)")
    print(f"{'hand':<8} {'compared':>8} {'mean wrist dist':>15} {'mean angle':>10} {'same':>5}")
    for d in distinct(records):
        print(
            f"{d['hand']:<8} {d['pairs_compared']:>8} {d['mean_wrist_distance_cm']:>12.1f} cm "
            f"{d['mean_wrist_angle_deg']:>7.0f} deg {d['same_grasp']:>5}"
        )
    print("\nfailures of the returned grasps (first reason per pair)")
    for r in records:
        if r.returned and not r.ok:
            print(f"  {r.hand:<8} {r.instruction:<34} {r.reason}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--objects-per-category", type=int, default=1)
    parser.add_argument("--hands", nargs="+", default=available_hands())
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=None, help="first N pairs only (quick look)")
    parser.add_argument("--out", type=Path, default=None, help="per-pair records (JSONL)")
    args = parser.parse_args()
    jobs = pairs(args.split, args.objects_per_category, args.hands)[: args.limit]
    records: list[IntentRecord] = []
    with ProcessPoolExecutor(args.workers) as pool:
        for rec in tqdm(pool.map(run_pair, jobs, chunksize=1), total=len(jobs), unit="pair"):
            records.append(rec)
    if args.out:
        args.out.write_text("".join(json.dumps(asdict(r)) + "\n" for r in records))
    print(
        f"split {args.split}, {args.objects_per_category} objects per category, "
        f"{len(records)} pairs, default planner settings"
    )
    print_tables(records)


if __name__ == "__main__":
    main()
