"""`drograsp objects`: list the procedural library, export an instance, label a mesh, draw the
contact sheet."""

from __future__ import annotations

import argparse
import json
import sys

from models.objects.names import CATEGORY_NAMES
from models.paths import output_file, write_text_atomic
from planner.commands.args import non_negative_int

SHEET_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg")


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "objects",
        help="list the procedural object library, export an object, label a mesh, draw the "
        "contact sheet",
        description=(
            "Without an action: list categories, parts and instructions. "
            "'export' writes one instance as OBJ with its part labels; 'label' writes a part "
            "labels file for your mesh in the loader's face order; 'sheet' draws every category."
        ),
    )
    p.add_argument("--json", action="store_true", help="print the listing as JSON")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    ex = actions.add_parser(
        "export", help="write CATEGORY instance SEED as OUT.obj + OUT.parts.json"
    )
    ex.add_argument("category", choices=CATEGORY_NAMES, metavar="CATEGORY")
    ex.add_argument("out", metavar="OUT.obj")
    ex.add_argument("--seed", type=non_negative_int, default=0, help="instance number (default 0)")
    lb = actions.add_parser(
        "label",
        help="write a part labels file for MESH in the loader's face order",
        description="Write OUT.json for `drograsp plan --mesh MESH --part-labels OUT.json`: "
        "one label per face in the order the loader keeps them (degenerate faces dropped), "
        "with each face's centre, so labels can be set by position and are matched to the mesh "
        "by geometry. Without --labels every face gets part 0 of --parts; with --labels, that "
        "file's labels (in the file's own face order, the loader's, or by face centres) are "
        "converted.",
    )
    lb.add_argument("mesh", metavar="MESH")
    lb.add_argument("out", metavar="OUT.json")
    lb.add_argument("--labels", metavar="FILE", help="labels to convert (see above)")
    lb.add_argument(
        "--parts",
        nargs="+",
        default=["body"],
        metavar="NAME",
        help="part names of a new labels file (default: body)",
    )
    sh = actions.add_parser("sheet", help="write a PNG contact sheet of every category")
    sh.add_argument("out", metavar="OUT.png")
    sh.add_argument(
        "--seed", type=non_negative_int, default=0, help="instance drawn per category (default 0)"
    )
    p.set_defaults(func=run)


def listing() -> list[dict]:
    """One entry per category: parts, instruction texts, held-out flag."""
    from models.objects import CATEGORIES, HELDOUT, categories, instructions

    return [
        {
            "category": name,
            "noun": CATEGORIES[name].noun,
            "parts": list(CATEGORIES[name].parts),
            "instructions": [i.text for i in instructions(name)],
            "heldout": name in HELDOUT,
            "summary": CATEGORIES[name].summary,
        }
        for name in categories()
    ]


def labels_file(mesh: str, labels: str | None, parts: list[str]) -> dict:
    """The labels file `drograsp objects label` writes, in the loader's face order."""
    import numpy as np

    from models.objects import load_object
    from models.objects.loading import part_names_arg, with_labels_file

    obj = load_object(mesh)
    if obj.mesh is None:
        from models.errors import ObjectError

        raise ObjectError(
            f"{mesh} is a point cloud; its labels are point_labels, one per point in file order"
        )
    if labels is not None:
        obj = with_labels_file(obj, labels)
        names, face_labels = obj.part_names, obj.face_labels
    else:
        names = part_names_arg(parts)
        face_labels = np.zeros(len(obj.mesh.faces), dtype=np.int64)
    return {
        "mesh": obj.source,
        "faces": len(obj.mesh.faces),
        "faces_in_file": obj.source_face_count,
        "part_names": list(names),
        "face_labels": [int(x) for x in face_labels],
        "face_centres": np.round(obj.mesh.triangles_center, 7).tolist(),
    }


def run(args: argparse.Namespace) -> int:
    if args.action == "export":
        out = output_file(args.out, (".obj",), "exported mesh")
        from models.objects import export_object, make_object, split_of

        obj = make_object(args.category, args.seed)
        mesh_path, parts_path = export_object(obj, out)
        print(f"wrote {mesh_path} ({len(obj.mesh.faces)} faces, watertight)")
        print(
            f"wrote {parts_path} (parts: {', '.join(obj.part_names)};"
            f" split: {split_of(obj.category, obj.seed)})"
        )
        return 0
    if args.action == "label":
        out = output_file(args.out, (".json",), "labels file")
        data = labels_file(args.mesh, args.labels, args.parts)
        write_text_atomic(out, json.dumps(data, separators=(",", ":")) + "\n", "labels file")
        dropped = (data["faces_in_file"] or data["faces"]) - data["faces"]
        print(
            f"wrote {out}: {data['faces']} faces in the loader's order ({dropped} degenerate "
            f"dropped), parts {', '.join(data['part_names'])}; set face_labels by face_centres "
            "and pass it as --part-labels"
        )
        return 0
    if args.action == "sheet":
        out = output_file(args.out, SHEET_SUFFIXES, "contact sheet")
        from models.objects.sheet import write_sheet

        path = write_sheet(out, seed=args.seed)
        print(f"wrote {path}")
        return 0
    rows = listing()
    if args.json:
        json.dump(rows, sys.stdout, indent=2)
        print()
        return 0
    for row in rows:
        held = "  [held out]" if row["heldout"] else ""
        print(f"{row['category']}{held}: parts {', '.join(row['parts'])}")
        for text in row["instructions"]:
            print(f"    {text}")
    return 0
