"""`drograsp objects`: list the procedural library, export an instance, draw the contact sheet."""

from __future__ import annotations

import argparse
import json
import sys

from models.objects import (
    CATEGORIES,
    HELDOUT,
    categories,
    export_object,
    instructions,
    make_object,
    split_of,
)


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "objects",
        help="list the procedural object library, export an object, draw the contact sheet",
        description=(
            "Without an action: list categories, parts and instructions. "
            "'export' writes one instance as OBJ with its part labels; 'sheet' draws every category."
        ),
    )
    p.add_argument("--json", action="store_true", help="print the listing as JSON")
    actions = p.add_subparsers(dest="action", metavar="ACTION")
    ex = actions.add_parser(
        "export", help="write CATEGORY instance SEED as OUT.obj + OUT.parts.json"
    )
    ex.add_argument("category", choices=categories(), metavar="CATEGORY")
    ex.add_argument("out", metavar="OUT.obj")
    ex.add_argument("--seed", type=int, default=0, help="instance number (default 0)")
    sh = actions.add_parser("sheet", help="write a PNG contact sheet of every category")
    sh.add_argument("out", metavar="OUT.png")
    sh.add_argument("--seed", type=int, default=0, help="instance drawn per category (default 0)")
    p.set_defaults(func=run)


def listing() -> list[dict]:
    """One entry per category: parts, instruction texts, held-out flag."""
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


def run(args: argparse.Namespace) -> int:
    if args.action == "export":
        obj = make_object(args.category, args.seed)
        mesh_path, parts_path = export_object(obj, args.out)
        print(f"wrote {mesh_path} ({len(obj.mesh.faces)} faces, watertight)")
        print(
            f"wrote {parts_path} (parts: {', '.join(obj.part_names)};"
            f" split: {split_of(obj.category, obj.seed)})"
        )
        return 0
    if args.action == "sheet":
        from models.objects.sheet import write_sheet

        path = write_sheet(args.out, seed=args.seed)
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
