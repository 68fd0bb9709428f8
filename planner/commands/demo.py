"""`drograsp demo`: the main job on built-in defaults, end to end, for every built-in hand."""

from __future__ import annotations

import argparse
import html
import sys
import time

from models.hand_names import builtin_hands, check_hand_name
from models.paths import output_folder, write_text_atomic

# (category, seed, instruction): the paper's running example, the same handle taken for
# another intent (Liftup: from above, palm down), and a power grasp
DEMO_TASKS = (
    ("mug", 3, "Use a mug by handle"),
    ("mug", 3, "Liftup a mug by handle"),
    ("bottle", 1, "Hold a bottle by body"),
)
# the two tasks the index page shows side by side for each hand: one part, two intents
SIDE_BY_SIDE = ("Use a mug by handle", "Liftup a mug by handle")
# (category, seed, sentence): unlabelled clouds (4096 surface points, no part labels) and
# free-form sentences, planned by the learned stages (interaction diffusion -> D(R,O))
LEARNED_TASKS = (
    ("mug", 3, "grab the mug by its handle"),
    ("bottle", 1, "hold the bottle around its body"),
    ("knife", 2, "hand me the knife handle first"),
)
CLOUD_POINTS = 4096


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "demo",
        help="plan three instructions on built-in objects with every hand; write viewer pages",
        description="Plan 'Use a mug by handle', 'Liftup a mug by handle' and 'Hold a bottle by "
        "body' with each built-in hand (model-based proposals, Drake grasp program, MuJoCo "
        "validation), then free-form sentences on unlabelled clouds with the learned stages; "
        "print a table (does each grasp hold, on which part, does it meet its intent), and "
        "write HTML pages showing every grasp, the two intents on the mug's handle side by side.",
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
    header = (
        f"{'hand':<8} {'instruction':<24} {'holds':<9} {'part touched':<13} "
        f"{'intent met':<10} {'time s':>7}"
    )
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
                stem = f"{hand_name}_{category}_{seed}_{text.split()[0].lower()}"
                result.grasp.save(out / f"{stem}.json")
                page = write_html(result.grasp, obj, hand, out / f"{stem}.html").name
            intent = _yes_no(result.intent_ok)
            row = (hand_name, text, result.status, result.part_touched, intent, elapsed, page)
            rows.append(row)
            print(
                f"{hand_name:<8} {text:<24} {_holds(result.status):<9} "
                f"{result.part_touched or '-':<13} {intent:<10} {elapsed:>7.2f}",
                flush=True,
            )
    learned_rows = _learned(hands, out)
    index = write_text_atomic(
        out / "index.html", _index_page(rows, learned_rows), "demo index page"
    )
    held = sum(r[2] == "holds" for r in rows) + sum(r[3] == "holds" for r in learned_rows)
    total = len(rows) + len(learned_rows)
    print(f"\n{held}/{total} grasps hold; open {index} to see them")
    return 0 if held else 1


def _learned(hands: list[str], out) -> list[tuple]:
    """Free-form sentences on unlabelled clouds, planned on the learned stages' proposals:
    rows of (hand, sentence, read as, holds, intent met, time s, page). On the clouds the
    intent is checked without labels (Liftup), on the region the samples point at (Hold) or on
    the parts the interaction model finds (Use, Handover: planner.model_labels); "-" where it
    could not be."""
    from models.hands import load_hand
    from models.objects import load_object, make_object
    from planner.functional import FunctionalPlanner, PlannerSettings
    from planner.objectref import object_ref
    from planner.viewer import caption, write_html

    print(
        f"\nlearned stages: {len(LEARNED_TASKS)} sentences on unlabelled {CLOUD_POINTS}-point "
        "clouds (no part labels)",
        flush=True,
    )
    header = (
        f"{'hand':<8} {'sentence':<34} {'read as':<28} {'holds':<9} {'intent met':<10} "
        f"{'time s':>7}"
    )
    print(header)
    print("-" * len(header))
    rows = []
    for hand_name in hands:
        hand = load_hand(hand_name)
        planner = FunctionalPlanner(hand, PlannerSettings(proposer="learned"))
        for category, seed, sentence in LEARNED_TASKS:
            cloud = load_object(make_object(category, seed).sample_cloud(CLOUD_POINTS).points)
            start = time.perf_counter()
            result = planner.plan(cloud, sentence)
            elapsed = time.perf_counter() - start
            read = result.instruction.text
            page = None
            if result.grasp is not None:
                result.grasp.metrics["object"] = object_ref(cloud)
                stem = f"{hand_name}_{category}_{seed}_learned"
                result.grasp.save(out / f"{stem}.json")
                text = f'"{sentence}" (read as: {read}) · learned · {caption(result.grasp)}'
                page = write_html(result.grasp, cloud, hand, out / f"{stem}.html", text).name
            intent = _yes_no(result.intent_ok)
            rows.append((hand_name, sentence, read, result.status, intent, elapsed, page))
            print(
                f"{hand_name:<8} {sentence:<34} {read:<28} "
                f"{_holds(result.status):<9} {intent:<10} {elapsed:>7.2f}",
                flush=True,
            )
    return rows


def _holds(status: str) -> str:
    """The "holds" column: yes, no, or uncertain (PlanResult.status)."""
    return {"holds": "yes", "none": "no"}.get(status, status)


def _yes_no(flag: bool | None) -> str:
    return "-" if flag is None else ("yes" if flag else "no")


def _index_page(rows, learned_rows=()) -> str:
    body = "".join(
        f"<tr><td>{html.escape(h)}</td><td>{html.escape(t)}</td><td>{_holds(ok)}</td>"
        f"<td>{html.escape(p or '-')}</td><td>{i}</td><td>{s:.2f}</td>"
        f"<td>{f'<a href={page!r}>view</a>' if page else '-'}</td></tr>"
        for h, t, ok, p, i, s, page in rows
    )
    learned = "".join(
        f"<tr><td>{html.escape(h)}</td><td>{html.escape(t)}</td><td>{html.escape(read)}</td>"
        f"<td>{_holds(ok)}</td><td>{i}</td><td>{s:.2f}</td>"
        f"<td>{f'<a href={page!r}>view</a>' if page else '-'}</td></tr>"
        for h, t, read, ok, i, s, page in learned_rows
    )
    pages = {(r[0], r[1]): r[6] for r in rows}
    pairs = ""
    for hand in dict.fromkeys(r[0] for r in rows):
        cells = "".join(
            f"<td><b>{html.escape(t)}</b><br>"
            + (
                f"<iframe src={pages[hand, t]!r} width=480 height=400></iframe>"
                if pages.get((hand, t))
                else "no grasp"
            )
            + "</td>"
            for t in SIDE_BY_SIDE
        )
        pairs += f"<tr><td>{html.escape(hand)}</td>{cells}</tr>"
    return (
        "<!doctype html><meta charset=utf-8><title>drograsp demo</title>"
        "<style>body{font-family:sans-serif}td,th{padding:4px 10px;vertical-align:top}</style>"
        "<h1>drograsp demo</h1><table><tr><th>hand</th><th>instruction</th><th>holds</th>"
        "<th>part touched</th><th>meets its intent</th><th>time (s)</th><th>grasp</th></tr>"
        f"{body}</table><h2>One part, two intents</h2><table>{pairs}</table>"
        "<h2>Learned stages: unlabelled clouds, free-form sentences</h2><table><tr><th>hand"
        "</th><th>sentence</th><th>read as</th><th>holds</th><th>meets its intent</th>"
        "<th>time (s)</th><th>grasp</th>"
        f"</tr>{learned}</table>"
    )
