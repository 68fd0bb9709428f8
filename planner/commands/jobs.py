"""`drograsp jobs`: make batch jobs files (from the object library, or transfers of results)."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

from models.hands import available_hands
from models.objects import SPLITS, categories
from planner.batch import make_jobs, read_results, write_jobs


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "jobs",
        help="make a batch jobs file (JSONL) for `drograsp batch`",
        description="Make jobs from the object library and instruction table (`make`), or "
        "cross-hand transfer jobs from the validated grasps of a finished batch (`transfer`).",
    )
    jsub = p.add_subparsers(dest="jobs_command", metavar="ACTION", required=True)

    m = jsub.add_parser("make", help="jobs for library objects x instructions x hands x variants")
    m.add_argument("out", metavar="OUT.jsonl")
    m.add_argument(
        "--split", nargs="+", default=["train", "val", "test"], choices=SPLITS, dest="splits"
    )
    m.add_argument("--categories", nargs="+", choices=categories(), metavar="CATEGORY")
    m.add_argument("--hands", nargs="+", default=available_hands(), metavar="HAND")
    m.add_argument(
        "--objects-per-category",
        type=int,
        default=10,
        metavar="N",
        help="seeds START..START+N-1 of each category, kept where their split is asked for",
    )
    m.add_argument("--start-seed", type=int, default=0)
    m.add_argument(
        "--variants", type=int, default=2, help="grasps with varied wrist poses per pair"
    )
    m.add_argument("--candidates", type=int, default=8, help="proposals each job may try")
    m.add_argument("--preset", default="paper", help="validation preset (default paper)")
    m.set_defaults(func=run_make)

    t = jsub.add_parser("transfer", help="every valid grasp of a batch seeds the other hands")
    t.add_argument("results", metavar="RESULTS_DIR", help="OUT_DIR of a finished batch")
    t.add_argument("out", metavar="OUT.jsonl")
    t.add_argument("--hands", nargs="+", default=available_hands(), metavar="HAND")
    t.add_argument(
        "--per-pair",
        type=int,
        metavar="N",
        help="at most N source grasps per object, instruction and source hand",
    )
    t.set_defaults(func=run_transfer)


def run_make(args: argparse.Namespace) -> int:
    jobs = make_jobs(
        hands=args.hands,
        splits=args.splits,
        category_names=args.categories,
        objects_per_category=args.objects_per_category,
        start_seed=args.start_seed,
        variants=args.variants,
        max_candidates=args.candidates,
        protocol=args.preset,
    )
    write_jobs(jobs, args.out)
    per_hand = Counter(j.hand for j in jobs)
    print(
        f"wrote {len(jobs)} jobs to {args.out} ({', '.join(f'{h} {n}' for h, n in sorted(per_hand.items()))})"
    )
    return 0


def run_transfer(args: argparse.Namespace) -> int:
    from planner.batch.transfer import transfer_jobs  # loads the planner: only when asked

    jobs = transfer_jobs(read_results(Path(args.results)), args.hands, args.per_pair)
    write_jobs(jobs, args.out)
    print(f"wrote {len(jobs)} transfer jobs to {args.out}")
    return 0
