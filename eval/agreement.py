"""Do the project's hands judge the planner's own grasps as DexGraspBench's hand files do?

For test-split (object, instruction) pairs, per hand: plan with the model-based planner (given the
part labels) or the learned pipeline (`--proposer learned`: the object without its labels, as
eval.benchmark's learned methods see it), keep every candidate it validated, and validate each of
those grasps twice under DexGraspBench's protocol: once with the project's hand
(models/hands/<hand>) and once with DexGraspBench's hand file (the grasp converted to that file's
root frame and joint order, as `drograsp export dexgraspbench` writes it and `drograsp validate
--hand-xml` reads it). The table reports each verdict's success rate and how often the two agree.

    python -m eval.agreement --objects-per-category 1 --workers 2 --out agreement.jsonl
    python -m eval.agreement --proposer learned --workers 2 --out agreement_learned.jsonl

Needs DexGraspBench's hand files (`--hand-files`, default ../shared/reference/dexgraspbench/hand
beside the repository), named <hand>_right_hand.xml.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from eval.benchmark import unlabelled
from models.grasp import Grasp, from_dexgraspbench, to_dexgraspbench
from models.hands import available_hands
from models.hands.mjcf_frame import mjcf_root_offset
from models.objects import make_object
from planner.batch.executors import one_thread
from planner.functional import FunctionalPlanner
from planner.grasp_program import first_closing
from planner.settings import PlannerSettings, ScheduleSettings
from planner.validation import validate
from planner.validation.hands import mjcf_hand, mjcf_joint_names

REPO = Path(__file__).resolve().parents[1]
HAND_FILES = REPO.parent / "shared" / "reference" / "dexgraspbench" / "hand"
PRESET = "dexgraspbench"


@dataclass
class CandidateVerdicts:
    rank: int
    returned: bool  # the grasp the planner returned for the pair
    planner: bool  # the planner's own verdict (paper preset, squeeze retry)
    project: bool  # DexGraspBench's protocol on the project's hand
    vendor: bool  # DexGraspBench's protocol on DexGraspBench's hand file
    project_reason: str
    vendor_reason: str
    vendor_pregrasp_penetration: float
    coupling_violation: float  # rad: largest |A q| over the three phases (0 for coupled plans)
    # the closing the grasp carries is one of the planner's retries (another squeeze depth or
    # pregrasp rule than the first): it held only there
    retried: bool = False


@dataclass
class PairVerdicts:
    hand: str
    category: str
    seed: int
    instruction: str
    proposer: str = "model"
    candidates: list[CandidateVerdicts] = field(default_factory=list)
    error: str = ""


def as_hand_file_grasp(grasp: Grasp, hand: str, xml: Path) -> Grasp:
    """`grasp` in the hand file's root frame and joint order (what the file's rows hold)."""
    xml_joints = mjcf_joint_names(str(xml))
    rows = to_dexgraspbench(
        grasp, xml_joint_names=xml_joints, root_offset=mjcf_root_offset(hand, xml).matrix
    )
    return from_dexgraspbench(
        rows["pregrasp_qpos"],
        rows["grasp_qpos"],
        rows["squeeze_qpos"],
        hand=xml.stem,
        joint_names=xml_joints,
        xml_joint_names=xml_joints,
        root_offset=np.eye(4),
    )


@dataclass(frozen=True)
class PairJob:
    """One (hand, object, instruction) to plan and judge; `hand_files` is the folder of
    DexGraspBench's `<hand>_right_hand.xml` files."""

    hand: str
    category: str
    seed: int
    text: str
    hand_files: Path
    max_candidates: int = 8
    proposer: str = "model"


def judge_pair(job: PairJob) -> PairVerdicts:
    """Plan one pair and judge every validated candidate on both hands."""
    hand, category, seed, text, proposer = job.hand, job.category, job.seed, job.text, job.proposer
    record = PairVerdicts(hand, category, seed, text, proposer)
    xml = Path(job.hand_files) / f"{hand}_right_hand.xml"
    try:
        settings = PlannerSettings(
            proposer=proposer, schedule=ScheduleSettings(max_candidates=job.max_candidates)
        )
        planner = FunctionalPlanner(hand, settings)
        obj = make_object(category, seed)
        result = planner.plan(obj if proposer == "model" else unlabelled(obj), text)
        pieces = obj.collision_pieces()
        vendor_hand = mjcf_hand(xml)
        best = result.best
        first = first_closing(settings.program, planner.hand)
        for cand in result.candidates:
            if cand.grasp is None or cand.order is None:
                continue
            grasp = cand.grasp
            ours = validate(grasp, pieces, hand, PRESET)
            theirs = validate(as_hand_file_grasp(grasp, hand, xml), pieces, vendor_hand, PRESET)
            model = planner.hand
            record.candidates.append(
                CandidateVerdicts(
                    rank=cand.rank,
                    returned=cand is best,
                    planner=bool(cand.success),
                    project=bool(ours.success),
                    vendor=bool(theirs.success),
                    project_reason=ours.reason,
                    vendor_reason=theirs.reason,
                    vendor_pregrasp_penetration=float(theirs.pregrasp_penetration),
                    coupling_violation=max(
                        model.coupling_violation(grasp.joints(phase))
                        for phase in ("pregrasp", "grasp", "squeeze")
                    ),
                    retried=(grasp.metrics["squeeze_depth"], grasp.metrics["pregrasp_rule"])
                    != first,
                )
            )
    except Exception as err:  # noqa: BLE001 - a benchmark records failures and goes on
        record.error = repr(err)
    return record


def jobs(
    split: str,
    per_category: int,
    hands: Sequence[str],
    hand_files: Path,
    max_candidates: int,
    proposer: str = "model",
) -> list[PairJob]:
    from eval.planner_benchmark import pairs

    return [
        PairJob(hand, cat, seed, text, Path(hand_files), max_candidates, proposer)
        for hand, cat, seed, text in pairs(split, per_category, list(hands))
    ]


def summarize(records: Sequence[PairVerdicts]) -> list[dict]:
    rows = []
    for hand in sorted({r.hand for r in records}):
        cands = [c for r in records if r.hand == hand for c in r.candidates]
        returned = [c for c in cands if c.returned]
        n = max(len(cands), 1)
        rows.append(
            {
                "hand": hand,
                "pairs": sum(r.hand == hand for r in records),
                "errors": sum(bool(r.error) for r in records if r.hand == hand),
                "candidates": len(cands),
                "planner_holds": sum(c.planner for c in cands),
                "project_holds": sum(c.project for c in cands),
                "vendor_holds": sum(c.vendor for c in cands),
                "agree": sum(c.project == c.vendor for c in cands),
                "agreement": sum(c.project == c.vendor for c in cands) / n,
                "project_only": sum(c.project and not c.vendor for c in cands),
                "vendor_only": sum(c.vendor and not c.project for c in cands),
                "returned": len(returned),
                "returned_vendor_holds": sum(c.vendor for c in returned),
                "returned_planner_holds": sum(c.planner for c in returned),
                "retried": sum(c.retried for c in cands),
                "retried_vendor_holds": sum(c.retried and c.vendor for c in cands),
            }
        )
    return rows


def print_table(rows: Sequence[dict]) -> None:
    print(
        f"{'hand':<8} {'pairs':>5} {'cands':>5} {'planner':>7} {'project':>7} {'vendor':>6} "
        f"{'agree':>11} {'proj-only':>9} {'vend-only':>9} {'returned held by vendor':>24} "
        f"{'held at a retry: by vendor':>27}"
    )
    for r in rows:
        print(
            f"{r['hand']:<8} {r['pairs']:>5} {r['candidates']:>5} {r['planner_holds']:>7} "
            f"{r['project_holds']:>7} {r['vendor_holds']:>6} "
            f"{r['agree']:>4}/{r['candidates']:<3} {r['agreement']:>4.0%} {r['project_only']:>9} "
            f"{r['vendor_only']:>9} {r['returned_vendor_holds']:>15}/{r['returned']:<3}"
            f"{r['retried_vendor_holds']:>23}/{r['retried']:<3}"
            + (f"  ({r['errors']} errors)" if r["errors"] else "")
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--split", default="test")
    parser.add_argument("--objects-per-category", type=int, default=1)
    parser.add_argument("--hands", nargs="+", default=available_hands())
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument(
        "--proposer",
        choices=("model", "learned"),
        default="model",
        help="model: the model-based planner given the part labels; learned: the learned "
        "pipeline on the object without labels",
    )
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--limit", type=int, default=None, help="first N pairs per hand")
    parser.add_argument("--hand-files", type=Path, default=HAND_FILES)
    parser.add_argument("--out", type=Path, default=None, help="per-candidate verdicts (JSONL)")
    args = parser.parse_args()
    missing = [h for h in args.hands if not (args.hand_files / f"{h}_right_hand.xml").is_file()]
    if missing:
        raise SystemExit(
            f"no DexGraspBench hand file for {missing} in {args.hand_files} "
            "(<hand>_right_hand.xml); pass --hand-files"
        )
    work = jobs(
        args.split,
        args.objects_per_category,
        args.hands,
        args.hand_files,
        args.candidates,
        args.proposer,
    )
    if args.limit:
        work = [j for h in args.hands for j in [j for j in work if j.hand == h][: args.limit]]
    records: list[PairVerdicts] = []
    out = args.out.open("w") if args.out else None
    with ProcessPoolExecutor(args.workers, initializer=one_thread) as pool:
        for rec in tqdm(pool.map(judge_pair, work, chunksize=1), total=len(work), unit="pair"):
            records.append(rec)
            if out:
                out.write(json.dumps(asdict(rec)) + "\n")
                out.flush()
    print(
        f"split {args.split}, {args.objects_per_category} object(s) per category, "
        f"{args.proposer} proposer, every "
        f"validated candidate, DexGraspBench protocol on the project's hand and on its hand file"
    )
    print_table(summarize(records))


if __name__ == "__main__":
    main()
