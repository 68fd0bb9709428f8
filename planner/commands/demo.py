"""`drograsp demo`: the main job on built-in defaults, end to end, for every built-in hand."""

from __future__ import annotations

import argparse
import html
import sys
import time

from models.hand_names import builtin_hands, check_hand_name
from models.paths import output_folder, write_text_atomic

# (category, seed, instruction): one of them is the paper's running example
DEMO_TASKS = (("mug", 3, "Use a mug by handle"), ("bottle", 1, "Hold a bottle by body"))


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="plan two instructions on built-in objects with every hand; write a viewer page",
        description="Plan 'Use a mug by handle' and 'Hold a bottle by body' with each built-in "
        "hand (Drake grasp program + MuJoCo validation), print a table, and write HTML pages "
        "showing every grasp.",
    )
    p.add_argument(
        "--out", default="drograsp_demo", help="folder for the pages (default drograsp_demo)"
    )
    p.add_argument("--hands", nargs="+", default=None, help="hands to run (default: all built-in)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    hands = [check_hand_name(h) for h in (args.hands or builtin_hands())]
    out = output_folder(args.out, "demo folder (--out)")

    from models.hands import load_hand
    from models.objects import make_object
    from planner.functional import FunctionalPlanner
    from planner.objectref import object_ref
    from planner.viewer import write_html

    print(
        f"planning {len(DEMO_TASKS)} instructions with {len(hands)} hands (a few seconds each)",
        file=sys.stderr,
        flush=True,
    )
    rows = []
    header = f"{'hand':<8} {'instruction':<24} {'success':<8} {'part touched':<13} {'time s':>7}"
    print(header)
    print("-" * len(header))
    for hand_name in hands:
        hand = load_hand(hand_name)
        planner = FunctionalPlanner(hand)
        for category, seed, text in DEMO_TASKS:
            obj = make_object(category, seed)
            start = time.perf_counter()
            result = planner.plan(obj, text)
            elapsed = time.perf_counter() - start
            page = None
            if result.grasp is not None:
                result.grasp.metrics["object"] = object_ref(obj)
                stem = f"{hand_name}_{category}_{seed}"
                result.grasp.save(out / f"{stem}.json")
                page = write_html(result.grasp, obj, hand, out / f"{stem}.html").name
            rows.append((hand_name, text, result.success, result.part_touched, elapsed, page))
            print(
                f"{hand_name:<8} {text:<24} {'yes' if result.success else 'no':<8} "
                f"{result.part_touched or '-':<13} {elapsed:>7.2f}",
                flush=True,
            )
    index = write_text_atomic(out / "index.html", _index_page(rows), "demo index page")
    held = sum(r[2] for r in rows)
    print(f"\n{held}/{len(rows)} grasps hold; open {index} to see them")
    return 0 if held else 1


def _index_page(rows) -> str:
    body = "".join(
        f"<tr><td>{html.escape(h)}</td><td>{html.escape(t)}</td><td>{'yes' if ok else 'no'}</td>"
        f"<td>{html.escape(p or '-')}</td><td>{s:.2f}</td>"
        f"<td>{f'<a href={page!r}>view</a>' if page else '-'}</td></tr>"
        for h, t, ok, p, s, page in rows
    )
    return (
        "<!doctype html><meta charset=utf-8><title>drograsp demo</title>"
        "<style>body{font-family:sans-serif}td,th{padding:4px 10px}</style>"
        "<h1>drograsp demo</h1><table><tr><th>hand</th><th>instruction</th><th>holds</th>"
        f"<th>part touched</th><th>time (s)</th><th>grasp</th></tr>{body}</table>"
    )
