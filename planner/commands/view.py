"""`drograsp view`: inspect a saved grasp in Drake's Meshcat."""

from __future__ import annotations

import argparse

from models.objects.names import CATEGORY_NAMES
from models.paths import output_file
from planner.commands.args import non_negative_int, positive_float


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "view",
        help="show a grasp in Meshcat (live on localhost, or as a self-contained HTML page)",
        description="Show the object (parts coloured), the hand at pregrasp, grasp and squeeze, "
        "and the anchors. The object comes from the grasp file unless given here. Meshcat "
        "listens on localhost only.",
    )
    p.add_argument("grasp", metavar="GRASP", help="a grasp file (.json or .npz)")
    p.add_argument("--html", metavar="OUT.html", help="write a page instead of serving live")
    p.add_argument("--object", choices=CATEGORY_NAMES, metavar="CATEGORY", help="library category")
    p.add_argument("--seed", type=non_negative_int, default=0, help="library instance (default 0)")
    p.add_argument("--mesh", metavar="FILE", help="your mesh or point cloud")
    p.add_argument("--part-labels", metavar="FILE", help="part labels JSON for --mesh")
    p.add_argument(
        "--seconds", type=positive_float, default=None, help="stop serving after this long"
    )
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.errors import DrograspError
    from models.grasp import Grasp

    if args.object and args.mesh:
        raise DrograspError("give --object or --mesh, not both")
    if args.part_labels and not args.mesh:
        raise DrograspError("--part-labels labels --mesh; give the mesh too")
    html = output_file(args.html, (".html", ".htm"), "--html page") if args.html else None
    grasp = Grasp.load(args.grasp)

    from models.hands import load_hand
    from models.objects import make_object
    from planner.objectref import load_labelled, resolve_object
    from planner.viewer import show_live, write_html

    if args.object:
        obj = make_object(args.object, args.seed)
    elif args.mesh:
        obj = load_labelled(args.mesh, args.part_labels)
    else:
        obj = resolve_object(grasp.metrics.get("object", {}))
    hand = load_hand(grasp.hand)
    grasp.check_hand(hand.joint_names, hand.name)
    if html is not None:
        print(f"wrote {write_html(grasp, obj, hand, html)}")
        return 0
    try:
        show_live(grasp, obj, hand, args.seconds)
    except KeyboardInterrupt:
        pass
    return 0
