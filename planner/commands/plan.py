"""`drograsp plan`: plan one functional grasp and write it.

Every argument is checked before the work (the `--out` file's folder and format included), so
a bad one costs nothing and a finished plan is never lost. Exit code 0: a grasp holds; 1: none
holds; 2: bad input.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from models.errors import DrograspError
from models.hand_names import check_hand_name
from models.objects.names import CATEGORY_NAMES
from models.paths import output_file
from planner.commands.args import PRESET_NAMES, non_negative_int, positive_int

GRASP_SUFFIXES = (".json", ".npz")


def add_object_arguments(p: argparse.ArgumentParser) -> None:
    """--object/--seed for a library object, or --mesh/--part-labels for your own."""
    group = p.add_mutually_exclusive_group(required=True)
    group.add_argument(
        "--object", choices=CATEGORY_NAMES, metavar="CATEGORY", help="library category"
    )
    group.add_argument("--mesh", metavar="FILE", help="your mesh or point cloud (metres)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="library instance (default 0)")
    p.add_argument(
        "--part-labels",
        metavar="FILE",
        help="part labels JSON for --mesh (`drograsp objects label MESH OUT.json` writes one)",
    )
    p.add_argument(
        "--viewpoint",
        nargs=3,
        type=float,
        metavar=("X", "Y", "Z"),
        help="camera position (metres, the cloud's frame) when --mesh is a single-view scan: "
        "normals face it and the hidden side is completed by mirror symmetry before planning",
    )
    p.add_argument(
        "--pieces",
        choices=("auto", "coacd", "surface"),
        default="auto",
        help="collision pieces of --mesh: auto (CoACD for a watertight mesh, surface pieces "
        "for an open one), coacd, or surface (fast, from surface samples)",
    )


def check_object_arguments(parser_name: str, args: argparse.Namespace) -> None:
    if getattr(args, "viewpoint", None) and not args.mesh:
        raise DrograspError(
            f"--viewpoint places the camera of a scanned cloud (--mesh); a library object "
            f"(--object) is whole (drograsp {parser_name})"
        )
    if args.part_labels and not args.mesh:
        raise DrograspError(
            f"--part-labels labels --mesh; a library object (--object) has its own parts "
            f"(drograsp {parser_name})"
        )


def object_from_args(args: argparse.Namespace) -> Any:
    from models.objects import make_object
    from planner.objectref import load_labelled

    if args.object:
        return make_object(args.object, args.seed)
    viewpoint = getattr(args, "viewpoint", None)
    obj = load_labelled(args.mesh, args.part_labels, viewpoint=viewpoint)
    if viewpoint is not None and obj.mesh is not None:
        raise DrograspError(
            f"--viewpoint is for a single-view point cloud; {args.mesh} is a mesh, which is "
            "planned on whole"
        )
    if obj.mesh is not None:
        obj.pieces = getattr(args, "pieces", "auto")
    return obj


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "plan",
        help="plan a functional grasp for an object, an instruction and a hand",
        description="Propose wrist poses and anchors on the instructed part, solve the Drake "
        "grasp program, validate in MuJoCo, and write the best grasp that holds. Exit code 0: "
        "a grasp holds; 1: none holds; 2: bad input.",
    )
    add_object_arguments(p)
    p.add_argument(
        "--text",
        required=True,
        help='instruction: "Use a mug by handle", or any sentence for the learned proposer '
        '("grab the mug by its handle")',
    )
    p.add_argument("--hand", default="shadow", help="built-in hand name or hand folder")
    p.add_argument("--out", metavar="FILE", help="write the grasp (.json or .npz)")
    p.add_argument(
        "--candidates", type=positive_int, default=8, help="grasps validated at most (default 8)"
    )
    p.add_argument(
        "--preset", default="paper", choices=PRESET_NAMES, help="validation preset (default paper)"
    )
    p.add_argument(
        "--proposer",
        default="auto",
        choices=("auto", "model", "learned", "direct"),  # planner.settings.PROPOSERS
        help="where proposals come from: model (needs part labels), learned (interaction "
        "diffusion -> D(R,O); any cloud, any sentence), auto (model where the object has part "
        "labels and the instruction parses; default), direct (the ablation: wrist and joints "
        "drawn by one diffusion model, validated as drawn)",
    )
    p.add_argument(
        "--samples",
        type=positive_int,
        default=16,
        help="samples the learned (or direct) proposer draws (default 16)",
    )
    p.add_argument(
        "--set",
        nargs="+",
        default=[],
        metavar="KEY=VALUE",
        help="any planner setting by its dotted key (planner.settings.with_overrides), e.g. "
        "--set schedule.solve_batch=4 intent.aware=false learned.seed=1",
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.set_defaults(func=run)


def print_summary(result: Any) -> None:
    s = result.summary()
    status = {
        "holds": "holds",
        "uncertain": "UNCERTAIN (held on the cloud, slipped on a cloud check)",
        "none": "NO GRASP FOUND",
    }[s["status"]]
    print(f"{s['hand']}: {s['instruction']}: {status} ({s['proposer']} proposals)")
    read = s["understood"]
    if read is not None and not read["parsed"]:
        print(
            f"  read {read['text']!r} as {read['understood_as']!r} (similarity "
            f"{read['similarity']:.2f}; next {read['runner_up']!r} {read['runner_up_similarity']:.2f})"
        )
    if read is not None and read.get("model_labels"):
        found = ", ".join(f"{part} {n}" for part, n in read["model_labels"].items())
        print(
            f"  parts found by the interaction model (seed points: {found}); the intent is "
            "checked on them"
        )
    print(f"  part touched: {s['part_touched']} (instructed: {s['part_instructed']})")
    if s["anchor_error_mm"] is not None:
        print(f"  anchor error: {s['anchor_error_mm']:.1f} mm")
    chosen = (
        "none chosen"
        if s["chosen_rank"] is None
        else f"chosen: {s['chosen_kind']} proposal {s['chosen_rank']}, "
        f"validated as #{s['chosen_validated_as']}, squeeze depth {s['chosen_squeeze_depth']:g}"
        f" from a {s['chosen_pregrasp_rule']} pregrasp"
    )
    print(
        f"  candidates: {s['candidates_solved']} solved, {s['candidates_validated']} validated; "
        f"{chosen}"
    )
    if s["intent"] is not None:
        print(f"  intent: {'met' if s['intent_ok'] else 'NOT met'}: {s['intent']}")
    times = ", ".join(f"{k} {v:.2f} s" for k, v in s["times_s"].items())
    print(f"  time per stage: {times}")
    for note in s["notes"]:
        print(f"  note: {note}")


def save_result(grasp: Any, out: Path) -> Path:
    """Write the grasp; if that fails after all (a full disk), keep it in a temporary file and
    say where, so the work is not lost."""
    try:
        return grasp.save(out)
    except DrograspError as err:
        fd, spare = tempfile.mkstemp(prefix="drograsp_grasp_", suffix=out.suffix)
        import os

        os.close(fd)
        grasp.save(spare)
        raise DrograspError(f"{err}; the grasp was kept in {spare}") from None


def run(args: argparse.Namespace) -> int:
    from models.objects import parse_instruction

    check_object_arguments("plan", args)
    if args.proposer == "model":
        parse_instruction(args.text)
    elif not args.text.strip():
        parse_instruction(args.text)  # the empty-instruction error
    check_hand_name(args.hand)
    out = output_file(args.out, GRASP_SUFFIXES, "--out grasp file") if args.out else None

    from planner.api import check_settings
    from planner.commands.validate import parse_overrides
    from planner.functional import FunctionalPlanner
    from planner.objectref import object_ref
    from planner.settings import LearnedSettings, PlannerSettings, ScheduleSettings, with_overrides

    settings = PlannerSettings(
        proposer=args.proposer,
        protocol=args.preset,
        schedule=ScheduleSettings(max_candidates=args.candidates),
        learned=LearnedSettings(samples=args.samples),
    )
    settings = check_settings(with_overrides(settings, parse_overrides(args.set)))
    obj = object_from_args(args)
    planner = FunctionalPlanner(args.hand, settings)
    chosen = planner.proposer_for(obj, args.text)
    learned = chosen in ("learned", "direct")
    if not learned and not obj.labelled:
        raise DrograspError(
            "the object has no part labels, so the planner cannot find the instructed part; "
            "give --part-labels FILE (`drograsp objects label MESH OUT.json` writes one) or a "
            "library object (--object), or plan with --proposer learned"
        )
    if not learned:
        parse_instruction(args.text)
    source = f"{args.samples} {chosen} proposals" if learned else "model-based proposals"
    print(
        f"planning {args.text!r} with {args.hand} from {source}: up to {args.candidates} "
        "candidates solved (Drake) and validated (MuJoCo)...",
        file=sys.stderr,
        flush=True,
    )
    result = planner.plan(obj, args.text)
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
        print(
            f"drograsp plan: no grasp found for {args.text!r} with {args.hand} ({tried})",
            file=sys.stderr,
        )
        return 1
    if out is not None:
        result.grasp.metrics["object"] = object_ref(obj)
        save_result(result.grasp, out)
        print(f"wrote {out}")
    return 0 if result.success else 1
