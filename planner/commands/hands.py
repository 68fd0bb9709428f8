"""`drograsp hands`: the built-in hands and what the planner knows about each."""

from __future__ import annotations

import argparse
import json


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "hands",
        help="list the built-in hands (DoF, joints, actuators and couplings, fingertips, anchor fingers)",
        description="List the built-in robot hands, or describe one hand (a built-in name or a "
        "folder holding your own hand.urdf and hand.json).",
    )
    p.add_argument("hand", nargs="?", help="one hand: a built-in name or a hand folder")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from models.hands import available_hands, load_hand  # torch: seconds, so only when run

    names = [args.hand] if args.hand else available_hands()
    hands = [load_hand(n).describe() for n in names]
    if args.json:
        print(json.dumps(hands, indent=2))
        return 0
    for h in hands:
        print(f"{h['name']}: {h['dof']} DoF, {h['links']} links, actuator kp {h['kp']:g}")
        print(f"  source:      {h['source']}")
        tips = ", ".join(f"{t['name']} ({t['link']})" for t in h["fingertips"])
        print(f"  fingertips:  {tips}")
        print(f"  anchors:     {', '.join(h['anchor_fingers'])}  (K = {len(h['anchor_fingers'])})")
        retry = ", ".join(f"{d:g}" for d in h["retry_squeeze_depths"])
        print(
            f"  closing:     pregrasp {1000 * h['pregrasp_clearance']:g} mm off, squeeze depth "
            f"{h['squeeze_depth']:g}"
            + (f", retried at {retry} in turn after a slip" if retry else "")
        )
        print(f"  proposals:   {h['pinch_proposals']} pinch proposals after the regular ones")
        print(
            f"  actuators:   {len(h['actuators'])} position actuators for {h['dof']} joints"
            + ("" if h["couplings"] else " (one per joint)")
        )
        for c in h["couplings"]:
            tendon = " + ".join(
                f"{k:g} x {j}" for j, k in zip(c["joints"], c["tendon"], strict=True)
            )
            ratio = ":".join(f"{r:g}" for r in c["plan_ratio"])
            print(f"    {c['name']:<10} drives the tendon {tendon}; planned in ratio {ratio}")
        print("  joints:      name [lower, upper] rad, closing direction")
        for j in h["joints"]:
            close = {1: "+ closes", -1: "- closes", 0: "spreads"}[j["closing"]]
            print(f"    {j['name']:<10} [{j['lower']:+.3f}, {j['upper']:+.3f}]  {close}")
        print()
    return 0
