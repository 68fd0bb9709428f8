"""`drograsp plan`: plan one functional grasp and write it."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from models.errors import DrograspError
from models.objects import categories, make_object
from planner.functional import FunctionalPlanner, PlannerSettings, PlanResult
from planner.objectref import load_labelled, object_ref


def add_object_arguments(p: argparse.ArgumentParser) -> None:
    """--object/--seed for a library object, or --mesh/--part-labels for your own."""
    group = p.add_mutually_exclusive_group(required=True)
    group.add_argument(
        "--object", choices=categories(), metavar="CATEGORY", help="library category"
    )
    group.add_argument("--mesh", metavar="FILE", help="your mesh or point cloud (metres)")
    p.add_argument("--seed", type=int, default=0, help="library instance (default 0)")
    p.add_argument("--part-labels", metavar="FILE", help="part labels JSON for --mesh")


def object_from_args(args: argparse.Namespace):
    if args.object:
        return make_object(args.object, args.seed)
    return load_labelled(args.mesh, args.part_labels)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="plan a functional grasp for an object, an instruction and a hand",
        description="Propose wrist poses and anchors on the instructed part, solve the Drake "
        "grasp program, validate in MuJoCo, and write the best grasp that holds.",
    )
    add_object_arguments(p)
    p.add_argument("--text", required=True, help='instruction, e.g. "Use a mug by handle"')
    p.add_argument("--hand", default="shadow", help="built-in hand name or hand folder")
    p.add_argument("--out", metavar="FILE", help="write the grasp (.json or .npz)")
    p.add_argument("--candidates", type=int, default=8, help="proposals to try (default 8)")
    p.add_argument("--preset", default="paper", help="validation preset (default paper)")
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def print_summary(result: PlanResult) -> None:
    s = result.summary()
    status = "holds" if s["success"] else "NO GRASP FOUND"
    print(f"{s['hand']}: {s['instruction']}: {status}")
    print(f"  part touched: {s['part_touched']} (instructed: {s['part_instructed']})")
    if s["anchor_error_mm"] is not None:
        print(f"  anchor error: {s['anchor_error_mm']:.1f} mm")
    chosen = (
        "none chosen"
        if s["chosen_rank"] is None
        else f"chosen: {s['chosen_kind']} proposal {s['chosen_rank']}, "
        f"validated as #{s['chosen_validated_as']}, squeeze depth {s['chosen_squeeze_depth']:g}"
    )
    print(
        f"  candidates: {s['candidates_solved']} solved, {s['candidates_validated']} validated; "
        f"{chosen}"
    )
    times = ", ".join(f"{k} {v:.2f} s" for k, v in s["times_s"].items())
    print(f"  time per stage: {times}")
    for note in s["notes"]:
        print(f"  note: {note}")


def run(args: argparse.Namespace) -> int:
    obj = object_from_args(args)
    settings = PlannerSettings(max_candidates=args.candidates, protocol=args.preset)
    result = FunctionalPlanner(args.hand, settings).plan(obj, args.text)
    if args.json:
        print(json.dumps(result.summary(), indent=2))
    else:
        print_summary(result)
    if result.grasp is None:
        tried = "; ".join(
            f"#{c.rank}: "
            + (c.solve.message or ("slipped in validation" if c.order is not None else "not tried"))
            for c in result.candidates
        )
        raise DrograspError(f"no grasp found for {args.text!r} with {args.hand} ({tried})")
    if args.out:
        result.grasp.metrics["object"] = object_ref(obj)
        result.grasp.save(Path(args.out))
        print(f"wrote {args.out}")
    return 0 if result.success else 1
