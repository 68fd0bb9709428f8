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
    add_job_arguments(m, splits=["train", "val", "test"], variants=2)
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


def add_job_arguments(p: argparse.ArgumentParser, splits: list[str], variants: int) -> None:
    """Which jobs to make: shared by `jobs make` and `dataset generate`."""
    p.add_argument("--split", nargs="+", default=splits, choices=SPLITS, dest="splits")
    p.add_argument("--categories", nargs="+", choices=categories(), metavar="CATEGORY")
    p.add_argument("--hands", nargs="+", default=available_hands(), metavar="HAND")
    p.add_argument(
        "--objects-per-category",
        type=int,
        default=10,
        metavar="N",
        help="seeds START..START+N-1 of each category, kept where their split is asked for",
    )
    p.add_argument("--start-seed", type=int, default=0)
    p.add_argument(
        "--variants", type=int, default=variants, help="grasps with varied wrist poses per pair"
    )
    p.add_argument(
        "--candidates", type=int, default=8, help="grasps each job may validate (default 8)"
    )
    p.add_argument("--preset", default="paper", help="validation preset (default paper)")


def add_backend_arguments(p: argparse.ArgumentParser) -> None:
    """Where jobs run: shared by `batch` and `dataset generate`."""
    p.add_argument("--workers", type=int, default=1, help="local processes or Ray CPUs (default 1)")
    where = p.add_mutually_exclusive_group()
    where.add_argument("--ray", action="store_true", help="start a local Ray instance")
    where.add_argument("--ray-address", metavar="ADDR", help="join a running Ray cluster")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


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
