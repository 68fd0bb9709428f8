"""`drograsp jobs`: make batch jobs files (from the object library, or transfers of results)."""

from __future__ import annotations

import argparse
from collections import Counter

from models.hand_names import builtin_hands, check_hand_name
from models.objects.names import CATEGORY_NAMES, SPLITS
from models.paths import input_folder, output_file
from planner.commands.args import PRESET_NAMES, non_negative_int, positive_int

JOBS_SUFFIXES = (".jsonl",)


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
    t.add_argument("--hands", nargs="+", default=None, metavar="HAND")
    t.add_argument(
        "--per-pair",
        type=positive_int,
        metavar="N",
        help="at most N source grasps per object, instruction and source hand",
    )
    t.set_defaults(func=run_transfer)


def add_job_arguments(p: argparse.ArgumentParser, splits: list[str], variants: int) -> None:
    """Which jobs to make: shared by `jobs make` and `dataset generate`."""
    p.add_argument("--split", nargs="+", default=splits, choices=SPLITS, dest="splits")
    p.add_argument("--categories", nargs="+", choices=CATEGORY_NAMES, metavar="CATEGORY")
    p.add_argument(
        "--hands", nargs="+", default=None, metavar="HAND", help="default: every built-in hand"
    )
    p.add_argument(
        "--objects-per-category",
        type=positive_int,
        default=10,
        metavar="N",
        help="seeds START..START+N-1 of each category, kept where their split is asked for",
    )
    p.add_argument("--start-seed", type=non_negative_int, default=0)
    p.add_argument(
        "--variants",
        type=positive_int,
        default=variants,
        help="grasps with varied wrist poses per pair",
    )
    p.add_argument(
        "--candidates",
        type=positive_int,
        default=8,
        help="grasps each job may validate (default 8)",
    )
    p.add_argument(
        "--preset", default="paper", choices=PRESET_NAMES, help="validation preset (default paper)"
    )


def add_backend_arguments(p: argparse.ArgumentParser) -> None:
    """Where jobs run: shared by `batch` and `dataset generate`."""
    p.add_argument(
        "--workers", type=positive_int, default=1, help="local processes or Ray CPUs (default 1)"
    )
    where = p.add_mutually_exclusive_group()
    where.add_argument("--ray", action="store_true", help="start a local Ray instance")
    where.add_argument("--ray-address", metavar="ADDR", help="join a running Ray cluster")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def hands_arg(hands: list[str] | None) -> list[str]:
    """--hands, each a built-in hand or a hand folder (default: every built-in hand)."""
    return [check_hand_name(h) for h in (hands or builtin_hands())]


def run_make(args: argparse.Namespace) -> int:
    out = output_file(args.out, JOBS_SUFFIXES, "jobs file")
    from planner.batch import make_jobs, write_jobs

    jobs = make_jobs(
        hands=hands_arg(args.hands),
        splits=args.splits,
        category_names=args.categories,
        objects_per_category=args.objects_per_category,
        start_seed=args.start_seed,
        variants=args.variants,
        max_candidates=args.candidates,
        protocol=args.preset,
    )
    write_jobs(jobs, out)
    per_hand = Counter(j.hand for j in jobs)
    print(
        f"wrote {len(jobs)} jobs to {args.out} ({', '.join(f'{h} {n}' for h, n in sorted(per_hand.items()))})"
    )
    return 0


def run_transfer(args: argparse.Namespace) -> int:
    hands = hands_arg(args.hands)
    out = output_file(args.out, JOBS_SUFFIXES, "jobs file")
    results = input_folder(args.results, "batch results folder")
    from planner.batch import read_results, write_jobs
    from planner.batch.runner import check_results_folder
    from planner.batch.transfer import transfer_jobs  # loads the planner: only when asked

    jobs = transfer_jobs(read_results(check_results_folder(results)), hands, args.per_pair)
    write_jobs(jobs, out)
    print(f"wrote {len(jobs)} transfer jobs to {args.out}")
    return 0
