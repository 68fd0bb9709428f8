"""`drograsp dataset`: generate the functional grasp dataset, compact batch results, show counts."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from pathlib import Path

from models.objects.names import CATEGORY_NAMES
from models.paths import input_folder, output_folder
from planner.commands.args import non_negative_int, positive_int
from planner.commands.jobs import add_backend_arguments, add_job_arguments, hands_arg

# The shipped dataset lives in the source checkout (objects regenerate from seeds; the installed package
# does not carry it): the default is relative to the current folder, the checkout's root.
DEFAULT_ROOT = Path("data") / "grasps_v2"


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "dataset",
        help="generate, compact and inspect the functional grasp dataset",
        description="The training set made the paper's way: planned, validated in MuJoCo, "
        "labelled with the voted part and anchors; cross-hand transfers added.",
    )
    dsub = p.add_subparsers(dest="dataset_command", metavar="ACTION", required=True)

    g = dsub.add_parser("generate", help="jobs -> batch -> transfers -> dataset + card")
    g.add_argument("out", metavar="OUT_DIR")
    g.add_argument("--work", metavar="DIR", help="jobs and result shards (default OUT_DIR/work)")
    add_job_arguments(g, splits=["train", "val", "test", "heldout"], variants=3)
    g.add_argument(
        "--first-only",
        action="store_true",
        help="keep only each job's first holding grasp (default: validate every candidate "
        "and keep all that hold on the part)",
    )
    g.add_argument("--no-transfer", action="store_true", help="skip cross-hand transfers")
    g.add_argument(
        "--transfer-per-pair",
        type=non_negative_int,
        default=1,
        metavar="N",
        help="source grasps per object, instruction and hand that seed other hands (default 1; "
        "0: every valid grasp)",
    )
    g.add_argument(
        "--block-seeds",
        type=positive_int,
        default=1,
        metavar="N",
        help="seeds per block (default 1): each finished block is added to OUT_DIR at once, so "
        "an interrupted generation keeps it; the same command resumes",
    )
    g.add_argument(
        "--extra-variants",
        type=non_negative_int,
        default=0,
        metavar="N",
        help="N more variants for each object, instruction and hand whose variants found no "
        "valid grasp (default 0)",
    )
    add_backend_arguments(g)
    g.set_defaults(func=run_generate)

    r = dsub.add_parser(
        "refresh",
        help="make the rows of some categories again with this code, keeping the others",
        description="After a change to some categories' objects or planning: every block is "
        "made again from the generation settings in DIR/meta.json; the other categories' "
        "results are taken from the blocks' work folders where present. Re-running resumes.",
    )
    r.add_argument("root", metavar="DIR")
    r.add_argument("--categories", nargs="+", required=True, metavar="NAME", choices=CATEGORY_NAMES)
    r.add_argument("--work", metavar="DIR", help="jobs and result shards (default DIR/work)")
    add_backend_arguments(r)
    r.set_defaults(func=run_refresh)

    c = dsub.add_parser("compact", help="batch result folders -> dataset folder + card")
    c.add_argument("results", nargs="+", metavar="RESULTS_DIR")
    c.add_argument("--out", required=True, metavar="DIR")
    c.set_defaults(func=run_compact)

    k = dsub.add_parser(
        "check-intents",
        help="check every grasp against every intent its part is asked for (for --relabel)",
        description="Writes DIR/intents/BLOCK.npz beside each block: whether each grasp meets "
        "each intent's definition that the instruction table asks of its part (not only its "
        "own intent's). `drograsp train interaction --relabel` learns each grasp for every "
        "intent it meets. Resumes: blocks already checked are skipped.",
    )
    k.add_argument("root", metavar="DIR")
    k.add_argument("--workers", type=positive_int, default=1, help="blocks in parallel")
    k.set_defaults(func=run_check_intents)

    i = dsub.add_parser("info", help="counts per split, hand, category and intent")
    i.add_argument(
        "root",
        nargs="?",
        default=str(DEFAULT_ROOT),
        metavar="DIR",
        help=f"dataset folder (default {DEFAULT_ROOT}, the shipped dataset when run from the checkout)",
    )
    i.add_argument("--json", action="store_true")
    i.set_defaults(func=run_info)


def _command() -> str:
    return "drograsp " + shlex.join(sys.argv[1:]) if sys.argv[1:] else ""


def run_generate(args: argparse.Namespace) -> int:
    hands = hands_arg(args.hands)
    output_folder(args.out, "dataset folder")
    from planner.batch.generate import GenerateSettings, generate_dataset

    settings = GenerateSettings(
        hands=hands,
        splits=args.splits,
        category_names=args.categories,
        objects_per_category=args.objects_per_category,
        start_seed=args.start_seed,
        variants=args.variants,
        max_candidates=args.candidates,
        protocol=args.preset,
        validate_all=not args.first_only,
        transfer=not args.no_transfer,
        transfer_per_pair=args.transfer_per_pair or None,
        block_seeds=args.block_seeds,
        extra_variants=args.extra_variants,
        workers=args.workers,
        ray=args.ray,
        ray_address=args.ray_address,
        progress=not args.no_progress,
    )
    info = generate_dataset(args.out, settings, args.work, _command())
    print_info(info)
    print(f"wrote {args.out} (card: {Path(args.out) / 'card.md'})")
    return 0


def run_refresh(args: argparse.Namespace) -> int:
    input_folder(args.root, "dataset folder")
    from planner.batch.generate import refresh_dataset

    info = refresh_dataset(
        args.root,
        args.categories,
        work=args.work,
        workers=args.workers,
        ray=args.ray,
        ray_address=args.ray_address,
        progress=not args.no_progress,
    )
    print_info(info)
    print(f"refreshed {args.root} (card: {Path(args.root) / 'card.md'})")
    return 0


def run_compact(args: argparse.Namespace) -> int:
    from planner.batch.runner import check_results_folder

    for folder in args.results:
        check_results_folder(input_folder(folder, "batch results folder"))
    output_folder(args.out, "dataset folder (--out)")
    from planner.batch.dataset import compact

    print_info(compact(args.results, args.out, _command()))
    return 0


def run_check_intents(args: argparse.Namespace) -> int:
    input_folder(args.root, "dataset folder")
    from tqdm import tqdm

    from learned.dataset import read_meta
    from planner.batch.intents import check_intents, pending_blocks

    blocks, todo = read_meta(args.root)["blocks"], pending_blocks(args.root)
    with tqdm(total=len(todo), desc="check-intents", unit="block") as bar:
        done = check_intents(args.root, args.workers, lambda name, rows: bar.update(1), todo)
    print(f"checked {len(done)} block(s); {len(blocks) - len(done)} were checked before")
    return 0


def run_info(args: argparse.Namespace) -> int:
    input_folder(args.root, "dataset folder")
    from learned.dataset import dataset_info

    info = dataset_info(args.root)
    if args.json:
        print(json.dumps(info, indent=2))
    else:
        print_info(info)
    return 0


def print_info(info: dict) -> None:
    print(f"{info['root']}: {info['total']} grasps")
    for key in ("splits", "hands", "categories", "intents", "sources"):
        print(f"  {key}: " + ", ".join(f"{k} {v}" for k, v in info[key].items()))
    met = ", ".join(f"{k} {v}" for k, v in info["intents_met"].items())
    print(
        f"  meeting each intent's definition: {met}; none {info['meets_none']}; not checked "
        f"{info['intents_unchecked']} (drograsp dataset check-intents)"
    )
