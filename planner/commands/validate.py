"""`drograsp validate`: check grasps in DexGraspBench's layout with the MuJoCo validator.

Reads an NPZ like ../shared/reference/dexgraspbench/grasps.npz (object, scale, obj_pose and
{pregrasp,grasp,squeeze}_qpos rows: 7 root values then the hand XML's joints), prints the success
rate and mean displacement, and the agreement with `reference_success` when the file has it.
`--out` writes the per-grasp results as JSON (checked before the work). Exit code 0: at least
one grasp holds; 1: none holds; 2: bad input.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from models.errors import DrograspError
from models.paths import input_file, input_folder, output_file, write_text_atomic
from planner.commands.args import PRESET_NAMES, positive_int


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "validate",
        help="simulate grasps (DexGraspBench layout) and report which hold",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("file", type=Path, help="grasps NPZ in DexGraspBench's layout")
    hand = p.add_mutually_exclusive_group(required=True)
    hand.add_argument("--hand-xml", type=Path, help="MJCF hand whose joint order the rows follow")
    hand.add_argument("--hand", help="built-in hand name (rows follow its joint order)")
    p.add_argument("--joint-map", type=Path, help="JSON {grasp joint: XML joint} for --hand-xml")
    p.add_argument("--objects", type=Path, required=True, help="folder of <object>/convex_pieces")
    p.add_argument("--preset", default="dexgraspbench", choices=PRESET_NAMES)
    p.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a protocol setting, e.g. --set hold_time=3 (repeatable)",
    )
    p.add_argument("--all-directions", action="store_true", help="test all six directions")
    p.add_argument(
        "--workers", type=positive_int, default=None, help="processes (default: all cores)"
    )
    p.add_argument(
        "--limit", type=positive_int, default=None, help="validate only the first N grasps"
    )
    p.add_argument("--json", action="store_true", help="print the summary as JSON")
    p.add_argument("--out", type=Path, help="write per-grasp results to this JSON file (.json)")
    p.set_defaults(func=run)


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """`--set KEY=VALUE` items as a dict; values are JSON where they parse (60, 0.5, false,
    [1, 2] as a tuple), True/False as booleans, else strings."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, text = item.partition("=")
        if not sep:
            raise DrograspError(f"--set expects KEY=VALUE, got {item!r}")
        try:
            value = json.loads(text)
        except json.JSONDecodeError:
            value = {"True": True, "False": False}.get(text, text)
        out[key.strip()] = tuple(value) if isinstance(value, list) else value
    return out


def _joint_map(path: Path | None) -> dict[str, str]:
    if path is None:
        return {}
    path = input_file(path, "joint map")
    try:
        data = json.loads(path.read_bytes().decode("utf-8"))
    except ValueError as err:
        raise DrograspError(f"joint map {path} is not JSON: {err}") from None
    if not isinstance(data, dict) or not all(
        isinstance(k, str) and isinstance(v, str) for k, v in data.items()
    ):
        raise DrograspError(
            f"joint map {path}: expected a JSON object of names, {{grasp joint: XML joint}}"
        )
    return data


def _hand(args: argparse.Namespace) -> tuple[Any, tuple[str, ...], dict[str, str]]:
    from planner.validation.hands import mjcf_hand, mjcf_joint_names, project_hand

    if args.hand:
        adapter = project_hand(args.hand)
        return adapter, adapter.joint_names, {}
    if args.joint_map and not args.hand_xml:
        raise DrograspError("--joint-map maps the joints of --hand-xml; give the hand file too")
    joint_map = _joint_map(args.joint_map)
    xml = input_file(args.hand_xml, "MJCF hand file (--hand-xml)")
    xml_joints = mjcf_joint_names(str(xml.resolve()))
    adapter = mjcf_hand(xml, joint_map)
    return adapter, xml_joints, joint_map


def _summary(rows: dict[str, Any], results: list, wall: float, preset: str) -> dict:
    import numpy as np

    ok = np.array([r.success for r in results], dtype=bool)
    tested = [r for r in results if r.directions]
    summary: dict[str, Any] = {
        "grasps": len(results),
        "preset": preset,
        "success_rate": float(ok.mean()) if len(ok) else 0.0,
        "successes": int(ok.sum()),
        "pregrasp_penetration_failures": sum(r.reason == "pregrasp_penetration" for r in results),
        "pregrasp_self_penetration_failures": sum(
            r.reason == "pregrasp_self_penetration" for r in results
        ),
        "unstable_simulations": sum(
            r.reason == "unstable" or any("unstable" in w for w in r.warnings) for r in results
        ),
        "mean_translation_m": float(np.mean([r.translation for r in tested])) if tested else None,
        "mean_rotation_deg": float(np.mean([r.rotation_deg for r in tested])) if tested else None,
        "mean_wall_time_s": float(np.mean([r.wall_time for r in results])) if results else 0.0,
        "total_wall_time_s": wall,
    }
    if "reference_success" in rows:
        ref = rows["reference_success"].astype(bool)[: len(ok)]
        summary["reference_success_rate"] = float(ref.mean())
        summary["agreement"] = float((ref == ok).mean())
        summary["agree"] = int((ref == ok).sum())
        summary["false_success"] = int((ok & ~ref).sum())
        summary["false_failure"] = int((~ok & ref).sum())
    return summary


def run(args: argparse.Namespace) -> int:
    from planner.validation.protocol import get_protocol

    protocol = get_protocol(args.preset, **parse_overrides(args.set))
    out = output_file(args.out, (".json",), "--out results file") if args.out else None
    input_folder(args.objects, "objects folder (--objects)")

    from planner.validation.batch import validate_many
    from planner.validation.layout import read_rows, row_case

    rows = read_rows(args.file, args.limit)
    adapter, xml_joints, joint_map = _hand(args)
    n = len(rows["grasp_qpos"])
    cases = [row_case(rows, i, adapter, xml_joints, args.objects, joint_map) for i in range(n)]
    grasps = [grasp for grasp, _ in cases]
    objects = [obj for _, obj in cases]
    poses = rows.get("obj_pose")
    start = time.perf_counter()
    results = validate_many(
        grasps,
        objects,
        adapter,
        protocol,
        object_poses=None if poses is None else list(poses),
        workers=args.workers,
        all_directions=args.all_directions or None,
        progress=True,
    )
    summary = _summary(rows, results, time.perf_counter() - start, args.preset)
    if out is not None:
        per_grasp = []
        for i, r in enumerate(results):
            entry = {"index": i, "object": str(rows["object"][i]), "scale": float(rows["scale"][i])}
            if "reference_success" in rows:
                entry["reference_success"] = bool(rows["reference_success"][i])
            per_grasp.append(entry | r.to_dict())
        text = json.dumps({"summary": summary, "grasps": per_grasp}, indent=1)
        write_text_atomic(out, text, "--out results file")
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(
            f"{summary['grasps']} grasps, preset {args.preset}: success "
            f"{summary['success_rate']:.1%} ({summary['successes']}); mean displacement "
            f"{(summary['mean_translation_m'] or 0) * 100:.2f} cm, "
            f"{summary['mean_rotation_deg'] or 0:.2f} deg; "
            f"{summary['mean_wall_time_s']:.2f} s per grasp"
        )
        if summary["unstable_simulations"]:
            print(
                f"{summary['unstable_simulations']} simulation(s) went unstable (MuJoCo reset "
                "them; such a grasp fails as 'unstable'); `--out` lists each grasp's warnings"
            )
        if "agreement" in summary:
            print(
                f"agreement with reference_success: {summary['agreement']:.1%} "
                f"({summary['agree']}/{summary['grasps']}; reference success "
                f"{summary['reference_success_rate']:.1%}; {summary['false_success']} false "
                f"successes, {summary['false_failure']} false failures)"
            )
    return 0 if summary["successes"] else 1
