"""`drograsp export`: write the project's grasps in another benchmark's layout.

`drograsp export dexgraspbench OUT_DIR GRASP... --hand-xml HAND_FILE` writes OUT_DIR/grasps.npz
(DexGraspBench's rows: the hand file's root frame in the world, then its joints in file order)
and each grasp's object under OUT_DIR/objects/<name>/ (convex_pieces/, simplified.obj,
info.json), so that `drograsp validate OUT_DIR/grasps.npz --hand-xml HAND_FILE --objects
OUT_DIR/objects` (or DexGraspBench itself) simulates the same grasps with that hand file. The
transform between the project hand's root link and the file's root frame is computed from the
two hands' files.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from models.objects import categories


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "export",
        help="write grasps in another benchmark's layout (DexGraspBench)",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    formats = p.add_subparsers(dest="format", metavar="FORMAT", required=True)
    d = formats.add_parser(
        "dexgraspbench",
        help="grasps.npz rows in a hand file's frame, plus the objects' folders",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    d.add_argument("out_dir", type=Path, metavar="OUT_DIR", help="folder to write into")
    d.add_argument(
        "grasps", nargs="+", type=Path, metavar="GRASP", help="grasp files (.json or .npz)"
    )
    d.add_argument(
        "--hand-xml",
        type=Path,
        required=True,
        metavar="HAND_FILE",
        help="the MJCF hand file the rows are for (e.g. DexGraspBench's shadow_right_hand.xml)",
    )
    d.add_argument(
        "--joint-map", type=Path, help="JSON {grasp joint: XML joint} where the names differ"
    )
    d.add_argument(
        "--object",
        choices=categories(),
        metavar="CATEGORY",
        help="library object of every grasp (default: the one each grasp file names)",
    )
    d.add_argument("--seed", type=int, default=0, help="library instance (default 0)")
    d.add_argument("--mesh", metavar="FILE", help="your mesh or point cloud, for every grasp")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.errors import DrograspError
    from models.grasp import Grasp
    from planner.dexgraspbench import check_out_dir, export_dexgraspbench, read_joint_map

    check_out_dir(args.out_dir)  # before any work
    if args.object and args.mesh:
        raise DrograspError("give --object or --mesh, not both")
    if not args.hand_xml.is_file():
        raise DrograspError(f"{args.hand_xml}: no such hand file")
    joint_map = read_joint_map(args.joint_map)
    grasps = [Grasp.load(path) for path in args.grasps]
    override = None
    if args.object:
        from models.objects import make_object

        override = make_object(args.object, args.seed)
    elif args.mesh:
        from planner.objectref import load_labelled

        override = load_labelled(args.mesh)
    result = export_dexgraspbench(
        grasps, args.out_dir, args.hand_xml, joint_map=joint_map, objects=override
    )
    pose = " ".join(f"{v:.6g}" for v in result.root_offset.pose)
    print(
        f"wrote {result.grasps_file}: {len(grasps)} {result.hand} grasp(s) in the frame of "
        f"{args.hand_xml.name} (its root in the {result.hand} root link frame: xyz wxyz {pose}); "
        f"{len(result.objects_written)} object(s) in {result.objects_dir}"
    )
    print(
        f"check: drograsp validate {result.grasps_file} --hand-xml {args.hand_xml} "
        f"--objects {result.objects_dir}" + (f" --joint-map {args.joint_map}" if joint_map else "")
    )
    return 0
